//! The gymnasium-style env API: [`make`], [`Env::reset`], [`Env::step`], spaces, the
//! registry, and exact ManiSkill seeding ([`rng`]).
//!
//! Semantics follow ManiSkill3's single-env CPU path (env.md): 20 Hz control, `terminated` =
//! success, `truncated` once `elapsed_steps ≥ max_episode_steps` (50), and the env keeps
//! running after either — nothing stops further `step` calls (`elapsed_steps` keeps
//! counting, `truncated` stays true), exactly as upstream.
pub mod checks;
pub mod render;
pub mod rng;
pub mod state_dict;
pub mod vec;
pub use render::CameraImage;
pub use state_dict::{ActionPart, StateDict};
pub use vec::VecEnv;

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::controllers::{Controller, Drives};
use crate::mjcf::{Mjcf, Scene, CONTROL_DT};
use crate::mujoco::{Data, Model, Warnings};
use crate::robots::{InitNoise, RobotIds, RobotSpec};
use crate::tasks::{finger_forces, Task, TaskCtx};
use rng::{NumpyRandomState, TorchGenerator};

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
    #[error("unknown env id {0:?}; valid env ids: {1}")]
    UnknownEnv(String, String),
    /// Robot not supported by this env.
    #[error("robot {robot:?} is not supported by {env}; supported robots: {valid}")]
    UnsupportedRobot {
        /// Env id.
        env: String,
        /// Requested robot.
        robot: String,
        /// Valid robots.
        valid: String,
    },
    /// Unknown mode (obs, reward or control).
    #[error("{0}")]
    UnknownMode(String),
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
    /// A state from another env, of the wrong size, or with a bad value (the message names
    /// the field).
    #[error("cannot set state: {0}")]
    BadState(String),
    /// A seed beyond ManiSkill's 32-bit seeds ([`checks::MAX_SEED`]).
    #[error("seed {0} is out of range: seeds are 32-bit, 0..=4294967295")]
    BadSeed(u64),
    /// Building the scene or model failed.
    #[error("{0}")]
    Build(String),
    /// Rendering is unavailable or failed (the message names what to install).
    #[error("{0}")]
    Render(String),
}

/// Observation modes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ObsMode {
    /// One flat f32 vector.
    State,
    /// The same values with named parts ([`Env::obs_layout`]).
    StateDict,
    /// No observation.
    None,
    /// State-free vector (agent, controller, non-privileged extras) plus the sensor camera's
    /// colour image ([`Env::sensor_rgb`]).
    Rgb,
    /// As `Rgb` with the depth image ([`Env::sensor_depth`]) instead of colour.
    Depth,
    /// As `Rgb` with both colour and depth.
    Rgbd,
}

