//! Fidelity: replays recorded episodes open loop in mjskill and measures, step by step, how
//! far mjskill's robot joints, TCP, objects, rewards and flags are from the recording.
//!
//! The reference is a ManiSkill trajectory file ([`RefFile`]) or, for recordings of mjskill
//! itself, frames produced by replaying the recording with its own settings
//! ([`Frame`]s from any source). `resync` re-imports the reference state every K steps
//! (through [`Env::set_state_dict`]), which separates the one-step dynamics error (K = 1)
//! from its compounding (no resync).
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde::Serialize;

use super::reference::{RefEpisode, RefFile, Snapshot};
use crate::env::{make, Env, EnvConfig, EnvError, ObsMode, RewardMode, SimConfig, StateDict};

/// An object counts as diverged once its position is this far from the reference (m).
pub const DIVERGENCE_DISTANCE: f64 = 0.01;

/// Step buckets of the summary: inclusive ranges of `t` (1-based step index).
pub const BUCKETS: [(u32, u32); 6] = [(1, 1), (2, 5), (6, 10), (11, 25), (26, 50), (51, u32::MAX)];

/// The reference state after one step (or after the reset, with no action).
#[derive(Debug, Clone)]
pub struct Frame {
    /// The action that led here (None for the initial frame).
    pub action: Option<Vec<f32>>,
    /// `elapsed_steps`.
    pub t: u32,
    /// The full state.
    pub state: StateDict,
    /// Robot qpos (ManiSkill order).
    pub qpos: Vec<f64>,
    /// `agent.tcp_pose`.
    pub tcp_pose: [f64; 7],
    /// Dense reward.
    pub reward_dense: f64,
    /// Boolean info entries (`success`, `is_grasped`, ...), in info order.
    pub flags: Vec<(String, bool)>,
}

impl Frame {
    /// The frame of a ManiSkill snapshot.
    pub fn from_snapshot(s: &Snapshot) -> Frame {
        Frame {
            action: s.action.clone(),
            t: s.t,
            state: s.state_dict.clone(),
            qpos: s.robot_qpos.clone(),
            tcp_pose: s.tcp_pose,
            reward_dense: s.reward_dense as f64,
            flags: s
                .info
                .iter()
                .filter_map(|(k, v)| Some((k.clone(), v.as_bool()?)))
                .filter(|(k, _)| k != "reconfigure")
                .collect(),
        }
    }

    /// The frame of an env's current state.
    pub fn from_env(env: &Env, action: Option<&[f32]>) -> Frame {
        let info = env.info();
        let (p, q) = env.robot().tcp_pose(env.data());
        let mut qpos = vec![0.0; env.robot().joints.len()];
        env.robot().joints.qpos(env.data(), &mut qpos);
        Frame {
            action: action.map(|a| a.to_vec()),
            t: info.elapsed_steps,
            state: env.get_state_dict(),
            qpos,
            tcp_pose: [p[0], p[1], p[2], q[0], q[1], q[2], q[3]],
            reward_dense: env.dense_reward(),
            flags: info
                .keys
                .iter()
                .zip(&info.values)
                .filter(|(k, _)| env.task().bool_info(k))
                .map(|(k, v)| (k.to_string(), *v != 0.0))
                .collect(),
        }
    }
}

/// Deviations of one step.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Default)]
pub struct StepError {
    /// Largest |Δqpos| over the robot joints (rad or m).
    pub joint: f64,
    /// TCP position error (m).
    pub tcp_pos: f64,
    /// TCP orientation error (rad).
    pub tcp_rot: f64,
    /// Largest position error over the dynamic objects (m).
    pub obj_pos: f64,
    /// Largest orientation error over the dynamic objects (rad).
    pub obj_rot: f64,
    /// |Δ dense reward|.
    pub reward: f64,
    /// Number of boolean info entries that disagree.
    pub flag_mismatches: u32,
    /// Whether `is_grasped` (or the task's grasp flag) agrees.
    pub grasp_agrees: bool,
    /// The reference's grasp flag after this step.
    pub reference_grasped: bool,
}

/// Summary over the steps of one bucket.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BucketStats {
    /// First step of the bucket.
    pub from: u32,
    /// Last step of the bucket (None: open end).
    pub to: Option<u32>,
    /// Steps in the bucket.
    pub steps: usize,
    /// Means over the bucket's steps.
    pub mean: StepMeans,
    /// Maxima over the bucket's steps.
    pub max: StepMeans,
    /// Fraction of steps whose every boolean flag agrees.
    pub flag_agreement: f64,
}

