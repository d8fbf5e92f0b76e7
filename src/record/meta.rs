//! The file-level metadata of a recording (`Metadata` record `"mjskill"`, docs/recording.md):
//! how the env was made, its spaces and observation layout, and the command that wrote the
//! file.
use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::{num, FORMAT_VERSION};
use crate::env::Env;

/// Why the metadata record of a file does not parse ([`Meta::from_map`]).
#[derive(Debug, thiserror::Error)]
pub enum MetaError {
    /// A value is not the JSON its key needs.
    #[error("metadata {key:?} = {value:?}: {source}")]
    Value {
        /// The key.
        key: String,
        /// The stored text.
        value: String,
        /// The JSON error.
        source: serde_json::Error,
    },
    /// The fields do not form mjskill's metadata (a missing or mistyped field).
    #[error(transparent)]
    Fields(#[from] serde_json::Error),
}

/// A box space as stored in the metadata.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Space {
    /// Shape.
    pub shape: Vec<usize>,
    /// Lower bounds (flattened).
    #[serde(with = "num::bounds")]
    pub low: Vec<f32>,
    /// Upper bounds (flattened).
    #[serde(with = "num::bounds")]
    pub high: Vec<f32>,
}

/// One named slice of the flat observation.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ObsSlice {
    /// Key, e.g. `"agent/qpos"`.
    pub name: String,
    /// Start index.
    pub start: usize,
    /// End index (exclusive).
    pub end: usize,
}

/// The file-level metadata (`Metadata` record `"mjskill"`). In the file every field is one
/// string value: strings as themselves, everything else as JSON text.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Meta {
    /// Layout version ([`FORMAT_VERSION`]).
    pub format: u32,
    /// Env id.
    pub env_id: String,
    /// Robot uid.
    pub robot: String,
    /// Observation mode name.
    pub obs_mode: String,
    /// Reward mode name.
    pub reward_mode: String,
    /// Control mode in effect (the robot's default when none was configured).
    pub control_mode: String,
    /// Std-dev of the initial joint noise.
    pub robot_init_qpos_noise: f64,
    /// Episode length for truncation.
    pub max_episode_steps: u32,
    /// Physics timestep (s).
    pub timestep: f64,
    /// Physics steps per control step.
    pub substeps: usize,
    /// Who took the pinch's physics steps ([`crate::env::PinchSolver`]); absent: MuJoCo.
    #[serde(default, skip_serializing_if = "is_mujoco")]
    pub pinch_solver: crate::env::PinchSolver,
    /// mjskill version that wrote the file.
    pub version: String,
    /// Action space.
    pub action_space: Space,
    /// Observation space.
    pub observation_space: Space,
    /// Observation layout.
    pub obs_layout: Vec<ObsSlice>,
    /// The command that wrote the file (`mjskill rollout ...`), where the writer gave one: how
    /// to record the same demonstrations again. Absent in files of other writers.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub command: Option<String>,
}

/// Whether the pinch solver is MuJoCo's (the default, not written).
fn is_mujoco(s: &crate::env::PinchSolver) -> bool {
    *s == crate::env::PinchSolver::Mujoco
}

const STRING_KEYS: &[&str] = &[
    "env_id",
    "robot",
    "obs_mode",
    "reward_mode",
    "control_mode",
    "version",
    "command",
    "pinch_solver",
];

impl Meta {
    /// The metadata of `env`.
    pub fn of(env: &Env) -> Meta {
        let space = |b: &crate::env::BoxSpace| Space {
            shape: b.shape.clone(),
            low: b.low.clone(),
            high: b.high.clone(),
        };
        let cfg = env.config();
        Meta {
            format: FORMAT_VERSION,
            env_id: env.id().to_string(),
            robot: env.robot_spec().uid().to_string(),
            obs_mode: cfg.obs_mode.name().to_string(),
            reward_mode: cfg.reward_mode.name().to_string(),
            control_mode: env.control_mode().to_string(),
            robot_init_qpos_noise: cfg.robot_init_qpos_noise,
            max_episode_steps: env.max_episode_steps(),
            timestep: env.model().timestep(),
            substeps: env.substeps(),
            pinch_solver: cfg.sim.pinch_solver,
            version: env!("CARGO_PKG_VERSION").to_string(),
            action_space: space(env.action_space()),
            observation_space: space(env.observation_space()),
            obs_layout: env
                .obs_layout()
                .iter()
                .map(|(name, r)| ObsSlice {
                    name: name.clone(),
                    start: r.start,
                    end: r.end,
                })
                .collect(),
            command: None,
        }
    }

    /// The string map stored in the MCAP `Metadata` record.
    pub fn to_map(&self) -> BTreeMap<String, String> {
        let v = serde_json::to_value(self).expect("Meta serializes");
        let obj = v.as_object().expect("Meta is an object");
        obj.iter()
            .map(|(k, v)| {
                let s = match v {
                    serde_json::Value::String(s) => s.clone(),
                    other => other.to_string(),
                };
                (k.clone(), s)
            })
            .collect()
    }

    /// Parses the string map of the MCAP `Metadata` record.
    pub fn from_map(map: &BTreeMap<String, String>) -> Result<Meta, MetaError> {
        let mut obj = serde_json::Map::new();
        for (k, v) in map {
            let value = if STRING_KEYS.contains(&k.as_str()) {
                serde_json::Value::String(v.clone())
            } else {
                serde_json::from_str(v).map_err(|source| MetaError::Value {
                    key: k.clone(),
                    value: v.clone(),
                    source,
                })?
            };
            obj.insert(k.clone(), value);
        }
        Ok(serde_json::from_value(serde_json::Value::Object(obj))?)
    }

    /// The env configuration the file was recorded with.
    pub fn config(&self) -> Result<crate::env::EnvConfig, crate::env::EnvError> {
        Ok(crate::env::EnvConfig {
            robot: Some(self.robot.clone()),
            obs_mode: crate::env::ObsMode::parse(&self.obs_mode)?,
            reward_mode: crate::env::RewardMode::parse(&self.reward_mode)?,
            control_mode: Some(self.control_mode.clone()),
            robot_init_qpos_noise: self.robot_init_qpos_noise,
            max_episode_steps: Some(self.max_episode_steps),
            sim: self.sim(),
            reconfiguration_freq: None,
        })
    }

    /// The physics settings the file was recorded with.
    pub fn sim(&self) -> crate::env::SimConfig {
        crate::env::SimConfig {
            sim_freq: self.substeps as u32 * crate::env::CONTROL_FREQ,
            pinch_solver: self.pinch_solver,
        }
    }

    /// Duration of one control step in nanoseconds.
    pub fn control_dt_ns(&self) -> u64 {
        (self.timestep * self.substeps as f64 * 1e9).round() as u64
    }
}