impl ObsMode {
    /// All modes, by name.
    pub const ALL: [(&'static str, ObsMode); 6] = [
        ("state", ObsMode::State),
        ("state_dict", ObsMode::StateDict),
        ("none", ObsMode::None),
        ("rgb", ObsMode::Rgb),
        ("depth", ObsMode::Depth),
        ("rgbd", ObsMode::Rgbd),
    ];
    /// Whether the mode renders camera images.
    pub fn is_visual(self) -> bool {
        matches!(self, ObsMode::Rgb | ObsMode::Depth | ObsMode::Rgbd)
    }
    /// Whether the observation includes privileged state (object poses): ManiSkill's
    /// `"state" in obs_mode`.
    pub fn is_state(self) -> bool {
        matches!(self, ObsMode::State | ObsMode::StateDict)
    }
    /// Parses a mode name.
    pub fn parse(s: &str) -> Result<ObsMode, EnvError> {
        parse_named(&Self::ALL, s, "obs_mode")
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
fn parse_named<T: Copy>(all: &[(&'static str, T)], s: &str, what: &str) -> Result<T, EnvError> {
    all.iter()
        .find(|(n, _)| *n == s)
        .map(|(_, m)| *m)
        .ok_or_else(|| {
            EnvError::UnknownMode(format!(
                "unknown {what} {s:?}; valid {}s: {}",
                what.replace('_', " "),
                names(all)
            ))
        })
}

/// The name of `m` in a (name, value) table (every value is listed, so the lookup succeeds).
fn name_of<T: PartialEq>(all: &[(&'static str, T)], m: T) -> &'static str {
    all.iter().find(|(_, v)| *v == m).map_or("", |(n, _)| *n)
}

fn names<T>(v: &[(&str, T)]) -> String {
    v.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
}

/// ManiSkill's control frequency (Hz): one env step is 1/20 s.
pub const CONTROL_FREQ: u32 = 20;

/// Physics settings (ManiSkill's `sim_config`): how many physics steps simulate one 20 Hz
/// control step. A higher `sim_freq` is slower and closer to the continuous-time dynamics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct SimConfig {
    /// Physics steps per second; a positive multiple of [`CONTROL_FREQ`].
    pub sim_freq: u32,
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
            return Err(EnvError::Build(format!(
                "sim_freq {} is not a multiple of the control frequency {CONTROL_FREQ} Hz \
                 between {CONTROL_FREQ} and 100000 (e.g. 100, 200, 500)",
                self.sim_freq
            )));
        }
        Ok(())
    }
}

impl Default for SimConfig {
    fn default() -> Self {
        SimConfig {
            sim_freq: Self::DEFAULT_SIM_FREQ,
        }
    }
}

/// Env construction options; `Default` equals ManiSkill's defaults (env.md §2).
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
        }
    }
}

/// A registered env.
#[derive(Debug, Clone)]
pub struct EnvSpec {
    /// Env id.
    pub id: &'static str,
    /// Supported robots (the first is the default).
    pub robots: &'static [&'static str],
    /// Steps until truncation.
    pub max_episode_steps: u32,
    make_task: fn(&'static str) -> Box<dyn Task>,
}

/// Public description of a registered env, for listings.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EnvInfo {
    /// Env id.
    pub id: &'static str,
    /// Default robot.
    pub default_robot: &'static str,
    /// Supported robots with their control modes (default first).
    pub robots: Vec<(&'static str, Vec<&'static str>)>,
    /// Observation modes.
    pub obs_modes: Vec<&'static str>,
    /// Reward modes.
    pub reward_modes: Vec<&'static str>,
    /// Steps until truncation.
    pub max_episode_steps: u32,
}

fn pick_cube(robot: &'static str) -> Box<dyn Task> {
    Box::new(crate::tasks::pick_cube::PickCube::new(robot))
}

fn place_sphere(_robot: &'static str) -> Box<dyn Task> {
    Box::new(crate::tasks::place_sphere::PlaceSphere::new())
}

fn poke_cube(_robot: &'static str) -> Box<dyn Task> {
    Box::new(crate::tasks::poke_cube::PokeCube::new())
}

static REGISTRY: [EnvSpec; 5] = [
    EnvSpec {
        id: "PickCube-v1",
        robots: &["panda", "fetch", "xarm6_robotiq", "so100", "widowxai"],
        max_episode_steps: MAX_EPISODE_STEPS,
        make_task: pick_cube,
    },
    EnvSpec {
        id: "PickCubeSO100-v1",
        robots: &["so100"],
        max_episode_steps: MAX_EPISODE_STEPS,
        make_task: pick_cube,
    },
    EnvSpec {
        id: "PickCubeWidowXAI-v1",
        robots: &["widowxai"],
        max_episode_steps: MAX_EPISODE_STEPS,
        make_task: pick_cube,
    },
    EnvSpec {
        id: "PlaceSphere-v1",
        robots: &["panda", "fetch"],
        max_episode_steps: MAX_EPISODE_STEPS,
        make_task: place_sphere,
    },
    EnvSpec {
        id: "PokeCube-v1",
        robots: &["panda", "fetch"],
        max_episode_steps: MAX_EPISODE_STEPS,
        make_task: poke_cube,
    },
];

fn env_spec(id: &str) -> Result<&'static EnvSpec, EnvError> {
    REGISTRY.iter().find(|e| e.id == id).ok_or_else(|| {
        EnvError::UnknownEnv(
            id.to_string(),
            REGISTRY.iter().map(|e| e.id).collect::<Vec<_>>().join(", "),
        )
    })
}

/// The default robot of a registered env.
pub fn default_robot(env_id: &str) -> Result<&'static str, EnvError> {
    Ok(env_spec(env_id)?.robots[0])
}

/// Every registered env id with its robots, their control modes, and the modes.
pub fn registry() -> Vec<EnvInfo> {
    REGISTRY
        .iter()
        .map(|e| EnvInfo {
            id: e.id,
            default_robot: e.robots[0],
            robots: e
                .robots
                .iter()
                .map(|r| {
                    (
                        *r,
                        crate::robots::spec(r)
                            .map(|s| s.control_modes.to_vec())
                            .unwrap_or_default(),
                    )
                })
                .collect(),
            obs_modes: ObsMode::ALL.iter().map(|(n, _)| *n).collect(),
            reward_modes: RewardMode::ALL.iter().map(|(n, _)| *n).collect(),
            max_episode_steps: e.max_episode_steps,
        })
        .collect()
}

