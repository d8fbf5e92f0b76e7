//! Env construction options and modes: [`EnvConfig`], [`SimConfig`], [`ObsMode`],
//! [`RewardMode`], and the env API's errors ([`EnvError`]).
use serde::{Deserialize, Serialize};

use crate::mjcf::CONTROL_DT;
use crate::mujoco::render::RenderError;
use crate::mujoco::MjError;
use crate::robots::RobotError;

/// Seed of the reset ManiSkill performs at the end of env construction.
pub const CONSTRUCTION_SEED: u64 = 2022;
/// Default std-dev of the initial joint noise.
pub const DEFAULT_QPOS_NOISE: f64 = 0.02;
/// Default episode length of every registered env.
pub const MAX_EPISODE_STEPS: u32 = 50;

/// Errors of the env API; each names the bad value and the valid choices.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EnvError {
    /// Unknown env id.
    #[error("unknown env id {id:?}; valid env ids: {1}", id = crate::files::short(.0))]
    UnknownEnv(String, String),
    /// Robot not supported by this env.
    #[error(
        "robot {r:?} is not supported by {env}; supported robots: {valid}",
        r = crate::files::short(.robot)
    )]
    UnsupportedRobot {
        /// Env id.
        env: String,
        /// Requested robot.
        robot: String,
        /// Valid robots.
        valid: String,
    },
    /// Unknown obs or reward mode.
    #[error(
        "unknown {what} {g:?}; valid {}s: {valid}",
        what.replace('_', " "),
        g = crate::files::short(.got)
    )]
    UnknownMode {
        /// What was being parsed (`obs_mode`, `reward_mode`).
        what: &'static str,
        /// The requested mode.
        got: String,
        /// The valid modes.
        valid: String,
    },
    /// A `+` obs mode with a part that is not a camera texture.
    #[error(
        "unknown obs mode part {p:?} in {m:?}; the parts of a + obs mode are camera \
         textures: {valid} (e.g. rgb+depth+segmentation)",
        p = crate::files::short(.part),
        m = crate::files::short(.mode)
    )]
    UnknownObsModePart {
        /// The bad part.
        part: String,
        /// The whole mode string.
        mode: String,
        /// The valid parts.
        valid: String,
    },
    /// A control mode the robot does not have (the message lists the robot's modes).
    #[error(transparent)]
    UnknownControlMode(RobotError),
    /// Action of the wrong length.
    #[error("action has {got} values, but {mode} expects {expected}")]
    ActionLength {
        /// Given length.
        got: usize,
        /// Expected length.
        expected: usize,
        /// Control mode.
        mode: String,
    },
    /// NaN or infinite action entry.
    #[error("action[{index}] = {value} is not finite; actions must not contain NaN or infinity")]
    ActionNotFinite {
        /// Index.
        index: usize,
        /// Value.
        value: f32,
    },
    /// NaN or infinite entry of [`VecEnv::step`](super::VecEnv::step)'s actions: `index`
    /// into the `[N × action_dim]` batch, which is component `component` of env `env`.
    #[error(
        "action[{index}] = {value} (env {env}, action component {component}) is not finite; \
         actions must not contain NaN or infinity"
    )]
    VecActionNotFinite {
        /// Index into the batch of actions.
        index: usize,
        /// The env of that entry.
        env: usize,
        /// The action component (of the env's action) of that entry.
        component: usize,
        /// Value.
        value: f32,
    },
    /// A state from another env, of the wrong size, or with a bad value (the message names
    /// the field).
    #[error("cannot set state: {0}")]
    BadState(String),
    /// An action of one control mode that cannot be converted to another
    /// ([`Env::convert_action`](super::Env::convert_action)); the message names the modes
    /// and the part.
    #[error("{0}")]
    ModeConversion(String),
    /// A seed beyond ManiSkill's 32-bit seeds ([`MAX_SEED`](super::checks::MAX_SEED)).
    #[error("seed {0} is out of range: seeds are 32-bit, 0..={max}", max = super::checks::MAX_SEED)]
    BadSeed(u64),
    /// A [`VecEnv`](super::VecEnv) reset seed `seed` whose per-env seeds `seed + i` (up to
    /// env `last_env`) leave ManiSkill's 32-bit range; names the seed given.
    #[error(
        "seed {seed} is out of range for these envs: env i is seeded with seed + i, and env \
         {last_env} would get {}, beyond the 32-bit seeds 0..={max}; give a seed at most {}",
        *seed as u128 + *last_env as u128,
        (super::checks::MAX_SEED as u128).saturating_sub(*last_env as u128),
        max = super::checks::MAX_SEED
    )]
    VecSeedRange {
        /// The seed given.
        seed: u64,
        /// The highest env index it seeds.
        last_env: usize,
    },
    /// An unknown robot uid, or the robot's scene could not be built.
    #[error(transparent)]
    Robot(#[from] RobotError),
    /// MuJoCo could not create the simulation data or a task's body is missing.
    #[error(transparent)]
    Mujoco(#[from] MjError),
    /// The scene has no body for one of the task's actors.
    #[error("the scene has no body for actor {0:?}")]
    NoActorBody(&'static str),
    /// A task actor's body has neither a free joint nor a mocap.
    #[error("actor {0:?} is neither free nor mocap")]
    ActorNotMovable(&'static str),
    /// `robot_init_qpos_noise` out of range.
    #[error(
        "robot_init_qpos_noise must be finite and in [0, {max}], got {0}",
        max = super::checks::MAX_QPOS_NOISE
    )]
    BadQposNoise(f64),
    /// `sim_freq` is not a multiple of the control frequency in range.
    #[error(
        "sim_freq {0} is not a multiple of the control frequency {CONTROL_FREQ} Hz between \
         {CONTROL_FREQ} and 100000 (e.g. 100, 200, 500)"
    )]
    BadSimFreq(u32),
    /// `pinch_solver` "physx_tgs" for a robot or task it cannot take.
    #[error("pinch_solver \"physx_tgs\" cannot run {robot} in {env}: {reason}")]
    PinchSolverUnsupported {
        /// Env id.
        env: String,
        /// Robot uid.
        robot: String,
        /// Why (and what it needs).
        reason: String,
    },
    /// A [`VecEnv`](super::VecEnv) of zero envs.
    #[error("a VecEnv needs at least one env")]
    NoEnvs,
    /// A [`VecEnv`](super::VecEnv) of more than
    /// [`MAX_NUM_ENVS`](super::vec::MAX_NUM_ENVS) envs.
    #[error(
        "num_envs {0} is out of range: 1..={max} (each env owns its MuJoCo model and data)",
        max = super::vec::MAX_NUM_ENVS
    )]
    TooManyEnvs(usize),
    /// A [`VecEnv`](super::VecEnv) whose envs would not fit in the memory this process may
    /// still take (the tightest of `MemAvailable` of `/proc/meminfo`, the address-space
    /// limit `RLIMIT_AS` and the cgroup's `memory.max`), refused before they are made.
    #[error(
        "num_envs {num_envs} would need about {} MB ({} KB per env: its MuJoCo model and data, \
         images and buffers), more than the {} MB of memory available ({limit}); use fewer \
         envs",
        (*num_envs as u64).saturating_mul(*per_env_bytes) >> 20,
        per_env_bytes >> 10,
        available_bytes >> 20
    )]
    EnvsExceedMemory {
        /// Envs asked for.
        num_envs: usize,
        /// Estimated memory of one env (bytes).
        per_env_bytes: u64,
        /// Memory available (bytes).
        available_bytes: u64,
        /// Which limit that is (`"MemAvailable in /proc/meminfo"`, the address-space limit,
        /// the cgroup's).
        limit: &'static str,
    },
    /// Env `index` of a [`VecEnv`](super::VecEnv) of `num_envs` could not be made (e.g. a
    /// memory limit reached while making them).
    #[error("cannot make env {index} of num_envs {num_envs}: {source}; use fewer envs")]
    VecEnvMake {
        /// The env that failed (0-based).
        index: usize,
        /// Envs asked for.
        num_envs: usize,
        /// Why.
        source: Box<EnvError>,
    },
    /// A [`VecEnv`](super::VecEnv) worker thread could not be started (the OS error's text).
    #[error("cannot start a VecEnv worker thread: {0}")]
    WorkerThread(String),
    /// [`VecEnv::step`](super::VecEnv::step) actions of the wrong length.
    #[error(
        "VecEnv actions have {got} values, expected {num_envs} envs × {act_dim} = {}",
        num_envs * act_dim
    )]
    VecActionLength {
        /// Given length.
        got: usize,
        /// Envs.
        num_envs: usize,
        /// Action dimension of each env.
        act_dim: usize,
    },
    /// [`VecEnv::reset_envs`](super::VecEnv::reset_envs) mask of the wrong length.
    #[error("VecEnv reset mask has {got} values, expected one per env ({num_envs})")]
    VecMaskLength {
        /// Given length.
        got: usize,
        /// Envs.
        num_envs: usize,
    },
    /// A [`VecEnv::rollout`](super::VecEnv::rollout) buffer of the wrong length.
    #[error(
        "rollout buffer {buffer} has {got} values, expected {expected} (T steps × num_envs, \
         × obs_dim for obs and × act_dim for actions)"
    )]
    RolloutBuffer {
        /// The buffer's name.
        buffer: &'static str,
        /// Its length.
        got: usize,
        /// The length that fits the rewards' T steps.
        expected: usize,
    },
    /// A [`VecEnv::rollout`](super::VecEnv::rollout) whose steps `first_step..first_step +
    /// steps` leave the policy's step range `0..`[`MAX_POLICY_STEP`](super::MAX_POLICY_STEP)
    /// (the step keys the policy's sampling noise; steps beyond it would repeat or wrap).
    #[error(
        "rollout steps {first_step}..{first_step}+{steps} leave the policy's step range \
         0..{max} (2^48; the step keys the sampling noise): give first_step at most {}",
        (super::MAX_POLICY_STEP as u128).saturating_sub(*steps as u128),
        max = super::MAX_POLICY_STEP
    )]
    RolloutSteps {
        /// The rollout's first step.
        first_step: u64,
        /// Its number of steps.
        steps: usize,
    },
    /// A rollout's policy gave a NaN or infinite action.
    #[error("the policy's action for env {env} at step {step} is {value}, not finite")]
    PolicyActionNotFinite {
        /// Global env index.
        env: usize,
        /// The policy's step.
        step: u64,
        /// The first non-finite action component.
        value: f32,
    },
    /// [`VecEnv::expert_actions`](super::VecEnv::expert_actions) or a labelled rollout without
    /// labellers.
    #[error(
        "the vector env has no expert labellers: set them first (VecEnv::set_labellers; \
         solvers::set_state_experts for the pairs with a state expert)"
    )]
    NoLabellers,
    /// An env's labeller failed to label its state.
    #[error("the expert labeller of env {env} failed: {message}")]
    Labeller {
        /// Global env index.
        env: usize,
        /// The labeller's message.
        message: String,
    },
    /// Rendering is unavailable or failed (the message names what to install).
    #[error(transparent)]
    Render(#[from] RenderError),
}

