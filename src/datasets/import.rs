//! `mjskill import-maniskill`: replays the episodes of a ManiSkill trajectory file in
//! mjskill, records them to MCAP and reports, per episode, ManiSkill's success, mjskill's
//! success by actions and by states, and the first step at which mjskill's objects leave
//! ManiSkill's.
//!
//! * By actions: the env is reset with the episode's seed and the actions are applied open
//!   loop.
//! * By states: every `env_states` row is imported with [`Env::set_state_dict`] (and
//!   `elapsed_steps` set to its index), rows after the first with the drive targets of the
//!   action that led to them ([`Env::set_state_dict_after_action`]: held objects stay
//!   squeezed, as in ManiSkill); obs, reward and info are recomputed from it. Step t of
//!   the recording then carries the state of row t as the state before it and the obs, reward
//!   and flags of row t+1, so `mjskill replay` of such a file reports the physics difference
//!   between ManiSkill and mjskill rather than zero.
//!
//! Both replays run for the report; the recording holds the one chosen with `--by`. Besides
//! the standard topics it has [`TOPIC_MANISKILL_STATE`]: the env state in ManiSkill's layout
//! after every reset and step, which `mjskill export --format maniskill` writes back as
//! `env_states`.
use std::path::{Path, PathBuf};

use serde::Serialize;
use serde_json::json;

use super::maniskill_h5::{self, EpisodeData, Trajectory};
use super::{check_outputs, DatasetError, Named, Staged};
use crate::env::{make, Env, EnvConfig, ObsMode, RewardMode, SimConfig, StateDict};
use crate::record::Recorder;

/// Topic of the ManiSkill-layout env state written by the importer (schema
/// [`SCHEMA_MANISKILL_STATE`]): `{"episode", "step", "state"}` with `state` in
/// [`StateDict::to_json`] form, after the reset (step 0) and after every step.
pub const TOPIC_MANISKILL_STATE: &str = "/maniskill/env_state";
/// Schema name of [`TOPIC_MANISKILL_STATE`].
pub const SCHEMA_MANISKILL_STATE: &str = "mjskill.ManiSkillEnvState";

/// The JSON schema of [`TOPIC_MANISKILL_STATE`] messages.
pub fn maniskill_state_schema() -> serde_json::Value {
    let map = json!({"type": "object", "additionalProperties": {"type": "array", "items": {"type": "number"}}});
    json!({
        "title": SCHEMA_MANISKILL_STATE,
        "description": "The env state in ManiSkill's get_state_dict() layout",
        "type": "object",
        "properties": {
            "episode": {"type": "integer", "minimum": 0},
            "step": {"type": "integer", "minimum": 0},
            "state": {
                "type": "object",
                "properties": {"actors": map, "articulations": map, "controller": {"type": "object"}, "drive": {"type": "object"}},
                "required": ["actors", "articulations"]
            }
        },
        "required": ["episode", "step", "state"]
    })
}

/// How the recording replays the demos.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReplayBy {
    /// Open loop from the episode's seed.
    Actions,
    /// Importing every `env_states` row.
    States,
}

impl ReplayBy {
    /// Parses `actions` / `states`.
    pub fn parse(s: &str) -> Result<ReplayBy, DatasetError> {
        match s {
            "actions" => Ok(ReplayBy::Actions),
            "states" => Ok(ReplayBy::States),
            _ => Err(DatasetError::Invalid {
                msg: format!("unknown --by {s:?}; valid: actions, states"),
            }),
        }
    }

    /// `actions` / `states`.
    pub fn name(self) -> &'static str {
        match self {
            ReplayBy::Actions => "actions",
            ReplayBy::States => "states",
        }
    }
}

/// What to import.
#[derive(Debug, Clone)]
pub struct ImportArgs {
    /// `trajectory.h5`.
    pub h5: PathBuf,
    /// `trajectory.json` (default: next to the h5).
    pub json: Option<PathBuf>,
    /// Output MCAP file.
    pub out: PathBuf,
    /// Which replay to record.
    pub by: ReplayBy,
    /// mjskill's physics settings.
    pub sim: SimConfig,
}

