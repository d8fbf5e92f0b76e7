//! PokeCube-v1 (docs/tasks.md §2): grasp a blue peg and push a red cube with the peg's head onto
//! a red/white target on the table.
//!
//! Robot-generic: every robot-dependent quantity goes through the robot spec — `agent.tcp`
//! is the robot's TCP link (panda `panda_hand_tcp`, fetch `gripper_link`), the grasp check is
//! the robot's, and the static reward term uses `qvel[:-2]` for every robot, as upstream.
//!
//! Upstream quirks kept for parity: the observation key `goal_pos` holds the **peg**
//! position; the peg head is `peg.p + (0.12, 0, 0)` in world axes (not rotated with the
//! peg); `angle_diff` is the unwrapped difference of the two yaw angles.
//!
//! The goal region is a mocap body whose pose is upstream's exactly: position
//! (cube.x + 0.1, cube.y, [`TARGET_Z`]) and quaternion [`TARGET_QUAT`] = `euler2quat(0, π/2, 0)`.
//! Its cylinders are built with their axis along the body's local x, as SAPIEN's cylinders
//! are (MuJoCo's are along local z; `Scene::add_marker_target` rotates each geom), so that
//! quaternion turns them vertical and the target lies flat, as upstream. Only the goal's
//! position enters observations, `evaluate()` and the reward.
use std::f64::consts::{FRAC_PI_3, FRAC_PI_6};

use nalgebra::Vector3;

use super::{
    add_cameras, body_id, closeness, free_joint_qpos, red_white_target, set_free_pose,
    set_mocap_pose, tabletop_cameras, yaw_quat_f32, CameraDef, ObsWriter, Task, TaskCtx,
    TARGET_QUAT, TARGET_Z,
};
use crate::mjcf::props::Rgba;
use crate::mjcf::Scene;
use crate::mujoco::{BodyId, Data, MjError, Model};
use crate::rng::TorchGenerator;

// ---- constants (docs/tasks.md §2) ---------------------------------------------------------------
/// Maximum dense reward.
pub const MAX_REWARD: f64 = 10.0;
/// Cube half edge (m).
pub const CUBE_HALF_SIZE: f64 = 0.02;
/// Peg half width (m): its cross-section is 0.05 × 0.05.
pub const PEG_HALF_WIDTH: f64 = 0.025;
/// Peg half length (m), along its local x.
pub const PEG_HALF_LENGTH: f64 = 0.12;
/// Radius of the goal region (and of `is_cube_placed`).
pub const GOAL_RADIUS: f64 = 0.05;
/// Cube colour.
pub const CUBE_RGBA: Rgba = [1.0, 0.0, 0.0, 1.0];
/// Peg colour (both halves): (12, 42, 160)/255.
pub const PEG_RGBA: Rgba = [12.0 / 255.0, 42.0 / 255.0, 160.0 / 255.0, 1.0];
/// `is_peg_cube_fit`: angle tolerance (rad).
const FIT_ANGLE: f64 = 0.05;
/// `is_peg_cube_fit`: head-to-cube distance tolerance (cube half size + 5 mm).
const FIT_DIST: f64 = 0.02 + 0.005;
/// `reached`: TCP-to-peg-centre distance (m).
const REACHED_DIST: f64 = 0.01;
/// Trailing qvel entries the static reward term ignores (both supported robots).
const STATIC_DROP: usize = 2;

evaluation! {
    /// PokeCube's `evaluate()`.
    pub struct PokeCubeEval {
        /// The cube is in the goal region and the robot is static.
        success: bool,
        /// The cube's centre is within the goal region (xy).
        is_cube_placed: bool,
        /// The peg head is aligned with and close to the cube.
        is_peg_cube_fit: bool,
        /// The fingers grasp the peg.
        is_peg_grasped: bool,
        /// |yaw(peg) − yaw(cube)| (rad).
        angle_diff: f64,
        /// Peg-head-to-cube distance in xy (m).
        head_to_cube_dist: f64,
    }
}

/// The peg head offset `peg_head_offsets.p` (world axes, not rotated: upstream quirk).
pub fn peg_head(peg: Vector3<f64>) -> Vector3<f64> {
    peg + Vector3::new(PEG_HALF_LENGTH, 0.0, 0.0)
}