/// Observation modes: ManiSkill's `obs_mode` strings.
///
/// The camera modes name the textures the sensor cameras render, ManiSkill's way: `rgb`,
/// `depth`, `segmentation` and their `+` combinations in any order (`rgb+depth+segmentation`;
/// `rgb+depth` is the same mode as `rgbd`), plus `pointcloud` (the fused point cloud of all
/// sensor cameras; docs/observations.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ObsMode {
    /// One flat f32 vector.
    State,
    /// The same values with named parts ([`Env::obs_layout`](super::Env::obs_layout)).
    StateDict,
    /// No observation.
    None,
    /// State-free vector (agent, controller, non-privileged extras) plus the sensor camera's
    /// colour image ([`Env::sensor_rgb`](super::Env::sensor_rgb)).
    Rgb,
    /// As `Rgb` with the depth image ([`Env::sensor_depth`](super::Env::sensor_depth)) instead of colour.
    Depth,
    /// As `Rgb` with both colour and depth (`rgbd`, also spelt `rgb+depth`).
    Rgbd,
    /// As `Rgb` with the segmentation image (ManiSkill's per-link / per-actor ids) instead of
    /// colour.
    Segmentation,
    /// Colour and segmentation.
    RgbSegmentation,
    /// Depth and segmentation.
    DepthSegmentation,
    /// Colour, depth and segmentation.
    RgbDepthSegmentation,
    /// The state-free vector plus ManiSkill's fused point cloud of all sensor cameras
    /// ([`Env::point_cloud`](super::Env::point_cloud)): world-frame `xyzw`, `rgb`,
    /// `segmentation` per pixel.
    PointCloud,
}

