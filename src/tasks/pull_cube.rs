//! PullCube-v1 (docs/tasks.md §7): pull a blue cube back (−x, towards the robot) into a
//! red/white goal region lying on the table; the gripper hooks the cube from its far side.
//!
//! The scene and the spawn draw are PushCube-v1's ([`add_cube`], [`spawn_cube`]); the goal lies
//! behind the cube instead of ahead of it. The goal region is a visual-only mocap body, as in
//! PushCube. Robot-generic: `agent.tcp` is the robot's TCP link.
//!
//! Upstream differences from PushCube kept: `goal_pos` is in the observation in every obs
//! mode; success does not require the cube to stay on the table; the dense reward has no
//! height term.
use nalgebra::Vector3;

use super::push_cube::{
    add_cube, goal_at, spawn_cube, ABSENT_GRASP_FLAG, CUBE_HALF_SIZE, GOAL_RADIUS,
};
use super::{
    add_cameras, body_id, closeness, free_joint_qpos, red_white_target, set_free_pose,
    set_mocap_pose, tabletop_cameras, CameraDef, ObsWriter, Task, TaskCtx, TARGET_QUAT,
};
use crate::mjcf::Scene;
use crate::mujoco::{BodyId, Data, MjError, Model};
use crate::rng::TorchGenerator;

// ---- constants (docs/tasks.md §7) ---------------------------------------------------------------
/// Maximum dense reward.
pub const MAX_REWARD: f64 = 3.0;
/// Distance along −x from the cube's spawn point to the goal's centre (m): `0.1 + goal_radius`.
pub const GOAL_OFFSET: f64 = 0.1 + GOAL_RADIUS;
/// The pull pose is this far beyond the cube's far (+x) face (m): upstream's `2 * 0.005`.
const PULL_GAP: f64 = 2.0 * 0.005;
/// `reached`: TCP-to-pull-pose distance (m).
const REACHED_DIST: f64 = 0.01;

evaluation! {
    /// PullCube's `evaluate()`.
    pub struct PullCubeEval {
        /// The cube's centre is within the goal region (xy).
        success: bool,
    }
}

/// PullCube-v1.
#[derive(Debug, Clone, Default)]
pub struct PullCube {
    cube: BodyId,
    cube_qadr: usize,
    goal: BodyId,
}

impl PullCube {
    /// The task (panda and fetch share every constant).
    pub fn new() -> Self {
        Self::default()
    }

    /// The pull pose: just beyond the cube's far (+x) face, at the cube's centre height.
    pub fn pull_pos(cube: Vector3<f64>) -> Vector3<f64> {
        cube + Vector3::new(CUBE_HALF_SIZE + PULL_GAP, 0.0, 0.0)
    }

    /// `evaluate()`, typed.
    pub fn eval(&self, ctx: &TaskCtx) -> PullCubeEval {
        let (cube, goal) = (ctx.body_pos(self.cube), ctx.body_pos(self.goal));
        PullCubeEval {
            success: (cube.xy() - goal.xy()).norm() < GOAL_RADIUS,
        }
    }
}

impl Task for PullCube {
    fn max_reward(&self) -> f64 {
        MAX_REWARD
    }

    // ---- scene (build order: cube, goal_region) ------------------------------------------
    fn build(&self, scene: &mut Scene) {
        add_cube(scene);
        // Not hidden: the sensor camera sees the target.
        scene.add_marker_target("goal_region", &red_white_target(GOAL_RADIUS));
        add_cameras(scene, self.cameras());
    }

    fn resolve(&mut self, model: &Model) -> Result<(), MjError> {
        self.cube = body_id(model, "cube")?;
        self.cube_qadr = free_joint_qpos(model, "cube")?;
        self.goal = body_id(model, "goal_region")?;
        Ok(())
    }

    fn grasp_object(&self) -> BodyId {
        self.cube
    }

    // ---- episode initialisation (torch draws: rand(2)) -----------------------------------
    fn initialize_episode(&mut self, data: &mut Data, torch: &mut TorchGenerator) {
        let cube = spawn_cube(torch);
        let goal = goal_at(cube, -GOAL_OFFSET);
        set_free_pose(
            data,
            self.cube_qadr,
            cube.map(f64::from),
            [1.0, 0.0, 0.0, 0.0],
        );
        let model = data.model().clone();
        set_mocap_pose(&model, data, self.goal, goal, TARGET_QUAT);
    }

    // ---- evaluate ------------------------------------------------------------------------
    fn info_keys(&self) -> &'static [&'static str] {
        PullCubeEval::KEYS
    }

    fn evaluate(&self, ctx: &TaskCtx, info: &mut [f64]) {
        self.eval(ctx).write(info);
    }

    // ---- observation extras ------------------------------------------------------------------
    fn observe_extra(&self, ctx: &TaskCtx, _info: &[f64], state: bool, out: &mut ObsWriter) {
        let (tcp, tcp_q) = ctx.tcp_link_pose();
        out.pose("tcp_pose", tcp, tcp_q);
        out.vec3("goal_pos", ctx.body_pos(self.goal));
        if state {
            out.pose(
                "obj_pose",
                ctx.body_pos(self.cube),
                ctx.body_quat(self.cube),
            );
        }
    }

    // ---- dense reward (max 3) ------------------------------------------------------------------
    fn dense_reward(&self, ctx: &TaskCtx, info: &[f64]) -> f64 {
        if PullCubeEval::read(info).success {
            return MAX_REWARD;
        }
        let (tcp, _) = ctx.tcp_link_pose();
        let (cube, goal) = (ctx.body_pos(self.cube), ctx.body_pos(self.goal));
        // Reaching the pull pose beyond the cube, then the cube towards the goal (xy).
        let d = (Self::pull_pos(cube) - tcp).norm();
        let reached = (d < REACHED_DIST) as u8 as f64;
        closeness(d) + closeness((cube.xy() - goal.xy()).norm()) * reached
    }

    /// PullCube reports no grasp flag ([`ABSENT_GRASP_FLAG`]).
    fn grasp_flag(&self) -> &'static str {
        ABSENT_GRASP_FLAG
    }

    fn actor_names(&self) -> &'static [&'static str] {
        &["cube", "goal_region"]
    }

    fn cameras(&self) -> (CameraDef, CameraDef) {
        tabletop_cameras(
            ([-0.5, 0.0, 0.25], [0.2, 0.0, -0.5]),
            ([0.6, 0.7, 0.6], [0.0, 0.0, 0.35]),
        )
    }
}
