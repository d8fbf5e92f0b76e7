//! `PDJointPosVelController` (ManiSkill's `agents/controllers/pd_joint_pos_vel.py`): the
//! `pd_joint_pos_vel` and `pd_joint_delta_pos_vel` modes, n positions (absolute or delta)
//! then n velocities.
use super::{clip_scale, Drives, JointMap, PartController, PartCore};

/// Configuration of a joint position + velocity part.
#[derive(Debug, Clone, PartialEq)]
pub struct JointPosVelConfig {
    /// Positions are deltas from the measured position.
    pub use_delta: bool,
    /// Whether the action is normalised (both halves; absolute positions of unlimited
    /// joints are never normalised).
    pub normalize: bool,
    /// Delta bounds (ignored for absolute positions, whose bounds are the joint limits).
    pub pos: (f32, f32),
    /// Velocity bounds.
    pub vel: (f32, f32),
}

/// A joint position + velocity part.
#[derive(Debug, Clone)]
pub struct PdJointPosVel {
    cfg: JointPosVelConfig,
    core: PartCore,
}

impl PdJointPosVel {
    /// Builds the part on the action joints `idx` (ManiSkill indices); `limits(i)` gives the
    /// limits of joint i.
    pub fn new(
        cfg: JointPosVelConfig,
        idx: Vec<usize>,
        limits: impl Fn(usize) -> (f32, f32),
    ) -> PdJointPosVel {
        let n = idx.len();
        let use_delta = cfg.use_delta;
        let (mut low, mut high): (Vec<f32>, Vec<f32>) = if cfg.normalize {
            // Absolute positions are normalised to the joint limits; an unlimited
            // (continuous) joint's position is taken as is (upstream scales it by ±inf and
            // produces NaN targets), so its bounds stay ±inf.
            let l = idx
                .iter()
                .map(|&i| match limits(i) {
                    (lo, _) if !use_delta && !lo.is_finite() => lo,
                    _ => -1.0,
                })
                .collect();
            let h = idx
                .iter()
                .map(|&i| match limits(i) {
                    (_, hi) if !use_delta && !hi.is_finite() => hi,
                    _ => 1.0,
                })
                .collect();
            (l, h)
        } else {
            let l = idx
                .iter()
                .map(|&i| if use_delta { -1.0 } else { limits(i).0 })
                .collect();
            let h = idx
                .iter()
                .map(|&i| if use_delta { 1.0 } else { limits(i).1 })
                .collect();
            (l, h)
        };
        let (vl, vh) = if cfg.normalize { (-1.0, 1.0) } else { cfg.vel };
        low.extend(std::iter::repeat_n(vl, n));
        high.extend(std::iter::repeat_n(vh, n));
        PdJointPosVel {
            cfg,
            core: PartCore::new(idx, low, high),
        }
    }
}

impl PartController for PdJointPosVel {
    fn core(&self) -> &PartCore {
        &self.core
    }

    fn core_mut(&mut self) -> &mut PartCore {
        &mut self.core
    }

    fn set_action(&mut self, a: &[f32], joints: &JointMap, q: &[f64], drives: &mut Drives) {
        let cfg = &self.cfg;
        let core = &mut self.core;
        let n = core.idx.len();
        for (k, &i) in core.idx.iter().enumerate() {
            let (x, v) = if cfg.normalize {
                let (lo, hi) = joints.limits[i];
                let x = if cfg.use_delta {
                    clip_scale(a[k], cfg.pos.0, cfg.pos.1)
                } else if lo.is_finite() && hi.is_finite() {
                    clip_scale(a[k], lo as f32, hi as f32)
                } else {
                    a[k]
                };
                (x, clip_scale(a[n + k], cfg.vel.0, cfg.vel.1))
            } else {
                (a[k], a[n + k])
            };
            core.target_q[k] = if cfg.use_delta { q[i] as f32 + x } else { x };
            drives.set_joint_target(i, core.target_q[k] as f64, v as f64);
        }
    }
}
