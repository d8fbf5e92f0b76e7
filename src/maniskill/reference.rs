//! Reader of ManiSkill reference trajectory files (`<env>__<robot>.json.gz`, format
//! `mjskill-ref-traj/1`): per-step actions and post-step states recorded from ManiSkill 3
//! (PhysX CPU). The format is described in `docs/reference-trajectories.md`.
use std::path::Path;

use indexmap::IndexMap;
use serde::Deserialize;
use serde_json::Value;

use crate::env::StateDict;

/// The format tag these files carry.
pub const FORMAT: &str = "mjskill-ref-traj/1";

/// Errors of reading a reference file; each names the file.
#[derive(Debug, thiserror::Error)]
pub enum ReferenceError {
    /// The file could not be read or decompressed (also: not a regular file, or beyond the
    /// size limit, [`crate::files`]).
    #[error(transparent)]
    File(#[from] crate::files::FileError),
    /// The JSON does not have the expected structure.
    #[error("{path} is not a ManiSkill reference trajectory file: {msg}")]
    Format {
        /// File.
        path: String,
        /// What is wrong.
        msg: String,
    },
}

/// One controller part of a recorded control mode.
#[derive(Debug, Clone, Deserialize)]
pub struct RefController {
    /// ManiSkill's controller class (`PDJointPosController`, ...).
    pub cls: String,
    /// `[start, end)` of the part in the action vector.
    pub action_slice: [usize; 2],
    /// Joints of the part.
    pub joints: Vec<String>,
}

/// A recorded control mode.
#[derive(Debug, Clone, Deserialize)]
pub struct RefMode {
    /// Controller parts by name, in action order.
    pub controllers: IndexMap<String, RefController>,
    /// `[key, start, end)` of each leaf of the flat `state` observation.
    pub obs_state_layout: Vec<(String, usize, usize)>,
}

/// A snapshot: the state after `env.reset` (`initial`) or after one `env.step`.
#[derive(Debug, Clone, Deserialize)]
pub struct Snapshot {
    /// `elapsed_steps` after the step (0 for the initial snapshot).
    pub t: u32,
    /// The action of this step (None for the initial snapshot).
    #[serde(default)]
    pub action: Option<Vec<f32>>,
    /// Dense reward.
    pub reward_dense: f32,
    /// Normalised dense reward.
    pub reward_normalized: f32,
    /// `terminated` (steps only).
    #[serde(default)]
    pub terminated: Option<bool>,
    /// `truncated` (steps only).
    #[serde(default)]
    pub truncated: Option<bool>,
    /// The info dict (bools, ints, floats).
    pub info: IndexMap<String, Value>,
    /// Actor poses `[x, y, z, qw, qx, qy, qz]`.
    pub actors: IndexMap<String, [f64; 7]>,
    /// `agent.tcp_pose`.
    pub tcp_pose: [f64; 7],
    /// Robot qpos in ManiSkill order.
    pub robot_qpos: Vec<f64>,
    /// Robot qvel in ManiSkill order.
    pub robot_qvel: Vec<f64>,
    /// Contact force on each grasp finger from the grasp object (N, world frame).
    pub grasp_contact: GraspContact,
    /// The flat `state` observation.
    pub obs_state: Vec<f32>,
    /// `env.get_state_dict()` (parsed from ManiSkill's nested JSON).
    #[serde(deserialize_with = "state_dict_from_json")]
    pub state_dict: StateDict,
}

impl Snapshot {
    /// A boolean info entry (false when absent or not a bool).
    pub fn flag(&self, key: &str) -> bool {
        self.info.get(key).and_then(Value::as_bool).unwrap_or(false)
    }
    /// A numeric info entry (bools as 0/1).
    pub fn info_value(&self, key: &str) -> Option<f64> {
        match self.info.get(key)? {
            Value::Bool(b) => Some(*b as u8 as f64),
            v => v.as_f64(),
        }
    }
}

/// The finger contact forces of a snapshot.
#[derive(Debug, Clone, Copy, Deserialize)]
pub struct GraspContact {
    /// Force on finger 1.
    pub finger1: [f64; 3],
    /// Force on finger 2.
    pub finger2: [f64; 3],
}

fn state_dict_from_json<'de, D: serde::Deserializer<'de>>(d: D) -> Result<StateDict, D::Error> {
    let v = Value::deserialize(d)?;
    StateDict::from_json(&v).map_err(serde::de::Error::custom)
}

/// One recorded episode.
#[derive(Debug, Clone, Deserialize)]
pub struct RefEpisode {
    /// Position in the file.
    pub episode_index: usize,
    /// `uniform_random`, `smooth_random_walk` or `motion_planning`.
    pub source: String,
    /// Control mode the env was made with.
    pub control_mode: String,
    /// Reset seed.
    pub seed: u64,
    /// Number of steps.
    pub n_steps: usize,
    /// `info["success"]` after the last step.
    pub final_success: bool,
    /// Motion planning only: whether the planner finished its solution.
    #[serde(default)]
    pub planner_ok: Option<bool>,
    /// The state right after the seeded reset.
    pub initial: Snapshot,
    /// One snapshot per step.
    pub steps: Vec<Snapshot>,
}

/// A whole reference file.
#[derive(Debug, Clone, Deserialize)]
pub struct RefFile {
    /// Format tag ([`FORMAT`]).
    pub format: String,
    /// Gym id.
    pub env_id: String,
    /// Robot uid.
    pub robot: String,
    /// ManiSkill joint names (qpos order).
    pub joint_names: Vec<String>,
    /// The grasp object: `actor_name` is the actor whose finger contacts decide `is_grasped`.
    pub grasp_object: IndexMap<String, String>,
    /// Actor name → `dynamic` / `kinematic` / `static`.
    pub actor_body_types: IndexMap<String, String>,
    /// Per recorded control mode.
    pub control_modes: IndexMap<String, RefMode>,
    /// Episodes.
    pub episodes: Vec<RefEpisode>,
}

impl RefFile {
    /// Reads a reference file (gzip-compressed or plain JSON; the rule of [`crate::files`]).
    pub fn open(path: &Path) -> Result<RefFile, ReferenceError> {
        let p = path.display().to_string();
        let text = crate::files::read_maybe_gzip(path, crate::files::max_bytes())?;
        let f: RefFile = serde_json::from_slice(&text).map_err(|e| ReferenceError::Format {
            path: p.clone(),
            msg: e.to_string(),
        })?;
        if f.format != FORMAT {
            return Err(ReferenceError::Format {
                path: p,
                msg: format!("format is {:?}, expected {FORMAT:?}", f.format),
            });
        }
        for e in &f.episodes {
            let bad = |msg: String| ReferenceError::Format {
                path: p.clone(),
                msg: format!("episode {}: {msg}", e.episode_index),
            };
            if e.seed > crate::env::checks::MAX_SEED {
                return Err(bad(format!(
                    "seed {} is not in 0..={} (ManiSkill's seeds are 32-bit)",
                    e.seed,
                    crate::env::checks::MAX_SEED
                )));
            }
            let n = f.joint_names.len();
            for (t, s) in std::iter::once(&e.initial).chain(&e.steps).enumerate() {
                for (key, v) in [("robot_qpos", &s.robot_qpos), ("robot_qvel", &s.robot_qvel)] {
                    if v.len() != n {
                        let at = if t == 0 {
                            "the initial state".to_string()
                        } else {
                            format!("step {t}")
                        };
                        return Err(bad(format!(
                            "{at}: {key} has {} values but joint_names lists {n} joints",
                            v.len()
                        )));
                    }
                }
            }
            if e.steps.len() != e.n_steps || e.steps.iter().any(|s| s.action.is_none()) {
                return Err(ReferenceError::Format {
                    path: p,
                    msg: format!(
                        "episode {} has {} steps (n_steps {}) or a step without an action",
                        e.episode_index,
                        e.steps.len(),
                        e.n_steps
                    ),
                });
            }
        }
        Ok(f)
    }

    /// Names of the dynamic actors (the objects whose errors fidelity reports), as the state
    /// dicts name them ([`super::merged_actor_name`]).
    pub fn dynamic_actors(&self) -> Vec<&str> {
        let in_state_dict = |n: &str| {
            self.episodes
                .first()
                .is_some_and(|e| e.initial.state_dict.actors.contains_key(n))
        };
        self.actor_body_types
            .iter()
            .filter(|(_, t)| t.as_str() == "dynamic")
            .map(|(n, _)| super::merged_actor_name(n, in_state_dict))
            .collect()
    }
}
