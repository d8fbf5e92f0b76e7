//! Controllers: ManiSkill's action → PD-target semantics (docs/controllers.md), per control mode.
//!
//! A control mode is a list of parts ([`PartSpec`]: arm, gripper, body, base) that each take
//! a slice of the action in order. Arithmetic follows upstream's float32 path: actions are
//! f32, normalised parts clip to [−1, 1] and rescale in f32, deltas are added to the f32
//! measured position. Targets go to the robot's [`Drives`], which turn them into forces.
pub mod drive;
pub mod ik;
pub mod joints;
pub mod mode;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use crate::mjcf::urdf::RobotDesc;
use crate::mjcf::Drive;
use crate::mujoco::Data;
use crate::obs::ObsWriter;
pub use drive::Drives;
use ik::Chain;
pub use joints::JointMap;
pub use mode::ControlMode;

/// What a part does with its action slice.
#[derive(Debug, Clone, PartialEq)]
pub enum PartKind {
    /// `PDJointPosController` (+ mimic followers): absolute or delta position targets.
    JointPos {
        /// Delta from the measured position (or from the last target with `use_target`).
        use_delta: bool,
        /// Accumulate on the previous target (and expose it as `target_qpos`).
        use_target: bool,
        /// Clip to [−1, 1] and rescale to [low, high].
        normalize: bool,
        /// Lower bounds per action entry (None ⇒ the joint limits).
        low: Option<Vec<f32>>,
        /// Upper bounds per action entry (None ⇒ the joint limits).
        high: Option<Vec<f32>>,
    },
    /// `PDJointVelController`: velocity targets, normalised to [low, high].
    JointVel {
        /// Lower velocity bound.
        low: f32,
        /// Upper velocity bound.
        high: f32,
    },
    /// `PDJointPosVelController`: n positions (absolute or delta) then n velocities.
    JointPosVel {
        /// Positions are deltas from the measured position.
        use_delta: bool,
        /// Whether the action is normalised (both halves; absolute positions of unlimited
        /// joints are never normalised).
        normalize: bool,
        /// Delta bounds (ignored for absolute positions, whose bounds are the joint limits).
        pos: (f32, f32),
        /// Velocity bounds.
        vel: (f32, f32),
    },
    /// `PDEEPosController` / `PDEEPoseController`.
    Ee {
        /// Include the 3 rotation entries.
        rotation: bool,
        /// Delta (normalised) or absolute (not normalised) targets.
        use_delta: bool,
        /// Accumulate on the stored target pose (exposed as `target_pose`).
        use_target: bool,
        /// Position bounds.
        pos: (f32, f32),
        /// Rotation bounds (the delta rotation is scaled by the *lower* bound, upstream).
        rot: (f32, f32),
        /// EE link.
        ee_link: &'static str,
        /// Link whose frame EE poses are expressed in (`root_link_name` upstream; None: the
        /// robot's root link).
        root_link: Option<&'static str>,
    },
    /// `PDBaseForwardVelController` (Fetch): [forward speed, yaw rate] → joint velocities of
    /// the virtual x, y, yaw joints.
    BaseForwardVel {
        /// Forward-speed bounds.
        lin: (f32, f32),
        /// Yaw-rate bounds.
        ang: (f32, f32),
    },
}

/// One part of a control mode.
#[derive(Debug, Clone, PartialEq)]
pub struct PartSpec {
    /// Part name (`arm`, `gripper`, `body`, `base`).
    pub name: &'static str,
    /// Joints that take action entries.
    pub joints: Vec<&'static str>,
    /// Mimic followers: (follower, control joint, multiplier, offset).
    pub followers: Vec<(&'static str, &'static str, f32, f32)>,
    /// Behaviour.
    pub kind: PartKind,
    /// Drive (stiffness, damping, force limit) for every joint of the part.
    pub gains: (f64, f64, f64),
}

impl PartKind {
    /// Normalised delta position targets, ±`bound` for each of `n` joints.
    pub fn joint_delta(n: usize, bound: f32, use_target: bool) -> PartKind {
        PartKind::joint_delta_per(vec![bound; n], use_target)
    }

    /// Normalised delta position targets, ±`bounds[i]` for joint i.
    pub fn joint_delta_per(bounds: Vec<f32>, use_target: bool) -> PartKind {
        PartKind::JointPos {
            use_delta: true,
            use_target,
            normalize: true,
            low: Some(bounds.iter().map(|b| -b).collect()),
            high: Some(bounds),
        }
    }

