//! Policy evaluation (`mjskill eval`): success rate and mean return of a policy over seeded
//! episodes, and the episode loop `rollout` records from.
use std::path::Path;
#[cfg(feature = "onnx")]
use std::sync::Arc;

use serde::Serialize;

use crate::env::checks::MAX_SEED;
use crate::env::{make, Env, EnvConfig, EnvError};
use crate::robots::RobotError;
#[cfg(feature = "onnx")]
use crate::solvers::onnx::{PolicyFile, PolicyFileError};
use crate::solvers::{make_policy, required_control_mode, Policy, SolverError, POLICIES};

/// Why an evaluation could not run. The seed-range messages name the `eval`/`rollout` flags
/// the arguments come from.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EvalError {
    /// Zero episodes.
    #[error("--episodes must be at least 1")]
    NoEpisodes,
    /// A first seed beyond ManiSkill's 32-bit seeds.
    #[error("--seed {0} is out of range: seeds are 32-bit, 0..={MAX_SEED}")]
    SeedOutOfRange(u64),
    /// Seeds `seed..seed + episodes` run beyond the 32-bit seeds.
    #[error(
        "--seed {seed} with --episodes {episodes} needs seeds up to {last}, beyond the \
         32-bit seeds 0..={MAX_SEED}; lower --seed or --episodes"
    )]
    SeedRangeTooLong {
        /// The first seed.
        seed: u64,
        /// Episodes.
        episodes: u64,
        /// The last seed the range needs.
        last: u128,
    },
    /// The policy needs a control mode other than the one requested.
    #[error("policy {policy:?} needs control mode {required}, not {mode}")]
    ModeMismatch {
        /// The policy.
        policy: String,
        /// The mode it needs.
        required: &'static str,
        /// The requested mode.
        mode: String,
    },
    /// The requested control mode is unknown for the robot.
    #[error(transparent)]
    Robot(#[from] RobotError),
    /// The env could not be built, reset or stepped.
    #[error(transparent)]
    Env(#[from] EnvError),
    /// The policy could not be built for the env.
    #[error(transparent)]
    Policy(#[from] SolverError),
    /// The policy gave an action the env refuses (NaN or infinite entries).
    #[error("policy {policy} gave a bad action in episode {episode} (seed {seed}): {source}")]
    BadAction {
        /// The policy's name or file.
        policy: String,
        /// The episode (0 is the first).
        episode: u64,
        /// Its reset seed.
        seed: u64,
        /// The env's error.
        source: Box<EnvError>,
    },
}

impl EvalError {
    /// This error, for an episode of `policy`: an action the env refused becomes
    /// [`EvalError::BadAction`] naming the policy, the episode and its seed.
    pub fn in_episode(self, policy: &PolicySpec, episode: u64, seed: u64) -> EvalError {
        match self {
            EvalError::Env(
                source @ (EnvError::ActionNotFinite { .. } | EnvError::ActionLength { .. }),
            ) => EvalError::BadAction {
                policy: policy.name(),
                episode,
                seed,
                source: Box::new(source),
            },
            e => e,
        }
    }
}

#[cfg(feature = "onnx")]
impl From<PolicyFileError> for EvalError {
    fn from(e: PolicyFileError) -> Self {
        EvalError::Policy(e.into())
    }
}

/// The env id `eval` and `rollout` run when neither `--env` nor a policy file names one.
pub const DEFAULT_ENV: &str = "PickCube-v1";

/// A policy `eval` and `rollout` run: a built-in one by name ([`POLICIES`]) or a policy file
/// (`PolicyFile` with the `onnx` feature, docs/training.md).
#[derive(Debug, Clone)]
pub enum PolicySpec {
    /// A built-in policy: solver, random or zero.
    Builtin(String),
    /// A policy file.
    #[cfg(feature = "onnx")]
    File(Arc<PolicyFile>),
}

impl PolicySpec {
    /// A built-in policy's name, or a policy file's path: a name ending in `.onnx` or an
    /// existing file is loaded as a policy file; anything else must be a built-in name.
    pub fn parse(policy: &str) -> Result<PolicySpec, EvalError> {
        if POLICIES.contains(&policy) {
            return Ok(PolicySpec::Builtin(policy.to_string()));
        }
        let path = Path::new(policy);
        let onnx = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("onnx"));
        if onnx || path.is_file() {
            #[cfg(feature = "onnx")]
            return Ok(PolicySpec::File(Arc::new(PolicyFile::load(path)?)));
            #[cfg(not(feature = "onnx"))]
            return Err(EvalError::Policy(SolverError::PolicyFilesDisabled {
                path: policy.to_string(),
            }));
        }
        Err(EvalError::Policy(SolverError::UnknownPolicy {
            name: policy.to_string(),
            valid: format!("{}, or a policy file (FILE.onnx)", POLICIES.join(", ")),
        }))
    }

    /// The name reports give it: the built-in name or the file's path.
    pub fn name(&self) -> String {
        match self {
            PolicySpec::Builtin(n) => n.clone(),
            #[cfg(feature = "onnx")]
            PolicySpec::File(f) => f.path().display().to_string(),
        }
    }

    /// The env id and configuration to run: `env` (default [`DEFAULT_ENV`]) and `config` for a
    /// built-in policy; for a policy file, its env id, robot, control mode and obs mode fill
    /// what was not given (`env` None, `config.robot`/`control_mode` None, `obs_mode_given`
    /// false) and a given value that differs from the file's is an error naming both
    /// ([`PolicyFile::configure`]).
    #[cfg_attr(not(feature = "onnx"), allow(unused_mut, unused_variables))]
    pub fn target(
        &self,
        env: Option<&str>,
        mut config: EnvConfig,
        obs_mode_given: bool,
    ) -> Result<(String, EnvConfig), EvalError> {
        match self {
            PolicySpec::Builtin(_) => Ok((env.unwrap_or(DEFAULT_ENV).to_string(), config)),
            #[cfg(feature = "onnx")]
            PolicySpec::File(f) => {
                let id = f.configure(env, &mut config, obs_mode_given)?;
                Ok((id, config))
            }
        }
    }

    /// Builds the env (a built-in policy's control mode is chosen for it: [`make_env`]).
    pub fn make_env(&self, env_id: &str, config: EnvConfig) -> Result<Env, EvalError> {
        match self {
            PolicySpec::Builtin(name) => make_env(env_id, config, name),
            #[cfg(feature = "onnx")]
            PolicySpec::File(f) => {
                let mut config = config;
                f.configure(Some(env_id), &mut config, true)?;
                make(env_id, config).map_err(|e| {
                    PolicyFileError::Env {
                        path: f.path().to_path_buf(),
                        reason: e.to_string(),
                    }
                    .into()
                })
            }
        }
    }

    /// Builds the policy for `env` (random: seeded with `seed`; a policy file: fitted to the
    /// env's observation and action sizes, [`PolicyFile::policy`]).
    pub fn make_policy(&self, env: &Env, seed: u64) -> Result<Box<dyn Policy>, EvalError> {
        match self {
            PolicySpec::Builtin(name) => Ok(make_policy(name, env, seed)?),
            #[cfg(feature = "onnx")]
            PolicySpec::File(f) => Ok(Box::new(f.policy(env)?)),
        }
    }
}

/// Checks that `episodes` episodes with seeds `seed..seed + episodes` are at least one and
/// all within ManiSkill's 32-bit seeds ([`MAX_SEED`]).
pub fn check_seed_range(seed: u64, episodes: u64) -> Result<(), EvalError> {
    if episodes == 0 {
        return Err(EvalError::NoEpisodes);
    }
    if seed > MAX_SEED {
        return Err(EvalError::SeedOutOfRange(seed));
    }
    let last = seed as u128 + episodes as u128 - 1;
    if last > MAX_SEED as u128 {
        return Err(EvalError::SeedRangeTooLong {
            seed,
            episodes,
            last,
        });
    }
    Ok(())
}

/// Result of one episode.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct EpisodeResult {
    /// Reset seed.
    pub seed: u64,
    /// Steps taken (the episode runs to truncation).
    pub steps: u32,
    /// Sum of rewards.
    pub ret: f64,
    /// Success at any step.
    pub success_once: bool,
    /// Success on the last step.
    pub success_at_end: bool,
    /// First step with success.
    pub first_success: Option<u32>,
}

