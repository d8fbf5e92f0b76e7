//! StackCube-v1 (docs/tasks.md §8): pick up the red cube A, stack it on the green cube B and
//! let go of it.
//!
//! Robot-generic, as upstream (panda and fetch share every constant): `agent.tcp` is the
//! robot's TCP link (panda `panda_hand_tcp`, fetch `gripper_link`), the grasp check is the
//! robot's, on cube A.
//!
//! Both cubes are drawn around a common random centre by ManiSkill's `UniformPlacementSampler`:
//! cube A anywhere in the region, cube B by rejection until it is more than two collision radii
//! from cube A ([`spawn_offsets`]); then each cube gets a random yaw.
use nalgebra::Vector3;

use super::{
    add_cameras, body_id, closeness, free_joint_qpos, set_free_pose, tabletop_cameras,
    yaw_quat_f32, CameraDef, ObsWriter, Task, TaskCtx,
};
use crate::mjcf::props::Rgba;
use crate::mjcf::Scene;
use crate::mujoco::{BodyId, Data, MjError, Model};
use crate::rng::TorchGenerator;

// ---- constants (docs/tasks.md §8) ---------------------------------------------------------------
/// Maximum dense reward.
pub const MAX_REWARD: f64 = 8.0;
/// Half edge of both cubes (m).
pub const CUBE_HALF_SIZE: f64 = 0.02;
/// Cube A (the one to stack): red.
pub const CUBE_A_RGBA: Rgba = [1.0, 0.0, 0.0, 1.0];
/// Cube B (the base): green.
pub const CUBE_B_RGBA: Rgba = [0.0, 1.0, 0.0, 1.0];
/// Cube A's and cube B's build positions (before the first reset), as upstream.
const CUBE_A_BUILD_POS: [f64; 3] = [0.0, 0.0, 0.1];
const CUBE_B_BUILD_POS: [f64; 3] = [1.0, 0.0, 0.1];
/// Half size of the square the common centre's xy is drawn from, centred at the origin (m).
const CENTRE_HALF_SIZE: f32 = 0.1;
/// The sampler's region around that centre: x in ±0.1, y in ±0.2 (m).
const REGION_LOW: [f32; 2] = [-0.1, -0.2];
const REGION_HIGH: [f32; 2] = [0.1, 0.2];
/// Margin added to a cube's collision radius `‖(h, h)‖` (m).
const RADIUS_MARGIN: f32 = 0.001;
/// The sampler's attempts at a cube B clear of cube A (after them its offset stays 0).
const MAX_TRIALS: usize = 100;
/// `is_cubeA_on_cubeB`: horizontal distance within `‖(h, h)‖` + this, height difference
/// within this of one cube edge (m).
const ON_TOL: f64 = 0.005;
/// `is_cubeA_static`: cube A's linear (m/s) and angular (rad/s) speed at most these.
const STATIC_LIN: f64 = 1e-2;
const STATIC_ANG: f64 = 0.5;
/// Reward stages: grasped (+ placement), on cube B (+ ungrasp and static terms), success.
const GRASPED_REWARD: f64 = 4.0;
const ON_CUBE_B_REWARD: f64 = 6.0;
/// Weight of the reaching term, and scale of cube A's linear speed in the static term.
const REACH_WEIGHT: f64 = 2.0;
const STATIC_LIN_SCALE: f64 = 10.0;

/// `evaluate()`'s result, its fields named as ManiSkill's keys (`is_cubeA_grasped`, ...).
#[allow(non_snake_case)]
mod eval {
    evaluation! {
        /// StackCube's `evaluate()`.
        pub struct StackCubeEval {
            /// The fingers grasp cube A.
            is_cubeA_grasped: bool,
            /// Cube A rests on cube B (centred within the tolerances).
            is_cubeA_on_cubeB: bool,
            /// Cube A is (nearly) at rest.
            is_cubeA_static: bool,
            /// On cube B, static and not grasped.
            success: bool,
        }
    }
}
pub use eval::StackCubeEval;

