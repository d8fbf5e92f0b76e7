//! `mjskill export`: a recording's finished episodes in ManiSkill's trajectory format
//! ([`to_maniskill`]) or as a LeRobotDataset v3 ([`super::lerobot::write`]).
use std::path::{Path, PathBuf};

use serde::Serialize;
use serde_json::{json, Map, Value};

use super::import::TOPIC_MANISKILL_STATE;
use super::maniskill_h5::{self, EnvInfo, EpisodeData, EpisodeInfo, Trajectory, TrajectoryJson};
use super::{DatasetError, Named};
use crate::env::{make, Env, StateDict};
use crate::record::{EpisodeRec, Recording};

/// Export formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// ManiSkill's `trajectory.h5` + `.json`.
    ManiSkill,
    /// LeRobotDataset v3 (a directory).
    LeRobot,
}

impl Format {
    /// Parses `maniskill` / `lerobot`.
    pub fn parse(s: &str) -> Result<Format, DatasetError> {
        match s {
            "maniskill" => Ok(Format::ManiSkill),
            "lerobot" => Ok(Format::LeRobot),
            _ => Err(DatasetError::Invalid {
                msg: format!("unknown --format {s:?}; valid: maniskill, lerobot"),
            }),
        }
    }
}

/// What was exported (printed as JSON by the command).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ExportSummary {
    /// The recording.
    pub file: String,
    /// `maniskill` or `lerobot`.
    pub format: &'static str,
    /// Files or directory written.
    pub outputs: Vec<String>,
    /// Episodes exported (the recording's finished episodes).
    pub episodes: usize,
    /// Steps exported.
    pub steps: usize,
    /// Video frames written per camera (LeRobot).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub videos: Vec<(String, usize)>,
}

/// Reads a recording and its ManiSkill-state messages (written by `import-maniskill`),
/// indexed `[episode][step]`.
pub(crate) fn read_recording(
    path: &Path,
) -> Result<(Recording, Vec<Vec<StateDict>>), DatasetError> {
    let rec = crate::record::read(path)?;
    let raw = crate::record::read_raw(path)?;
    let mut states: Vec<Vec<StateDict>> = Vec::new();
    for m in raw
        .messages
        .iter()
        .filter(|m| m.topic == TOPIC_MANISKILL_STATE)
    {
        let bad =
            |msg: String| DatasetError::format(path, format!("{TOPIC_MANISKILL_STATE}: {msg}"));
        let v: Value = serde_json::from_slice(&m.data).map_err(|e| bad(e.to_string()))?;
        let ep = v["episode"]
            .as_u64()
            .ok_or_else(|| bad("no episode".into()))? as usize;
        let step = v["step"].as_u64().ok_or_else(|| bad("no step".into()))? as usize;
        let sd = StateDict::from_json(&v["state"]).map_err(|e| bad(e.to_string()))?;
        if states.len() <= ep {
            states.resize(ep + 1, Vec::new());
        }
        if states[ep].len() != step {
            return Err(bad(format!("episode {ep}: step {step} out of order")));
        }
        states[ep].push(sd);
    }
    Ok((rec, states))
}

/// The env a recording was made with.
pub(crate) fn env_of(path: &Path, rec: &Recording) -> Result<Env, DatasetError> {
    let config = rec.meta.config().map_err(DatasetError::env(path))?;
    make(&rec.meta.env_id, config).map_err(DatasetError::env(path))
}