/// The camera textures a visual obs mode renders (ManiSkill's `CameraObsTextures`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Textures {
    /// Colour, H×W×3 bytes.
    pub rgb: bool,
    /// Depth: metres (f32) and ManiSkill's int16 millimetres.
    pub depth: bool,
    /// ManiSkill's per-link / per-actor segmentation ids (int16).
    pub segmentation: bool,
}

impl Textures {
    /// Whether any texture is on.
    pub fn any(self) -> bool {
        self.rgb || self.depth || self.segmentation
    }
}

/// The parts a `+` obs mode may combine.
const TEXTURE_PARTS: [&str; 3] = ["rgb", "depth", "segmentation"];

impl ObsMode {
    /// All modes, by name (`rgb+depth` is [`ObsMode::Rgbd`] and not listed).
    pub const ALL: [(&'static str, ObsMode); 11] = [
        ("state", ObsMode::State),
        ("state_dict", ObsMode::StateDict),
        ("none", ObsMode::None),
        ("rgb", ObsMode::Rgb),
        ("depth", ObsMode::Depth),
        ("rgbd", ObsMode::Rgbd),
        ("segmentation", ObsMode::Segmentation),
        ("rgb+segmentation", ObsMode::RgbSegmentation),
        ("depth+segmentation", ObsMode::DepthSegmentation),
        ("rgb+depth+segmentation", ObsMode::RgbDepthSegmentation),
        ("pointcloud", ObsMode::PointCloud),
    ];
    /// Whether the mode renders camera images.
    pub fn is_visual(self) -> bool {
        self.textures().any()
    }
    /// Whether the mode is `pointcloud`.
    pub fn is_point_cloud(self) -> bool {
        self == ObsMode::PointCloud
    }
    /// The textures the sensor cameras render (all three for `pointcloud`, none for the
    /// state modes).
    pub fn textures(self) -> Textures {
        let t = |rgb, depth, segmentation| Textures {
            rgb,
            depth,
            segmentation,
        };
        match self {
            ObsMode::State | ObsMode::StateDict | ObsMode::None => Textures::default(),
            ObsMode::Rgb => t(true, false, false),
            ObsMode::Depth => t(false, true, false),
            ObsMode::Rgbd => t(true, true, false),
            ObsMode::Segmentation => t(false, false, true),
            ObsMode::RgbSegmentation => t(true, false, true),
            ObsMode::DepthSegmentation => t(false, true, true),
            ObsMode::RgbDepthSegmentation | ObsMode::PointCloud => t(true, true, true),
        }
    }
    /// Whether the observation includes privileged state (object poses): ManiSkill's
    /// `"state" in obs_mode`.
    pub fn is_state(self) -> bool {
        matches!(self, ObsMode::State | ObsMode::StateDict)
    }
    /// Parses a mode name: one of [`ObsMode::ALL`], or camera textures joined with `+` in any
    /// order (`depth+rgb`). The error names the bad part and the valid ones.
    pub fn parse(s: &str) -> Result<ObsMode, EnvError> {
        if let Some((_, m)) = Self::ALL.iter().find(|(n, _)| *n == s) {
            return Ok(*m);
        }
        let valid = || {
            format!(
                "{}, or camera textures joined with + ({}; e.g. rgb+depth+segmentation)",
                names(&Self::ALL),
                TEXTURE_PARTS.join(", ")
            )
        };
        if !s.contains('+') {
            return Err(EnvError::UnknownMode {
                what: "obs_mode",
                got: s.to_string(),
                valid: valid(),
            });
        }
        let mut t = Textures::default();
        for part in s.split('+') {
            match part {
                "rgb" => t.rgb = true,
                "depth" => t.depth = true,
                "segmentation" => t.segmentation = true,
                _ => {
                    return Err(EnvError::UnknownObsModePart {
                        part: part.to_string(),
                        mode: s.to_string(),
                        valid: TEXTURE_PARTS.join(", "),
                    })
                }
            }
        }
        Ok(Self::of_textures(t))
    }
    /// The camera mode rendering exactly `t` ([`ObsMode::None`] for no texture).
    pub fn of_textures(t: Textures) -> ObsMode {
        match (t.rgb, t.depth, t.segmentation) {
            (false, false, false) => ObsMode::None,
            (true, false, false) => ObsMode::Rgb,
            (false, true, false) => ObsMode::Depth,
            (true, true, false) => ObsMode::Rgbd,
            (false, false, true) => ObsMode::Segmentation,
            (true, false, true) => ObsMode::RgbSegmentation,
            (false, true, true) => ObsMode::DepthSegmentation,
            (true, true, true) => ObsMode::RgbDepthSegmentation,
        }
    }
    /// The mode's name.
    pub fn name(self) -> &'static str {
        name_of(&Self::ALL, self)
    }
}