/// The eval summary printed as JSON.
#[derive(Debug, Clone, Serialize)]
pub struct EvalReport {
    /// Env id.
    pub env: String,
    /// Robot uid.
    pub robot: String,
    /// Control mode.
    pub control_mode: String,
    /// Policy name.
    pub policy: String,
    /// Episodes run (seeds `seed .. seed + episodes`).
    pub episodes: usize,
    /// Episodes that succeeded at some step.
    pub successes: usize,
    /// successes / episodes.
    pub success_rate: f64,
    /// Fraction of episodes successful on their last step.
    pub success_at_end_rate: f64,
    /// Mean undiscounted return.
    pub mean_return: f64,
    /// Mean first-success step over successful episodes.
    pub mean_first_success_step: Option<f64>,
}

/// Builds the env for a policy: the solver (or the state expert) dictates its control mode,
/// unless `config` names another it converts to.
pub fn make_env(env_id: &str, mut config: EnvConfig, policy: &str) -> Result<Env, EvalError> {
    let robot = match &config.robot {
        Some(r) => r.clone(),
        None => crate::env::default_robot(env_id)?.to_string(),
    };
    if let Some(required) = required_control_mode(policy, env_id, &robot) {
        match config.control_mode.as_deref() {
            None => config.control_mode = Some(required.to_string()),
            Some(m) if m == required => {}
            // The scripted solvers and the state experts run in other modes through
            // `ModeConverted`, which reports a mode it cannot convert to when the policy is
            // built.
            Some(m) if policy == "solver" || policy == "expert" => {
                crate::robots::spec(&robot)?.control_mode(m)?;
            }
            Some(m) => {
                // An unknown mode is reported as such, with the robot's valid modes.
                crate::robots::spec(&robot)?.control_mode(m)?;
                return Err(EvalError::ModeMismatch {
                    policy: policy.to_string(),
                    required,
                    mode: m.to_string(),
                });
            }
        }
    }
    Ok(make(env_id, config)?)
}