    /// Absolute position targets bounded by the joint limits, not normalised.
    pub fn joint_absolute() -> PartKind {
        PartKind::JointPos {
            use_delta: false,
            use_target: false,
            normalize: false,
            low: None,
            high: None,
        }
    }

    /// Absolute position targets in `[low, high]` for each of `n` joints (`normalize`: the
    /// action is clipped to [−1, 1] and rescaled to the range).
    pub fn joint_range(n: usize, (low, high): (f32, f32), normalize: bool) -> PartKind {
        PartKind::JointPos {
            use_delta: false,
            use_target: false,
            normalize,
            low: Some(vec![low; n]),
            high: Some(vec![high; n]),
        }
    }

    /// Velocity targets in ±`bound`.
    pub fn joint_vel(bound: f32) -> PartKind {
        PartKind::JointVel {
            low: -bound,
            high: bound,
        }
    }

    /// Absolute positions then velocities in ±`vel`.
    pub fn joint_pos_vel(normalize: bool, vel: f32) -> PartKind {
        PartKind::JointPosVel {
            use_delta: false,
            normalize,
            pos: (0.0, 0.0),
            vel: (-vel, vel),
        }
    }

    /// Normalised position deltas in ±`bound` then velocities in ±`vel`.
    pub fn joint_delta_pos_vel(bound: f32, vel: f32) -> PartKind {
        PartKind::JointPosVel {
            use_delta: true,
            normalize: true,
            pos: (-bound, bound),
            vel: (-vel, vel),
        }
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
        PartKind::Ee {
            rotation,
            use_delta: true,
            use_target,
            pos: bounds,
            rot: bounds,
            ee_link,
            root_link,
        }
    }

    /// Absolute (not normalised) EE pose targets of `ee_link`.
    pub fn ee_pose(
        ee_link: &'static str,
        root_link: Option<&'static str>,
        pos: (f32, f32),
        rot: (f32, f32),
    ) -> PartKind {
        PartKind::Ee {
            rotation: true,
            use_delta: false,
            use_target: false,
            pos,
            rot,
            ee_link,
            root_link,
        }
    }
}