/// Per-metric aggregates.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Default)]
pub struct StepMeans {
    /// Joint error.
    pub joint: f64,
    /// TCP position error.
    pub tcp_pos: f64,
    /// TCP orientation error.
    pub tcp_rot: f64,
    /// Object position error.
    pub obj_pos: f64,
    /// Object orientation error.
    pub obj_rot: f64,
    /// Reward difference.
    pub reward: f64,
}

/// Step errors split by whether the reference holds an object: a step is *held* when the
/// reference's grasp flag is set before or after it. With `--resync 1` this separates the
/// one-step error of in-hand dynamics from that of free objects and the arm.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GraspSplit {
    /// Number of held steps.
    pub held_steps: usize,
    /// Means over the held steps (None without any).
    pub held: Option<StepMeans>,
    /// Number of the other steps.
    pub free_steps: usize,
    /// Means over the other steps (None without any).
    pub free: Option<StepMeans>,
}

impl GraspSplit {
    /// The split of episodes given as (the reference's grasp flag before step 1, per-step
    /// errors with `errors[i]` belonging to step i + 1).
    pub fn of(episodes: &[(bool, &[StepError])]) -> GraspSplit {
        let (mut held, mut free) = (Vec::new(), Vec::new());
        for &(start, steps) in episodes {
            let mut before = start;
            for s in steps {
                if before || s.reference_grasped {
                    held.push(s);
                } else {
                    free.push(s);
                }
                before = s.reference_grasped;
            }
        }
        GraspSplit {
            held_steps: held.len(),
            held: (!held.is_empty()).then(|| mean_and_max(&held).0),
            free_steps: free.len(),
            free: (!free.is_empty()).then(|| mean_and_max(&free).0),
        }
    }
}

/// Per-metric means and maxima over `sel` (not empty).
fn mean_and_max(sel: &[&StepError]) -> (StepMeans, StepMeans) {
    let n = sel.len() as f64;
    let (mut mean, mut max) = (StepMeans::default(), StepMeans::default());
    for s in sel {
        for (m, x, v) in [
            (&mut mean.joint, &mut max.joint, s.joint),
            (&mut mean.tcp_pos, &mut max.tcp_pos, s.tcp_pos),
            (&mut mean.tcp_rot, &mut max.tcp_rot, s.tcp_rot),
            (&mut mean.obj_pos, &mut max.obj_pos, s.obj_pos),
            (&mut mean.obj_rot, &mut max.obj_rot, s.obj_rot),
            (&mut mean.reward, &mut max.reward, s.reward),
        ] {
            *m += v / n;
            *x = x.max(v);
        }
    }
    (mean, max)
}

/// The report of one episode.
#[derive(Debug, Clone, Serialize)]
pub struct EpisodeFidelity {
    /// Episode index in the file.
    pub index: usize,
    /// Where its actions came from.
    pub source: String,
    /// Control mode.
    pub control_mode: String,
    /// Reset seed.
    pub seed: u64,
    /// Steps replayed.
    pub steps: usize,
    /// Deviation of the seeded initial state.
    pub initial: StepError,
    /// `success` after the last step in the reference.
    pub reference_success: bool,
    /// `success` after the last step in mjskill.
    pub mjskill_success: bool,
    /// Whether success was reached at any step, in the reference and in mjskill.
    pub ever_success: (bool, bool),
    /// First step at which an object is more than [`DIVERGENCE_DISTANCE`] from the reference.
    pub first_object_divergence: Option<u32>,
    /// Per-bucket summary.
    pub buckets: Vec<BucketStats>,
    /// Per-step deviations (index i = step i + 1).
    pub per_step: Vec<StepError>,
}

/// The report of a whole file.
#[derive(Debug, Clone, Serialize)]
pub struct FileFidelity {
    /// Env id.
    pub env_id: String,
    /// Robot uid.
    pub robot: String,
    /// The physics settings replayed with.
    pub sim: SimConfig,
    /// `resync` interval (None: open loop).
    pub resync: Option<u32>,
    /// Episodes.
    pub episodes: Vec<EpisodeFidelity>,
    /// Per-bucket summary over every episode.
    pub buckets: Vec<BucketStats>,
    /// Every episode's steps split by whether the reference holds an object.
    pub grasp_split: GraspSplit,
}

impl FileFidelity {
    /// The report of `episodes` replayed with `opts`, with the summaries over all of them.
    fn summarise(
        env_id: String,
        robot: String,
        opts: FidelityOptions,
        episodes: Vec<EpisodeFidelity>,
    ) -> FileFidelity {
        let all: Vec<&[StepError]> = episodes.iter().map(|e| e.per_step.as_slice()).collect();
        let starts: Vec<(bool, &[StepError])> = episodes
            .iter()
            .map(|e| (e.initial.reference_grasped, e.per_step.as_slice()))
            .collect();
        FileFidelity {
            buckets: buckets(&all),
            grasp_split: GraspSplit::of(&starts),
            env_id,
            robot,
            sim: opts.sim,
            resync: opts.resync,
            episodes,
        }
    }
}