/// Yaw as upstream extracts it: the third angle of the intrinsic XYZ Euler decomposition,
/// `atan2(−R₀₁, R₀₀)` of the rotation matrix of `q` (w, x, y, z).
pub fn yaw_xyz(q: [f64; 4]) -> f64 {
    let [w, x, y, z] = q;
    let r00 = 1.0 - 2.0 * (y * y + z * z);
    let r01 = 2.0 * (x * y - w * z);
    (-r01).atan2(r00)
}

/// PokeCube-v1.
#[derive(Debug, Clone, Default)]
pub struct PokeCube {
    cube: BodyId,
    cube_qadr: usize,
    peg: BodyId,
    peg_qadr: usize,
    goal: BodyId,
}

impl PokeCube {
    /// The task (panda and fetch share every constant).
    pub fn new() -> Self {
        Self::default()
    }

    /// `evaluate()`, typed.
    pub fn eval(&self, ctx: &TaskCtx) -> PokeCubeEval {
        let (cube, peg, goal) = (
            ctx.body_pos(self.cube),
            ctx.body_pos(self.peg),
            ctx.body_pos(self.goal),
        );
        let placed = (cube.xy() - goal.xy()).norm() < GOAL_RADIUS;
        // The head pose's rotation is the peg's.
        let angle_diff =
            (yaw_xyz(ctx.body_quat(self.peg)) - yaw_xyz(ctx.body_quat(self.cube))).abs();
        let head_to_cube = (peg_head(peg).xy() - cube.xy()).norm();
        let fit = angle_diff < FIT_ANGLE && head_to_cube <= FIT_DIST;
        PokeCubeEval {
            success: placed && ctx.is_robot_static(),
            is_cube_placed: placed,
            is_peg_cube_fit: fit,
            is_peg_grasped: ctx.is_grasping(),
            angle_diff,
            head_to_cube_dist: head_to_cube,
        }
    }
}

impl Task for PokeCube {
    fn max_reward(&self) -> f64 {
        MAX_REWARD
    }

    // ---- scene (build order: cube, peg, goal_region) ---------------------------------------
    fn build(&self, scene: &mut Scene) {
        let h = CUBE_HALF_SIZE;
        scene.add_box("cube", [h; 3], CUBE_RGBA, [1.0, 0.0, h]);
        let w = PEG_HALF_WIDTH;
        scene.add_peg("peg", PEG_HALF_LENGTH, w, PEG_RGBA, [0.0, 0.0, w]);
        // Not hidden: the sensor camera sees the target.
        scene.add_marker_target("goal_region", &red_white_target(GOAL_RADIUS));
        add_cameras(scene, self.cameras());
    }

    fn resolve(&mut self, model: &Model) -> Result<(), MjError> {
        self.cube = body_id(model, "cube")?;
        self.cube_qadr = free_joint_qpos(model, "cube")?;
        self.peg = body_id(model, "peg")?;
        self.peg_qadr = free_joint_qpos(model, "peg")?;
        self.goal = body_id(model, "goal_region")?;
        Ok(())
    }

    fn grasp_object(&self) -> BodyId {
        self.peg
    }

    // ---- episode initialisation (torch draws: rand(3) × 3), in float32 as upstream ---------
    fn initialize_episode(&mut self, data: &mut Data, torch: &mut TorchGenerator) {
        // 1. Peg: xy ∈ U(−0.1, 0.1), yaw 0.
        let mut u1 = [0f32; 3];
        torch.fill_rand(&mut u1);
        let peg = [u1[0] * 0.2 - 0.1, u1[1] * 0.2 - 0.1, PEG_HALF_WIDTH as f32];
        // 2. Cube: y ∈ U(−0.1, 0.1), x = peg.x + half length + 0.1 (u2[0], u2[2] unused).
        let mut u2 = [0f32; 3];
        torch.fill_rand(&mut u2);
        let cube = [
            peg[0] + PEG_HALF_LENGTH as f32 + 0.1,
            u2[1] * 0.2 - 0.1,
            CUBE_HALF_SIZE as f32,
        ];
        // 3. Cube yaw ∈ U(−π/6, π/6): rand·(b1 − b0) + b0 with the bounds computed in
        //    Python floats (b1 − b0 = π/3 exactly) and rounded to f32 by torch.
        let mut u3 = [0f32; 3];
        torch.fill_rand(&mut u3);
        let yaw = u3[2] * (FRAC_PI_3 as f32) + (-FRAC_PI_6 as f32);
        // 4. Goal: cube + (goal_radius + 0.05, 0, 0), z := 0.001.
        let goal = [
            cube[0] + (GOAL_RADIUS + 0.05) as f32,
            cube[1],
            TARGET_Z as f32,
        ];

        let f64s = |v: [f32; 3]| v.map(|x| x as f64);
        set_free_pose(data, self.peg_qadr, f64s(peg), [1.0, 0.0, 0.0, 0.0]);
        set_free_pose(data, self.cube_qadr, f64s(cube), yaw_quat_f32(yaw));
        let model = data.model().clone();
        set_mocap_pose(&model, data, self.goal, f64s(goal), TARGET_QUAT);
    }

