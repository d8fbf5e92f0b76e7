//! docs/solvers.md §7.1: the EE-space scripted PickCube policy (`pd_ee_delta_pos`).
//!
//! Above the cube, down to it, close for [`CLOSE_STEPS`](super::CLOSE_STEPS) steps, carry to the
//! goal at [`CARRY_SPEED`]. Positions are the robot's `tcp_pose` and the cube and goal centres,
//! read before each step. Robot-generic: the gripper commands are a parameter.
use super::body_id;
use super::{body_xyz, ee_action, tcp_xyz, Grasp, Gripper, Phases, Policy};
use crate::env::Env;
use crate::mujoco::BodyId;

/// Largest action component of the carry to the goal (×0.1 m per step): 3 cm. The cube, closed
/// on two of its edges where it lay turned to the fingers, turns in MuJoCo's grip under a carry
/// at the action's limit (10 cm a step) and stays put in PhysX's, so an episode recorded here
/// ended elsewhere in ManiSkill; carried at 3 cm a step, the two agree in 48 and 49 of 50
/// replays (seeds 0–49, 1000–1049) instead of 47 and 46 (docs/outcome-physics.md).
pub const CARRY_SPEED: f64 = 0.3;

/// The Panda's gripper action while it holds the cube: a finger target of 7.5 mm, which squeezes
/// the 2 cm half-width cube with about half the force of the fully closed −1 (−0.01 m target).
/// A cube closed on two of its vertical edges (it lay turned to the fingers) loads the wrist
/// through the pads' rims in MuJoCo's box–box contacts, and the wrist's turn (joint 7) drifts
/// in proportion to the squeeze under `pd_ee_delta_pos`, which never turns it back: fully
/// closed, it reached 0.14–0.20 rad/s by step 50 and the cube turned to a face grasp, so the
/// episode lost `is_robot_static` at its end where ManiSkill's replay held still; at −0.3 the
/// drift stays under 0.07 rad/s, and the episodes replayed in ManiSkill end the same in 50 of
/// 50 on five seed sets instead of 47–49 (docs/outcome-physics.md).
pub const PANDA_CLOSE: f32 = -0.3;

/// The PickCube policy.
#[derive(Debug)]
pub struct PickCubeSolver {
    cube: BodyId,
    goal: BodyId,
    grasp: Grasp,
    phases: Phases,
}

impl PickCubeSolver {
    /// Resolves the cube and goal bodies of a PickCube env.
    pub fn new(env: &Env, gripper: Gripper) -> Result<Self, super::SolverError> {
        Ok(PickCubeSolver {
            cube: body_id(env.model(), "cube")?,
            goal: body_id(env.model(), "goal_site")?,
            grasp: Grasp::new(gripper),
            phases: Phases::default(),
        })
    }
}

impl Policy for PickCubeSolver {
    fn reset(&mut self, _env: &Env) {
        self.phases.reset();
    }

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        let tcp = tcp_xyz(env);
        let cube = body_xyz(env, self.cube);
        let goal = body_xyz(env, self.goal);
        let grasp = self.grasp;
        let (target, grip) = self.phases.run(|phase, steps| match phase {
            0..=2 => {
                let (t, grip, done) = grasp.phase(phase, steps, cube, tcp, true);
                ((t, grip), done)
            }
            _ => ((goal, grasp.gripper.close), false),
        });
        let limit = if self.phases.phase > 2 {
            CARRY_SPEED
        } else {
            1.0
        };
        ee_action(target, tcp, limit, grip, action);
    }
}
