//! Controllers: ManiSkill's action → PD-target semantics (docs/controllers.md), per control mode.
//!
//! A control mode is a list of parts ([`PartSpec`]: arm, gripper, body, base) that each take
//! a slice of the action in order. Each part is one controller kind, one file each as in
//! ManiSkill's `agents/controllers/`: [`pd_joint_pos`] (absolute/delta joint positions and
//! mimic grippers), [`pd_joint_vel`], [`pd_joint_pos_vel`], [`pd_ee_pose`] (EE position and
//! pose through IK) and [`pd_base_vel`] (Fetch's base). They share the [`PartController`]
//! trait; a [`PartKind`] (the part's configuration) is turned into its controller once, when
//! the [`Controller`] is built.
//!
//! Arithmetic follows upstream's float32 path: actions are f32, normalised parts clip to
//! [−1, 1] and rescale in f32, deltas are added to the f32 measured position. Targets go to
//! the robot's [`Drives`], which turn them into forces.
pub mod convex;
pub mod desc;
pub mod drive;
pub mod error;
pub mod ik;
pub mod joints;
pub mod mode;
pub mod pd_base_vel;
pub mod pd_ee_pose;
pub mod pd_joint_pos;
pub mod pd_joint_pos_vel;
pub mod pd_joint_vel;
pub mod tgs;

use nalgebra::{Isometry3, UnitQuaternion, Vector3};

use crate::mujoco::{Data, Pose};
use crate::obs::ObsWriter;
use desc::{Drive, RobotDesc};
pub use drive::Drives;
pub use error::ControllerError;
use ik::Chain;
pub use joints::JointMap;
pub use mode::ControlMode;
use pd_base_vel::{BaseForwardVelConfig, PdBaseForwardVel};
use pd_ee_pose::{EeConfig, PdEePose};
use pd_joint_pos::{JointPosConfig, PdJointPos};
use pd_joint_pos_vel::{JointPosVelConfig, PdJointPosVel};
use pd_joint_vel::{JointVelConfig, PdJointVel};

/// The configuration of a part: which controller kind, with which parameters.
#[derive(Debug, Clone, PartialEq)]
pub enum PartKind {
    /// [`PdJointPos`]: absolute or delta position targets (+ mimic followers).
    JointPos(JointPosConfig),
    /// [`PdJointVel`]: velocity targets, normalised to [low, high].
    JointVel(JointVelConfig),
    /// [`PdJointPosVel`]: n positions (absolute or delta) then n velocities.
    JointPosVel(JointPosVelConfig),
    /// [`PdEePose`]: EE position or pose targets.
    Ee(EeConfig),
    /// [`PdBaseForwardVel`]: [forward speed, yaw rate] of a mobile base.
    BaseForwardVel(BaseForwardVelConfig),
}

/// One part of a control mode.
#[derive(Debug, Clone, PartialEq)]
pub struct PartSpec {
    /// Part name (`arm`, `gripper`, `body`, `base`).
    pub name: &'static str,
    /// Joints that take action entries.
    pub joints: Vec<&'static str>,
    /// Mimic followers: (follower, control joint, multiplier, offset). Only joint position
    /// parts have them (ManiSkill's `PDJointPosMimicController`).
    pub followers: Vec<(&'static str, &'static str, f32, f32)>,
    /// Behaviour.
    pub kind: PartKind,
    /// Drive (stiffness, damping, force limit) for every joint of the part (a velocity part
    /// drives with stiffness 0 whatever this says).
    pub gains: (f64, f64, f64),
    /// The part is an entry of ManiSkill's controller dict even when it is the mode's only
    /// part (`dict(arm=...)`, a `CombinedController`): its state and observation keys carry
    /// its name (`arm.target_qpos`). A lone part without it is the mode's controller itself
    /// (so100: `target_qpos`).
    pub keyed: bool,
}

impl PartKind {
    /// Normalised delta position targets, ±`bound` for each of `n` joints.
    pub fn joint_delta(n: usize, bound: f32, use_target: bool) -> PartKind {
        PartKind::joint_delta_per(vec![bound; n], use_target)
    }

    /// Normalised delta position targets, ±`bounds[i]` for joint i.
    pub fn joint_delta_per(bounds: Vec<f32>, use_target: bool) -> PartKind {
        PartKind::JointPos(JointPosConfig {
            use_delta: true,
            use_target,
            normalize: true,
            low: Some(bounds.iter().map(|b| -b).collect()),
            high: Some(bounds),
        })
    }