/// The result of one episode.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EpisodeReport {
    /// `episode_id` (group `traj_<k>`).
    pub episode_id: usize,
    /// Reset seed.
    pub seed: Option<u64>,
    /// Steps.
    pub steps: usize,
    /// ManiSkill's `success` after the last step.
    pub maniskill_success: bool,
    /// mjskill's `success` after the last step, replaying the actions open loop.
    pub by_actions_success: bool,
    /// mjskill's `success` for the imported final state.
    pub by_states_success: bool,
    /// First step (1-based; 0 = the initial state) after which an object of the open-loop
    /// replay is more than [`crate::maniskill::fidelity::DIVERGENCE_DISTANCE`] from ManiSkill's;
    /// `null` if it never is.
    pub first_divergence_step: Option<usize>,
    /// Largest object position error of the open-loop replay (m).
    pub max_object_error_m: f64,
    /// Steps whose `success` flag differs between ManiSkill and mjskill by states.
    pub by_states_success_mismatches: usize,
}

/// The import report (printed as JSON by the command).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ImportReport {
    /// The h5 file.
    pub file: String,
    /// The recording written.
    pub out: String,
    /// Env id.
    pub env_id: String,
    /// Robot uid.
    pub robot: String,
    /// Control mode.
    pub control_mode: String,
    /// The replay recorded.
    pub by: &'static str,
    /// Per episode.
    pub episodes: Vec<EpisodeReport>,
}

/// The env configuration of a trajectory: env id, robot (its articulation) and control mode
/// (shared by all episodes). Errors name the bad value and the valid choices.
pub fn env_config(
    traj: &Trajectory,
    h5: &Path,
    json_path: &Path,
    sim: SimConfig,
) -> Result<(String, EnvConfig), DatasetError> {
    let env_id = traj.json.env_info.env_id.clone();
    let registry = crate::env::registry();
    let Some(info) = registry.iter().find(|e| e.id == env_id) else {
        return Err(DatasetError::format(
            json_path,
            format!(
                "env_info.env_id {env_id:?} is not an mjskill env; valid: {}",
                registry.iter().map(|e| e.id).collect::<Vec<_>>().join(", ")
            ),
        ));
    };
    let (Some(first), Some(first_info)) = (traj.episodes.first(), traj.json.episodes.first())
    else {
        return Err(DatasetError::format(h5, "holds no episodes"));
    };
    let first_id = first_info.episode_id;
    let valid_robots = || {
        info.robots
            .iter()
            .map(|(r, _)| *r)
            .collect::<Vec<_>>()
            .join(", ")
    };
    let robots: Vec<&String> = first.env_states[0].articulations.keys().collect();
    let robot = match robots.as_slice() {
        [r] => r.to_string(),
        _ => {
            return Err(DatasetError::format(
                h5,
                format!(
                    "traj_{first_id}/env_states/articulations holds {robots:?}; expected exactly \
                     one robot"
                ),
            ))
        }
    };
    if !info.robots.iter().any(|(r, _)| *r == robot) {
        return Err(DatasetError::format(
            h5,
            format!(
                "robot {robot:?} is not available for {env_id}; valid: {}",
                valid_robots()
            ),
        ));
    }
    match traj.json.env_info.env_kwargs.get("robot_uids") {
        None | Some(serde_json::Value::Null) => {}
        Some(serde_json::Value::String(u)) if *u == robot => {}
        Some(serde_json::Value::String(u)) if info.robots.iter().any(|(r, _)| r == u) => {
            return Err(DatasetError::format(
                json_path,
                format!(
                    "env_info.env_kwargs.robot_uids is {u:?} but the h5's episodes hold the \
                     robot {robot:?} (traj_{}/env_states/articulations); they must agree",
                    first_id
                ),
            ))
        }
        Some(v) => {
            return Err(DatasetError::format(
                json_path,
                format!(
                    "env_info.env_kwargs.robot_uids {v} is not a robot of {env_id}; valid: {}",
                    valid_robots()
                ),
            ))
        }
    }
    let mode = traj.json.episodes[0].control_mode.clone();
    if let Some(e) = traj.json.episodes.iter().find(|e| e.control_mode != mode) {
        return Err(DatasetError::format(
            json_path,
            format!(
                "episode {} uses control mode {:?} and episode 0 {mode:?}; a recording has one",
                e.episode_id, e.control_mode
            ),
        ));
    }
    let reward_mode = match traj.json.env_info.env_kwargs.get("reward_mode") {
        Some(serde_json::Value::String(s)) => {
            RewardMode::parse(s).map_err(DatasetError::env(json_path))?
        }
        _ => RewardMode::NormalizedDense,
    };
    Ok((
        env_id,
        EnvConfig {
            robot: Some(robot),
            control_mode: Some(mode),
            obs_mode: ObsMode::State,
            reward_mode,
            sim,
            ..EnvConfig::default()
        },
    ))
}

