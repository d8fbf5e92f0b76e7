//! # mjskill
//!
//! ManiSkill3's tabletop manipulation tasks (PickCube-v1 and its SO100/WidowX AI variants,
//! PokeCube-v1, PlaceSphere-v1, PushCube-v1, PullCube-v1, StackCube-v1, LiftPegUpright-v1,
//! PushT-v1) on MuJoCo 2.2, from Rust.
//!
//! ```no_run
//! let mut env = mjskill::make("PickCube-v1", mjskill::EnvConfig::default())?;
//! env.reset(Some(0));
//! let action = vec![0.0f32; env.action_space().shape[0]];
//! let step = env.step(&action)?;
//! println!("reward {} success {}", step.reward, step.terminated);
//! # Ok::<(), mjskill::EnvError>(())
//! ```
//!
//! The gymnasium-style env API ([`make`], [`Env`], [`VecEnv`], the [`registry`], spaces,
//! modes and [`EnvError`]) is exported at the crate root. The modules users need beyond it:
//! [`record`] (MCAP recordings: [`Recorder`], [`record::read`], replay), [`datasets`]
//! (LeRobot / ManiSkill trajectory import and export), [`maniskill`] (fidelity against
//! ManiSkill's reference trajectories), [`solvers`] (the scripted demonstration policies and
//! [`solvers::evaluate`]) and [`mujoco`] (read access to the simulation behind
//! [`Env::model`] and [`Env::data`] for custom sensing, and the render settings).
//!
//! Errors are typed per layer, each naming the bad value, with the lower layer's error as its
//! `source`: [`EnvError`] (from [`RobotError`], itself from [`ControllerError`],
//! [`SceneError`], [`UrdfError`], [`ModelFileError`] and [`mujoco::MjError`]; and
//! [`RenderError`], [`StateDictError`]), [`RecordError`], [`solvers::SolverError`] and
//! [`solvers::EvalError`], and the errors of [`record::replay`], [`record::image`] and
//! [`datasets`].
//!
//! Inside, the modules follow the flow of data, and every module only uses modules before it
//! (`tests/layering.rs` checks this): `mujoco-sys` (FFI) → `mujoco` (the safe layer) → `mjcf`
//! (URDF → MJCF scene generation) → `controllers` → `robots` → `tasks` → `env` → `record` →
//! `maniskill`, `solvers` → `datasets`. `rng` (ManiSkill's random streams), `models` (the
//! embedded robot files) and `obs` (the observation writer) are leaves. The `mjskill` command
//! line is the binary's own code (`src/bin/mjskill/`), built on this public API.
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub(crate) mod controllers;
#[cfg(feature = "datasets")]
pub mod datasets;
pub(crate) mod env;
pub mod files;
pub mod maniskill;
pub(crate) mod mjcf;
pub(crate) mod models;
pub mod mujoco;
pub(crate) mod obs;
pub mod record;
pub(crate) mod rng;
pub(crate) mod robots;
pub mod solvers;
pub(crate) mod tasks;

#[cfg(test)]
mod tests;

pub use controllers::convex;
pub use controllers::desc::RobotError as UrdfError;
pub use controllers::tgs;
pub use controllers::{ControlMode, ControllerError, Drives};
pub use env::checks::MAX_SEED;
pub use env::vec::MAX_NUM_ENVS;
pub use env::{
    default_robot, depth_to_mm, make, registry, scene_mjcf, ActionPart, BoxSpace, CameraImage,
    DriveTargets, Env, EnvConfig, EnvError, EnvId, EnvInfo, EnvState, Info, ObsMode, PinchSolver,
    PointCloud, RewardMode, RolloutBuffers, SimConfig, StateDict, StateDictError, Step, Textures,
    VecEnv, VecPolicy, CONTROL_FREQ, DEFAULT_QPOS_NOISE, MAX_EPISODE_STEPS, MAX_POLICY_STEP,
};
pub use mjcf::{Mjcf, SceneError};
pub use models::ModelFileError;
pub use mujoco::render::{RenderError, RenderOptions, Segmentation};
pub use record::{RecordError, Recorder};
pub use robots::{robot_scene_mjcf, RobotError, RobotId};
pub use tasks::CameraDef;

/// The README's examples, compiled and run as doc tests.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctests;

/// The examples of `docs/rust-api.md`, compiled and run as doc tests (`tests/docs_links.rs`
/// checks that every page with Rust code is included here).
#[doc = include_str!("../docs/rust-api.md")]
#[cfg(doctest)]
pub struct DocsRustApiDoctests;