    /// Absolute position targets bounded by the joint limits, not normalised.
    pub fn joint_absolute() -> PartKind {
        PartKind::JointPos(JointPosConfig {
            use_delta: false,
            use_target: false,
            normalize: false,
            low: None,
            high: None,
        })
    }

    /// Absolute position targets in `[low, high]` for each of `n` joints (`normalize`: the
    /// action is clipped to [−1, 1] and rescaled to the range).
    pub fn joint_range(n: usize, (low, high): (f32, f32), normalize: bool) -> PartKind {
        PartKind::JointPos(JointPosConfig {
            use_delta: false,
            use_target: false,
            normalize,
            low: Some(vec![low; n]),
            high: Some(vec![high; n]),
        })
    }

    /// Velocity targets in ±`bound`.
    pub fn joint_vel(bound: f32) -> PartKind {
        PartKind::JointVel(JointVelConfig {
            low: -bound,
            high: bound,
        })
    }

    /// Absolute positions then velocities in ±`vel`.
    pub fn joint_pos_vel(normalize: bool, vel: f32) -> PartKind {
        PartKind::JointPosVel(JointPosVelConfig {
            use_delta: false,
            normalize,
            pos: (0.0, 0.0),
            vel: (-vel, vel),
        })
    }

    /// Normalised position deltas in ±`bound` then velocities in ±`vel`.
    pub fn joint_delta_pos_vel(bound: f32, vel: f32) -> PartKind {
        PartKind::JointPosVel(JointPosVelConfig {
            use_delta: true,
            normalize: true,
            pos: (-bound, bound),
            vel: (-vel, vel),
        })
    }

    /// Normalised EE delta targets of `ee_link` (position, plus rotation with `rotation`),
    /// position and rotation bounds both `bounds`.
    pub fn ee_delta(
        ee_link: &'static str,
        root_link: Option<&'static str>,
        rotation: bool,
        use_target: bool,
        bounds: (f32, f32),
    ) -> PartKind {
        PartKind::Ee(EeConfig {
            rotation,
            use_delta: true,
            use_target,
            pos: bounds,
            rot: bounds,
            ee_link,
            root_link,
        })
    }

    /// Absolute (not normalised) EE pose targets of `ee_link`.
    pub fn ee_pose(
        ee_link: &'static str,
        root_link: Option<&'static str>,
        pos: (f32, f32),
        rot: (f32, f32),
    ) -> PartKind {
        PartKind::Ee(EeConfig {
            rotation: true,
            use_delta: false,
            use_target: false,
            pos,
            rot,
            ee_link,
            root_link,
        })
    }

    /// A mobile base driven by [forward speed, yaw rate] within `lin` and `ang`.
    pub fn base_forward_vel(lin: (f32, f32), ang: (f32, f32)) -> PartKind {
        PartKind::BaseForwardVel(BaseForwardVelConfig { lin, ang })
    }
}

impl PartSpec {
    /// A part without mimic followers.
    pub fn new(
        name: &'static str,
        joints: &[&'static str],
        kind: PartKind,
        gains: (f64, f64, f64),
    ) -> PartSpec {
        PartSpec {
            name,
            joints: joints.to_vec(),
            followers: vec![],
            kind,
            gains,
            keyed: false,
        }
    }

    /// Marks the part as an entry of ManiSkill's controller dict ([`PartSpec::keyed`]).
    pub fn keyed(mut self) -> PartSpec {
        self.keyed = true;
        self
    }

    /// Adds a mimic follower: `follower` tracks `multiplier · control + offset`.
    pub fn with_follower(
        mut self,
        follower: &'static str,
        control: &'static str,
        multiplier: f32,
        offset: f32,
    ) -> PartSpec {
        self.followers.push((follower, control, multiplier, offset));
        self
    }
}

/// What every part holds: its action joints, action bounds and targets.
#[derive(Debug, Clone)]
pub struct PartCore {
    /// ManiSkill indices of the action joints.
    pub idx: Vec<usize>,
    /// Lower bounds of the part's action slice (its length is the slice length).
    pub low: Vec<f32>,
    /// Upper bounds of the part's action slice.
    pub high: Vec<f32>,
    /// Joint position target of each action joint.
    pub target_q: Vec<f32>,
    /// EE target pose (identity for joint-space parts).
    pub target_pose: Isometry3<f64>,
}

impl PartCore {
    /// A core on joints `idx` with action bounds `low`/`high`, zero targets.
    pub fn new(idx: Vec<usize>, low: Vec<f32>, high: Vec<f32>) -> PartCore {
        PartCore {
            target_q: vec![0.0; idx.len()],
            idx,
            low,
            high,
            target_pose: Isometry3::identity(),
        }
    }