/// How to replay.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FidelityOptions {
    /// Re-import the reference state every K steps (None: open loop).
    pub resync: Option<u32>,
    /// Physics settings of the replaying env.
    pub sim: SimConfig,
}

fn quat(q: &[f64]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]))
}

fn pos_err(a: &[f64], b: &[f64]) -> f64 {
    (Vector3::from_column_slice(&a[..3]) - Vector3::from_column_slice(&b[..3])).norm()
}

/// Deviations of `got` from `want`; `objects` are the dynamic actors and `grasp_key` the
/// task's grasp flag.
pub fn compare(want: &Frame, got: &Frame, objects: &[String], grasp_key: &str) -> StepError {
    let joint = want
        .qpos
        .iter()
        .zip(&got.qpos)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    let (mut obj_pos, mut obj_rot) = (0.0f64, 0.0f64);
    for o in objects {
        if let (Some(a), Some(b)) = (want.state.actors.get(o), got.state.actors.get(o)) {
            obj_pos = obj_pos.max(pos_err(a, b));
            obj_rot = obj_rot.max(quat(&a[3..7]).angle_to(&quat(&b[3..7])));
        }
    }
    let mut flag_mismatches = 0;
    let mut grasp_agrees = true;
    let reference_grasped = want.flags.iter().any(|(k, v)| k == grasp_key && *v);
    for (k, v) in &want.flags {
        if let Some((_, g)) = got.flags.iter().find(|(gk, _)| gk == k) {
            if g != v {
                flag_mismatches += 1;
                if k == grasp_key {
                    grasp_agrees = false;
                }
            }
        }
    }
    StepError {
        joint,
        tcp_pos: pos_err(&want.tcp_pose, &got.tcp_pose),
        tcp_rot: quat(&want.tcp_pose[3..7]).angle_to(&quat(&got.tcp_pose[3..7])),
        obj_pos,
        obj_rot,
        reward: (want.reward_dense - got.reward_dense).abs(),
        flag_mismatches,
        grasp_agrees,
        reference_grasped,
    }
}

/// Aggregates step errors (`errors[i]` belongs to step i + 1) into [`BUCKETS`].
pub fn buckets(errors: &[&[StepError]]) -> Vec<BucketStats> {
    BUCKETS
        .iter()
        .filter_map(|&(from, to)| {
            let sel: Vec<&StepError> = errors
                .iter()
                .flat_map(|e| {
                    e.iter()
                        .enumerate()
                        .filter(|(i, _)| (from..=to).contains(&(*i as u32 + 1)))
                        .map(|(_, s)| s)
                })
                .collect();
            if sel.is_empty() {
                return None;
            }
            let n = sel.len() as f64;
            let (mean, max) = mean_and_max(&sel);
            Some(BucketStats {
                from,
                to: (to != u32::MAX).then_some(to),
                steps: sel.len(),
                mean,
                max,
                flag_agreement: sel.iter().filter(|s| s.flag_mismatches == 0).count() as f64 / n,
            })
        })
        .collect()
}

/// The env a reference episode was recorded in, with mjskill's physics settings `sim`.
pub fn env_for(
    env_id: &str,
    robot: &str,
    control_mode: &str,
    sim: SimConfig,
) -> Result<Env, EnvError> {
    make(
        env_id,
        EnvConfig {
            robot: Some(robot.to_string()),
            control_mode: Some(control_mode.to_string()),
            obs_mode: ObsMode::State,
            reward_mode: RewardMode::Dense,
            sim,
            ..EnvConfig::default()
        },
    )
}

/// Replays one episode given as frames (`frames[0]` is the initial state, `frames[i]` the
/// state after action i) in `env`, which must be freshly reset with the episode's seed.
pub fn replay_frames(
    env: &mut Env,
    frames: &[Frame],
    objects: &[String],
    grasp_key: &str,
    resync: Option<u32>,
) -> Result<(StepError, Vec<StepError>, Vec<bool>), EnvError> {
    let initial = compare(&frames[0], &Frame::from_env(env, None), objects, grasp_key);
    let mut per_step = Vec::with_capacity(frames.len() - 1);
    let mut success = Vec::with_capacity(frames.len() - 1);
    for (i, f) in frames.iter().enumerate().skip(1) {
        if let Some(k) = resync {
            let prev = &frames[i - 1];
            if (i as u32 - 1).is_multiple_of(k.max(1)) {
                env.set_state_dict(&prev.state)?;
                env.set_elapsed_steps(prev.t);
            }
        }
        let action = f
            .action
            .as_deref()
            .ok_or_else(|| EnvError::BadState(format!("reference step {i} has no action")))?;
        let s = env.step(action)?;
        success.push(s.terminated);
        per_step.push(compare(
            f,
            &Frame::from_env(env, Some(action)),
            objects,
            grasp_key,
        ));
    }
    Ok((initial, per_step, success))
}

