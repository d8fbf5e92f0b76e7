//! docs/solvers.md §7.1: the EE-space scripted PickCube policy (`pd_ee_delta_pos`).
//!
//! Above the cube, down to it, close for [`CLOSE_STEPS`](super::CLOSE_STEPS) steps, carry to the goal. Positions
//! are the robot's `tcp_pose` and the cube and goal centres, read before each step.
//! Robot-generic: the gripper commands are a parameter.
use super::body_id;
use super::{body_xyz, ee_action, tcp_xyz, Grasp, Gripper, Phases, Policy};
use crate::env::Env;
use crate::mujoco::BodyId;

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
        ee_action(target, tcp, 1.0, grip, action);
    }
}
