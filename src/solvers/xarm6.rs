//! The scripted PickCube solver for the xArm6 with the Robotiq 2F-85 (control mode
//! `pd_ee_delta_pose`).
//!
//! It runs the phases of docs/solvers.md §7.1 (above the cube, down to it, close for H steps,
//! carry to the goal) and, while approaching, turns the gripper about the vertical so that its
//! closing axis is perpendicular to a cube face (the smallest turn, at most 45°). The Robotiq's
//! closing drive is limited to 0.1 N·m (ManiSkill's force limit): a cube lying at 25–65° to the
//! pads is pinched on two vertical edges and squeezes out when lifted, whereas a face-on grasp
//! holds.
//!
//! The carry to the goal is slower than the spec's (action limit [`CARRY_LIMIT`]), so that the
//! pinched cube does not slide in the fingers.
//!
//! The rotation part of the action is scaled by upstream's rot_lower = −0.1 (docs/controllers.md §1),
//! so +1 turns −0.1 rad. The absolute gripper of this mode (docs/robots.md §4) takes 0 (open) and
//! 0.81 rad (closed) as targets.
use nalgebra::{UnitQuaternion, Vector3};

use super::body_id;
use super::{
    body_quat, body_xyz, descended, tcp_xyz, write_pos, write_rot, Grasp, Phases, Policy,
    ACTION_SCALE, XARM6_ABS_GRIPPER,
};
use crate::env::Env;
use crate::mujoco::BodyId;

/// Steps the gripper closes before lifting (the absolute target closes it in ~3 steps; the
/// delta gripper of `pd_ee_delta_pos` needs 8).
const HOLD: usize = 4;
/// Orientation tolerance before descending (rad).
const ROT_TOL: f64 = 0.03;
/// Position action limit while carrying the cube to the goal (the spec's 1): at the 0.01 s
/// step a full-speed start of the lift shakes the pinched cube in the 0.1 N·m gripper, and
/// it slides a few cm in the fingers or out of them (2 % of the episodes, seeds 0–399).
const CARRY_LIMIT: f64 = 0.7;
/// The grasp phases with the absolute gripper.
const GRASP: Grasp = Grasp {
    gripper: XARM6_ABS_GRIPPER,
    descended,
    hold: HOLD,
};

/// docs/solvers.md §7.1 for the xArm6, with the gripper turned to the cube's faces.
#[derive(Debug)]
pub struct Xarm6PickCube {
    cube: BodyId,
    goal: BodyId,
    eef: BodyId,
    pads: [BodyId; 2],
    phases: Phases,
    /// The gripper orientation to keep for this episode (world frame).
    want: UnitQuaternion<f64>,
}

impl Xarm6PickCube {
    /// Resolves the bodies of a PickCube env with the xArm6.
    pub fn new(env: &Env) -> Result<Self, super::SolverError> {
        Ok(Xarm6PickCube {
            cube: body_id(env.model(), "cube")?,
            goal: body_id(env.model(), "goal_site")?,
            eef: env.robot().body("eef")?,
            pads: [
                env.robot().body("left_inner_finger_pad")?,
                env.robot().body("right_inner_finger_pad")?,
            ],
            phases: Phases::default(),
            want: UnitQuaternion::identity(),
        })
    }
}

/// The smallest turn about the vertical (in [−45°, 45°)) that brings direction `from` (an
/// angle in the xy plane) onto one of the four directions `to` + k·90°.
pub(super) fn quarter_turn(from: f64, to: f64) -> f64 {
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
        self.phases.reset();
        // Closing axis (pad to pad) and the cube's x axis, as angles in the xy plane.
        let axis = body_xyz(env, self.pads[0]) - body_xyz(env, self.pads[1]);
        let cube_x = body_quat(env, self.cube) * Vector3::x();
        let turn = quarter_turn(axis.y.atan2(axis.x), cube_x.y.atan2(cube_x.x));
        self.want =
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), turn) * body_quat(env, self.eef);
    }

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        let tcp = tcp_xyz(env);
        let cube = body_xyz(env, self.cube);
        let goal = body_xyz(env, self.goal);
        let rot_err = (self.want * body_quat(env, self.eef).inverse()).scaled_axis();
        let ready = rot_err.norm() < ROT_TOL;
        let (target, grip, limit) = self.phases.run(|phase, steps| match phase {
            0..=2 => {
                let (t, grip, done) = GRASP.phase(phase, steps, cube, tcp, ready);
                ((t, grip, 1.0), done)
            }
            _ => ((goal, GRASP.gripper.close, CARRY_LIMIT), false),
        });
        write_pos((target - tcp) / ACTION_SCALE, limit, action);
        write_rot(rot_err, action);
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
