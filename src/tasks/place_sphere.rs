//! PlaceSphere-v1 (docs/tasks.md §3): grasp a small blue sphere and release it in a shallow bin.
use nalgebra::Vector3;

use super::{
    add_cameras, body_id, closeness, free_joint_qpos, set_free_pose, set_mocap_pose,
    tabletop_cameras, CameraDef, InfoValue, ObsWriter, Task, TaskCtx,
};
use crate::mjcf::Scene;
use crate::mujoco::{BodyId, Data, MjError, Model};
use crate::rng::TorchGenerator;

// ---- constants (docs/tasks.md §3) ---------------------------------------------------------------
/// Maximum dense reward.
pub const MAX_REWARD: f64 = 13.0;
/// Sphere radius (m).
pub const RADIUS: f64 = 0.02;
/// Bin floor half thickness (m); the bin frame sits at this height.
pub const SHORT_SIDE_HALF: f64 = 0.0025;
/// Bin floor half extents.
pub const BLOCK_HALF: [f64; 3] = [0.0025, 0.025, 0.025];
/// Bin wall half extents (along the wall's short axis first).
pub const EDGE_BLOCK_HALF: [f64; 3] = [0.0025, 0.025, 0.005];
/// Sphere colour (12, 42, 160)/255.
pub const SPHERE_RGBA: [f64; 4] = [12.0 / 255.0, 42.0 / 255.0, 160.0 / 255.0, 1.0];
/// Bin colour (ManiSkill's default white material).
pub const BIN_RGBA: [f64; 4] = [1.0, 1.0, 1.0, 1.0];
/// `is_obj_on_bin`: horizontal tolerance (m).
const ON_BIN_XY: f64 = 0.005;
/// `is_obj_on_bin`: vertical tolerance (m).
const ON_BIN_Z: f64 = 0.005;
/// `is_obj_static` thresholds: linear (m/s) and angular (rad/s).
const STATIC_LIN: f64 = 1e-2;
const STATIC_ANG: f64 = 0.5;
/// PhysX torsional patch radius of the Panda's and Fetch's finger material (m; ManiSkill's
/// `patch_radius` = `min_patch_radius` = 0.1): without it the sphere spins freely about the
/// pinch axis in mjskill's grasp (docs/outcome-physics.md).
pub const FINGER_PATCH_RADIUS: f64 = 0.1;
/// The `ungrasp` term when the sphere is not grasped.
const UNGRASP_FREE: f64 = 16.0;

evaluation! {
    /// PlaceSphere's `evaluate()`.
    pub struct PlaceSphereEval {
        /// The fingers grasp the sphere.
        is_obj_grasped: bool,
        /// The sphere rests on the bin's floor, within the bin.
        is_obj_on_bin: bool,
        /// The sphere is (nearly) at rest.
        is_obj_static: bool,
        /// On the bin, static and released.
        success: bool,
    }
}

/// The five bin boxes (centre, half extents) in the bin frame: floor, walls −x, +x, −y, +y.
pub fn bin_boxes() -> [([f64; 3], [f64; 3]); 5] {
    let d = BLOCK_HALF[1] - EDGE_BLOCK_HALF[0]; // 0.0225
    let z = EDGE_BLOCK_HALF[2] + BLOCK_HALF[0]; // 0.0075
    let floor = [BLOCK_HALF[1], BLOCK_HALF[2], BLOCK_HALF[0]];
    let wall_x = [EDGE_BLOCK_HALF[0], EDGE_BLOCK_HALF[1], EDGE_BLOCK_HALF[2]];
    let wall_y = [EDGE_BLOCK_HALF[1], EDGE_BLOCK_HALF[0], EDGE_BLOCK_HALF[2]];
    [
        ([0.0, 0.0, 0.0], floor),
        ([-d, 0.0, z], wall_x),
        ([d, 0.0, z], wall_x),
        ([0.0, -d, z], wall_y),
        ([0.0, d, z], wall_y),
    ]
}

/// PlaceSphere-v1.
#[derive(Debug, Clone, Default)]
pub struct PlaceSphere {
    sphere: BodyId,
    sphere_qadr: usize,
    bin: BodyId,
}

impl PlaceSphere {
    /// The task (panda and fetch share every constant).
    pub fn new() -> Self {
        Self::default()
    }

    /// `evaluate()`, typed.
    pub fn eval(&self, ctx: &TaskCtx) -> PlaceSphereEval {
        let o = ctx.body_pos(self.sphere) - ctx.body_pos(self.bin);
        let on_bin =
            o.xy().norm() <= ON_BIN_XY && (o.z - RADIUS - SHORT_SIDE_HALF).abs() <= ON_BIN_Z;
        let (lin, ang) = ctx.body_velocity(self.sphere);
        let stat = lin.norm() <= STATIC_LIN && ang.norm() <= STATIC_ANG;
        let grasped = ctx.is_grasping();
        PlaceSphereEval {
            is_obj_grasped: grasped,
            is_obj_on_bin: on_bin,
            is_obj_static: stat,
            success: on_bin && stat && !grasped,
        }
    }
}

