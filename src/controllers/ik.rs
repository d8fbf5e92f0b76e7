//! Inverse kinematics for the end-effector controllers (docs/controllers.md §3.3).
//!
//! Kinematics come from the robot's URDF chain (root link → EE link), independent of MuJoCo,
//! as ManiSkill's Pinocchio model is built from the URDF. The solver is damped least squares
//! on the masked arm joints, like SAPIEN's `compute_inverse_kinematics` (eps 1e-4, damping
//! 1e-6, at most 100 iterations, the best evaluated q is returned, failure ⇒ `None`), with one
//! documented difference: SAPIEN scales each update by dt = 0.1 (≈ 0.9 contraction per
//! iteration) and stops at the first iterate under eps, mjskill takes full Gauss–Newton steps
//! (a few iterations instead of ~70). They do not stop at the same point: SAPIEN's keeps a
//! residual just under eps along the first error, and a redundant arm's small steps take
//! another path through its null space. Tried both ways on 50 Panda PickCube episodes, the
//! outcome agreement with ManiSkill was the same (docs/outcome-physics.md). The error is the
//! 6-vector [Δp; rotation vector] in the root frame. Fixed-size matrices: a solve allocates
//! nothing.
use nalgebra::{Isometry3, Matrix6, SMatrix, Translation3, Unit, UnitQuaternion, Vector3, Vector6};

use super::desc::{JointKind, RobotDesc};
use super::ControllerError;

/// Maximum number of joints in a chain.
pub const MAX_CHAIN: usize = 10;
/// Convergence threshold on ‖error‖.
pub const EPS: f64 = 1e-4;
/// Maximum iterations.
pub const MAX_ITERATIONS: usize = 100;
/// Damping of the least-squares solve.
pub const DAMP: f64 = 1e-6;

#[derive(Debug, Clone)]
struct ChainJoint {
    name: String,
    origin: Isometry3<f64>,
    axis: Unit<Vector3<f64>>,
    kind: JointKind,
    /// Index of this joint in ManiSkill's qpos order (None for fixed joints).
    q_index: Option<usize>,
    /// Whether the IK may move it.
    active: bool,
    /// Joint limits (read by the tests).
    #[cfg_attr(not(test), allow(dead_code))]
    limits: (f64, f64),
}

/// A serial chain from a root link (the robot's root link unless given) to an end-effector
/// link. EE poses are expressed in the root link's frame.
#[derive(Debug, Clone)]
pub struct Chain {
    joints: Vec<ChainJoint>,
    /// Transform from the last chain link to the EE frame (identity unless offset).
    tip: Isometry3<f64>,
}

type Jac = SMatrix<f64, 6, MAX_CHAIN>;

impl Chain {
    /// The chain from the root link of `robot` to `ee_link`, where `arm` lists the joints the
    /// solver may move (ManiSkill indices are taken from `robot.active_joints()`).
    pub fn new(robot: &RobotDesc, ee_link: &str, arm: &[&str]) -> Result<Chain, ControllerError> {
        Chain::from_root(robot, None, ee_link, arm)
    }

    /// The chain from `root_link` (None: the robot's root link) to `ee_link`; EE poses are
    /// then relative to `root_link` (ManiSkill's `root_link_name`, e.g. Fetch's
    /// `torso_lift_link`). Errors if `root_link` is not an ancestor of `ee_link`.
    pub fn from_root(
        robot: &RobotDesc,
        root_link: Option<&str>,
        ee_link: &str,
        arm: &[&str],
    ) -> Result<Chain, ControllerError> {
        let mut link = robot
            .link(ee_link)
            .ok_or_else(|| ControllerError::NoLink(ee_link.to_string()))?;
        let root = match root_link {
            Some(r) => robot
                .link(r)
                .ok_or_else(|| ControllerError::NoIkRoot(r.to_string()))?,
            None => robot.root,
        };
        let active_order = robot.active_joints();
        let mut rev = Vec::new();
        while link != root {
            let Some(j) = robot.parent_joint(link) else {
                return Err(ControllerError::NotAncestor {
                    root: robot.links[root].name.clone(),
                    ee: ee_link.to_string(),
                });
            };
            let jd = &robot.joints[j];
            let q_index = active_order.iter().position(|&a| a == j);
            rev.push(ChainJoint {
                name: jd.name.clone(),
                origin: jd.origin,
                axis: Unit::new_normalize(jd.axis),
                kind: jd.kind,
                q_index,
                active: arm.contains(&jd.name.as_str()),
                limits: jd.limits,
            });
            link = jd.parent;
        }
        rev.reverse();
        let movable = rev.iter().filter(|j| j.kind != JointKind::Fixed).count();
        if movable > MAX_CHAIN {
            return Err(ControllerError::ChainTooLong {
                ee: ee_link.to_string(),
                movable,
                max: MAX_CHAIN,
            });
        }
        for a in arm {
            if !rev.iter().any(|j| j.name == *a) {
                return Err(ControllerError::OffChain {
                    joint: a.to_string(),
                    ee: ee_link.to_string(),
                });
            }
        }
        Ok(Chain {
            joints: rev,
            tip: Isometry3::identity(),
        })
    }

