//! Inverse kinematics for the end-effector controllers (docs/controllers.md §3.3).
//!
//! Kinematics come from the robot's URDF chain (root link → EE link), independent of MuJoCo,
//! as ManiSkill's Pinocchio model is built from the URDF. The solver is SAPIEN's
//! `compute_inverse_kinematics` (SAPIEN 3.0, the CLIK of Pinocchio's examples), step for step:
//! the error is Pinocchio's `log6` of the last movable joint's frame against its goal, taken in
//! that frame; the joint Jacobian in the same frame is turned into the error's through
//! `−Jlog6`; each iteration takes a tenth ([`CLIK_DT`]) of the damped least-squares step
//! ([`DAMP`]) on the masked arm joints; it stops at the first iterate whose error is under
//! [`EPS`], or after [`MAX_ITERATIONS`] steps, and returns the best iterate, failing
//! (`false`) unless it got under [`EPS`]. So a redundant arm takes the same path through its
//! null space as ManiSkill's, and the joint targets agree to float rounding (docs/physics.md,
//! "IK"). Fixed-size matrices: a solve allocates nothing.
use nalgebra::{Isometry3, Matrix3, Matrix6, Translation3, Unit, UnitQuaternion, Vector3, Vector6};

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
/// The fraction of the least-squares step an iteration takes (SAPIEN's `dt`): the error
/// contracts by about 0.9 per iteration, about 70 iterations for a 0.1 m step.
pub const CLIK_DT: f64 = 0.1;

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
    /// The movable joints, each with the fixed joints before it merged into its origin.
    movable: Vec<Movable>,
    /// The inverse of the EE frame's placement in the last movable joint's frame (the fixed
    /// joints after it).
    ee_in_joint_inv: Isometry3<f64>,
}