/// The ManiSkill-layout states of an episode (T+1): the importer's messages when the
/// recording has them, else the recorded mjskill states converted through `env` (the state
/// after the last step is re-simulated from the state before it, which is exact: replay is
/// bitwise deterministic).
pub(crate) fn episode_states(
    path: &Path,
    env: &mut Env,
    ep: &EpisodeRec,
    imported: Option<&Vec<StateDict>>,
) -> Result<Vec<StateDict>, DatasetError> {
    if let Some(s) = imported.filter(|s| s.len() == ep.steps.len() + 1) {
        // JSON objects come back in name order: restore ManiSkill's scene order.
        let order = env.actor_names();
        return Ok(s
            .iter()
            .map(|sd| {
                let mut sd = sd.clone();
                sd.actors.sort_by_key(|name, _| {
                    order.iter().position(|o| o == name).unwrap_or(usize::MAX)
                });
                sd
            })
            .collect());
    }
    let mut out = Vec::with_capacity(ep.steps.len() + 1);
    let restore = |env: &mut Env, s| env.set_state(s).map_err(DatasetError::env(path));
    restore(env, &ep.initial_state)?;
    out.push(env.get_state_dict());
    for s in ep.steps.iter().skip(1) {
        restore(env, &s.state)?;
        out.push(env.get_state_dict());
    }
    if let Some(last) = ep.steps.last() {
        restore(env, &last.state)?;
        env.step(&last.action).map_err(DatasetError::env(path))?;
        out.push(env.get_state_dict());
    }
    Ok(out)
}

fn info_flag(info: &[(String, f64)], key: &str) -> Option<bool> {
    info.iter().find(|(k, _)| k == key).map(|(_, v)| *v != 0.0)
}

/// Exports the finished episodes of the recording `path` to ManiSkill's format: `h5` and
/// `json` (default: `h5` with extension `.json`). Refused before anything is read or written
/// when an output is the recording, when the two outputs are one file, or when an output
/// exists and is not a regular file (see [`crate::datasets`]).
pub fn to_maniskill(
    path: &Path,
    h5: &Path,
    json_path: Option<&Path>,
) -> Result<ExportSummary, DatasetError> {
    to_maniskill_in_mode(path, h5, json_path, None)
}

/// The control mode [`to_maniskill_in_mode`] converts actions to.
pub const CONVERTIBLE_MODE: &str = "pd_joint_pos";

/// How one part of the converted action is filled.
enum PartFill {
    /// Copied from the recorded action's slice (the part is the same in both modes).
    Copy(std::ops::Range<usize>),
    /// The drive position targets of these joints (ManiSkill indices).
    Targets(Vec<usize>),
}