/// The sampler's offsets of cube A and cube B from the common centre, in float32 as upstream:
/// cube A's from one `torch.rand(2)`, cube B's from one `torch.rand(2)` per trial until it lies
/// more than two collision radii from cube A's (at most [`MAX_TRIALS`]; none: offset 0).
pub fn spawn_offsets(torch: &mut TorchGenerator) -> ([f32; 2], [f32; 2]) {
    let h = CUBE_HALF_SIZE as f32;
    let radius = (h * h + h * h).sqrt() + RADIUS_MARGIN;
    let clearance = radius + radius;
    let mut draw = || {
        let mut u = [0f32; 2];
        torch.fill_rand(&mut u);
        [0, 1].map(|k| u[k] * (REGION_HIGH[k] - REGION_LOW[k]) + REGION_LOW[k])
    };
    let a = draw();
    let mut b = [0f32; 2];
    for _ in 0..MAX_TRIALS {
        let p = draw();
        let (dx, dy) = (p[0] - a[0], p[1] - a[1]);
        if (dx * dx + dy * dy).sqrt() > clearance {
            b = p;
            break;
        }
    }
    (a, b)
}

/// StackCube-v1.
#[derive(Debug, Clone, Default)]
pub struct StackCube {
    cube_a: BodyId,
    cube_a_qadr: usize,
    cube_b: BodyId,
    cube_b_qadr: usize,
}

impl StackCube {
    /// The task (panda and fetch share every constant).
    pub fn new() -> Self {
        Self::default()
    }

    /// Where cube A's centre rests on cube B: one cube edge above cube B's centre.
    pub fn goal(cube_b: Vector3<f64>) -> Vector3<f64> {
        cube_b + Vector3::new(0.0, 0.0, 2.0 * CUBE_HALF_SIZE)
    }

    /// `evaluate()`, typed.
    pub fn eval(&self, ctx: &TaskCtx) -> StackCubeEval {
        let offset = ctx.body_pos(self.cube_a) - ctx.body_pos(self.cube_b);
        let h = CUBE_HALF_SIZE;
        let xy = offset.xy().norm() <= (h * h + h * h).sqrt() + ON_TOL;
        let z = (offset.z - 2.0 * h).abs() <= ON_TOL;
        let (lin, ang) = ctx.body_velocity(self.cube_a);
        let stat = lin.norm() <= STATIC_LIN && ang.norm() <= STATIC_ANG;
        let grasped = ctx.is_grasping();
        StackCubeEval {
            is_cubeA_grasped: grasped,
            is_cubeA_on_cubeB: xy && z,
            is_cubeA_static: stat,
            success: xy && z && stat && !grasped,
        }
    }
}

impl Task for StackCube {
    fn max_reward(&self) -> f64 {
        MAX_REWARD
    }

    // ---- scene (build order: cubeA, cubeB) ---------------------------------------------
    fn build(&self, scene: &mut Scene) {
        let h = CUBE_HALF_SIZE;
        scene.add_box("cubeA", [h; 3], CUBE_A_RGBA, CUBE_A_BUILD_POS);
        scene.add_box("cubeB", [h; 3], CUBE_B_RGBA, CUBE_B_BUILD_POS);
        add_cameras(scene, self.cameras());
    }

    fn resolve(&mut self, model: &Model) -> Result<(), MjError> {
        self.cube_a = body_id(model, "cubeA")?;
        self.cube_a_qadr = free_joint_qpos(model, "cubeA")?;
        self.cube_b = body_id(model, "cubeB")?;
        self.cube_b_qadr = free_joint_qpos(model, "cubeB")?;
        Ok(())
    }

    fn grasp_object(&self) -> BodyId {
        self.cube_a
    }

