//! PickCube-v1 (docs/tasks.md §1): grasp a red cube and move it to a green goal point.
//! Registered variants PickCubeSO100-v1 / PickCubeWidowXAI-v1 force the robot.
use std::f32::consts::PI;

use nalgebra::Vector3;

use super::{
    add_cameras, body_id, closeness, free_joint_qpos, set_free_pose, set_mocap_pose,
    tabletop_cameras, yaw_quat_f32, CameraDef, InfoValue, ObsWriter, Task, TaskCtx,
};
use crate::mjcf::Scene;
use crate::mujoco::{BodyId, Data, MjError, Model};
use crate::rng::{uniform_scaled, TorchGenerator};
use crate::robots::RobotId;

/// Maximum dense reward.
pub const MAX_REWARD: f64 = 5.0;
/// Cube colour.
pub const CUBE_RGBA: [f64; 4] = [1.0, 0.0, 0.0, 1.0];
/// Goal marker colour.
pub const GOAL_RGBA: [f64; 4] = [0.0, 1.0, 0.0, 1.0];

/// Per-robot task configuration (`PICK_CUBE_CONFIGS`, docs/tasks.md §1.2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PickCubeConfig {
    /// Half edge of the cube.
    pub cube_half_size: f32,
    /// Success radius around the goal.
    pub goal_thresh: f32,
    /// Half size of the square spawn region of cube and goal xy.
    pub cube_spawn_half_size: f32,
    /// Centre of the spawn region.
    pub cube_spawn_center: [f32; 2],
    /// Goal height range above the cube half size.
    pub max_goal_height: f32,
    /// Sensor camera (eye, target).
    pub sensor_cam: ([f64; 3], [f64; 3]),
    /// Human camera (eye, target).
    pub human_cam: ([f64; 3], [f64; 3]),
}

/// A camera as (eye, target).
type Eye = ([f64; 3], [f64; 3]);

const PANDA_CAMS: (Eye, Eye) = (
    ([0.3, 0.0, 0.6], [-0.1, 0.0, 0.1]),
    ([0.6, 0.7, 0.6], [0.0, 0.0, 0.35]),
);

/// The panda configuration (fetch and xarm6_robotiq have identical entries).
pub const PANDA_CONFIG: PickCubeConfig = PickCubeConfig {
    cube_half_size: 0.02,
    goal_thresh: 0.025,
    cube_spawn_half_size: 0.1,
    cube_spawn_center: [0.0, 0.0],
    max_goal_height: 0.3,
    sensor_cam: PANDA_CAMS.0,
    human_cam: PANDA_CAMS.1,
};

/// The SO100 configuration.
pub const SO100_CONFIG: PickCubeConfig = PickCubeConfig {
    cube_half_size: 0.0125,
    goal_thresh: 0.0125 * 1.25,
    cube_spawn_half_size: 0.05,
    cube_spawn_center: [-0.46, 0.0],
    max_goal_height: 0.08,
    sensor_cam: ([-0.27, 0.0, 0.4], [-0.56, 0.0, -0.25]),
    human_cam: ([-0.1, 0.3, 0.4], [-0.46, 0.0, 0.1]),
};

/// The WidowX AI configuration.
pub const WIDOWXAI_CONFIG: PickCubeConfig = PickCubeConfig {
    cube_half_size: 0.018,
    goal_thresh: 0.018 * 1.25,
    cube_spawn_half_size: 0.05,
    cube_spawn_center: [-0.25, 0.0],
    max_goal_height: 0.2,
    sensor_cam: ([0.0, 0.0, 0.35], [-0.2, 0.0, 0.1]),
    human_cam: ([0.45, 0.5, 0.5], [-0.2, 0.0, 0.2]),
};

/// The configuration ManiSkill uses for `robot`.
pub fn config_for(robot: RobotId) -> PickCubeConfig {
    match robot {
        // Upstream falls back to the Panda's configuration for robots it does not list.
        RobotId::Panda
        | RobotId::PandaStick
        | RobotId::PandaWristCam
        | RobotId::Fetch
        | RobotId::Xarm6Robotiq => PANDA_CONFIG,
        RobotId::So100 => SO100_CONFIG,
        RobotId::WidowxAi => WIDOWXAI_CONFIG,
    }
}

evaluation! {
    /// PickCube's `evaluate()`.
    pub struct PickCubeEval {
        /// The cube is at the goal and the robot is static.
        success: bool,
        /// The cube is within `goal_thresh` of the goal.
        is_obj_placed: bool,
        /// The robot's joints are (nearly) at rest.
        is_robot_static: bool,
        /// The fingers grasp the cube.
        is_grasped: bool,
    }
}

/// PickCube-v1.
#[derive(Debug, Clone)]
pub struct PickCube {
    cfg: PickCubeConfig,
    /// The robot (the dense reward's static term depends on it).
    robot: RobotId,
    cube: BodyId,
    cube_qadr: usize,
    goal: BodyId,
}

impl PickCube {
    /// PickCube with the configuration of `robot`.
    pub fn new(robot: RobotId) -> Self {
        PickCube {
            cfg: config_for(robot),
            robot,
            cube: BodyId::default(),
            cube_qadr: 0,
            goal: BodyId::default(),
        }
    }

