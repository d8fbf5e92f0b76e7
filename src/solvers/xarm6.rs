//! The scripted PickCube solver for the xArm6 with the Robotiq 2F-85 (control mode
//! `pd_ee_delta_pose`).
//!
//! It runs the phases of solvers.md §7.1 (above the cube, down to it, close for H steps,
//! carry to the goal) and, while approaching, turns the gripper about the vertical so that its
//! closing axis is perpendicular to a cube face (the smallest turn, at most 45°). The Robotiq's
//! closing drive is limited to 0.1 N·m (ManiSkill's force limit): a cube lying at 25–65° to the
//! pads is pinched on two vertical edges and squeezes out when lifted, whereas a face-on grasp
//! holds.
//!
//! The rotation part of the action is scaled by upstream's rot_lower = −0.1 (controllers.md §1),
//! so +1 turns −0.1 rad. The absolute gripper of this mode (robots.md §4) takes 0 (open) and
//! 0.81 rad (closed) as targets.
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use super::{Gripper, Policy};
use crate::env::Env;
use crate::tasks::body_id;

/// The absolute gripper of `pd_ee_delta_pose`: target 0 rad opens, 0.81 rad closes.
pub const XARM6_ABS_GRIPPER: Gripper = Gripper {
    open: 0.0,
    close: 0.81,
};

/// Steps the gripper closes before lifting (the absolute target closes it in ~3 steps; the
/// delta gripper of `pd_ee_delta_pos` needs 8).
const HOLD: usize = 4;
/// Height of the approach point above the cube (m).
const APPROACH_HEIGHT: f64 = 0.05;
/// Approach and descent tolerances (m).
const APPROACH_TOL: f64 = 0.01;
const DESCEND_TOL: f64 = 0.004;
/// Orientation tolerance before descending (rad).
const ROT_TOL: f64 = 0.03;
/// Position error scale (m per unit action).
const POS_SCALE: f64 = 0.1;
/// Rotation per unit action (rad; upstream scales by rot_lower = −0.1, hence the sign).
const ROT_SCALE: f64 = -0.1;

/// solvers.md §7.1 for the xArm6, with the gripper turned to the cube's faces.
#[derive(Debug)]
pub struct Xarm6PickCube {
    cube: usize,
    goal: usize,
    eef: usize,
    pads: [usize; 2],
    phase: usize,
    steps_in_phase: usize,
    /// The gripper orientation to keep for this episode (world frame).
    want: UnitQuaternion<f64>,
}

impl Xarm6PickCube {
    /// Resolves the bodies of a PickCube env with the xArm6.
    pub fn new(env: &Env) -> Result<Self, String> {
        Ok(Xarm6PickCube {
            cube: body_id(env.model(), "cube")?,
            goal: body_id(env.model(), "goal_site")?,
            eef: env.robot().body("eef")?,
            pads: [
                env.robot().body("left_inner_finger_pad")?,
                env.robot().body("right_inner_finger_pad")?,
            ],
            phase: 0,
            steps_in_phase: 0,
            want: UnitQuaternion::identity(),
        })
    }
}

fn xyz(env: &Env, body: usize) -> Vector3<f64> {
    Vector3::from_column_slice(&env.data().xpos()[3 * body..3 * body + 3])
}

fn quat(env: &Env, body: usize) -> UnitQuaternion<f64> {
    let q = &env.data().xquat()[4 * body..4 * body + 4];
    UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]))
}

/// The smallest turn about the vertical (in [−45°, 45°)) that brings direction `from` (an
/// angle in the xy plane) onto one of the four directions `to` + k·90°.
fn quarter_turn(from: f64, to: f64) -> f64 {
    use std::f64::consts::FRAC_PI_2;
    let d = (to - from).rem_euclid(FRAC_PI_2);
    if d >= FRAC_PI_2 / 2.0 {
        d - FRAC_PI_2
    } else {
        d
    }
}

impl Policy for Xarm6PickCube {
    fn reset(&mut self, env: &Env) {
        self.phase = 0;
        self.steps_in_phase = 0;
        // Closing axis (pad to pad) and the cube's x axis, as angles in the xy plane.
        let axis = xyz(env, self.pads[0]) - xyz(env, self.pads[1]);
        let cube_x = quat(env, self.cube) * Vector3::x();
        let turn = quarter_turn(axis.y.atan2(axis.x), cube_x.y.atan2(cube_x.x));
        self.want = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), turn) * quat(env, self.eef);
    }

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        let tcp = Vector3::from(env.robot().tcp_pose(env.data()).0);
        let cube = xyz(env, self.cube);
        let goal = xyz(env, self.goal);
        let rot_err = (self.want * quat(env, self.eef).inverse()).scaled_axis();
        let (target, grip) = loop {
            let (target, grip) = match self.phase {
                0 => (
                    cube + Vector3::new(0.0, 0.0, APPROACH_HEIGHT),
                    XARM6_ABS_GRIPPER.open,
                ),
                1 => (cube, XARM6_ABS_GRIPPER.open),
                2 => (cube, XARM6_ABS_GRIPPER.close),
                _ => (goal, XARM6_ABS_GRIPPER.close),
            };
            let done = match self.phase {
                0 => (target - tcp).norm() < APPROACH_TOL && rot_err.norm() < ROT_TOL,
                1 => (target - tcp).norm() < DESCEND_TOL,
                2 => self.steps_in_phase >= HOLD,
                _ => false,
            };
            if done {
                self.phase += 1;
                self.steps_in_phase = 0;
                continue;
            }
            self.steps_in_phase += 1;
            break (target, grip);
        };
        for k in 0..3 {
            action[k] = ((target[k] - tcp[k]) / POS_SCALE).clamp(-1.0, 1.0) as f32;
        }
        let mut r = rot_err / ROT_SCALE;
        if r.norm() > 1.0 {
            r /= r.norm();
        }
        action[3..6].copy_from_slice(&[r.x as f32, r.y as f32, r.z as f32]);
        action[6] = grip;
    }
}

#[cfg(test)]
mod tests {
    use super::quarter_turn;
    use std::f64::consts::PI;

    #[test]
    fn quarter_turn_is_the_smallest_turn_onto_a_face() {
        let deg = |d: f64| d * PI / 180.0;
        for (from, to, want) in [
            (0.0, 30.0, 30.0),
            (0.0, 60.0, -30.0),
            (90.0, 10.0, 10.0),
            (-170.0, 0.0, -10.0),
            (20.0, 20.0, 0.0),
        ] {
            let got = quarter_turn(deg(from), deg(to));
            assert!((got - deg(want)).abs() < 1e-9, "{from} {to}: {got}");
        }
    }
}