impl PartSpec {
    /// A part without mimic followers. A [`PartKind::JointVel`] part gets stiffness 0 (a pure
    /// velocity drive, as upstream's `PDJointVelController`), whatever `gains.0` says.
    pub fn new(
        name: &'static str,
        joints: &[&'static str],
        kind: PartKind,
        gains: (f64, f64, f64),
    ) -> PartSpec {
        let gains = match kind {
            PartKind::JointVel { .. } => (0.0, gains.1, gains.2),
            _ => gains,
        };
        PartSpec {
            name,
            joints: joints.to_vec(),
            followers: vec![],
            kind,
            gains,
        }
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

#[derive(Debug, Clone)]
struct Part {
    spec: PartSpec,
    /// ManiSkill indices of the action joints.
    idx: Vec<usize>,
    /// (follower index, position of its control joint in `idx`, multiplier, offset).
    followers: Vec<(usize, usize, f32, f32)>,
    /// Per-entry lower bounds of this part's action slice (its length is the slice length).
    low: Vec<f32>,
    target_q: Vec<f32>,
    target_pose: Isometry3<f64>,
    chain: Option<Chain>,
}

/// A constructed controller for one robot and control mode.
#[derive(Debug, Clone)]
pub struct Controller {
    mode: ControlMode,
    parts: Vec<Part>,
    low: Vec<f32>,
    high: Vec<f32>,
    n_dof: usize,
    /// Scratch: measured qpos (f64) and IK output, sized n_dof.
    q: Vec<f64>,
    q_ik: Vec<f64>,
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
    ) -> Result<Controller, String> {
        let active = desc.active_joints();
        let index = |name: &str| {
            active
                .iter()
                .position(|&j| desc.joints[j].name == name)
                .ok_or_else(|| format!("no active joint {name:?}"))
        };
        let n_dof = active.len();
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
                let ci = spec.joints.iter().position(|j| j == c).ok_or_else(|| {
                    format!("mimic control joint {c:?} is not in part {}", spec.name)
                })?;
                followers.push((index(f)?, ci, *m, *o));
            }
            let limits = |i: usize| {
                let l = desc.joints[active[i]].limits;
                (l.0 as f32, l.1 as f32)
            };
            let n = idx.len();
            let (pl, ph): (Vec<f32>, Vec<f32>) = match &spec.kind {
                PartKind::JointPos {
                    normalize,
                    low,
                    high,
                    ..
                } => {
                    if *normalize {
                        (vec![-1.0; n], vec![1.0; n])
                    } else {
                        let l = low
                            .clone()
                            .unwrap_or_else(|| idx.iter().map(|&i| limits(i).0).collect());
                        let h = high
                            .clone()
                            .unwrap_or_else(|| idx.iter().map(|&i| limits(i).1).collect());
                        (l, h)
                    }
                }
                PartKind::JointVel { .. } => (vec![-1.0; n], vec![1.0; n]),
                PartKind::JointPosVel {
                    use_delta,
                    normalize,
                    vel,
                    ..
                } => {
                    if *normalize {
                        // Absolute positions are normalised to the joint limits; an unlimited
                        // (continuous) joint's position is taken as is (upstream scales it by
                        // ±inf and produces NaN targets), so its bounds stay ±inf.
                        let mut l: Vec<f32> = idx
                            .iter()
                            .map(|&i| match limits(i) {
                                (lo, _) if !*use_delta && !lo.is_finite() => lo,
                                _ => -1.0,
                            })
                            .collect();
                        let mut h: Vec<f32> = idx
                            .iter()
                            .map(|&i| match limits(i) {
                                (_, hi) if !*use_delta && !hi.is_finite() => hi,
                                _ => 1.0,
                            })
                            .collect();
                        l.extend(std::iter::repeat_n(-1.0, n));
                        h.extend(std::iter::repeat_n(1.0, n));
                        (l, h)
                    } else {
                        let mut l: Vec<f32> = idx
                            .iter()
                            .map(|&i| if *use_delta { -1.0 } else { limits(i).0 })
                            .collect();
                        let mut h: Vec<f32> = idx
                            .iter()
                            .map(|&i| if *use_delta { 1.0 } else { limits(i).1 })
                            .collect();
                        l.extend(std::iter::repeat_n(vel.0, n));
                        h.extend(std::iter::repeat_n(vel.1, n));
                        (l, h)
                    }
                }
                PartKind::Ee {
                    rotation,
                    use_delta,
                    pos,
                    rot,
                    ..
                } => {
                    let k = if *rotation { 6 } else { 3 };
                    if *use_delta {
                        (vec![-1.0; k], vec![1.0; k])
                    } else {
                        let mut l = vec![pos.0; 3];
                        let mut h = vec![pos.1; 3];
                        if *rotation {
                            l.extend([rot.0; 3]);
                            h.extend([rot.1; 3]);
                        }
                        (l, h)
                    }
                }
                PartKind::BaseForwardVel { .. } => (vec![-1.0; 2], vec![1.0; 2]),
            };
            let chain = match &spec.kind {
                PartKind::Ee {
                    ee_link, root_link, ..
                } => Some(Chain::from_root(desc, *root_link, ee_link, &spec.joints)?),
                _ => None,
            };
            low.extend_from_slice(&pl);
            high.extend_from_slice(&ph);
            built.push(Part {
                target_q: vec![0.0; n],
                idx,
                followers,
                low: pl,
                target_pose: Isometry3::identity(),
                chain,
                spec,
            });
        }
        Ok(Controller {
            mode,
            parts: built,
            low,
            high,
            n_dof,
            q: vec![0.0; n_dof],
            q_ik: vec![0.0; n_dof],
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
        for p in &self.parts {
            let mut joints: Vec<usize> = p.idx.clone();
            joints.extend(p.followers.iter().map(|f| f.0));
            if let PartKind::BaseForwardVel { .. } = p.spec.kind {
                joints = p.idx.clone();
            }
            for i in joints {
                let name = desc.joints[active[i]].name.clone();
                let d = Drive {
                    joint: name.clone(),
                    kp: p.spec.gains.0,
                    kd: p.spec.gains.1,
                    force_limit: p.spec.gains.2,
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
        let nested = self.parts.len() > 1;
        for p in &self.parts {
            let path = |key: &'static str| -> ([&'static str; 2], usize) {
                if nested {
                    ([p.spec.name, key], 0)
                } else {
                    (["", key], 1)
                }
            };
            match p.spec.kind {
                PartKind::JointPos {
                    use_target: true, ..
                } => {
                    let (segs, skip) = path("target_qpos");
                    out.put_path(&segs[skip..], p.target_q.iter().map(|&x| x as f64));
                }
                PartKind::Ee {
                    use_target: true, ..
                } => {
                    let t = p.target_pose.translation.vector;
                    let q = standardize(p.target_pose.rotation);
                    let (segs, skip) = path("target_pose");
                    out.put_path(&segs[skip..], [t.x, t.y, t.z, q.w, q.i, q.j, q.k]);
                }
                _ => {}
            }
        }
    }

    /// The action range of every part, in action order (ManiSkill's `action_space` dict).
    pub fn part_ranges(&self) -> Vec<(&'static str, std::ops::Range<usize>)> {
        let mut off = 0;
        self.parts
            .iter()
            .map(|p| {
                let r = off..off + p.low.len();
                off = r.end;
                (p.spec.name, r)
            })
            .collect()
    }

    /// The controller state of ManiSkill's `get_state_dict()`: `("<part>.target_qpos",
    /// values)` / `("<part>.target_pose", [p, q])` for the parts that accumulate targets
    /// (without the part prefix when the mode has a single part).
    pub fn state_entries(&self) -> Vec<(String, Vec<f64>)> {
        let nested = self.parts.len() > 1;
        let key = |p: &Part, k: &str| {
            if nested {
                format!("{}.{k}", p.spec.name)
            } else {
                k.to_string()
            }
        };
        let mut v = Vec::new();
        for p in &self.parts {
            match p.spec.kind {
                PartKind::JointPos {
                    use_target: true, ..
                } => v.push((
                    key(p, "target_qpos"),
                    p.target_q.iter().map(|&x| x as f64).collect(),
                )),
                PartKind::Ee {
                    use_target: true, ..
                } => {
                    let t = p.target_pose.translation.vector;
                    let q = p.target_pose.rotation;
                    v.push((
                        key(p, "target_pose"),
                        vec![t.x, t.y, t.z, q.w, q.i, q.j, q.k],
                    ));
                }
                _ => {}
            }
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
        let nested = self.parts.len() > 1;
        for p in &mut self.parts {
            let key = |k: &str| {
                if nested {
                    format!("{}.{k}", p.spec.name)
                } else {
                    k.to_string()
                }
            };
            match p.spec.kind {
                PartKind::JointPos {
                    use_target: true, ..
                } => {
                    if let Some(v) = entries.get(&key("target_qpos")) {
                        for (t, &x) in p.target_q.iter_mut().zip(v) {
                            *t = x as f32;
                        }
                        for (k, &i) in p.idx.iter().enumerate() {
                            drives.set_joint_target(i, p.target_q[k] as f64, 0.0);
                        }
                        for &(fi, ci, m, o) in &p.followers {
                            let t = m * p.target_q[ci] + o;
                            drives.set_joint_target(fi, t as f64, 0.0);
                        }
                    }
                }
                PartKind::Ee {
                    use_target: true, ..
                } => {
                    if let Some(v) = entries.get(&key("target_pose")) {
                        p.target_pose = Isometry3::from_parts(
                            Translation3::new(v[0], v[1], v[2]),
                            UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                                v[3], v[4], v[5], v[6],
                            )),
                        );
                    }
                }
                _ => {}
            }
        }
    }

    /// Raw controller state for get/set_state: all targets (positions and poses).
    pub fn save(&self, out: &mut Vec<f64>) {
        for p in &self.parts {
            out.extend(p.target_q.iter().map(|&x| x as f64));
            let t = p.target_pose.translation.vector;
            let q = p.target_pose.rotation;
            out.extend_from_slice(&[t.x, t.y, t.z, q.w, q.i, q.j, q.k]);
        }
    }

    /// Number of values [`Controller::save`] writes.
    pub fn save_len(&self) -> usize {
        self.parts.iter().map(|p| p.target_q.len() + 7).sum()
    }

    /// Restores what [`Controller::save`] wrote; returns the number of values read.
    pub fn load(&mut self, s: &[f64]) -> usize {
        let mut k = 0;
        for p in &mut self.parts {
            for t in p.target_q.iter_mut() {
                *t = s[k] as f32;
                k += 1;
            }
            let v = &s[k..k + 7];
            p.target_pose = Isometry3::from_parts(
                Translation3::new(v[0], v[1], v[2]),
                UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(v[3], v[4], v[5], v[6])),
            );
            k += 7;
        }
        k
    }

    /// `reset()` of every part: targets := measured joint positions / EE pose; the drive
    /// targets are written right away (upstream writes them on the first action; identical
    /// whenever the first step carries an action).
    pub fn reset(&mut self, joints: &JointMap, data: &Data, drives: &mut Drives) {
        joints.qpos(data, &mut self.q);
        for p in &mut self.parts {
            for (t, &i) in p.target_q.iter_mut().zip(&p.idx) {
                *t = self.q[i] as f32;
            }
            if let Some(c) = &p.chain {
                p.target_pose = c.fk(&self.q);
            }
        }
        for k in 0..self.n_dof {
            let q = self.q[k];
            drives.set_joint_target(k, q, 0.0);
        }
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
            let n = p.low.len();
            let a = &action[off..off + n];
            off += n;
            match &p.spec.kind {
                PartKind::JointPos {
                    use_delta,
                    use_target,
                    normalize,
                    low,
                    high,
                } => {
                    for (k, &i) in p.idx.iter().enumerate() {
                        let x = if *normalize {
                            let lo = low
                                .as_ref()
                                .map(|l| l[k])
                                .unwrap_or(joints.limits[i].0 as f32);
                            let hi = high
                                .as_ref()
                                .map(|h| h[k])
                                .unwrap_or(joints.limits[i].1 as f32);
                            clip_scale(a[k], lo, hi)
                        } else {
                            a[k]
                        };
                        p.target_q[k] = match (*use_delta, *use_target) {
                            (true, true) => p.target_q[k] + x,
                            (true, false) => self.q[i] as f32 + x,
                            (false, _) => x,
                        };
                        drives.set_joint_target(i, p.target_q[k] as f64, 0.0);
                    }
                }
                PartKind::JointVel { low, high } => {
                    for (k, &i) in p.idx.iter().enumerate() {
                        let v = clip_scale(a[k], *low, *high);
                        drives.set_joint_target(i, p.target_q[k] as f64, v as f64);
                    }
                }
                PartKind::JointPosVel {
                    use_delta,
                    normalize,
                    pos,
                    vel,
                } => {
                    let n = p.idx.len();
                    for (k, &i) in p.idx.iter().enumerate() {
                        let (x, v) = if *normalize {
                            let (lo, hi) = joints.limits[i];
                            let x = if *use_delta {
                                clip_scale(a[k], pos.0, pos.1)
                            } else if lo.is_finite() && hi.is_finite() {
                                clip_scale(a[k], lo as f32, hi as f32)
                            } else {
                                a[k]
                            };
                            (x, clip_scale(a[n + k], vel.0, vel.1))
                        } else {
                            (a[k], a[n + k])
                        };
                        p.target_q[k] = if *use_delta { self.q[i] as f32 + x } else { x };
                        drives.set_joint_target(i, p.target_q[k] as f64, v as f64);
                    }
                }
                PartKind::Ee {
                    rotation,
                    use_delta,
                    use_target,
                    pos,
                    rot,
                    ..
                } => {
                    let chain = p.chain.as_ref().expect("EE parts have a chain");
                    let prev = if *use_target {
                        p.target_pose
                    } else {
                        chain.fk(&self.q)
                    };
                    let target = if *use_delta {
                        let dp = Vector3::new(
                            clip_scale(a[0], pos.0, pos.1) as f64,
                            clip_scale(a[1], pos.0, pos.1) as f64,
                            clip_scale(a[2], pos.0, pos.1) as f64,
                        );
                        let mut q = prev.rotation;
                        if *rotation {
                            let mut r = Vector3::new(a[3], a[4], a[5]);
                            let norm = r.norm();
                            if norm > 1.0 {
                                r /= norm;
                            }
                            r *= rot.0;
                            q = standardize(
                                euler_xyz(r.x as f64, r.y as f64, r.z as f64) * prev.rotation,
                            );
                        }
                        Isometry3::from_parts(Translation3::from(prev.translation.vector + dp), q)
                    } else {
                        let q = if *rotation {
                            euler_xyz(a[3] as f64, a[4] as f64, a[5] as f64)
                        } else {
                            prev.rotation
                        };
                        Isometry3::from_parts(
                            Translation3::new(a[0] as f64, a[1] as f64, a[2] as f64),
                            q,
                        )
                    };
                    p.target_pose = target;
                    let ok = chain.solve(&target, &self.q, &mut self.q_ik);
                    for (k, &i) in p.idx.iter().enumerate() {
                        // On IK failure the arm holds its measured position for this step.
                        let t = if ok { self.q_ik[i] } else { self.q[i] };
                        p.target_q[k] = t as f32;
                        drives.set_joint_target(i, t, 0.0);
                    }
                }
                PartKind::BaseForwardVel { lin, ang } => {
                    let v = clip_scale(a[0], lin.0, lin.1) as f64;
                    let w = clip_scale(a[1], ang.0, ang.1) as f64;
                    let theta = self.q[p.idx[2]];
                    let targets = [theta.cos() * v, theta.sin() * v, w];
                    for (k, &i) in p.idx.iter().enumerate() {
                        drives.set_joint_target(i, 0.0, targets[k]);
                    }
                }
            }
            for &(fi, ci, m, o) in &p.followers {
                let t = m * p.target_q[ci] + o;
                drives.set_joint_target(fi, t as f64, 0.0);
            }
        }
    }
}