    /// Number of trailing qvel entries the static bonus ignores (docs/tasks.md §1.7).
    fn static_drop(&self) -> usize {
        match self.robot {
            RobotId::Panda | RobotId::PandaStick | RobotId::PandaWristCam | RobotId::WidowxAi => 2,
            RobotId::So100 => 1,
            RobotId::Fetch | RobotId::Xarm6Robotiq => 0,
        }
    }

    /// `evaluate()`, typed.
    pub fn eval(&self, ctx: &TaskCtx) -> PickCubeEval {
        let d = (ctx.body_pos(self.goal) - ctx.body_pos(self.cube)).norm();
        let placed = d <= self.cfg.goal_thresh as f64;
        let stat = ctx.is_robot_static();
        PickCubeEval {
            success: placed && stat,
            is_obj_placed: placed,
            is_robot_static: stat,
            is_grasped: ctx.is_grasping(),
        }
    }
}

impl Task for PickCube {
    fn max_reward(&self) -> f64 {
        MAX_REWARD
    }

    // ---- scene -------------------------------------------------------------------------
    fn build(&self, scene: &mut Scene) {
        let h = self.cfg.cube_half_size as f64;
        scene.add_box("cube", [h; 3], CUBE_RGBA, [0.0, 0.0, h]);
        scene.add_marker_sphere("goal_site", self.cfg.goal_thresh as f64, GOAL_RGBA, true);
        add_cameras(scene, self.cameras());
    }

    fn resolve(&mut self, model: &Model) -> Result<(), MjError> {
        self.cube = body_id(model, "cube")?;
        self.cube_qadr = free_joint_qpos(model, "cube")?;
        self.goal = body_id(model, "goal_site")?;
        Ok(())
    }

    fn grasp_object(&self) -> BodyId {
        self.cube
    }

    // ---- episode initialisation (torch draws: rand(2), rand(3), rand(2), rand(1)) ------
    fn initialize_episode(&mut self, data: &mut Data, torch: &mut TorchGenerator) {
        let (s, c, h) = (
            self.cfg.cube_spawn_half_size,
            self.cfg.cube_spawn_center,
            self.cfg.cube_half_size,
        );
        let mut u1 = [0f32; 2];
        torch.fill_rand(&mut u1);
        let mut u2 = [0f32; 3];
        torch.fill_rand(&mut u2);
        let yaw = u2[2] * (2.0 * PI);
        let cube_pos = [
            uniform_scaled(u1[0], s, c[0]) as f64,
            uniform_scaled(u1[1], s, c[1]) as f64,
            h as f64,
        ];
        set_free_pose(data, self.cube_qadr, cube_pos, yaw_quat_f32(yaw));

        let mut u3 = [0f32; 2];
        torch.fill_rand(&mut u3);
        let mut u4 = [0f32; 1];
        torch.fill_rand(&mut u4);
        let goal_pos = [
            uniform_scaled(u3[0], s, c[0]) as f64,
            uniform_scaled(u3[1], s, c[1]) as f64,
            (u4[0] * self.cfg.max_goal_height + h) as f64,
        ];
        let model = data.model().clone();
        set_mocap_pose(&model, data, self.goal, goal_pos, [1.0, 0.0, 0.0, 0.0]);
    }

    // ---- evaluate ------------------------------------------------------------------------
    fn info_keys(&self) -> &'static [&'static str] {
        PickCubeEval::KEYS
    }

    fn evaluate(&self, ctx: &TaskCtx, info: &mut [f64]) {
        self.eval(ctx).write(info);
    }

    // ---- observation extras ------------------------------------------------------------------
    fn observe_extra(&self, ctx: &TaskCtx, info: &[f64], state: bool, out: &mut ObsWriter) {
        let tcp = Vector3::from(ctx.tcp_pos);
        let (cube, goal) = (ctx.body_pos(self.cube), ctx.body_pos(self.goal));
        let e = PickCubeEval::read(info);
        out.scalar("is_grasped", e.is_grasped.to_info());
        out.pose("tcp_pose", tcp, ctx.tcp_quat);
        out.vec3("goal_pos", goal);
        if state {
            out.pose("obj_pose", cube, ctx.body_quat(self.cube));
            out.vec3("tcp_to_obj_pos", cube - tcp);
            out.vec3("obj_to_goal_pos", goal - cube);
        }
    }

    // ---- dense reward (max 5) ----------------------------------------------------------------
    fn dense_reward(&self, ctx: &TaskCtx, info: &[f64]) -> f64 {
        let e = PickCubeEval::read(info);
        if e.success {
            return MAX_REWARD;
        }
        let tcp = Vector3::from(ctx.tcp_pos);
        let (cube, goal) = (ctx.body_pos(self.cube), ctx.body_pos(self.goal));
        let grasped = e.is_grasped.to_info();
        let mut r = closeness((cube - tcp).norm());
        r += grasped;
        r += closeness((goal - cube).norm()) * grasped;
        let n = ctx.qvel.len() - self.static_drop();
        let qv = ctx.qvel[..n].iter().map(|v| v * v).sum::<f64>().sqrt();
        r += closeness(qv) * e.is_obj_placed.to_info();
        r
    }

    fn grasp_flag(&self) -> &'static str {
        "is_grasped"
    }

    fn actor_names(&self) -> &'static [&'static str] {
        &["cube", "goal_site"]
    }

    fn cameras(&self) -> (CameraDef, CameraDef) {
        tabletop_cameras(self.cfg.sensor_cam, self.cfg.human_cam)
    }
}
