//! The joint/actuator map a controller works on: a robot's active joints in ManiSkill
//! (breadth-first) order resolved to qpos/dof addresses, limits and actuators of a compiled
//! model. Robots embed it (`RobotIds::joints`); controllers and drives read
//! joint state through it and nothing else.
use super::desc::{actuator_name, RobotDesc};
use crate::mujoco::{Data, Model, ObjType};

/// A robot's active joints in a compiled model, ManiSkill order.
#[derive(Debug, Clone, PartialEq)]
pub struct JointMap {
    /// qpos address of each active joint.
    pub qpos_adr: Vec<usize>,
    /// dof address of each active joint.
    pub dof_adr: Vec<usize>,
    /// Joint names.
    pub names: Vec<String>,
    /// Joint limits (±inf for continuous joints).
    pub limits: Vec<(f64, f64)>,
    /// Whether each joint is continuous (an unlimited revolute joint: targets 2π apart are
    /// the same pose).
    pub continuous: Vec<bool>,
    /// Drive actuator of each joint (None if undriven).
    pub actuator: Vec<Option<usize>>,
}

impl JointMap {
    /// Resolves the active joints of `robot` in `model`. Errors name a missing joint.
    pub fn resolve(model: &Model, robot: &RobotDesc) -> Result<JointMap, super::ControllerError> {
        let mut m = JointMap {
            qpos_adr: Vec::new(),
            dof_adr: Vec::new(),
            names: Vec::new(),
            limits: Vec::new(),
            continuous: Vec::new(),
            actuator: Vec::new(),
        };
        for j in robot.active_joints() {
            let jd = &robot.joints[j];
            let id = model.require_id(ObjType::Joint, &jd.name)?;
            m.qpos_adr.push(model.jnt_qposadr()[id] as usize);
            m.dof_adr.push(model.jnt_dofadr()[id] as usize);
            m.names.push(jd.name.clone());
            m.limits.push(jd.limits);
            m.continuous
                .push(jd.kind == super::desc::JointKind::Continuous);
            m.actuator
                .push(model.id(ObjType::Actuator, &actuator_name(&jd.name)));
        }
        Ok(m)
    }

    /// Number of active joints (the robot's dof).
    pub fn len(&self) -> usize {
        self.qpos_adr.len()
    }

    /// Reads the joint positions (ManiSkill order) into `out`.
    pub fn qpos(&self, data: &Data, out: &mut [f64]) {
        let q = data.qpos();
        for (o, &a) in out.iter_mut().zip(&self.qpos_adr) {
            *o = q[a];
        }
    }

    /// Reads the joint velocities (ManiSkill order) into `out`.
    pub fn qvel(&self, data: &Data, out: &mut [f64]) {
        let v = data.qvel();
        for (o, &a) in out.iter_mut().zip(&self.dof_adr) {
            *o = v[a];
        }
    }

    /// Writes joint positions (ManiSkill order) and zeroes the joints' velocities.
    pub fn set_qpos(&self, data: &mut Data, q: &[f64]) {
        let qp = data.qpos_mut();
        for (&a, &x) in self.qpos_adr.iter().zip(q) {
            qp[a] = x;
        }
        let qv = data.qvel_mut();
        for &a in &self.dof_adr {
            qv[a] = 0.0;
        }
    }
}