    /// Joint targets := the measured positions `q` (all of the robot's joints).
    pub fn reset(&mut self, q: &[f64]) {
        for (t, &i) in self.target_q.iter_mut().zip(&self.idx) {
            *t = q[i] as f32;
        }
    }
}

/// A target a part accumulates across steps (ManiSkill's controller state).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Target<'a> {
    /// `target_qpos`: joint targets.
    Qpos(&'a [f32]),
    /// `target_pose`: EE target pose.
    Pose(Isometry3<f64>),
}

impl Target<'_> {
    /// The state-dict key of the target.
    pub fn key(&self) -> &'static str {
        match self {
            Target::Qpos(_) => "target_qpos",
            Target::Pose(_) => "target_pose",
        }
    }
}

/// One controller kind: what a part does with its action slice. Implementations do not
/// allocate in [`PartController::set_action`].
pub trait PartController {
    /// The part's joints, bounds and targets.
    fn core(&self) -> &PartCore;

    /// Mutable [`PartController::core`].
    fn core_mut(&mut self) -> &mut PartCore;

    /// Action bounds of the part's slice (informational for non-normalised parts, as
    /// upstream).
    fn bounds(&self) -> (&[f32], &[f32]) {
        (&self.core().low, &self.core().high)
    }

    /// Appends the (ManiSkill indices of the) joints the part drives.
    fn drive_joints(&self, out: &mut Vec<usize>) {
        out.extend_from_slice(&self.core().idx);
    }

    /// The drive gains of the part's joints given the configured `gains`.
    fn gains(&self, gains: (f64, f64, f64)) -> (f64, f64, f64) {
        gains
    }

    /// `reset()`: targets := the measured joint positions `q` (all of the robot's joints).
    fn reset(&mut self, q: &[f64]) {
        self.core_mut().reset(q);
    }

    /// Applies the part's action slice `a` given the measured positions `q`: updates the
    /// targets and writes the drive targets.
    fn set_action(&mut self, a: &[f32], joints: &JointMap, q: &[f64], drives: &mut Drives);

    /// The target the part accumulates and exposes as state, if any.
    fn target(&self) -> Option<Target<'_>> {
        None
    }

    /// Restores the accumulated target from state values (as [`Target`] lays them out:
    /// joint targets, or `[p, q]`) and holds the drives on it.
    fn restore_target(&mut self, _values: &[f64], _drives: &mut Drives) {}

    /// The inverse of [`PartController::set_action`] for joint position parts: writes into
    /// `out` (the part's action slice) the action that sets each action joint `i` (ManiSkill
    /// index) to the position target `target(i)` given the measured positions `q`, clipped
    /// to the action bounds. `false` (with `out` unspecified) for parts whose action is not a
    /// joint position (velocities, EE poses, a base) or when a joint has no target.
    fn action_for_targets(
        &self,
        _target: &dyn Fn(usize) -> Option<f64>,
        _joints: &JointMap,
        _q: &[f64],
        _out: &mut [f32],
    ) -> bool {
        false
    }

    /// Raw state (joint targets, then the target pose as `[p, q]`).
    fn save(&self, out: &mut Vec<f64>) {
        let c = self.core();
        out.extend(c.target_q.iter().map(|&x| x as f64));
        out.extend_from_slice(&Pose::from_isometry(&c.target_pose).to_array());
    }

    /// Number of values [`PartController::save`] writes.
    fn save_len(&self) -> usize {
        self.core().target_q.len() + Pose::LEN
    }

    /// Restores what [`PartController::save`] wrote; returns the number of values read.
    fn load(&mut self, s: &[f64]) -> usize {
        let c = self.core_mut();
        let mut k = 0;
        for t in c.target_q.iter_mut() {
            *t = s[k] as f32;
            k += 1;
        }
        let mut v = [0.0; Pose::LEN];
        v.copy_from_slice(&s[k..k + Pose::LEN]);
        c.target_pose = Pose::from_array(v).isometry();
        k + Pose::LEN
    }
}

