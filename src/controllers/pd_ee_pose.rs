//! `PDEEPosController` and `PDEEPoseController` (ManiSkill's
//! `agents/controllers/pd_ee_pose.py`): the `pd_ee_delta_pos`, `pd_ee_delta_pose`,
//! `pd_ee_target_delta_pos`, `pd_ee_target_delta_pose` and `pd_ee_pose` modes. The EE target
//! pose goes through damped-least-squares IK ([`Chain`]) to joint position targets.
use nalgebra::{Isometry3, Translation3, Vector3};

use super::ik::Chain;
use super::{
    clip_scale, euler_xyz, standardize, Drives, JointMap, PartController, PartCore, Target,
};
use crate::mujoco::Pose;

/// Configuration of an end-effector part.
#[derive(Debug, Clone, PartialEq)]
pub struct EeConfig {
    /// Include the 3 rotation entries.
    pub rotation: bool,
    /// Delta (normalised) or absolute (not normalised) targets.
    pub use_delta: bool,
    /// Accumulate on the stored target pose (exposed as `target_pose`).
    pub use_target: bool,
    /// Position bounds.
    pub pos: (f32, f32),
    /// Rotation bounds (the delta rotation is scaled by the *lower* bound, upstream).
    pub rot: (f32, f32),
    /// EE link.
    pub ee_link: &'static str,
    /// Link whose frame EE poses are expressed in (`root_link_name` upstream; None: the
    /// robot's root link).
    pub root_link: Option<&'static str>,
}

/// An end-effector position or pose part.
#[derive(Debug, Clone)]
pub struct PdEePose {
    cfg: EeConfig,
    core: PartCore,
    chain: Chain,
    /// Scratch: IK output, sized to the robot's dof.
    q_ik: Vec<f64>,
}

impl PdEePose {
    /// Builds the part on the arm joints `idx` (ManiSkill indices) with the kinematic
    /// `chain` of those joints; `n_dof` is the robot's dof.
    pub fn new(cfg: EeConfig, idx: Vec<usize>, chain: Chain, n_dof: usize) -> PdEePose {
        let k = if cfg.rotation { 6 } else { 3 };
        let (low, high) = if cfg.use_delta {
            (vec![-1.0; k], vec![1.0; k])
        } else {
            let mut l = vec![cfg.pos.0; 3];
            let mut h = vec![cfg.pos.1; 3];
            if cfg.rotation {
                l.extend([cfg.rot.0; 3]);
                h.extend([cfg.rot.1; 3]);
            }
            (l, h)
        };
        PdEePose {
            cfg,
            core: PartCore::new(idx, low, high),
            chain,
            q_ik: vec![0.0; n_dof],
        }
    }
}

impl PartController for PdEePose {
    fn core(&self) -> &PartCore {
        &self.core
    }

    fn core_mut(&mut self) -> &mut PartCore {
        &mut self.core
    }

    fn reset(&mut self, q: &[f64]) {
        self.core.reset(q);
        self.core.target_pose = self.chain.fk(q);
    }

    fn set_action(&mut self, a: &[f32], _joints: &JointMap, q: &[f64], drives: &mut Drives) {
        let cfg = &self.cfg;
        let (pos, rot) = (cfg.pos, cfg.rot);
        let prev = if cfg.use_target {
            self.core.target_pose
        } else {
            self.chain.fk(q)
        };
        let target = if cfg.use_delta {
            let dp = Vector3::new(
                clip_scale(a[0], pos.0, pos.1) as f64,
                clip_scale(a[1], pos.0, pos.1) as f64,
                clip_scale(a[2], pos.0, pos.1) as f64,
            );
            let mut r_q = prev.rotation;
            if cfg.rotation {
                let mut r = Vector3::new(a[3], a[4], a[5]);
                let norm = r.norm();
                if norm > 1.0 {
                    r /= norm;
                }
                r *= rot.0;
                r_q = standardize(euler_xyz(r.x as f64, r.y as f64, r.z as f64) * prev.rotation);
            }
            Isometry3::from_parts(Translation3::from(prev.translation.vector + dp), r_q)
        } else {
            let r_q = if cfg.rotation {
                euler_xyz(a[3] as f64, a[4] as f64, a[5] as f64)
            } else {
                prev.rotation
            };
            Isometry3::from_parts(
                Translation3::new(a[0] as f64, a[1] as f64, a[2] as f64),
                r_q,
            )
        };
        self.core.target_pose = target;
        let ok = self.chain.solve(&target, q, &mut self.q_ik);
        for (k, &i) in self.core.idx.iter().enumerate() {
            // On IK failure the arm holds its measured position for this step.
            let t = if ok { self.q_ik[i] } else { q[i] };
            self.core.target_q[k] = t as f32;
            drives.set_joint_target(i, t, 0.0);
        }
    }

    fn target(&self) -> Option<Target<'_>> {
        self.cfg
            .use_target
            .then_some(Target::Pose(self.core.target_pose))
    }

    fn restore_target(&mut self, v: &[f64], _drives: &mut Drives) {
        // Targets restored from a state dict (ManiSkill's are float32) are renormalised.
        let mut pose = [0.0; Pose::LEN];
        pose.copy_from_slice(&v[..Pose::LEN]);
        self.core.target_pose = Pose::from_array(pose).isometry_renormalized();
    }
}
