//! # mjskill
//!
//! ManiSkill3's tabletop manipulation tasks (PickCube-v1 and its SO100/WidowX AI variants,
//! PokeCube-v1, PlaceSphere-v1) on MuJoCo 2.2, from Rust.
//!
//! The modules follow the flow of data:
//! `mujoco-sys` (FFI) → [`mujoco`] (the safe layer) → [`mjcf`] (URDF → MJCF scene generation)
//! → [`robots`] and [`controllers`] → [`tasks`] → [`env`] (the gymnasium-style API)
//! → the `mjskill` command line ([`cli`]).
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
pub mod record;
pub mod robots;
pub mod solvers;
pub mod tasks;

pub use env::{
    make, registry, BoxSpace, Env, EnvConfig, EnvError, EnvState, Info, ObsMode, RewardMode,
    SimConfig, StateDict, Step,
};

/// The README's examples, compiled and run as doc tests.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctests;