fn resolve_robot(spec: &EnvSpec, robot: Option<&str>) -> Result<&'static RobotSpec, EnvError> {
    let uid = robot.unwrap_or(spec.robots[0]);
    crate::robots::spec(uid).map_err(EnvError::Build)?;
    if !spec.robots.contains(&uid) {
        return Err(EnvError::UnsupportedRobot {
            env: spec.id.into(),
            robot: uid.into(),
            valid: spec.robots.join(", "),
        });
    }
    crate::robots::spec(uid).map_err(EnvError::Build)
}

/// Builds the MJCF of an env's scene for `robot` with its default control mode.
pub fn scene_mjcf(env_id: &str, robot: &str) -> Result<Mjcf, String> {
    let spec = env_spec(env_id).map_err(|e| e.to_string())?;
    let rs = resolve_robot(spec, Some(robot)).map_err(|e| e.to_string())?;
    let (mjcf, ..) = build_scene(spec, rs, rs.control_modes[0], SimConfig::default())
        .map_err(|e| e.to_string())?;
    Ok(mjcf)
}

type Built = (
    Mjcf,
    crate::mjcf::urdf::RobotDesc,
    Controller,
    Box<dyn Task>,
    Vec<crate::mjcf::Drive>,
);

fn build_scene(
    spec: &EnvSpec,
    rs: &'static RobotSpec,
    control_mode: &str,
    sim: SimConfig,
) -> Result<Built, EnvError> {
    let desc = rs.description().map_err(EnvError::Build)?;
    let parts = rs
        .control_mode(control_mode)
        .map_err(EnvError::UnknownMode)?;
    let controller = Controller::new(control_mode, parts, &desc).map_err(EnvError::Build)?;
    let task = (spec.make_task)(rs.uid);
    let mut scene = Scene::new(&format!("{}-{}", spec.id, rs.uid), sim.timestep());
    scene.add_table_scene();
    let drives = controller.drives(&desc);
    let opts = rs.options(rs.table_base(), drives.clone());
    scene
        .add_robot(&desc, &opts, &|_| None)
        .map_err(EnvError::Build)?;
    task.build(&mut scene);
    Ok((scene.finish(), desc, controller, task, drives))
}

/// A box-shaped space with per-entry bounds.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BoxSpace {
    /// Shape.
    pub shape: Vec<usize>,
    /// Lower bounds (flattened).
    pub low: Vec<f32>,
    /// Upper bounds (flattened).
    pub high: Vec<f32>,
}

/// `info` of a reset or step: `elapsed_steps` plus the task's `evaluate()` keys in upstream
/// order (bools as 0/1). Overwritten in place every step (no allocation).
#[derive(Debug, Clone, PartialEq)]
pub struct Info {
    /// Steps since the last reset.
    pub elapsed_steps: u32,
    /// Present on reset only (always false: the scene is never rebuilt).
    pub reconfigure: Option<bool>,
    /// Task keys.
    pub keys: &'static [&'static str],
    /// Task values aligned with `keys`.
    pub values: Vec<f64>,
    /// MuJoCo instability warnings raised during the step (e.g. BADQACC: the simulation
    /// diverged and MuJoCo reset it). Not part of ManiSkill's info.
    pub warnings: Warnings,
}

impl Info {
    /// Value of a task key.
    pub fn get(&self, key: &str) -> Option<f64> {
        self.keys
            .iter()
            .position(|k| *k == key)
            .map(|i| self.values[i])
    }
    /// Boolean value of a task key (false if absent).
    pub fn flag(&self, key: &str) -> bool {
        self.get(key).is_some_and(|v| v != 0.0)
    }
    /// `success`.
    pub fn success(&self) -> bool {
        self.flag("success")
    }
}

/// The result of [`Env::step`], borrowing the env's buffers.
#[derive(Debug)]
pub struct Step<'a> {
    /// Observation (empty for obs mode `none`).
    pub obs: &'a [f32],
    /// Reward in the configured mode.
    pub reward: f32,
    /// `info["success"]`.
    pub terminated: bool,
    /// `elapsed_steps ≥ max_episode_steps`.
    pub truncated: bool,
    /// Info.
    pub info: &'a Info,
}

/// Everything that determines an env's future, for [`Env::get_state`] / [`Env::set_state`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EnvState {
    /// Env id.
    pub env_id: String,
    /// Robot uid.
    pub robot: String,
    /// Control mode.
    pub control_mode: String,
    /// MuJoCo state ([`Data::get_state`]).
    pub physics: Vec<f64>,
    /// Controller targets.
    pub controller: Vec<f64>,
    /// Steps since reset.
    pub elapsed_steps: u32,
    /// Finger contact forces of the last substep (seen by a following reset).
    pub finger_forces: [[f64; 3]; 2],
    /// The numpy episode RNG.
    pub numpy: NumpyRandomState,
    /// The process-global torch generator (unseeded resets).
    pub torch_global: TorchGenerator,
    /// Main and episode seeds.
    pub seeds: (Option<u64>, Option<u64>),
}

