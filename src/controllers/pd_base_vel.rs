//! `PDBaseForwardVelController` (ManiSkill's `agents/controllers/pd_base_vel.py`, Fetch's
//! base): [forward speed, yaw rate] → velocity targets of the virtual x, y, yaw joints.
use super::{clip_scale, ControllerError, Drives, JointMap, PartController, PartCore};

/// Configuration of a forward-velocity base part.
#[derive(Debug, Clone, PartialEq)]
pub struct BaseForwardVelConfig {
    /// Forward-speed bounds.
    pub lin: (f32, f32),
    /// Yaw-rate bounds.
    pub ang: (f32, f32),
}

/// A forward-velocity base part on the virtual (x, y, yaw) joints.
#[derive(Debug, Clone)]
pub struct PdBaseForwardVel {
    cfg: BaseForwardVelConfig,
    core: PartCore,
}

impl PdBaseForwardVel {
    /// Builds the part on the three virtual joints `idx` = [x, y, yaw] (ManiSkill indices).
    /// Errors unless there are exactly three.
    pub fn new(
        cfg: BaseForwardVelConfig,
        idx: Vec<usize>,
    ) -> Result<PdBaseForwardVel, ControllerError> {
        if idx.len() != 3 {
            return Err(ControllerError::BaseJoints(idx.len()));
        }
        Ok(PdBaseForwardVel {
            cfg,
            core: PartCore::new(idx, vec![-1.0; 2], vec![1.0; 2]),
        })
    }
}

impl PartController for PdBaseForwardVel {
    fn core(&self) -> &PartCore {
        &self.core
    }

    fn core_mut(&mut self) -> &mut PartCore {
        &mut self.core
    }

    fn set_action(&mut self, a: &[f32], _joints: &JointMap, q: &[f64], drives: &mut Drives) {
        let (lin, ang) = (self.cfg.lin, self.cfg.ang);
        let v = clip_scale(a[0], lin.0, lin.1) as f64;
        let w = clip_scale(a[1], ang.0, ang.1) as f64;
        let theta = q[self.core.idx[2]];
        let targets = [theta.cos() * v, theta.sin() * v, w];
        for (k, &i) in self.core.idx.iter().enumerate() {
            drives.set_joint_target(i, 0.0, targets[k]);
        }
    }
}