impl Task for PlaceSphere {
    fn max_reward(&self) -> f64 {
        MAX_REWARD
    }

    // ---- scene -------------------------------------------------------------------------
    fn build(&self, scene: &mut Scene) {
        scene.add_sphere("sphere", RADIUS, SPHERE_RGBA, [0.0, 0.0, RADIUS]);
        scene.add_finger_pairs("sphere", FINGER_PATCH_RADIUS);
        scene.add_kinematic_boxes("bin", &bin_boxes(), BIN_RGBA);
        add_cameras(scene, self.cameras());
    }

    fn resolve(&mut self, model: &Model) -> Result<(), MjError> {
        self.sphere = body_id(model, "sphere")?;
        self.sphere_qadr = free_joint_qpos(model, "sphere")?;
        self.bin = body_id(model, "bin")?;
        Ok(())
    }

    fn grasp_object(&self) -> BodyId {
        self.sphere
    }

    // ---- episode initialisation (torch draws: rand(1) × 4) -------------------------------
    fn initialize_episode(&mut self, data: &mut Data, torch: &mut TorchGenerator) {
        let mut u = [0f32; 4];
        for x in u.iter_mut() {
            *x = torch.rand_f32();
        }
        let sphere = [
            (u[0] * 0.05 - 0.1) as f64,
            (u[1] * 0.2 - 0.1) as f64,
            RADIUS as f32 as f64,
        ];
        set_free_pose(data, self.sphere_qadr, sphere, [1.0, 0.0, 0.0, 0.0]);
        let bin = [
            (u[2] * 0.1) as f64,
            (u[3] * 0.2 - 0.1) as f64,
            SHORT_SIDE_HALF as f32 as f64,
        ];
        let model = data.model().clone();
        set_mocap_pose(&model, data, self.bin, bin, [1.0, 0.0, 0.0, 0.0]);
    }

    // ---- evaluate ------------------------------------------------------------------------
    fn info_keys(&self) -> &'static [&'static str] {
        PlaceSphereEval::KEYS
    }

    fn evaluate(&self, ctx: &TaskCtx, info: &mut [f64]) {
        self.eval(ctx).write(info);
    }

    // ---- observation extras ------------------------------------------------------------------
    fn observe_extra(&self, ctx: &TaskCtx, info: &[f64], state: bool, out: &mut ObsWriter) {
        let tcp = ctx.tcp_link_pos();
        let sphere = ctx.body_pos(self.sphere);
        let e = PlaceSphereEval::read(info);
        out.scalar("is_grasped", e.is_obj_grasped.to_info());
        out.pose("tcp_pose", tcp, ctx.tcp_quat);
        out.vec3("bin_pos", ctx.body_pos(self.bin));
        if state {
            out.pose("obj_pose", sphere, ctx.body_quat(self.sphere));
            out.vec3("tcp_to_obj_pos", sphere - tcp);
        }
    }

    // ---- dense reward (max 13) -----------------------------------------------------------------
    fn dense_reward(&self, ctx: &TaskCtx, info: &[f64]) -> f64 {
        let tcp = ctx.tcp_link_pos();
        let (sphere, bin) = (ctx.body_pos(self.sphere), ctx.body_pos(self.bin));
        let e = PlaceSphereEval::read(info);
        let grasped = e.is_obj_grasped;
        let mut r = 2.0 * closeness((tcp - sphere).norm());
        let bin_top = bin + Vector3::new(0.0, 0.0, SHORT_SIDE_HALF + RADIUS);
        let place = closeness((bin_top - sphere).norm());
        if grasped {
            r = 4.0 + place;
        }
        let gripper_width = 2.0 * ctx.robot.joints.limits.last().map_or(0.0, |l| l.1);
        let n = ctx.qpos.len();
        let ungrasp = if grasped {
            (ctx.qpos[n - 2] + ctx.qpos[n - 1]) / gripper_width
        } else {
            UNGRASP_FREE
        };
        let (lin, ang) = ctx.body_velocity(self.sphere);
        let stat = 1.0 - (10.0 * lin.norm() + ang.norm()).tanh();
        let robot_static = ctx.is_robot_static() as u8 as f64;
        if e.is_obj_on_bin {
            r = 6.0 + (ungrasp + stat + robot_static) / 3.0;
        }
        if e.success {
            r = MAX_REWARD;
        }
        r
    }

    fn grasp_flag(&self) -> &'static str {
        "is_obj_grasped"
    }

    fn actor_names(&self) -> &'static [&'static str] {
        &["sphere", "bin"]
    }

    fn cameras(&self) -> (CameraDef, CameraDef) {
        tabletop_cameras(
            ([0.3, 0.0, 0.2], [-0.1, 0.0, 0.0]),
            ([0.6, -0.2, 0.2], [0.0, 0.0, 0.2]),
        )
    }
}