    fn joint_motion(j: &ChainJoint, q: f64) -> Isometry3<f64> {
        match j.kind {
            JointKind::Revolute | JointKind::Continuous => Isometry3::from_parts(
                Translation3::identity(),
                UnitQuaternion::from_axis_angle(&j.axis, q),
            ),
            JointKind::Prismatic => Isometry3::from_parts(
                Translation3::from(j.axis.into_inner() * q),
                UnitQuaternion::identity(),
            ),
            JointKind::Fixed => Isometry3::identity(),
        }
    }

    /// EE pose in the root frame for the full robot qpos `q` (ManiSkill order).
    pub fn fk(&self, q: &[f64]) -> Isometry3<f64> {
        let mut t = Isometry3::identity();
        for j in &self.joints {
            let qv = j.q_index.map(|i| q[i]).unwrap_or(0.0);
            t = t * j.origin * Self::joint_motion(j, qv);
        }
        t * self.tip
    }

    /// EE pose and the geometric Jacobian (root frame; rows [linear; angular]; columns in
    /// chain order, zero for masked joints).
    fn fk_jac(&self, q: &[f64], jac: &mut Jac) -> Isometry3<f64> {
        // Joint frames and axes in the root frame.
        let mut t = Isometry3::identity();
        let mut axes = [(Vector3::zeros(), Vector3::zeros(), JointKind::Fixed, false); MAX_CHAIN];
        let mut n = 0;
        for j in &self.joints {
            let qv = j.q_index.map(|i| q[i]).unwrap_or(0.0);
            t *= j.origin;
            if j.kind != JointKind::Fixed {
                axes[n] = (
                    t.translation.vector,
                    t.rotation * j.axis.into_inner(),
                    j.kind,
                    j.active,
                );
                n += 1;
            }
            t *= Self::joint_motion(j, qv);
        }
        let ee = t * self.tip;
        jac.fill(0.0);
        let p = ee.translation.vector;
        for (c, (o, a, kind, active)) in axes.iter().take(n).enumerate() {
            if !active {
                continue;
            }
            let (lin, ang) = match kind {
                JointKind::Prismatic => (*a, Vector3::zeros()),
                _ => (a.cross(&(p - o)), *a),
            };
            jac.fixed_view_mut::<3, 1>(0, c).copy_from(&lin);
            jac.fixed_view_mut::<3, 1>(3, c).copy_from(&ang);
        }
        ee
    }

    /// Solves for joint values that put the EE at `target` (root frame), starting from `q0`
    /// (full robot qpos, ManiSkill order). Writes the solution into `out` (same layout; only
    /// arm joints change) and returns true on success (‖error‖ < [`EPS`]).
    pub fn solve(&self, target: &Isometry3<f64>, q0: &[f64], out: &mut [f64]) -> bool {
        out.copy_from_slice(q0);
        let mut jac = Jac::zeros();
        let mut best_err = f64::INFINITY;
        let mut best = [0.0; MAX_CHAIN];
        for it in 0..=MAX_ITERATIONS {
            let ee = self.fk_jac(out, &mut jac);
            let dp = target.translation.vector - ee.translation.vector;
            let dr = (target.rotation * ee.rotation.inverse()).scaled_axis();
            let err = Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z);
            let e = err.norm();
            if e < best_err {
                best_err = e;
                self.gather(out, &mut best);
            }
            if e < EPS || it == MAX_ITERATIONS {
                break;
            }
            let jjt: Matrix6<f64> = jac * jac.transpose() + Matrix6::identity() * DAMP;
            let Some(chol) = jjt.cholesky() else { break };
            let dq = jac.transpose() * chol.solve(&err);
            let mut c = 0;
            for j in &self.joints {
                if j.kind == JointKind::Fixed {
                    continue;
                }
                if j.active {
                    if let Some(i) = j.q_index {
                        out[i] += dq[c];
                    }
                }
                c += 1;
            }
        }
        self.scatter(&best, out);
        best_err < EPS
    }

    fn gather(&self, q: &[f64], buf: &mut [f64; MAX_CHAIN]) {
        for (b, j) in buf
            .iter_mut()
            .zip(self.joints.iter().filter(|j| j.kind != JointKind::Fixed))
        {
            *b = j.q_index.map(|i| q[i]).unwrap_or(0.0);
        }
    }

    fn scatter(&self, buf: &[f64; MAX_CHAIN], q: &mut [f64]) {
        for (b, j) in buf
            .iter()
            .zip(self.joints.iter().filter(|j| j.kind != JointKind::Fixed))
        {
            if let Some(i) = j.q_index {
                q[i] = *b;
            }
        }
    }

    /// Joint limits of the movable chain joints (for tests).
    #[cfg(test)]
    pub fn limits(&self) -> Vec<(f64, f64)> {
        self.joints
            .iter()
            .filter(|j| j.kind != JointKind::Fixed)
            .map(|j| j.limits)
            .collect()
    }
}