    // ---- episode initialisation (torch draws: rand(2), rand(2), rand(2) per trial,
    // rand(3), rand(3)) --------------------------------------------------------------------
    fn initialize_episode(&mut self, data: &mut Data, torch: &mut TorchGenerator) {
        let mut u = [0f32; 2];
        torch.fill_rand(&mut u);
        let centre = u.map(|x| x * (2.0 * CENTRE_HALF_SIZE) - CENTRE_HALF_SIZE);
        let (a, b) = spawn_offsets(torch);
        let z = CUBE_HALF_SIZE as f32 as f64;
        for (offset, qadr) in [(a, self.cube_a_qadr), (b, self.cube_b_qadr)] {
            // random_quaternions(lock_x, lock_y): rand(3), only the z angle kept.
            let mut e = [0f32; 3];
            torch.fill_rand(&mut e);
            let yaw = e[2] * (2.0 * std::f32::consts::PI);
            let pos = [
                (centre[0] + offset[0]) as f64,
                (centre[1] + offset[1]) as f64,
                z,
            ];
            set_free_pose(data, qadr, pos, yaw_quat_f32(yaw));
        }
    }

    // ---- evaluate ------------------------------------------------------------------------
    fn info_keys(&self) -> &'static [&'static str] {
        StackCubeEval::KEYS
    }

    fn evaluate(&self, ctx: &TaskCtx, info: &mut [f64]) {
        self.eval(ctx).write(info);
    }

    // ---- observation extras ------------------------------------------------------------------
    fn observe_extra(&self, ctx: &TaskCtx, _info: &[f64], state: bool, out: &mut ObsWriter) {
        let (tcp, tcp_q) = ctx.tcp_link_pose();
        out.pose("tcp_pose", tcp, tcp_q);
        if state {
            let (a, b) = (ctx.body_pos(self.cube_a), ctx.body_pos(self.cube_b));
            out.pose("cubeA_pose", a, ctx.body_quat(self.cube_a));
            out.pose("cubeB_pose", b, ctx.body_quat(self.cube_b));
            out.vec3("tcp_to_cubeA_pos", a - tcp);
            out.vec3("tcp_to_cubeB_pos", b - tcp);
            out.vec3("cubeA_to_cubeB_pos", b - a);
        }
    }

    // ---- dense reward (max 8) ------------------------------------------------------------------
    fn dense_reward(&self, ctx: &TaskCtx, info: &[f64]) -> f64 {
        let e = StackCubeEval::read(info);
        if e.success {
            return MAX_REWARD;
        }
        let tcp = ctx.tcp_link_pos();
        let (a, b) = (ctx.body_pos(self.cube_a), ctx.body_pos(self.cube_b));
        if e.is_cubeA_on_cubeB {
            // Ungrasp: the fingers' opening as a fraction of the gripper's full width (1 once
            // let go); static: cube A at rest.
            let ungrasp = if e.is_cubeA_grasped {
                let width = 2.0 * ctx.robot.joints.limits.last().map_or(0.0, |l| l.1);
                let n = ctx.qpos.len();
                (ctx.qpos[n - 2] + ctx.qpos[n - 1]) / width
            } else {
                1.0
            };
            let (lin, ang) = ctx.body_velocity(self.cube_a);
            let stat = 1.0 - (STATIC_LIN_SCALE * lin.norm() + ang.norm()).tanh();
            return ON_CUBE_B_REWARD + (ungrasp + stat) / 2.0;
        }
        if e.is_cubeA_grasped {
            return GRASPED_REWARD + closeness((Self::goal(b) - a).norm());
        }
        REACH_WEIGHT * closeness((tcp - a).norm())
    }

    fn grasp_flag(&self) -> &'static str {
        "is_cubeA_grasped"
    }

    fn actor_names(&self) -> &'static [&'static str] {
        &["cubeA", "cubeB"]
    }

    fn cameras(&self) -> (CameraDef, CameraDef) {
        tabletop_cameras(
            ([0.3, 0.0, 0.6], [-0.1, 0.0, 0.1]),
            ([0.6, 0.7, 0.6], [0.0, 0.0, 0.35]),
        )
    }
}