/// The controller of a part: one of the kinds (static dispatch storage, no allocation).
#[derive(Debug, Clone)]
enum AnyPart {
    JointPos(PdJointPos),
    JointVel(PdJointVel),
    JointPosVel(PdJointPosVel),
    Ee(PdEePose),
    BaseForwardVel(PdBaseForwardVel),
}

/// `$body` with `$c` bound to the controller of part kind `$part` (an `AnyPart`, by
/// reference or by mutable reference): the one dispatch over the kinds, static.
macro_rules! with_part {
    ($part:expr, $c:ident => $body:expr) => {
        match $part {
            AnyPart::JointPos($c) => $body,
            AnyPart::JointVel($c) => $body,
            AnyPart::JointPosVel($c) => $body,
            AnyPart::Ee($c) => $body,
            AnyPart::BaseForwardVel($c) => $body,
        }
    };
}

#[derive(Debug, Clone)]
struct Part {
    name: &'static str,
    gains: (f64, f64, f64),
    ctl: AnyPart,
}

/// A constructed controller for one robot and control mode.
#[derive(Debug, Clone)]
pub struct Controller {
    mode: ControlMode,
    parts: Vec<Part>,
    /// State and observation keys carry the part names (several parts, or a keyed one).
    nested: bool,
    low: Vec<f32>,
    high: Vec<f32>,
    n_dof: usize,
    /// Scratch: measured qpos (f64), sized n_dof.
    q: Vec<f64>,
}

fn clip_scale(a: f32, low: f32, high: f32) -> f32 {
    let a = a.clamp(-1.0, 1.0);
    0.5 * (high + low) + 0.5 * (high - low) * a
}

/// quat(Rx(a)·Ry(b)·Rz(c)): pytorch3d's intrinsic "XYZ" Euler convention.
pub fn euler_xyz(a: f64, b: f64, c: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::x_axis(), a)
        * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), b)
        * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), c)
}

/// Standardises a quaternion to w ≥ 0 (ManiSkill's `quaternion_multiply` output).
pub fn standardize(q: UnitQuaternion<f64>) -> UnitQuaternion<f64> {
    if q.w < 0.0 {
        UnitQuaternion::new_unchecked(-q.into_inner())
    } else {
        q
    }
}

impl Controller {
    /// Builds the controller for `mode` from its parts. Bounds that default to joint limits
    /// are read from `desc`.
    pub fn new(
        mode: ControlMode,
        parts: Vec<PartSpec>,
        desc: &RobotDesc,
    ) -> Result<Controller, ControllerError> {
        let active = desc.active_joints();
        let index = |name: &str| {
            active
                .iter()
                .position(|&j| desc.joints[j].name == name)
                .ok_or_else(|| ControllerError::NoActiveJoint(name.to_string()))
        };
        let limits = |i: usize| {
            let l = desc.joints[active[i]].limits;
            (l.0 as f32, l.1 as f32)
        };
        let n_dof = active.len();
        let nested = parts.len() > 1 || parts.iter().any(|p| p.keyed);
        let mut built = Vec::new();
        let (mut low, mut high) = (Vec::new(), Vec::new());
        for spec in parts {
            let idx: Vec<usize> = spec
                .joints
                .iter()
                .map(|j| index(j))
                .collect::<Result<_, _>>()?;
            let mut followers = Vec::new();
            for (f, c, m, o) in &spec.followers {
                let ci = spec.joints.iter().position(|j| j == c).ok_or(
                    ControllerError::MimicControl {
                        joint: c,
                        part: spec.name,
                    },
                )?;
                followers.push((index(f)?, ci, *m, *o));
            }
            if !followers.is_empty() && !matches!(spec.kind, PartKind::JointPos(_)) {
                return Err(ControllerError::MimicKind(spec.name));
            }
            let ctl = match spec.kind {
                PartKind::JointPos(cfg) => {
                    AnyPart::JointPos(PdJointPos::new(cfg, idx, followers, limits))
                }
                PartKind::JointVel(cfg) => AnyPart::JointVel(PdJointVel::new(cfg, idx)),
                PartKind::JointPosVel(cfg) => {
                    AnyPart::JointPosVel(PdJointPosVel::new(cfg, idx, limits))
                }
                PartKind::Ee(cfg) => {
                    let chain = Chain::from_root(desc, cfg.root_link, cfg.ee_link, &spec.joints)?;
                    AnyPart::Ee(PdEePose::new(cfg, idx, chain, n_dof))
                }
                PartKind::BaseForwardVel(cfg) => {
                    AnyPart::BaseForwardVel(PdBaseForwardVel::new(cfg, idx)?)
                }
            };
            let (pl, ph) = with_part!(&ctl, c => c.bounds());
            low.extend_from_slice(pl);
            high.extend_from_slice(ph);
            let gains = with_part!(&ctl, c => c.gains(spec.gains));
            built.push(Part {
                name: spec.name,
                gains,
                ctl,
            });
        }
        Ok(Controller {
            mode,
            parts: built,
            nested,
            low,
            high,
            n_dof,
            q: vec![0.0; n_dof],
        })
    }