/// Replays one ManiSkill episode open loop (or with `resync`).
pub fn replay_episode(
    file: &RefFile,
    ep: &RefEpisode,
    opts: FidelityOptions,
) -> Result<EpisodeFidelity, EnvError> {
    let mut env = env_for(&file.env_id, &file.robot, &ep.control_mode, opts.sim)?;
    env.reset(Some(ep.seed));
    let frames: Vec<Frame> = std::iter::once(&ep.initial)
        .chain(&ep.steps)
        .map(Frame::from_snapshot)
        .collect();
    let objects: Vec<String> = file
        .dynamic_actors()
        .into_iter()
        .map(String::from)
        .collect();
    let grasp_key = env.task().grasp_flag();
    let (initial, per_step, success) =
        replay_frames(&mut env, &frames, &objects, grasp_key, opts.resync)?;
    let first_object_divergence = per_step
        .iter()
        .position(|e| e.obj_pos > DIVERGENCE_DISTANCE)
        .map(|i| i as u32 + 1);
    Ok(EpisodeFidelity {
        index: ep.episode_index,
        source: ep.source.clone(),
        control_mode: ep.control_mode.clone(),
        seed: ep.seed,
        steps: per_step.len(),
        initial,
        reference_success: ep.final_success,
        mjskill_success: success.last().copied().unwrap_or(false),
        ever_success: (
            ep.steps.iter().any(|s| s.flag("success")),
            success.iter().any(|&s| s),
        ),
        first_object_divergence,
        buckets: buckets(&[&per_step]),
        per_step,
    })
}

/// Replays the finished episodes of an mjskill recording with the physics settings `opts`:
/// the reference is the recording replayed with its own settings (bitwise what was
/// recorded), so this measures how far other settings (`--sim-freq`) take the same actions.
pub fn replay_recording(
    rec: &crate::record::Recording,
    opts: FidelityOptions,
) -> Result<FileFidelity, EnvError> {
    let m = &rec.meta;
    let recorded = m.config()?;
    let mut reference = make(&m.env_id, recorded.clone())?;
    let mut candidate = make(
        &m.env_id,
        EnvConfig {
            sim: opts.sim,
            ..recorded
        },
    )?;
    let objects: Vec<String> = reference
        .dynamic_actor_names()
        .into_iter()
        .map(String::from)
        .collect();
    let grasp_key = reference.task().grasp_flag();
    let mut episodes = Vec::new();
    for ep in rec.finished() {
        reference.set_state(&ep.initial_state)?;
        candidate.set_state(&ep.initial_state)?;
        let mut frames = vec![Frame::from_env(&reference, None)];
        let mut success = Vec::with_capacity(ep.steps.len());
        for s in &ep.steps {
            let term = reference.step(&s.action)?.terminated;
            success.push(term);
            frames.push(Frame::from_env(&reference, Some(&s.action)));
        }
        let (initial, per_step, mj_success) =
            replay_frames(&mut candidate, &frames, &objects, grasp_key, opts.resync)?;
        let first_object_divergence = per_step
            .iter()
            .position(|e| e.obj_pos > DIVERGENCE_DISTANCE)
            .map(|i| i as u32 + 1);
        episodes.push(EpisodeFidelity {
            index: ep.index as usize,
            source: "recording".into(),
            control_mode: m.control_mode.clone(),
            seed: ep.seed.unwrap_or(0),
            steps: per_step.len(),
            initial,
            reference_success: success.last().copied().unwrap_or(false),
            mjskill_success: mj_success.last().copied().unwrap_or(false),
            ever_success: (success.iter().any(|&s| s), mj_success.iter().any(|&s| s)),
            first_object_divergence,
            buckets: buckets(&[&per_step]),
            per_step,
        });
    }
    Ok(FileFidelity::summarise(
        m.env_id.clone(),
        m.robot.clone(),
        opts,
        episodes,
    ))
}

/// Replays every episode of a ManiSkill reference file.
pub fn replay_file(file: &RefFile, opts: FidelityOptions) -> Result<FileFidelity, EnvError> {
    let episodes = file
        .episodes
        .iter()
        .map(|ep| replay_episode(file, ep, opts))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(FileFidelity::summarise(
        file.env_id.clone(),
        file.robot.clone(),
        opts,
        episodes,
    ))
}
