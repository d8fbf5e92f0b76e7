//! The values the env API hands out: spaces, `info`, step results and saved states.
use serde::{Deserialize, Serialize};

use crate::mujoco::Warnings;
use crate::rng::{NumpyRandomState, TorchGenerator};

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

/// The result of [`Env::step`](super::Env::step), borrowing the env's buffers.
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

/// Everything that determines an env's future, for [`Env::get_state`](super::Env::get_state) / [`Env::set_state`](super::Env::set_state).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EnvState {
    /// Env id.
    pub env_id: String,
    /// Robot uid.
    pub robot: String,
    /// Control mode.
    pub control_mode: String,
    /// MuJoCo state ([`Data::get_state`](crate::mujoco::Data::get_state)).
    pub physics: Vec<f64>,
    /// Controller targets, then the drives' state: their targets and, for the SO100, its
    /// jaw's release counters, for a robot whose gripper moves a linkage (WidowX AI, xArm6)
    /// whether its arm took the pinch's kick, and with `pinch_solver = "physx_tgs"` the
    /// replica's contact cache (`Drives::save`).
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
    /// The main RNG (ManiSkill's `_main_rng`), which draws the episode seed of an unseeded
    /// reset of a task whose shapes change every episode. Absent from states saved before it
    /// was part of them: the main RNG then restarts from the main seed.
    #[serde(default)]
    pub main_numpy: Option<NumpyRandomState>,
    /// The episode's shapes, for a task that draws them every episode (PegInsertionSide-v1:
    /// the peg's half length and radius, the hole's centre; `Task::geometry`); empty for the
    /// others.
    #[serde(default)]
    pub geometry: Vec<f64>,
}