/// Reward modes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum RewardMode {
    /// Dense reward divided by the task maximum.
    NormalizedDense,
    /// Dense reward.
    Dense,
    /// 1 on success, else 0.
    Sparse,
    /// Always 0.
    None,
}

impl RewardMode {
    /// All modes, by name (default first).
    pub const ALL: [(&'static str, RewardMode); 4] = [
        ("normalized_dense", RewardMode::NormalizedDense),
        ("dense", RewardMode::Dense),
        ("sparse", RewardMode::Sparse),
        ("none", RewardMode::None),
    ];
    /// Parses a mode name.
    pub fn parse(s: &str) -> Result<RewardMode, EnvError> {
        parse_named(&Self::ALL, s, "reward_mode")
    }
    /// The mode's name.
    pub fn name(self) -> &'static str {
        name_of(&Self::ALL, self)
    }
}

/// Looks `s` up in a (name, value) table; the error lists the valid names.
fn parse_named<T: Copy>(
    all: &[(&'static str, T)],
    s: &str,
    what: &'static str,
) -> Result<T, EnvError> {
    all.iter()
        .find(|(n, _)| *n == s)
        .map(|(_, m)| *m)
        .ok_or_else(|| EnvError::UnknownMode {
            what,
            got: s.to_string(),
            valid: names(all),
        })
}

/// The name of `m` in a (name, value) table (every value is listed, so the lookup succeeds).
fn name_of<T: PartialEq>(all: &[(&'static str, T)], m: T) -> &'static str {
    all.iter().find(|(_, v)| *v == m).map_or("", |(n, _)| *n)
}

fn names<T>(v: &[(&str, T)]) -> String {
    v.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
}

pub use crate::mjcf::CONTROL_FREQ;

/// Physics settings (ManiSkill's `sim_config`): how many physics steps simulate one 20 Hz
/// control step. A higher `sim_freq` is slower and closer to the continuous-time dynamics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct SimConfig {
    /// Physics steps per second; a positive multiple of [`CONTROL_FREQ`].
    pub sim_freq: u32,
    /// Who takes the physics steps in which the gripper pinches the task's object.
    #[serde(default)]
    pub pinch_solver: PinchSolver,
}

/// Who takes the physics steps in which a gripper pinches the task's object
/// (docs/physics.md, "The pinch in PhysX's step").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PinchSolver {
    /// MuJoCo's step, as every other step (the default).
    #[default]
    Mujoco,
    /// A replica of PhysX's TGS step for the robot and the pinched object (a box or a
    /// sphere), from the jaws' convex parts (`models/so100/convex_parts.json`; the Panda's
    /// finger boxes, `robots::BOX_FINGER_ROBOTS`). Experimental:
    /// it reproduces PhysX's stall and reported velocities, and does not yet hold every
    /// grasp PhysX holds (docs/outcome-physics.md).
    PhysxTgs,
}

impl PinchSolver {
    /// The solvers by name.
    pub const ALL: [(&'static str, PinchSolver); 2] = [
        ("mujoco", PinchSolver::Mujoco),
        ("physx_tgs", PinchSolver::PhysxTgs),
    ];

    /// Parses a solver name; an error names the valid ones.
    pub fn parse(s: &str) -> Result<PinchSolver, EnvError> {
        Self::ALL
            .iter()
            .find(|(n, _)| *n == s)
            .map(|(_, v)| *v)
            .ok_or_else(|| EnvError::UnknownMode {
                what: "pinch_solver",
                got: s.to_string(),
                valid: names(&Self::ALL),
            })
    }

    /// The solver's name.
    pub fn name(self) -> &'static str {
        Self::ALL
            .iter()
            .find(|(_, v)| *v == self)
            .map(|(n, _)| *n)
            .expect("every solver is named")
    }
}

impl SimConfig {
    /// The default physics rate: ManiSkill's own (0.01 s steps).
    pub const DEFAULT_SIM_FREQ: u32 = 100;
    /// Physics steps per control step.
    pub fn substeps(&self) -> usize {
        (self.sim_freq / CONTROL_FREQ) as usize
    }
    /// Physics timestep (s).
    pub fn timestep(&self) -> f64 {
        CONTROL_DT / self.substeps() as f64
    }
    /// Checks that `sim_freq` is a positive multiple of the control frequency.
    pub fn validate(&self) -> Result<(), EnvError> {
        if self.sim_freq == 0
            || !self.sim_freq.is_multiple_of(CONTROL_FREQ)
            || self.sim_freq > 100_000
        {
            return Err(EnvError::BadSimFreq(self.sim_freq));
        }
        Ok(())
    }
}

impl Default for SimConfig {
    fn default() -> Self {
        SimConfig {
            sim_freq: Self::DEFAULT_SIM_FREQ,
            pinch_solver: PinchSolver::Mujoco,
        }
    }
}

/// Env construction options; `Default` equals ManiSkill's defaults (docs/env.md §2).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EnvConfig {
    /// Robot uid (None: the env's default robot).
    pub robot: Option<String>,
    /// Observation mode.
    pub obs_mode: ObsMode,
    /// Reward mode.
    pub reward_mode: RewardMode,
    /// Control mode (None: the robot's default, `pd_joint_delta_pos`).
    pub control_mode: Option<String>,
    /// Std-dev of the initial joint noise.
    pub robot_init_qpos_noise: f64,
    /// Episode length for truncation (None: 50).
    pub max_episode_steps: Option<u32>,
    /// Physics settings.
    #[serde(default)]
    pub sim: SimConfig,
    /// ManiSkill's `reconfiguration_freq`: every how many resets a task whose shapes are drawn
    /// per episode (PegInsertionSide-v1) draws them anew; 0: only when the env is made and on
    /// [`super::Env::reset_with`]`(.., true)`. `None`: ManiSkill's default, 1 for a single env
    /// (every reset) and 0 for a [`super::vec::VecEnv`] of more than one env (each env keeps
    /// the shapes of its construction seed, 2022 + i). No effect on the other tasks, whose
    /// scenes are fixed.
    #[serde(default)]
    pub reconfiguration_freq: Option<u32>,
}

impl Default for EnvConfig {
    fn default() -> Self {
        EnvConfig {
            robot: None,
            obs_mode: ObsMode::State,
            reward_mode: RewardMode::NormalizedDense,
            control_mode: None,
            robot_init_qpos_noise: DEFAULT_QPOS_NOISE,
            max_episode_steps: None,
            sim: SimConfig::default(),
            reconfiguration_freq: None,
        }
    }
}
