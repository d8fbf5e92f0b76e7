//! PushCube-v1 (docs/tasks.md §6): push a blue cube forward (+x, away from the robot) into a
//! red/white goal region lying on the table.
//!
//! Robot-generic, as upstream (panda and fetch share every constant): `agent.tcp` is the
//! robot's TCP link (panda `panda_hand_tcp`, fetch `gripper_link`).
//!
//! The goal region is a visual-only mocap body (no collision), addressed by its body: position
//! (cube.x + [`GOAL_OFFSET`], cube.y, [`TARGET_Z`]) and quaternion [`TARGET_QUAT`], as upstream
//! sets its kinematic actor. Only its position enters the observation, `evaluate()` and the
//! reward.
//!
//! Upstream quirk kept: the observation's `goal_pos` is a privileged (state-only) key here,
//! while PullCube-v1 gives it in every obs mode.
//!
//! The cube and its spawn draw are shared with PullCube-v1 ([`add_cube`], [`spawn_cube`]):
//! upstream builds the same cube and draws its position the same way in both tasks.
use nalgebra::Vector3;

use super::{
    add_cameras, body_id, closeness, free_joint_qpos, red_white_target, set_free_pose,
    set_mocap_pose, tabletop_cameras, CameraDef, ObsWriter, Task, TaskCtx, TARGET_QUAT, TARGET_Z,
};
use crate::mjcf::props::Rgba;
use crate::mjcf::Scene;
use crate::mujoco::{BodyId, Data, MjError, Model};
use crate::rng::TorchGenerator;

// ---- constants (docs/tasks.md §6) ---------------------------------------------------------------
/// Maximum dense reward.
pub const MAX_REWARD: f64 = 4.0;
/// Cube half edge (m).
pub const CUBE_HALF_SIZE: f64 = 0.02;
/// Cube colour: (12, 42, 160)/255.
pub const CUBE_RGBA: Rgba = [12.0 / 255.0, 42.0 / 255.0, 160.0 / 255.0, 1.0];
/// Radius of the goal region, and of success (m).
pub const GOAL_RADIUS: f64 = 0.1;
/// Half size of the square the cube's xy is drawn from, centred at the origin (m).
pub const SPAWN_HALF_SIZE: f64 = 0.1;
/// Distance along +x from the cube's spawn point to the goal's centre (m): `0.1 + goal_radius`.
pub const GOAL_OFFSET: f64 = 0.1 + GOAL_RADIUS;
/// Success also needs the cube's centre below `CUBE_HALF_SIZE` + this (m): still on the table.
const ON_TABLE_TOL: f64 = 5e-3;
/// The push pose is this far behind the cube's back face (m).
const PUSH_GAP: f64 = 0.005;
/// `reached`: TCP-to-push-pose distance (m).
const REACHED_DIST: f64 = 0.01;
/// What PushCube and PullCube answer for the grasp flag they do not report: a key absent from
/// their `info`, so the env's grasp queries read false.
pub const ABSENT_GRASP_FLAG: &str = "is_grasped";

evaluation! {
    /// PushCube's `evaluate()`.
    pub struct PushCubeEval {
        /// The cube's centre is within the goal region (xy) and the cube is on the table.
        success: bool,
    }
}

/// Adds the cube (a free body named `cube`) to the scene at its upstream build pose.
pub fn add_cube(scene: &mut Scene) {
    let h = CUBE_HALF_SIZE;
    scene.add_box("cube", [h; 3], CUBE_RGBA, [0.0, 0.0, h]);
}

/// Draws the cube's spawn position as upstream, in float32: one `torch.rand(2)`, xy =
/// u·0.2 − 0.1, z = the half size.
pub fn spawn_cube(torch: &mut TorchGenerator) -> [f32; 3] {
    let mut u = [0f32; 2];
    torch.fill_rand(&mut u);
    let (scale, shift) = ((2.0 * SPAWN_HALF_SIZE) as f32, SPAWN_HALF_SIZE as f32);
    [
        u[0] * scale - shift,
        u[1] * scale - shift,
        CUBE_HALF_SIZE as f32,
    ]
}