/// A movable joint of a [`Chain`], as the solver walks it.
#[derive(Debug, Clone)]
struct Movable {
    /// Its frame in the previous movable joint's frame (at zero motion).
    origin: Isometry3<f64>,
    axis: Unit<Vector3<f64>>,
    kind: JointKind,
    q_index: Option<usize>,
    active: bool,
}

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
        let mut movable = Vec::new();
        let mut origin = Isometry3::identity();
        for j in &rev {
            origin *= j.origin;
            if j.kind != JointKind::Fixed {
                movable.push(Movable {
                    origin,
                    axis: j.axis,
                    kind: j.kind,
                    q_index: j.q_index,
                    active: j.active,
                });
                origin = Isometry3::identity();
            }
        }
        Ok(Chain {
            joints: rev,
            movable,
            ee_in_joint_inv: origin.inverse(),
        })
    }

    fn joint_motion(j: &ChainJoint, q: f64) -> Isometry3<f64> {
        motion(j.kind, &j.axis, q)
    }

    /// EE pose in the root frame for the full robot qpos `q` (ManiSkill order).
    pub fn fk(&self, q: &[f64]) -> Isometry3<f64> {
        let mut t = Isometry3::identity();
        for j in &self.joints {
            let qv = j.q_index.map(|i| q[i]).unwrap_or(0.0);
            t = t * j.origin * Self::joint_motion(j, qv);
        }
        t
    }

    /// Solves for joint values that put the EE at `target` (root frame), starting from `q0`
    /// (full robot qpos, ManiSkill order), as SAPIEN's `compute_inverse_kinematics` does (the
    /// module docs). Writes the best iterate into `out` (same layout; only arm joints change)
    /// and returns true on success (its error under [`EPS`]).
    pub fn solve(&self, target: &Isometry3<f64>, q0: &[f64], out: &mut [f64]) -> bool {
        out.copy_from_slice(q0);
        let goal = target * self.ee_in_joint_inv;
        let n = self.movable.len();
        let mut q = [0.0; MAX_CHAIN];
        for (qk, m) in q.iter_mut().zip(&self.movable) {
            *qk = m.q_index.map(|i| q0[i]).unwrap_or(0.0);
        }
        let mut best = q;
        let mut best_err = f64::INFINITY;
        let mut success = false;
        let mut cols = [Vector6::zeros(); MAX_CHAIN];
        let mut axes = [(Vector3::zeros(), Vector3::zeros()); MAX_CHAIN];
        for it in 0..=MAX_ITERATIONS {
            // The last movable joint's frame, and every joint's origin and axis in the root.
            let mut t = Isometry3::identity();
            for (k, m) in self.movable.iter().enumerate() {
                t *= m.origin;
                axes[k] = (t.translation.vector, t.rotation * m.axis.into_inner());
                t *= motion(m.kind, &m.axis, q[k]);
            }
            // Pinocchio's `log6` of the frame's error, in the frame.
            let err_pose = t.inv_mul(&goal);
            let w = err_pose.rotation.scaled_axis();
            let err = log6(&w, &err_pose.translation.vector);
            let e = err.norm();
            if e < best_err {
                best_err = e;
                best = q;
            }
            if e < EPS {
                success = true;
                break;
            }
            if it == MAX_ITERATIONS {
                break;
            }
            // The joint Jacobian in the frame (Pinocchio's LOCAL, masked), turned into the
            // error's by J = −Jlog6(error⁻¹) J_local, a column at a time; then
            // v = −Jᵀ (J Jᵀ + damp)⁻¹ err and q += dt v.
            let (p, r_inv) = (
                t.translation.vector,
                t.rotation.inverse().to_rotation_matrix(),
            );
            let inv = err_pose.inverse();
            let jlog = jlog6(&-w, &inv.translation.vector);
            let mut jjt = Matrix6::identity() * DAMP;
            for (c, (m, (o, a))) in self.movable.iter().zip(&axes).enumerate() {
                cols[c] = if m.active {
                    let (lin, ang) = match m.kind {
                        JointKind::Prismatic => (*a, Vector3::zeros()),
                        _ => (a.cross(&(p - o)), *a),
                    };
                    let (lin, ang) = (r_inv * lin, r_inv * ang);
                    let local = Vector6::new(lin.x, lin.y, lin.z, ang.x, ang.y, ang.z);
                    -(jlog * local)
                } else {
                    Vector6::zeros()
                };
                jjt += cols[c] * cols[c].transpose();
            }
            let Some(chol) = jjt.cholesky() else { break };
            let s = chol.solve(&err);
            for (qk, col) in q.iter_mut().zip(&cols).take(n) {
                *qk -= CLIK_DT * col.dot(&s);
            }
        }
        for (m, &b) in self.movable.iter().zip(&best) {
            if let Some(i) = m.q_index {
                out[i] = b;
            }
        }
        success
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

/// The motion of a joint of `kind` about or along `axis` by `q`.
fn motion(kind: JointKind, axis: &Unit<Vector3<f64>>, q: f64) -> Isometry3<f64> {
    match kind {
        JointKind::Revolute | JointKind::Continuous => Isometry3::from_parts(
            Translation3::identity(),
            UnitQuaternion::from_axis_angle(axis, q),
        ),
        JointKind::Prismatic => Isometry3::from_parts(
            Translation3::from(axis.into_inner() * q),
            UnitQuaternion::identity(),
        ),
        JointKind::Fixed => Isometry3::identity(),
    }
}

/// The skew-symmetric (cross-product) matrix of `v`.
fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Below this angle Pinocchio's `log6` and `Jlog6` use their Taylor expansions.
const TAYLOR_ANGLE: f64 = 1e-4;

/// Pinocchio's `log6` of the pose with rotation vector `w` (its `log3`) and translation `p`:
/// [linear; angular].
fn log6(w: &Vector3<f64>, p: &Vector3<f64>) -> Vector6<f64> {
    let t2 = w.norm_squared();
    let t = t2.sqrt();
    let (alpha, beta) = if t < TAYLOR_ANGLE {
        (1.0 - t2 / 12.0 - t2 * t2 / 720.0, 1.0 / 12.0 + t2 / 720.0)
    } else {
        let (st, ct) = t.sin_cos();
        (
            t * st / (2.0 * (1.0 - ct)),
            1.0 / t2 - st / (2.0 * t * (1.0 - ct)),
        )
    };
    let v = alpha * p - 0.5 * w.cross(p) + beta * w.dot(p) * w;
    Vector6::new(v.x, v.y, v.z, w.x, w.y, w.z)
}

/// Pinocchio's `Jlog3` at rotation vector `w` of angle `t`.
fn jlog3(t: f64, w: &Vector3<f64>) -> Matrix3<f64> {
    let (alpha, diag) = if t < TAYLOR_ANGLE {
        (1.0 / 12.0 + t * t / 720.0, 0.5 * (2.0 - t * t / 6.0))
    } else {
        let (st, ct) = t.sin_cos();
        let st_1mct = st / (1.0 - ct);
        (1.0 / (t * t) - st_1mct / (2.0 * t), 0.5 * t * st_1mct)
    };
    alpha * w * w.transpose() + Matrix3::from_diagonal_element(diag) + skew(&(0.5 * w))
}

/// Pinocchio's `Jlog6` of the pose with rotation vector `w` and translation `p`:
/// `[[A, B], [0, A]]` with `A = Jlog3`.
fn jlog6(w: &Vector3<f64>, p: &Vector3<f64>) -> Matrix6<f64> {
    let t2 = w.norm_squared();
    let t = t2.sqrt();
    let a = jlog3(t, w);
    let (beta, beta_dot_over_t) = if t < TAYLOR_ANGLE {
        (1.0 / 12.0 + t2 / 720.0, 1.0 / 360.0)
    } else {
        let (tinv, t2inv) = (1.0 / t, 1.0 / t2);
        let (st, ct) = t.sin_cos();
        let inv_2_2ct = 1.0 / (2.0 * (1.0 - ct));
        (
            t2inv - st * tinv * inv_2_2ct,
            -2.0 * t2inv * t2inv + (1.0 + st * tinv) * t2inv * inv_2_2ct,
        )
    };
    let wtp = w.dot(p);
    let v = (beta_dot_over_t * wtp) * w - (t2 * beta_dot_over_t + 2.0 * beta) * p;
    let c = v * w.transpose()
        + beta * w * p.transpose()
        + Matrix3::from_diagonal_element(wtp * beta)
        + skew(&(0.5 * p));
    let mut out = Matrix6::zeros();
    out.fixed_view_mut::<3, 3>(0, 0).copy_from(&a);
    out.fixed_view_mut::<3, 3>(0, 3).copy_from(&(c * a));
    out.fixed_view_mut::<3, 3>(3, 3).copy_from(&a);
    out
}