/// One environment.
#[derive(Debug)]
pub struct Env {
    id: &'static str,
    spec: &'static RobotSpec,
    config: EnvConfig,
    max_episode_steps: u32,
    model: Arc<Model>,
    data: Data,
    robot: RobotIds,
    controller: Controller,
    /// The robot's joint drives (targets and force law).
    drives: Drives,
    task: Box<dyn Task>,
    /// ManiSkill's actors (table first, then the task's), resolved to bodies.
    actors: Vec<state_dict::Actor>,
    numpy: NumpyRandomState,
    torch_global: TorchGenerator,
    main_seed: Option<u64>,
    episode_seed: Option<u64>,
    elapsed_steps: u32,
    info: Info,
    finger_forces: [[f64; 3]; 2],
    qpos: Vec<f64>,
    qvel: Vec<f64>,
    noise: Vec<f64>,
    obs: Vec<f32>,
    obs_layout: Vec<(String, std::ops::Range<usize>)>,
    action_space: BoxSpace,
    observation_space: BoxSpace,
    scratch_state: Vec<f64>,
    vision: Option<render::Vision>,
    render_options: crate::mujoco::render::RenderOptions,
}

/// Creates an env (gymnasium's `make`). Like ManiSkill, the new env has already been reset
/// with seed 2022.
pub fn make(env_id: &str, config: EnvConfig) -> Result<Env, EnvError> {
    Env::new(env_id, config)
}

impl Env {
    fn new(env_id: &str, config: EnvConfig) -> Result<Env, EnvError> {
        let spec = env_spec(env_id)?;
        let rs = resolve_robot(spec, config.robot.as_deref())?;
        let mode = config
            .control_mode
            .clone()
            .unwrap_or_else(|| rs.control_modes[0].to_string());
        checks::check_qpos_noise(config.robot_init_qpos_noise)?;
        config.sim.validate()?;
        let (mjcf, desc, controller, mut task, drive_list) =
            build_scene(spec, rs, &mode, config.sim)?;
        let model = Arc::new(mjcf.compile().map_err(|e| EnvError::Build(e.to_string()))?);
        let data = Data::new(model.clone()).map_err(|e| EnvError::Build(e.to_string()))?;
        let robot = RobotIds::resolve(&model, &desc, rs).map_err(EnvError::Build)?;
        task.resolve(&model).map_err(EnvError::Build)?;
        let drives = Drives::new(&model, &drive_list, &robot.joint_names, rs.gripper_joints)
            .map_err(EnvError::Build)?;
        let actors =
            state_dict::resolve_actors(&model, task.actor_names()).map_err(EnvError::Build)?;
        let n = robot.qpos_adr.len();
        let keys = task.info_keys();
        let state = config.obs_mode != ObsMode::None;
        let mut obs_layout = Vec::new();
        let mut off = 0;
        if state {
            let mut parts: Vec<(String, usize)> =
                vec![("agent/qpos".into(), n), ("agent/qvel".into(), n)];
            parts.extend(controller.state_layout());
            parts.extend(
                task.extra_layout(config.obs_mode.is_state())
                    .into_iter()
                    .map(|(k, l)| (format!("extra/{k}"), l)),
            );
            for (k, l) in parts {
                obs_layout.push((k, off..off + l));
                off += l;
            }
        }
        let (low, high) = controller.bounds();
        let action_space = BoxSpace {
            shape: vec![low.len()],
            low: low.to_vec(),
            high: high.to_vec(),
        };
        let observation_space = BoxSpace {
            shape: vec![off],
            low: vec![f32::NEG_INFINITY; off],
            high: vec![f32::INFINITY; off],
        };
        let max_episode_steps = config.max_episode_steps.unwrap_or(spec.max_episode_steps);
        let render_options = crate::mujoco::render::RenderOptions::default();
        let vision = match config.obs_mode {
            ObsMode::Rgb | ObsMode::Depth | ObsMode::Rgbd => Some(
                render::Vision::new(
                    &model,
                    task.cameras(),
                    rs.cameras,
                    config.obs_mode != ObsMode::Depth,
                    config.obs_mode != ObsMode::Rgb,
                    render_options,
                )
                .map_err(|e| EnvError::Render(e.to_string()))?,
            ),
            _ => None,
        };
        let mut env = Env {
            id: spec.id,
            spec: rs,
            config: EnvConfig {
                robot: Some(rs.uid.to_string()),
                control_mode: Some(mode),
                ..config
            },
            max_episode_steps,
            model,
            data,
            robot,
            controller,
            drives,
            task,
            actors,
            numpy: NumpyRandomState::new(CONSTRUCTION_SEED),
            torch_global: TorchGenerator::default(),
            main_seed: None,
            episode_seed: None,
            elapsed_steps: 0,
            info: Info {
                elapsed_steps: 0,
                reconfigure: None,
                keys,
                values: vec![0.0; keys.len()],
                warnings: Warnings::default(),
            },
            finger_forces: [[0.0; 3]; 2],
            qpos: vec![0.0; n],
            qvel: vec![0.0; n],
            noise: vec![0.0; n],
            obs: vec![0.0; off],
            obs_layout,
            action_space,
            observation_space,
            scratch_state: Vec::new(),
            vision,
            render_options,
        };
        env.reset(Some(CONSTRUCTION_SEED));
        env.drives.prepare(&mut env.data);
        Ok(env)
    }