/// The goal's position `cube + (dx, 0, 0)` with z := [`TARGET_Z`], computed in float32 as upstream.
pub fn goal_at(cube: [f32; 3], dx: f64) -> [f64; 3] {
    [
        (cube[0] + dx as f32) as f64,
        cube[1] as f64,
        TARGET_Z as f32 as f64,
    ]
}

/// PushCube-v1.
#[derive(Debug, Clone, Default)]
pub struct PushCube {
    cube: BodyId,
    cube_qadr: usize,
    goal: BodyId,
}

impl PushCube {
    /// The task (panda and fetch share every constant).
    pub fn new() -> Self {
        Self::default()
    }

    /// The push pose: just behind the cube's back (−x) face, at the cube's centre height.
    pub fn push_pos(cube: Vector3<f64>) -> Vector3<f64> {
        cube - Vector3::new(CUBE_HALF_SIZE + PUSH_GAP, 0.0, 0.0)
    }

    /// `evaluate()`, typed.
    pub fn eval(&self, ctx: &TaskCtx) -> PushCubeEval {
        let (cube, goal) = (ctx.body_pos(self.cube), ctx.body_pos(self.goal));
        let in_goal = (cube.xy() - goal.xy()).norm() < GOAL_RADIUS;
        PushCubeEval {
            success: in_goal && cube.z < CUBE_HALF_SIZE + ON_TABLE_TOL,
        }
    }
}

impl Task for PushCube {
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
        let goal = goal_at(cube, GOAL_OFFSET);
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
        PushCubeEval::KEYS
    }

    fn evaluate(&self, ctx: &TaskCtx, info: &mut [f64]) {
        self.eval(ctx).write(info);
    }

    // ---- observation extras ------------------------------------------------------------------
    fn observe_extra(&self, ctx: &TaskCtx, _info: &[f64], state: bool, out: &mut ObsWriter) {
        let (tcp, tcp_q) = ctx.tcp_link_pose();
        out.pose("tcp_pose", tcp, tcp_q);
        if state {
            out.vec3("goal_pos", ctx.body_pos(self.goal));
            out.pose(
                "obj_pose",
                ctx.body_pos(self.cube),
                ctx.body_quat(self.cube),
            );
        }
    }

    // ---- dense reward (max 4) ------------------------------------------------------------------
    fn dense_reward(&self, ctx: &TaskCtx, info: &[f64]) -> f64 {
        if PushCubeEval::read(info).success {
            return MAX_REWARD;
        }
        let (tcp, _) = ctx.tcp_link_pose();
        let (cube, goal) = (ctx.body_pos(self.cube), ctx.body_pos(self.goal));
        // Reaching the push pose behind the cube.
        let d = (Self::push_pos(cube) - tcp).norm();
        let reached = (d < REACHED_DIST) as u8 as f64;
        // Once there: the cube towards the goal's centre (xy), and kept on the table.
        let place = closeness((cube.xy() - goal.xy()).norm());
        let on_table = closeness((cube.z - CUBE_HALF_SIZE).abs());
        closeness(d) + place * reached + place * on_table * reached
    }

    /// PushCube reports no grasp flag ([`ABSENT_GRASP_FLAG`]).
    fn grasp_flag(&self) -> &'static str {
        ABSENT_GRASP_FLAG
    }

    fn actor_names(&self) -> &'static [&'static str] {
        &["cube", "goal_region"]
    }

    fn cameras(&self) -> (CameraDef, CameraDef) {
        tabletop_cameras(
            ([0.3, 0.0, 0.6], [-0.1, 0.0, 0.1]),
            ([0.6, 0.7, 0.6], [0.0, 0.0, 0.35]),
        )
    }
}
