//! # mjskill
//!
//! ManiSkill3's tabletop manipulation tasks (PickCube-v1 and its SO100/WidowX AI variants,
//! PokeCube-v1, PlaceSphere-v1) on MuJoCo 2.2, from Rust.
//!
//! The modules follow the flow of data, and every module only uses modules before it
//! (`tests/layering.rs` checks this):
//! `mujoco-sys` (FFI) → [`mujoco`] (the safe layer) → [`mjcf`] (URDF → MJCF scene generation)
//! → [`controllers`] → [`robots`] → [`tasks`] → [`env`] (the gymnasium-style API)
//! → [`record`] (MCAP recordings) → [`maniskill`], [`solvers`], [`tools`] → the `mjskill`
//! command line ([`cli`]). [`rng`] (ManiSkill's random streams) and [`models`] (the embedded
//! robot files) are leaves.
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod cli;
pub mod controllers;
pub mod datasets;
pub mod env;
pub mod maniskill;
pub mod mjcf;
pub mod models;
pub mod mujoco;
pub mod obs;
pub mod record;
pub mod rng;
pub mod robots;
pub mod solvers;
pub mod tasks;
pub mod tools;

pub use env::{
    make, registry, BoxSpace, Env, EnvConfig, EnvError, EnvId, EnvState, Info, ObsMode, RewardMode,
    SimConfig, StateDict, Step, VecEnv,
};
pub use robots::RobotId;

/// The README's examples, compiled and run as doc tests.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctests;