/// Runs one seeded episode to truncation, calling `on_step(env, action, reward, terminated,
/// truncated)` after every step; its error (or the env's) ends the episode.
pub fn run_episode(
    env: &mut Env,
    policy: &mut dyn Policy,
    seed: Option<u64>,
    action: &mut [f32],
    mut on_step: impl FnMut(&Env, &[f32], f32, bool, bool) -> Result<(), EvalError>,
) -> Result<EpisodeResult, EvalError> {
    env.try_reset(seed)?;
    policy.reset(env);
    let mut r = EpisodeResult {
        seed: seed.unwrap_or(0),
        steps: 0,
        ret: 0.0,
        success_once: false,
        success_at_end: false,
        first_success: None,
    };
    loop {
        policy.try_act(env, action)?;
        let (reward, terminated, truncated) = {
            let s = env.step(action)?;
            (s.reward, s.terminated, s.truncated)
        };
        r.steps += 1;
        r.ret += reward as f64;
        if terminated && r.first_success.is_none() {
            r.first_success = Some(r.steps);
        }
        r.success_once |= terminated;
        r.success_at_end = terminated;
        on_step(env, action, reward, terminated, truncated)?;
        if truncated {
            return Ok(r);
        }
    }
}

/// Evaluates policy `policy` ([`POLICIES`], or a policy file: [`PolicySpec::parse`]) on
/// `env_id`: [`evaluate_spec`].
pub fn evaluate(
    env_id: &str,
    config: EnvConfig,
    policy: &str,
    episodes: usize,
    seed: u64,
) -> Result<EvalReport, EvalError> {
    let spec = PolicySpec::parse(policy)?;
    let (env_id, config) = spec.target(Some(env_id), config, true)?;
    evaluate_spec(&env_id, config, &spec, episodes, seed)
}

/// Evaluates `policy` on `env_id` (resolved with [`PolicySpec::target`]): runs `episodes`
/// episodes with seeds `seed..seed + episodes` (32-bit seeds: the range must end at
/// [`MAX_SEED`] or below), each to truncation. The solver's control mode is chosen for it
/// ([`make_env`]). Results are accumulated as the episodes run, so memory does not grow with
/// `episodes`.
pub fn evaluate_spec(
    env_id: &str,
    config: EnvConfig,
    policy: &PolicySpec,
    episodes: usize,
    seed: u64,
) -> Result<EvalReport, EvalError> {
    check_seed_range(seed, episodes as u64)?;
    let mut env = policy.make_env(env_id, config)?;
    let mut pol = policy.make_policy(&env, seed)?;
    let mut action = vec![0.0f32; env.action_space().shape[0]];
    let (mut successes, mut at_end, mut returns) = (0usize, 0usize, 0.0f64);
    let (mut first_sum, mut first_count) = (0.0f64, 0usize);
    for k in 0..episodes as u64 {
        let r = run_episode(
            &mut env,
            pol.as_mut(),
            Some(seed + k),
            &mut action,
            |_, _, _, _, _| Ok(()),
        )
        .map_err(|e| e.in_episode(policy, k, seed + k))?;
        successes += r.success_once as usize;
        at_end += r.success_at_end as usize;
        returns += r.ret;
        if let Some(s) = r.first_success {
            first_sum += s as f64;
            first_count += 1;
        }
    }
    let n = episodes.max(1) as f64;
    Ok(EvalReport {
        env: env_id.to_string(),
        robot: env.robot_id().uid().to_string(),
        control_mode: env.control_mode().to_string(),
        policy: policy.name(),
        episodes,
        successes,
        success_rate: successes as f64 / n,
        success_at_end_rate: at_end as f64 / n,
        mean_return: returns / n,
        mean_first_success_step: (first_count > 0).then(|| first_sum / first_count as f64),
    })
}