/// Largest deviation from 1 of the norm of a pose quaternion in an `env_states` row: the
/// poses come from a physics engine, normalised to float32 precision.
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

/// Checks every `env_states` row of episode `id` before anything is replayed: the actor rows
/// and the robot's row are finite and their pose quaternions (entries 3..7, `w x y z`) have
/// unit norm within [`QUATERNION_NORM_TOLERANCE`]. Errors name the dataset, the row and the
/// values.
fn check_states(h5: &Path, id: usize, ep: &EpisodeData) -> Result<(), DatasetError> {
    for (t, s) in ep.env_states.iter().enumerate() {
        let rows = s.actors.iter().map(|(n, a)| ("actors", n, &a[..])).chain(
            s.articulations
                .iter()
                .map(|(n, a)| ("articulations", n, &a[..])),
        );
        for (kind, name, row) in rows {
            let what = format!("traj_{id}/env_states/{kind}/{name} row {t}");
            if let Some((i, v)) = row.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(DatasetError::format(
                    h5,
                    format!("{what}: entry {i} is {v}; states must be finite"),
                ));
            }
            let Some(q) = row.get(3..7) else {
                continue; // set_state_dict reports the length
            };
            let norm = q.iter().map(|x| x * x).sum::<f64>().sqrt();
            if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
                return Err(DatasetError::format(
                    h5,
                    format!(
                        "{what}: the pose quaternion (w, x, y, z) {q:?} has norm {norm}, not 1 \
                         (within {QUATERNION_NORM_TOLERANCE}): it is no rotation"
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// The reward of the env's current state in its reward mode.
fn reward_of(env: &Env) -> f32 {
    match env.config().reward_mode {
        RewardMode::None => 0.0,
        RewardMode::Sparse => env.info().success() as u8 as f32,
        RewardMode::Dense => env.dense_reward() as f32,
        RewardMode::NormalizedDense => (env.dense_reward() / env.task().max_reward()) as f32,
    }
}

/// Where the recording goes while an episode is replayed.
struct Sink<'a> {
    rec: &'a mut Recorder,
    channel: u16,
    episode: u64,
}

impl Sink<'_> {
    fn state(&mut self, env: &Env, step: usize) -> Result<(), DatasetError> {
        let msg =
            json!({"episode": self.episode, "step": step, "state": env.get_state_dict().to_json()});
        Ok(self.rec.write_message(self.channel, &msg)?)
    }
}

struct ActionsResult {
    success: bool,
    divergence: Option<usize>,
    max_err: f64,
}

fn object_error(env: &Env, want: &StateDict, objects: &[&str]) -> f64 {
    let got = env.get_state_dict();
    objects
        .iter()
        .filter_map(|o| {
            let (a, b) = (got.actors.get(*o)?, want.actors.get(*o)?);
            Some(((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt())
        })
        .fold(0.0, f64::max)
}

fn replay_actions(
    env: &mut Env,
    ep: &EpisodeData,
    seed: Option<u64>,
    path: &Path,
    mut sink: Option<Sink<'_>>,
) -> Result<ActionsResult, DatasetError> {
    env.reset(seed);
    let objects = env.dynamic_actor_names();
    if let Some(s) = sink.as_mut() {
        s.rec.begin_episode(env, seed)?;
        s.state(env, 0)?;
    }
    let limit = crate::maniskill::fidelity::DIVERGENCE_DISTANCE;
    let mut max_err = object_error(env, &ep.env_states[0], &objects);
    let mut divergence = (max_err > limit).then_some(0);
    let mut success = env.info().success();
    for t in 0..ep.steps() {
        let a = ep.action(t);
        match sink.as_mut() {
            Some(s) => {
                s.rec.step(env, a).map_err(|e| match e {
                    crate::record::RecordError::Env { source, .. } => DatasetError::Env {
                        path: path.to_path_buf(),
                        source,
                    },
                    e => e.into(),
                })?;
                s.state(env, t + 1)?;
            }
            None => {
                env.step(a).map_err(DatasetError::env(path))?;
            }
        }
        success = env.info().success();
        let err = object_error(env, &ep.env_states[t + 1], &objects);
        max_err = max_err.max(err);
        if divergence.is_none() && err > limit {
            divergence = Some(t + 1);
        }
    }
    if let Some(s) = sink {
        s.rec.end_episode(success)?;
    }
    Ok(ActionsResult {
        success,
        divergence,
        max_err,
    })
}

/// Imports every state row; returns mjskill's `success` after each step.
fn replay_states(
    env: &mut Env,
    ep: &EpisodeData,
    seed: Option<u64>,
    path: &Path,
    mut sink: Option<Sink<'_>>,
) -> Result<Vec<bool>, DatasetError> {
    // Row t > 0 is imported with the drive targets of action t − 1, applied to row t − 1
    // (ManiSkill's rows lack them; PhysX keeps them across steps).
    let import = |env: &mut Env, t: usize| -> Result<(), DatasetError> {
        let r = match t {
            0 => env.set_state_dict(&ep.env_states[0]),
            _ => env.set_state_dict_after_action(ep.action(t - 1), &ep.env_states[t]),
        };
        r.map_err(|e| {
            DatasetError::format(path, format!("env_states row {t} cannot be imported: {e}"))
        })?;
        env.set_elapsed_steps(t as u32);
        Ok(())
    };
    // Reset first so the seeds and RNG streams are those of the episode.
    env.reset(seed);
    import(env, 0)?;
    if let Some(s) = sink.as_mut() {
        s.rec.begin_episode(env, seed)?;
        s.state(env, 0)?;
    }
    let max_steps = env.max_episode_steps() as usize;
    let mut success = Vec::with_capacity(ep.steps());
    for t in 0..ep.steps() {
        let before = env.get_state();
        import(env, t + 1)?;
        let ok = env.info().success();
        success.push(ok);
        if let Some(s) = sink.as_mut() {
            s.rec.record_step(
                env,
                ep.action(t),
                reward_of(env),
                ok,
                t + 1 >= max_steps,
                &before,
            )?;
            s.state(env, t + 1)?;
        }
    }
    if let Some(s) = sink {
        s.rec
            .end_episode(success.last().copied().unwrap_or(false))?;
    }
    Ok(success)
}

/// Runs the import (see the [module docs](self)); the recording is written under a
/// temporary name and moved to `out` only when every episode is recorded.
///
/// Refused before anything is written: an `out` that is the h5 or the json, or that exists
/// and is not a regular file; a json whose episode ids repeat, whose seeds are missing, not
/// 32-bit or disagree (`episode_seed` and `reset_kwargs.seed`), whose
/// `env_kwargs.robot_uids` is not the h5's robot, or whose `elapsed_steps` differ from the
/// h5's action counts (checked on the declared shapes, before the data is read); state rows
/// with non-finite values or non-unit quaternions.
pub fn run(a: &ImportArgs) -> Result<ImportReport, DatasetError> {
    let json_path = a
        .json
        .clone()
        .unwrap_or_else(|| maniskill_h5::json_path_for(&a.h5));
    check_outputs(
        &[
            Named::new("the h5", &a.h5),
            Named::new(
                if a.json.is_some() {
                    "--json"
                } else {
                    "the json (default: the h5 with extension .json)"
                },
                &json_path,
            ),
        ],
        &[Named::new("--out", &a.out)],
    )?;
    let json = maniskill_h5::read_json(&json_path)?;
    let seeds = json
        .episodes
        .iter()
        .map(|e| {
            e.checked_seed()
                .map_err(|e| DatasetError::format(&json_path, e.to_string()))
        })
        .collect::<Result<Vec<u64>, _>>()?;
    let traj = maniskill_h5::read_h5(&a.h5, &json_path, json)?;
    let (env_id, config) = env_config(&traj, &a.h5, &json_path, a.sim)?;
    for (info, ep) in traj.json.episodes.iter().zip(&traj.episodes) {
        check_states(&a.h5, info.episode_id, ep)?;
    }
    let mut env = make(&env_id, config.clone()).map_err(DatasetError::env(&json_path))?;
    for (info, ep) in traj.json.episodes.iter().zip(&traj.episodes) {
        let dim = env.action_space().low.len();
        if ep.action_dim != dim {
            return Err(DatasetError::format(
                &a.h5,
                format!(
                    "traj_{}/actions has {} entries per action; {env_id} with {} in {} takes {dim}",
                    info.episode_id,
                    ep.action_dim,
                    env.robot_spec().uid(),
                    env.control_mode()
                ),
            ));
        }
    }
    let mut staged = Staged::default();
    let tmp = staged.add(&a.out);
    let mut rec = Recorder::create(&tmp, &env)?;
    rec.renamed(&a.out);
    let channel = rec.add_json_channel(
        SCHEMA_MANISKILL_STATE,
        &maniskill_state_schema(),
        TOPIC_MANISKILL_STATE,
    )?;
    let mut episodes = Vec::new();
    for (k, (info, ep)) in traj.json.episodes.iter().zip(&traj.episodes).enumerate() {
        let seed = Some(seeds[k]);
        let sink = Sink {
            rec: &mut rec,
            channel,
            episode: k as u64,
        };
        let (acts, states) = match a.by {
            ReplayBy::Actions => (
                replay_actions(&mut env, ep, seed, &a.h5, Some(sink))?,
                replay_states(&mut env, ep, seed, &a.h5, None)?,
            ),
            ReplayBy::States => {
                let states = replay_states(&mut env, ep, seed, &a.h5, Some(sink))?;
                (replay_actions(&mut env, ep, seed, &a.h5, None)?, states)
            }
        };
        let ms_success = ep
            .success
            .as_ref()
            .and_then(|s| s.last().copied())
            .or(info.success)
            .unwrap_or(false);
        let mismatches = ep
            .success
            .as_ref()
            .map_or(0, |s| s.iter().zip(&states).filter(|(a, b)| a != b).count());
        episodes.push(EpisodeReport {
            episode_id: info.episode_id,
            seed,
            steps: ep.steps(),
            maniskill_success: ms_success,
            by_actions_success: acts.success,
            by_states_success: states.last().copied().unwrap_or(false),
            first_divergence_step: acts.divergence,
            max_object_error_m: acts.max_err,
            by_states_success_mismatches: mismatches,
        });
    }
    rec.finish()?;
    staged.commit()?;
    Ok(ImportReport {
        file: a.h5.display().to_string(),
        out: a.out.display().to_string(),
        env_id,
        robot: env.robot_spec().uid().to_string(),
        control_mode: env.control_mode().to_string(),
        by: a.by.name(),
        episodes,
    })
}
