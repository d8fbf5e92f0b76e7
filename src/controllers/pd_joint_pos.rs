//! `PDJointPosController` and `PDJointPosMimicController` (ManiSkill's
//! `agents/controllers/pd_joint_pos.py`): absolute or delta joint position targets — the
//! `pd_joint_pos`, `pd_joint_delta_pos` and `pd_joint_target_delta_pos` arm modes and every
//! gripper — with mimic followers that track `multiplier · control + offset`.
use super::{clip_scale, Drives, JointMap, PartController, PartCore, Target};
use std::f64::consts::PI;

/// Configuration of a joint position part.
#[derive(Debug, Clone, PartialEq)]
pub struct JointPosConfig {
    /// Delta from the measured position (or from the last target with `use_target`).
    pub use_delta: bool,
    /// Accumulate on the previous target (and expose it as `target_qpos`).
    pub use_target: bool,
    /// Clip to [−1, 1] and rescale to [low, high].
    pub normalize: bool,
    /// Lower bounds per action entry (None ⇒ the joint limits).
    pub low: Option<Vec<f32>>,
    /// Upper bounds per action entry (None ⇒ the joint limits).
    pub high: Option<Vec<f32>>,
}

/// A joint position part with its mimic followers.
#[derive(Debug, Clone)]
pub struct PdJointPos {
    cfg: JointPosConfig,
    core: PartCore,
    /// (follower index, position of its control joint in the part, multiplier, offset).
    followers: Vec<(usize, usize, f32, f32)>,
}

impl JointPosConfig {
    /// The range a normalised action entry `k` (robot joint `i`) is scaled to: the explicit
    /// bounds, else the joint's limits.
    fn range(&self, k: usize, i: usize, joints: &JointMap) -> (f32, f32) {
        let lo = self
            .low
            .as_ref()
            .map(|l| l[k])
            .unwrap_or(joints.limits[i].0 as f32);
        let hi = self
            .high
            .as_ref()
            .map(|h| h[k])
            .unwrap_or(joints.limits[i].1 as f32);
        (lo, hi)
    }
}

impl PdJointPos {
    /// Builds the part on the action joints `idx` (ManiSkill indices); `limits(i)` gives the
    /// limits of joint i, the bounds of a part that is not normalised and has no explicit
    /// bounds.
    pub fn new(
        cfg: JointPosConfig,
        idx: Vec<usize>,
        followers: Vec<(usize, usize, f32, f32)>,
        limits: impl Fn(usize) -> (f32, f32),
    ) -> PdJointPos {
        let n = idx.len();
        let (low, high) = if cfg.normalize {
            (vec![-1.0; n], vec![1.0; n])
        } else {
            let l = cfg
                .low
                .clone()
                .unwrap_or_else(|| idx.iter().map(|&i| limits(i).0).collect());
            let h = cfg
                .high
                .clone()
                .unwrap_or_else(|| idx.iter().map(|&i| limits(i).1).collect());
            (l, h)
        };
        PdJointPos {
            cfg,
            core: PartCore::new(idx, low, high),
            followers,
        }
    }

    fn drive_followers(&self, drives: &mut Drives) {
        for &(fi, ci, m, o) in &self.followers {
            let t = m * self.core.target_q[ci] + o;
            drives.set_joint_target(fi, t as f64, 0.0);
        }
    }
}

impl PartController for PdJointPos {
    fn core(&self) -> &PartCore {
        &self.core
    }

    fn core_mut(&mut self) -> &mut PartCore {
        &mut self.core
    }

    fn drive_joints(&self, out: &mut Vec<usize>) {
        out.extend_from_slice(&self.core.idx);
        out.extend(self.followers.iter().map(|f| f.0));
    }

    fn set_action(&mut self, a: &[f32], joints: &JointMap, q: &[f64], drives: &mut Drives) {
        let cfg = &self.cfg;
        let core = &mut self.core;
        for (k, &i) in core.idx.iter().enumerate() {
            let x = if cfg.normalize {
                let (lo, hi) = cfg.range(k, i, joints);
                clip_scale(a[k], lo, hi)
            } else {
                a[k]
            };
            core.target_q[k] = match (cfg.use_delta, cfg.use_target) {
                (true, true) => core.target_q[k] + x,
                (true, false) => q[i] as f32 + x,
                (false, _) => x,
            };
            drives.set_joint_target(i, core.target_q[k] as f64, 0.0);
        }
        self.drive_followers(drives);
    }