    // ---- evaluate ------------------------------------------------------------------------
    fn info_keys(&self) -> &'static [&'static str] {
        PokeCubeEval::KEYS
    }

    fn evaluate(&self, ctx: &TaskCtx, info: &mut [f64]) {
        self.eval(ctx).write(info);
    }

    // ---- observation extras ------------------------------------------------------------------
    fn observe_extra(&self, ctx: &TaskCtx, _info: &[f64], state: bool, out: &mut ObsWriter) {
        let (tcp, tcp_q) = ctx.tcp_link_pose();
        out.pose("tcp_pose", tcp, tcp_q);
        if state {
            let (cube, peg, goal) = (
                ctx.body_pos(self.cube),
                ctx.body_pos(self.peg),
                ctx.body_pos(self.goal),
            );
            out.pose("cube_pose", cube, ctx.body_quat(self.cube));
            out.pose("peg_pose", peg, ctx.body_quat(self.peg));
            out.vec3("goal_pos", peg); // the peg position (upstream quirk)
            out.vec3("tcp_to_peg_pos", peg - tcp);
            out.vec3("peg_to_cube_pos", cube - peg);
            out.vec3("cube_to_goal_pos", goal - cube);
            out.vec3("peghead_to_cube_pos", peg_head(peg) - cube);
        }
    }

    // ---- dense reward (max 10) -----------------------------------------------------------------
    fn dense_reward(&self, ctx: &TaskCtx, info: &[f64]) -> f64 {
        let e = PokeCubeEval::read(info);
        if e.success {
            return MAX_REWARD;
        }
        let (tcp, _) = ctx.tcp_link_pose();
        let (cube, peg, goal) = (
            ctx.body_pos(self.cube),
            ctx.body_pos(self.peg),
            ctx.body_pos(self.goal),
        );
        // Reaching the peg centre.
        let d = (tcp - peg).norm();
        let mut r = 2.0 * closeness(d);
        // Grasped (and reached): head close to the cube and aligned with it.
        let grasped_reached = e.is_peg_grasped && d < REACHED_DIST;
        if grasped_reached {
            let close = closeness(e.head_to_cube_dist);
            let align = closeness(e.angle_diff);
            r = 4.0 + close + align;
        }
        // Fitted: cube towards the goal (3-D distance).
        if e.is_peg_cube_fit && grasped_reached {
            r = 7.0 + closeness((goal - cube).norm());
        }
        // Placed: robot at rest.
        if e.is_cube_placed {
            let n = ctx.qvel.len().saturating_sub(STATIC_DROP);
            let qv = ctx.qvel[..n].iter().map(|v| v * v).sum::<f64>().sqrt();
            r += closeness(qv);
        }
        r
    }

    fn grasp_flag(&self) -> &'static str {
        "is_peg_grasped"
    }

    fn bool_info(&self, key: &str) -> bool {
        PokeCubeEval::is_flag(key)
    }

    fn actor_names(&self) -> &'static [&'static str] {
        &["cube", "peg", "goal_region"]
    }

    fn cameras(&self) -> (CameraDef, CameraDef) {
        tabletop_cameras(
            ([0.3, 0.0, 0.6], [-0.1, 0.0, 0.1]),
            ([0.6, 0.7, 0.6], [0.2, 0.2, 0.35]),
        )
    }
}