    /// The control mode's name.
    pub fn mode(&self) -> &'static str {
        self.mode.name()
    }
    /// Action length.
    pub fn action_dim(&self) -> usize {
        self.low.len()
    }
    /// Advertised action bounds (informational for non-normalised parts, as upstream).
    pub fn bounds(&self) -> (&[f32], &[f32]) {
        (&self.low, &self.high)
    }

    /// PD drives for every joint a part touches (later parts override earlier ones on the
    /// same joint, as upstream).
    pub fn drives(&self, desc: &RobotDesc) -> Vec<Drive> {
        let active = desc.active_joints();
        let mut out: Vec<Drive> = Vec::new();
        let mut joints = Vec::new();
        for p in &self.parts {
            joints.clear();
            with_part!(&p.ctl, c => c.drive_joints(&mut joints));
            for &i in &joints {
                let name = desc.joints[active[i]].name.clone();
                let d = Drive {
                    joint: name.clone(),
                    kp: p.gains.0,
                    kd: p.gains.1,
                    force_limit: p.gains.2,
                };
                match out.iter_mut().find(|x| x.joint == name) {
                    Some(x) => *x = d,
                    None => out.push(d),
                }
            }
        }
        out
    }

    /// Writes the controller state of the observation (ManiSkill's `agent/controller`):
    /// `target_qpos` / `target_pose` of the parts that accumulate targets, nested under the
    /// part name when the mode has several parts.
    pub fn observe(&self, out: &mut ObsWriter) {
        let nested = self.nested;
        for p in &self.parts {
            let Some(target) = with_part!(&p.ctl, c => c.target()) else {
                continue;
            };
            let segs = [p.name, target.key()];
            let segs = if nested { &segs[..] } else { &segs[1..] };
            match target {
                Target::Qpos(q) => out.put_path(segs, q.iter().map(|&x| x as f64)),
                Target::Pose(pose) => {
                    let t = pose.translation.vector;
                    let q = standardize(pose.rotation);
                    out.put_path(segs, [t.x, t.y, t.z, q.w, q.i, q.j, q.k]);
                }
            }
        }
    }

    /// The action range of every part, in action order (ManiSkill's `action_space` dict).
    pub fn part_ranges(&self) -> Vec<(&'static str, std::ops::Range<usize>)> {
        let mut off = 0;
        self.parts
            .iter()
            .map(|p| {
                let r = off..off + with_part!(&p.ctl, c => c.bounds().0.len());
                off = r.end;
                (p.name, r)
            })
            .collect()
    }

    fn state_key(&self, p: &Part, k: &str) -> String {
        if self.nested {
            format!("{}.{k}", p.name)
        } else {
            k.to_string()
        }
    }

    /// The controller state of ManiSkill's `get_state_dict()`: `("<part>.target_qpos",
    /// values)` / `("<part>.target_pose", [p, q])` for the parts that accumulate targets
    /// (without the part prefix when the mode has a single part that is not keyed).
    pub fn state_entries(&self) -> Vec<(String, Vec<f64>)> {
        let mut v = Vec::new();
        for p in &self.parts {
            let Some(target) = with_part!(&p.ctl, c => c.target()) else {
                continue;
            };
            let values = match target {
                Target::Qpos(q) => q.iter().map(|&x| x as f64).collect(),
                Target::Pose(pose) => {
                    let t = pose.translation.vector;
                    let q = pose.rotation;
                    vec![t.x, t.y, t.z, q.w, q.i, q.j, q.k]
                }
            };
            v.push((self.state_key(p, target.key()), values));
        }
        v
    }

    /// After the physics state was set from outside (ManiSkill's `set_state_dict`): every
    /// target restarts from the measured positions as in [`Controller::reset`], then the
    /// given `state_entries`-style values override the accumulated targets, and the drives
    /// hold the accumulated joint targets (or the measured positions).
    pub fn set_targets_from_state(
        &mut self,
        joints: &JointMap,
        data: &Data,
        drives: &mut Drives,
        entries: &indexmap::IndexMap<String, Vec<f64>>,
    ) {
        self.reset(joints, data, drives);
        for k in 0..self.parts.len() {
            let Some(key) = with_part!(&self.parts[k].ctl, c => c.target().map(|t| t.key())) else {
                continue;
            };
            if let Some(v) = entries.get(&self.state_key(&self.parts[k], key)) {
                with_part!(&mut self.parts[k].ctl, c => c.restore_target(v, drives));
            }
        }
    }

    /// The action of this mode that reproduces joint position targets (converting an action
    /// of another mode of the same robot, as ManiSkill's `replay_trajectory
    /// --target-control-mode` does): every part for which `copy(name)` gives a slice takes
    /// it as is (the same part in both modes); every other part must be a joint position
    /// part and takes the action that sets its joints to `target(i)` (ManiSkill index i)
    /// from the measured positions of `data` ([`PartController::action_for_targets`]).
    /// Returns the name of the first part that can be neither copied nor inverted.
    pub fn action_for_targets<'a>(
        &self,
        joints: &JointMap,
        data: &Data,
        target: &dyn Fn(usize) -> Option<f64>,
        copy: &dyn Fn(&str) -> Option<&'a [f32]>,
        out: &mut [f32],
    ) -> Result<(), &'static str> {
        let mut q = vec![0.0; self.n_dof];
        joints.qpos(data, &mut q);
        for (p, (_, r)) in self.parts.iter().zip(self.part_ranges()) {
            let slot = &mut out[r.clone()];
            match copy(p.name) {
                Some(a) if a.len() == slot.len() => slot.copy_from_slice(a),
                _ => {
                    if !with_part!(&p.ctl, c => c.action_for_targets(target, joints, &q, slot)) {
                        return Err(p.name);
                    }
                }
            }
        }
        Ok(())
    }

    /// Raw controller state for get/set_state: all targets (positions and poses).
    pub fn save(&self, out: &mut Vec<f64>) {
        for p in &self.parts {
            with_part!(&p.ctl, c => c.save(out));
        }
    }

    /// Number of values [`Controller::save`] writes.
    pub fn save_len(&self) -> usize {
        self.parts
            .iter()
            .map(|p| with_part!(&p.ctl, c => c.save_len()))
            .sum()
    }

    /// Restores what [`Controller::save`] wrote; returns the number of values read.
    pub fn load(&mut self, s: &[f64]) -> usize {
        let mut k = 0;
        for p in &mut self.parts {
            k += with_part!(&mut p.ctl, c => c.load(&s[k..]));
        }
        k
    }

    /// `reset()` of every part: targets := measured joint positions / EE pose; the drive
    /// targets are written right away (upstream writes them on the first action; identical
    /// whenever the first step carries an action).
    pub fn reset(&mut self, joints: &JointMap, data: &Data, drives: &mut Drives) {
        joints.qpos(data, &mut self.q);
        for p in &mut self.parts {
            with_part!(&mut p.ctl, c => c.reset(&self.q));
        }
        for k in 0..self.n_dof {
            let q = self.q[k];
            drives.set_joint_target(k, q, 0.0);
        }
        drives.forget_contacts();
    }

    /// Applies an action (already validated for length and finiteness): computes the part
    /// targets and writes the drive controls.
    pub fn set_action(
        &mut self,
        action: &[f32],
        joints: &JointMap,
        data: &Data,
        drives: &mut Drives,
    ) {
        joints.qpos(data, &mut self.q);
        let mut off = 0;
        for p in &mut self.parts {
            let q = &self.q;
            off += with_part!(&mut p.ctl, c => {
                let n = c.bounds().0.len();
                c.set_action(&action[off..off + n], joints, q, drives);
                n
            });
        }
    }
}