/// How to turn a recorded action into an action of [`CONVERTIBLE_MODE`]: per part of that
/// mode, in action order. Errors name the part that cannot be converted.
fn conversion_plan(
    path: &Path,
    env: &Env,
    target_mode: &str,
) -> Result<Vec<PartFill>, DatasetError> {
    let bad = |msg: String| DatasetError::Invalid { msg };
    let spec = env.robot_spec();
    let source_mode = env.control_mode().to_string();
    if target_mode != CONVERTIBLE_MODE {
        return Err(bad(format!(
            "--control-mode {target_mode:?}: actions convert to {CONVERTIBLE_MODE} only \
             (the recording is in {source_mode}); valid: {CONVERTIBLE_MODE}, {source_mode}"
        )));
    }
    if !env.get_state_dict().controller.is_empty() {
        return Err(bad(format!(
            "--control-mode {target_mode}: the recording's mode {source_mode} accumulates \
             targets across steps (controller state), which {target_mode} has not; convert \
             from a mode without `target` in its name"
        )));
    }
    let (_, source_parts) = spec
        .control_mode(&source_mode)
        .map_err(|e| DatasetError::env(path)(e.into()))?;
    let (_, target_parts) = spec
        .control_mode(target_mode)
        .map_err(|e| bad(format!("--control-mode {target_mode}: {e}")))?;
    let source_ranges = env.action_parts();
    let joints = &env.robot().joints.names;
    let mut plan = Vec::new();
    for part in &target_parts {
        let same = source_parts.iter().find(|p| p.name == part.name) == Some(part);
        let absolute = matches!(
            &part.kind,
            crate::controllers::PartKind::JointPos(c) if !c.use_delta && !c.normalize
        );
        let range = source_ranges
            .iter()
            .find(|r| r.name == part.name)
            .map(|r| r.range.clone());
        match (same, range) {
            (true, Some(r)) => plan.push(PartFill::Copy(r)),
            // A part that takes no action in either mode (the xArm6's passive linkage).
            (true, None) => {}
            _ if absolute => {
                let idx = part
                    .joints
                    .iter()
                    .map(|j| {
                        joints.iter().position(|n| n == j).ok_or_else(|| {
                            bad(format!("part {} names an unknown joint {j}", part.name))
                        })
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                plan.push(PartFill::Targets(idx));
            }
            _ => {
                return Err(bad(format!(
                    "--control-mode {target_mode}: its part {:?} differs from {source_mode}'s \
                     and takes no absolute joint positions, so it cannot be derived from the \
                     recorded actions",
                    part.name
                )))
            }
        }
    }
    Ok(plan)
}

/// Like [`to_maniskill`]; with `control_mode` [`CONVERTIBLE_MODE`] (`pd_joint_pos`) the
/// actions are converted the way ManiSkill's `replay_trajectory -c` converts modes, but
/// exactly: every step's absolute joint targets are the drive targets the recorded action
/// set in mjskill (for EE modes: the IK solution), the other parts (gripper, body, base)
/// are copied where both modes define them alike. Replayed in `pd_joint_pos`, the episode
/// gives the drives the same targets as the recording; this also makes episodes of modes
/// ManiSkill cannot build (Fetch's EE modes) replayable there. `None`, or the recording's
/// own mode, exports the actions as recorded. Modes with accumulated targets
/// (`*_target_*`) are not converted (error).
pub fn to_maniskill_in_mode(
    path: &Path,
    h5: &Path,
    json_path: Option<&Path>,
    control_mode: Option<&str>,
) -> Result<ExportSummary, DatasetError> {
    let json_given = json_path.is_some();
    let json_path = json_path.map_or_else(|| maniskill_h5::json_path_for(h5), Path::to_path_buf);
    super::check_outputs(
        &[Named::new("the recording", path)],
        &[
            Named::new("-o", h5),
            Named::new(
                if json_given {
                    "--json"
                } else {
                    "the json (default: -o with extension .json)"
                },
                &json_path,
            ),
        ],
    )?;
    let (rec, imported) = read_recording(path)?;
    let mut env = env_of(path, &rec)?;
    let m = &rec.meta;
    let convert = control_mode.filter(|c| *c != m.control_mode);
    let plan = match convert {
        Some(c) => Some(conversion_plan(path, &env, c)?),
        None => None,
    };
    let out_mode = convert.unwrap_or(&m.control_mode).to_string();
    let mut infos = Vec::new();
    let mut episodes = Vec::new();
    let mut steps = 0;
    for (k, ep) in rec.finished().enumerate() {
        let mut env_states = episode_states(path, &mut env, ep, imported.get(ep.index as usize))?;
        let actions = match &plan {
            None => ep
                .steps
                .iter()
                .flat_map(|s| s.action.iter().copied())
                .collect(),
            Some(plan) => {
                // The source mode keeps no controller state (checked), nor does the target.
                for sd in &mut env_states {
                    sd.controller.clear();
                }
                converted_actions(path, &mut env, ep, plan)?
            }
        };
        let t = ep.steps.len();
        steps += t;
        let data = episode_data(m, ep, actions, env_states);
        infos.push(EpisodeInfo {
            episode_id: k,
            episode_seed: ep.seed,
            control_mode: out_mode.clone(),
            elapsed_steps: t as u32,
            reset_kwargs: json!({"options": null, "seed": ep.seed}),
            success: Some(ep.success),
        });
        episodes.push(data);
    }
    if episodes.is_empty() {
        return Err(DatasetError::format(
            path,
            "has no finished episode to export",
        ));
    }
    let (env_kwargs, extra) = trajectory_kwargs(path, m, &out_mode, convert);
    let traj = Trajectory {
        json: TrajectoryJson {
            env_info: EnvInfo {
                env_id: m.env_id.clone(),
                env_kwargs,
                max_episode_steps: Some(m.max_episode_steps),
            },
            commit_info: Value::Null,
            episodes: infos,
            extra,
        },
        episodes,
    };
    maniskill_h5::write(&traj, h5, &json_path)?;
    Ok(ExportSummary {
        file: path.display().to_string(),
        format: "maniskill",
        outputs: vec![h5.display().to_string(), json_path.display().to_string()],
        episodes: traj.episodes.len(),
        steps,
        videos: Vec::new(),
    })
}

/// A recorded episode's actions converted by `plan` (every step re-simulated from its
/// recorded state to read the drive targets its action set).
fn converted_actions(
    path: &Path,
    env: &mut Env,
    ep: &EpisodeRec,
    plan: &[PartFill],
) -> Result<Vec<f32>, DatasetError> {
    let mut out = Vec::new();
    for s in &ep.steps {
        env.set_state(&s.state).map_err(DatasetError::env(path))?;
        let d = env
            .action_drive_targets(&s.action)
            .map_err(DatasetError::env(path))?;
        for fill in plan {
            match fill {
                PartFill::Copy(r) => out.extend_from_slice(&s.action[r.clone()]),
                PartFill::Targets(idx) => out.extend(idx.iter().map(|&j| d.qpos[j] as f32)),
            }
        }
    }
    Ok(out)
}

/// One episode of a ManiSkill trajectory file: `actions` (flat, as exported), the env states,
/// and the recorded flags, rewards and (obs mode `state`) observations.
fn episode_data(
    m: &crate::record::Meta,
    ep: &EpisodeRec,
    actions: Vec<f32>,
    env_states: Vec<StateDict>,
) -> EpisodeData {
    let action_dim = if ep.steps.is_empty() {
        m.action_space.low.len()
    } else {
        actions.len() / ep.steps.len()
    };
    let has_fail = ep
        .steps
        .first()
        .is_some_and(|s| info_flag(&s.info, "fail").is_some());
    let obs = (m.obs_mode == "state").then(|| {
        let mut o = ep.initial_obs.clone();
        for s in &ep.steps {
            o.extend_from_slice(&s.obs);
        }
        (o, ep.initial_obs.len())
    });
    EpisodeData {
        actions,
        action_dim,
        env_states,
        terminated: ep.steps.iter().map(|s| s.terminated).collect(),
        truncated: ep.steps.iter().map(|s| s.truncated).collect(),
        success: Some(
            ep.steps
                .iter()
                .map(|s| info_flag(&s.info, "success").unwrap_or(false))
                .collect(),
        ),
        fail: has_fail.then(|| {
            ep.steps
                .iter()
                .map(|s| info_flag(&s.info, "fail").unwrap_or(false))
                .collect()
        }),
        rewards: Some(ep.steps.iter().map(|s| s.reward).collect()),
        obs,
    }
}

/// The trajectory's `env_kwargs` and `extra` (where it came from, what was converted).
fn trajectory_kwargs(
    path: &Path,
    m: &crate::record::Meta,
    out_mode: &str,
    convert: Option<&str>,
) -> (Map<String, Value>, Map<String, Value>) {
    let mut env_kwargs = Map::new();
    env_kwargs.insert("obs_mode".into(), json!(m.obs_mode));
    env_kwargs.insert("control_mode".into(), json!(out_mode));
    env_kwargs.insert("reward_mode".into(), json!(m.reward_mode));
    env_kwargs.insert("robot_uids".into(), json!(m.robot));
    env_kwargs.insert("render_mode".into(), Value::Null);
    env_kwargs.insert("num_envs".into(), json!(1));
    let mut extra = Map::new();
    extra.insert("source_type".into(), json!("mjskill"));
    extra.insert(
        "source_desc".into(),
        json!(match convert {
            None => format!(
                "exported by mjskill {} from {}",
                env!("CARGO_PKG_VERSION"),
                path.display()
            ),
            Some(c) => format!(
                "exported by mjskill {} from {}; actions converted from {} to {c} (the joint \
             targets mjskill's controller set)",
                env!("CARGO_PKG_VERSION"),
                path.display(),
                m.control_mode
            ),
        }),
    );
    (env_kwargs, extra)
}

/// The default output of a format: `<recording stem>.h5` / `<recording stem>_lerobot`.
pub fn default_output(path: &Path, format: Format) -> PathBuf {
    match format {
        Format::ManiSkill => path.with_extension("h5"),
        Format::LeRobot => {
            let stem = path
                .file_stem()
                .map_or_else(|| "dataset".into(), |s| s.to_string_lossy().into_owned());
            path.with_file_name(format!("{stem}_lerobot"))
        }
    }
}