    /// Env id.
    pub fn id(&self) -> &'static str {
        self.id
    }
    /// Contact forces (N, world frame) on the two grasp fingers from the task's grasp object
    /// in the last physics substep (what `is_grasping` reads).
    pub fn finger_forces(&self) -> &[[f64; 3]; 2] {
        &self.finger_forces
    }
    /// The robot's joint drives (targets and force law).
    pub fn drives(&self) -> &Drives {
        &self.drives
    }
    /// Physics steps per env step.
    pub fn substeps(&self) -> usize {
        self.config.sim.substeps()
    }
    /// The effective configuration (robot and control mode filled in).
    pub fn config(&self) -> &EnvConfig {
        &self.config
    }
    /// Robot spec.
    pub fn robot_spec(&self) -> &'static RobotSpec {
        self.spec
    }
    /// The control mode in use (the robot's default when the config names none).
    pub fn control_mode(&self) -> &str {
        self.controller.mode()
    }
    /// The compiled model.
    pub fn model(&self) -> &Arc<Model> {
        &self.model
    }
    /// The simulation data (read-only).
    pub fn data(&self) -> &Data {
        &self.data
    }
    /// Resolved robot ids.
    pub fn robot(&self) -> &RobotIds {
        &self.robot
    }
    /// The task.
    pub fn task(&self) -> &dyn Task {
        self.task.as_ref()
    }
    /// Steps until truncation.
    pub fn max_episode_steps(&self) -> u32 {
        self.max_episode_steps
    }
    /// Action space (normalised parts are [−1, 1]).
    pub fn action_space(&self) -> &BoxSpace {
        &self.action_space
    }
    /// Observation space (flat state vector; empty for obs mode `none`).
    pub fn observation_space(&self) -> &BoxSpace {
        &self.observation_space
    }
    /// Names and ranges of the parts of the flat observation (the `state_dict` view).
    pub fn obs_layout(&self) -> &[(String, std::ops::Range<usize>)] {
        &self.obs_layout
    }
    /// The current observation.
    pub fn obs(&self) -> &[f32] {
        if self.config.obs_mode == ObsMode::None {
            &[]
        } else {
            &self.obs
        }
    }
    /// A named part of the current observation (`state_dict` access), e.g. `"extra/tcp_pose"`.
    pub fn obs_part(&self, key: &str) -> Option<&[f32]> {
        self.obs_layout
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, r)| &self.obs[r.clone()])
    }
    /// The current info.
    pub fn info(&self) -> &Info {
        &self.info
    }
    /// Main seed.
    pub fn main_seed(&self) -> Option<u64> {
        self.main_seed
    }
    /// Seed of the current episode (the last seeded reset).
    pub fn episode_seed(&self) -> Option<u64> {
        self.episode_seed
    }

    /// Like [`Env::reset`], but a seed above [`checks::MAX_SEED`] is an error
    /// ([`EnvError::BadSeed`]) and the env is left unchanged.
    pub fn try_reset(&mut self, seed: Option<u64>) -> Result<(&[f32], &Info), EnvError> {
        if let Some(s) = seed {
            checks::check_seed(s)?;
        }
        Ok(self.reset(seed))
    }

    /// Resets (env.md §3): with a seed, both RNG streams restart from it; without, the numpy
    /// stream continues and placement draws come from the env's global torch generator.
    /// Returns the observation and info (`reconfigure = false`).
    ///
    /// Seeds are 32-bit as in ManiSkill: a seed above [`checks::MAX_SEED`] is reduced mod 2³²
    /// by both RNG streams, so `reset(Some(s))` and `reset(Some(s + 2³²))` give the same
    /// episode (the seed itself is kept as given, e.g. in recordings). Use [`Env::try_reset`]
    /// to reject such seeds instead.
    pub fn reset(&mut self, seed: Option<u64>) -> (&[f32], &Info) {
        if let Some(s) = seed {
            self.main_seed = Some(s);
            self.episode_seed = Some(s);
            self.numpy = NumpyRandomState::new(s);
        }
        self.elapsed_steps = 0;
        // _clear_sim_state + agent.reset: zero every velocity and the solver warm start.
        self.data.qvel_mut().fill(0.0);
        self.data.qacc_warmstart_mut().fill(0.0);
        self.data.set_time(0.0);
        // Table scene: robot placement and joint noise (numpy stream).
        let rs = self.spec;
        self.qpos.copy_from_slice(rs.table_qpos);
        let sigma = self.config.robot_init_qpos_noise;
        match rs.init_noise {
            InitNoise::None => {}
            InitNoise::All | InitNoise::AllButLast(_) => {
                self.numpy.fill_normal(0.0, sigma, &mut self.noise);
                let keep = match rs.init_noise {
                    InitNoise::AllButLast(k) => self.noise.len() - k,
                    _ => self.noise.len(),
                };
                for (q, z) in self.qpos.iter_mut().zip(&self.noise).take(keep) {
                    *q += z;
                }
            }
        }
        // PhysX stores joint positions as float32.
        for q in self.qpos.iter_mut() {
            *q = *q as f32 as f64;
        }
        self.robot.set_qpos(&mut self.data, &self.qpos);
        // Task placement (torch stream: a fresh generator for seeded resets).
        match seed {
            Some(s) => {
                let mut torch = TorchGenerator::new(s);
                self.task.initialize_episode(&mut self.data, &mut torch);
            }
            None => self
                .task
                .initialize_episode(&mut self.data, &mut self.torch_global),
        }
        self.robot.apply_gravity_compensation(&mut self.data);
        self.data.forward();
        self.controller
            .reset(&self.robot, &self.data, &mut self.drives);
        self.data.clear_warnings();
        // Contacts are not refreshed by a reset (env.md §3 step 8): the grasp check sees the
        // previous episode's last finger forces at the new poses.
        self.evaluate();
        self.info.reconfigure = Some(false);
        self.write_obs();
        (self.obs(), &self.info)
    }

    /// One control step (env.md §4). Errors (wrong length, NaN/inf) leave the env unchanged.
    pub fn step(&mut self, action: &[f32]) -> Result<Step<'_>, EnvError> {
        let expected = self.controller.action_dim();
        if action.len() != expected {
            return Err(EnvError::ActionLength {
                got: action.len(),
                expected,
                mode: self.controller.mode().to_string(),
            });
        }
        if let Some((index, &value)) = action.iter().enumerate().find(|(_, a)| !a.is_finite()) {
            return Err(EnvError::ActionNotFinite { index, value });
        }
        self.controller
            .set_action(action, &self.robot, &self.data, &mut self.drives);
        Ok(self.advance())
    }

    /// A control step without a new action (`action=None` upstream): the drives keep their
    /// targets while physics advances.
    pub fn step_no_action(&mut self) -> Step<'_> {
        self.advance()
    }

    fn advance(&mut self) -> Step<'_> {
        for _ in 0..self.config.sim.substeps() {
            self.drives.step(&mut self.data);
        }
        // mj_step leaves poses at the start of its last substep; observations, rewards and
        // success must see the poses of the final state.
        self.data.update_kinematics();
        self.elapsed_steps = self.elapsed_steps.saturating_add(1);
        finger_forces(
            &self.model,
            &self.data,
            self.robot.fingers,
            self.task.grasp_object(),
            &mut self.finger_forces,
        );
        self.evaluate();
        self.info.reconfigure = None;
        self.info.warnings = self.data.warnings();
        self.data.clear_warnings();
        self.write_obs();
        let reward = self.reward();
        Step {
            obs: if self.config.obs_mode == ObsMode::None {
                &[]
            } else {
                &self.obs
            },
            reward,
            terminated: self.info.success(),
            truncated: self.elapsed_steps >= self.max_episode_steps,
            info: &self.info,
        }
    }

    fn ctx(&self) -> TaskCtx<'_> {
        let (tcp_pos, tcp_quat) = self.robot.tcp_pose(&self.data);
        TaskCtx {
            model: &self.model,
            data: &self.data,
            robot: &self.robot,
            spec: self.spec,
            tcp_pos,
            tcp_quat,
            qpos: &self.qpos,
            qvel: &self.qvel,
            finger_forces: &self.finger_forces,
        }
    }

    fn evaluate(&mut self) {
        self.robot.qpos(&self.data, &mut self.qpos);
        self.robot.qvel(&self.data, &mut self.qvel);
        let mut values = std::mem::take(&mut self.info.values);
        self.task.evaluate(&self.ctx(), &mut values);
        self.info.values = values;
        self.info.elapsed_steps = self.elapsed_steps;
    }

    fn write_obs(&mut self) {
        if let Some(v) = self.vision.as_mut() {
            v.invalidate();
        }
        if self.config.obs_mode == ObsMode::None {
            return;
        }
        let n = self.qpos.len();
        let mut obs = std::mem::take(&mut self.obs);
        for (o, q) in obs[..n].iter_mut().zip(&self.qpos) {
            *o = *q as f32;
        }
        for (o, v) in obs[n..2 * n].iter_mut().zip(&self.qvel) {
            *o = *v as f32;
        }
        let c = self.controller.state_len();
        self.controller.write_state(&mut obs[2 * n..2 * n + c]);
        let privileged = self.config.obs_mode.is_state();
        self.task.write_extra(
            &self.ctx(),
            &self.info.values,
            privileged,
            &mut obs[2 * n + c..],
        );
        self.obs = obs;
        self.render_sensors();
    }

    /// Renders the sensor images of a visual obs mode (and marks the human frame stale).
    ///
    /// # Panics
    /// If EGL fails to make the env's GL context current after it was created successfully
    /// (the context is never left current on another thread, so this indicates a broken GL
    /// driver).
    fn render_sensors(&mut self) {
        if let Some(v) = self.vision.as_mut() {
            if let Err(e) = v.render_sensor(&mut self.data) {
                panic!("rendering the sensor camera failed after the renderer was created: {e}");
            }
        }
    }

    fn reward(&self) -> f32 {
        match self.config.reward_mode {
            RewardMode::None => 0.0,
            RewardMode::Sparse => self.info.success() as u8 as f32,
            RewardMode::Dense => self.task.dense_reward(&self.ctx(), &self.info.values) as f32,
            RewardMode::NormalizedDense => {
                (self.task.dense_reward(&self.ctx(), &self.info.values) / self.task.max_reward())
                    as f32
            }
        }
    }

    /// Dense reward of the current state (independent of the reward mode).
    pub fn dense_reward(&self) -> f64 {
        self.task.dense_reward(&self.ctx(), &self.info.values)
    }

    /// Captures everything that determines the future.
    pub fn get_state(&self) -> EnvState {
        let mut physics = Vec::with_capacity(self.data.state_len());
        self.data.get_state(&mut physics);
        let mut controller =
            Vec::with_capacity(self.controller.save_len() + self.drives.save_len());
        self.controller.save(&mut controller);
        self.drives.save(&mut controller);
        EnvState {
            env_id: self.id.to_string(),
            robot: self.spec.uid.to_string(),
            control_mode: self.controller.mode().to_string(),
            physics,
            controller,
            elapsed_steps: self.elapsed_steps,
            finger_forces: self.finger_forces,
            numpy: self.numpy.clone(),
            torch_global: self.torch_global.clone(),
            seeds: (self.main_seed, self.episode_seed),
        }
    }

    /// Restores a state from [`Env::get_state`]; the following steps equal the original
    /// trajectory bitwise. A state of another env, robot or control mode, or with a
    /// non-finite or out-of-range value ([`checks::check_state_values`]: the error names the
    /// field), is an error and the env is left unchanged.
    pub fn set_state(&mut self, s: &EnvState) -> Result<(), EnvError> {
        let mine = (self.id, self.spec.uid, self.controller.mode());
        if (s.env_id.as_str(), s.robot.as_str(), s.control_mode.as_str()) != mine {
            return Err(EnvError::BadState(format!(
                "state is from {}/{}/{}, this env is {}/{}/{}",
                s.env_id, s.robot, s.control_mode, mine.0, mine.1, mine.2
            )));
        }
        if s.physics.len() != self.data.state_len()
            || s.controller.len() != self.controller.save_len() + self.drives.save_len()
        {
            return Err(EnvError::BadState(format!(
                "state sizes {} / {} do not match this env's {} / {}",
                s.physics.len(),
                s.controller.len(),
                self.data.state_len(),
                self.controller.save_len() + self.drives.save_len()
            )));
        }
        checks::check_state_values(&self.model, s)?;
        self.data
            .set_state(&s.physics)
            .map_err(|e| EnvError::BadState(e.to_string()))?;
        let k = self.controller.load(&s.controller);
        self.drives.load(&s.controller[k..]);
        self.elapsed_steps = s.elapsed_steps;
        self.finger_forces = s.finger_forces;
        self.numpy = s.numpy.clone();
        self.torch_global = s.torch_global.clone();
        (self.main_seed, self.episode_seed) = s.seeds;
        self.evaluate();
        self.write_obs();
        Ok(())
    }

    /// Raw physics state (for recording), written into `out`.
    pub fn physics_state(&mut self) -> &[f64] {
        let mut buf = std::mem::take(&mut self.scratch_state);
        self.data.get_state(&mut buf);
        self.scratch_state = buf;
        &self.scratch_state
    }

    // ---- camera images (rendering: see `render.rs`) ------------------------------------

    /// The sensor camera's colour image of the current state (H×W×3 bytes, top row first),
    /// rewritten in place by every step; `None` unless the obs mode is `rgb` or `rgbd`.
    pub fn sensor_rgb(&self) -> Option<&[u8]> {
        self.vision
            .as_ref()
            .filter(|v| v.rgb_on)
            .map(|v| v.sensor_rgb.as_slice())
    }

    /// The sensor camera's depth image (H×W×1 metres along the optical axis); `None` unless
    /// the obs mode is `depth` or `rgbd`.
    pub fn sensor_depth(&self) -> Option<&[f32]> {
        self.vision
            .as_ref()
            .filter(|v| v.depth_on)
            .map(|v| v.sensor_depth.as_slice())
    }

    /// A sensor camera's images by name (ManiSkill's `obs["sensor_data"][name]`): the task's
    /// `env.image("base_camera")` or a robot-mounted camera (Fetch's `"fetch_head"`,
    /// `"fetch_hand"`); `None` for an unknown name or a non-visual obs mode.
    pub fn image(&self, camera: &str) -> Option<CameraImage<'_>> {
        let v = self.vision.as_ref()?;
        if !(v.rgb_on || v.depth_on) {
            return None;
        }
        let def = v.sensor_def();
        if def.name == camera {
            return Some(CameraImage {
                name: def.name,
                width: def.size.0,
                height: def.size.1,
                rgb: self.sensor_rgb(),
                depth: self.sensor_depth(),
            });
        }
        let m = v.mounted.iter().find(|m| m.name == camera)?;
        Some(CameraImage {
            name: m.name,
            width: m.size.0,
            height: m.size.1,
            rgb: v.rgb_on.then_some(m.rgb.as_slice()),
            depth: v.depth_on.then_some(m.depth.as_slice()),
        })
    }

    /// Names of the sensor cameras of a visual obs mode, as [`Env::image`] takes them: the
    /// task's sensor camera, then the robot's mounted cameras.
    pub fn sensor_names(&self) -> Vec<&'static str> {
        std::iter::once(self.task.cameras().0.name)
            .chain(self.spec.cameras.iter().map(|c| c.name))
            .collect()
    }

    /// The task's (sensor, human render) cameras.
    pub fn cameras(&self) -> (crate::tasks::CameraDef, crate::tasks::CameraDef) {
        self.task.cameras()
    }

    /// Renders the human camera (ManiSkill's `render_mode="rgb_array"`, 512×512 for the
    /// tabletop tasks) and returns its RGB frame, H×W×3 bytes, top row first. The goal
    /// markers hidden from the sensor are visible here. The first call of an env in a
    /// non-visual obs mode creates its renderer; an error says what to install.
    pub fn render(&mut self) -> Result<&[u8], EnvError> {
        if self.vision.is_none() {
            self.vision = Some(
                render::Vision::new(
                    &self.model,
                    self.task.cameras(),
                    self.spec.cameras,
                    false,
                    false,
                    self.render_options,
                )
                .map_err(|e| EnvError::Render(e.to_string()))?,
            );
        }
        let v = self.vision.as_mut().expect("created above");
        v.render_human(&mut self.data)
            .map_err(|e| EnvError::Render(e.to_string()))
    }

    /// Size (width, height) of [`Env::render`]'s frames.
    pub fn render_size(&self) -> (usize, usize) {
        self.task.cameras().1.size
    }

    /// The render quality settings (defaults favour speed).
    pub fn render_options(&self) -> crate::mujoco::render::RenderOptions {
        self.render_options
    }

    /// Changes the render quality (shadows, multisampling, reflections, clip planes); an
    /// existing renderer is rebuilt and the sensor images are redrawn.
    pub fn set_render_options(
        &mut self,
        options: crate::mujoco::render::RenderOptions,
    ) -> Result<(), EnvError> {
        if let Some(old) = self.vision.as_ref() {
            // Build the new renderer first: on error the env keeps the old one.
            let new = render::Vision::new(
                &self.model,
                self.task.cameras(),
                self.spec.cameras,
                old.rgb_on,
                old.depth_on,
                options,
            )
            .map_err(|e| EnvError::Render(e.to_string()))?;
            self.vision = Some(new);
        }
        self.render_options = options;
        self.render_sensors();
        Ok(())
    }
}