    fn target(&self) -> Option<Target<'_>> {
        self.cfg
            .use_target
            .then_some(Target::Qpos(&self.core.target_q))
    }

    fn action_for_targets(
        &self,
        target: &dyn Fn(usize) -> Option<f64>,
        joints: &JointMap,
        q: &[f64],
        out: &mut [f32],
    ) -> bool {
        let cfg = &self.cfg;
        let core = &self.core;
        for (k, &i) in core.idx.iter().enumerate() {
            let Some(t) = target(i) else {
                return false;
            };
            // A continuous joint's target is taken within half a turn of the joint: the same
            // pose, reached the short way (an IK that wandered off by thousands of radians
            // would otherwise spin the joint for seconds).
            let t = if joints.continuous[i] {
                q[i] + (t - q[i] + PI).rem_euclid(2.0 * PI) - PI
            } else {
                t
            };
            let x = match (cfg.use_delta, cfg.use_target) {
                (true, true) => t - core.target_q[k] as f64,
                (true, false) => t - q[i],
                (false, _) => t,
            };
            out[k] = if cfg.normalize {
                // The inverse of `clip_scale`, clipped to [−1, 1].
                let (lo, hi) = cfg.range(k, i, joints);
                let (mid, half) = (0.5 * (hi as f64 + lo as f64), 0.5 * (hi as f64 - lo as f64));
                (((x - mid) / half) as f32).clamp(-1.0, 1.0)
            } else {
                (x as f32).clamp(core.low[k], core.high[k])
            };
        }
        true
    }

    fn restore_target(&mut self, v: &[f64], drives: &mut Drives) {
        for (t, &x) in self.core.target_q.iter_mut().zip(v) {
            *t = x as f32;
        }
        for (k, &i) in self.core.idx.iter().enumerate() {
            drives.set_joint_target(i, self.core.target_q[k] as f64, 0.0);
        }
        self.drive_followers(drives);
    }
}

#[cfg(test)]
mod tests {
    use std::f64::consts::PI;

    use super::{JointPosConfig, PartController, PdJointPos};
    use crate::controllers::JointMap;

    /// Joint 0 continuous, joint 1 a limited revolute joint.
    fn joints() -> JointMap {
        JointMap {
            qpos_adr: vec![0, 1],
            dof_adr: vec![0, 1],
            names: vec!["roll".into(), "flex".into()],
            limits: vec![(f64::NEG_INFINITY, f64::INFINITY), (-2.0, 2.0)],
            continuous: vec![true, false],
            actuator: vec![None, None],
        }
    }

    fn part(use_delta: bool) -> PdJointPos {
        let cfg = JointPosConfig {
            use_delta,
            use_target: false,
            normalize: false,
            low: use_delta.then(|| vec![-1e3, -1e3]),
            high: use_delta.then(|| vec![1e3, 1e3]),
        };
        let limits = |i: usize| {
            let (lo, hi) = joints().limits[i];
            (lo as f32, hi as f32)
        };
        PdJointPos::new(cfg, vec![0, 1], Vec::new(), limits)
    }

    #[test]
    fn a_continuous_joints_target_is_converted_within_half_a_turn_of_the_joint() {
        let q = [0.3, 0.3];
        // An IK that wandered off: 1.3e5 rad on both joints.
        let wild = 132228.81;
        let target = |_: usize| Some(wild);
        let mut out = [0.0f32; 2];
        assert!(part(false).action_for_targets(&target, &joints(), &q, &mut out));
        let same_pose = (wild - out[0] as f64).rem_euclid(2.0 * PI);
        assert!(
            (out[0] as f64 - q[0]).abs() <= PI && (same_pose.min(2.0 * PI - same_pose)) < 1e-2,
            "{out:?}"
        );
        // A limited joint's target is what the source set (clipped to its bounds, as before).
        assert_eq!(out[1], 2.0);
        // A target within half a turn is kept as it is; deltas are taken the short way too.
        let near = |_: usize| Some(0.3 + 3.0);
        assert!(part(false).action_for_targets(&near, &joints(), &q, &mut out));
        assert!((out[0] as f64 - 3.3).abs() < 1e-6, "{out:?}");
        assert!(part(true).action_for_targets(&target, &joints(), &q, &mut out));
        assert!((out[0] as f64).abs() <= PI, "{out:?}");
    }
}
