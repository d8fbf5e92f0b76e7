//! `PDJointVelController` (ManiSkill's `agents/controllers/pd_joint_vel.py`): the
//! `pd_joint_vel` mode, normalised velocity targets on a pure velocity drive (stiffness 0).
use super::{clip_scale, Drives, JointMap, PartController, PartCore};

/// Configuration of a joint velocity part.
#[derive(Debug, Clone, PartialEq)]
pub struct JointVelConfig {
    /// Lower velocity bound.
    pub low: f32,
    /// Upper velocity bound.
    pub high: f32,
}

/// A joint velocity part.
#[derive(Debug, Clone)]
pub struct PdJointVel {
    cfg: JointVelConfig,
    core: PartCore,
}

impl PdJointVel {
    /// Builds the part on the action joints `idx` (ManiSkill indices).
    pub fn new(cfg: JointVelConfig, idx: Vec<usize>) -> PdJointVel {
        let n = idx.len();
        PdJointVel {
            cfg,
            core: PartCore::new(idx, vec![-1.0; n], vec![1.0; n]),
        }
    }
}

impl PartController for PdJointVel {
    fn core(&self) -> &PartCore {
        &self.core
    }

    fn core_mut(&mut self) -> &mut PartCore {
        &mut self.core
    }

    fn gains(&self, gains: (f64, f64, f64)) -> (f64, f64, f64) {
        (0.0, gains.1, gains.2)
    }

    fn set_action(&mut self, a: &[f32], _joints: &JointMap, _q: &[f64], drives: &mut Drives) {
        for (k, &i) in self.core.idx.iter().enumerate() {
            let v = clip_scale(a[k], self.cfg.low, self.cfg.high);
            drives.set_joint_target(i, self.core.target_q[k] as f64, v as f64);
        }
    }
}
