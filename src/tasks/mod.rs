//! Tasks: one file per task that reads top-down — scene, episode initialisation, observation
//! extras, `evaluate()`, dense reward — with every constant named once. This module holds
//! what they share: the [`Task`] trait, the per-step [`TaskCtx`], the grasp check and pose
//! helpers.
/// Declares a task's typed `evaluate()` result once: a struct with one named field per
/// `info` key (the field name is the key, in upstream insertion order; `bool` flags and `f64`
/// values), with its key list and the conversion to and from the env's `info` slice
/// (bools as 0/1).
macro_rules! evaluation {
    ($(#[$m:meta])* pub struct $name:ident {
        $($(#[$fm:meta])* $field:ident: $ty:ty),+ $(,)?
    }) => {
        $(#[$m])*
        #[derive(Debug, Clone, Copy, PartialEq)]
        pub struct $name {
            $($(#[$fm])* pub $field: $ty),+
        }

        impl $name {
            /// The `info` keys (the field names), in upstream insertion order.
            pub const KEYS: &'static [&'static str] = &[$(stringify!($field)),+];

            /// Whether `key` is one of the boolean flags (not every task's `info` needs it).
            #[allow(dead_code)]
            pub fn is_flag(key: &str) -> bool {
                [$((stringify!($field), <$ty as $crate::tasks::InfoValue>::IS_FLAG)),+]
                    .iter()
                    .any(|&(k, flag)| flag && k == key)
            }

            /// Writes the result into `info` (aligned with [`Self::KEYS`]).
            pub fn write(&self, info: &mut [f64]) {
                let values = [$($crate::tasks::InfoValue::to_info(self.$field)),+];
                info[..values.len()].copy_from_slice(&values);
            }

            /// Reads a result that [`Self::write`] wrote.
            pub fn read(info: &[f64]) -> Self {
                let mut k = 0usize;
                $(
                    let $field = $crate::tasks::InfoValue::from_info(info[k]);
                    k += 1;
                )+
                let _ = k;
                Self { $($field),+ }
            }
        }
    };
}

/// A value of an `evaluate()` result as stored in the env's `info` slice.
pub trait InfoValue: Copy {
    /// Whether the value is a boolean flag.
    const IS_FLAG: bool;
    /// The value in the `info` slice.
    fn to_info(self) -> f64;
    /// The value of an `info` entry.
    fn from_info(x: f64) -> Self;
}

impl InfoValue for bool {
    const IS_FLAG: bool = true;
    fn to_info(self) -> f64 {
        self as u8 as f64
    }
    fn from_info(x: f64) -> bool {
        x > 0.0
    }
}

impl InfoValue for f64 {
    const IS_FLAG: bool = false;
    fn to_info(self) -> f64 {
        self
    }
    fn from_info(x: f64) -> f64 {
        x
    }
}

pub mod lift_peg_upright;
pub mod peg_insertion_side;
pub mod pick_cube;
pub mod place_sphere;
pub mod poke_cube;
pub mod pull_cube;
pub mod push_cube;
pub mod push_t;
pub mod stack_cube;

use nalgebra::{UnitQuaternion, Vector3};

use crate::mjcf::props::Rgba;
use crate::mjcf::Scene;
use crate::mujoco::{BodyId, Data, MjError, Model, Pose};
pub use crate::obs::ObsWriter;
use crate::rng::{NumpyRandomState, TorchGenerator};
use crate::robots::{GraspDef, RobotIds, RobotSpec};

/// Threshold of `agent.is_static` as every task calls it (rad/s or m/s).
pub const ROBOT_STATIC_THRESHOLD: f64 = 0.2;

/// Scale of ManiSkill's distance shaping `1 − tanh(5·d)` in every task's dense reward.
pub const REWARD_SCALE: f64 = 5.0;

/// ManiSkill's shaped closeness `1 − tanh(REWARD_SCALE·d)` of a distance (or speed) `d ≥ 0`:
/// 1 at 0, towards 0 far away.
#[inline]
pub fn closeness(d: f64) -> f64 {
    1.0 - (REWARD_SCALE * d).tanh()
}

/// Red of ManiSkill's `build_red_white_target`: (194, 19, 22)/255.
pub const TARGET_RED: Rgba = [194.0 / 255.0, 19.0 / 255.0, 22.0 / 255.0, 1.0];
/// White of ManiSkill's `build_red_white_target`.
pub const TARGET_WHITE: Rgba = [1.0, 1.0, 1.0, 1.0];
/// Thickness the tasks pass to `build_red_white_target` (m): the outermost ring's half
/// thickness is half of it, each inner ring is [`TARGET_RING_STEP`] thicker.
pub const TARGET_THICKNESS: f64 = 1e-5;
/// Half-thickness increment of each inner ring of the red/white target (m).
const TARGET_RING_STEP: f64 = 1e-5;
/// Height at which the tasks place their red/white target's frame, "a little bit above 0 so
/// the target is sitting on the table" (m).
pub const TARGET_Z: f64 = 1e-3;
/// The red/white target's quaternion `euler2quat(0, π/2, 0)` = (√½, 0, √½, 0) (w, x, y, z): it
/// turns the target's x-axis cylinders vertical (`Scene::add_marker_target`).
pub const TARGET_QUAT: [f64; 4] = [
    std::f64::consts::FRAC_1_SQRT_2,
    0.0,
    std::f64::consts::FRAC_1_SQRT_2,
    0.0,
];

/// The rings `(radius, half thickness, colour)` of ManiSkill's `build_red_white_target` of
/// radius `radius`, outermost first: radii `radius`·{1, 4/5, 3/5, 2/5, 1/5}, alternating red
/// and white, each inner ring 1e-5 thicker so that it shows above the one below.
pub fn red_white_target(radius: f64) -> [(f64, f64, Rgba); 5] {
    std::array::from_fn(|k| {
        let r = radius * (5 - k) as f64 / 5.0;
        let colour = if k % 2 == 0 { TARGET_RED } else { TARGET_WHITE };
        (
            r,
            TARGET_THICKNESS / 2.0 + k as f64 * TARGET_RING_STEP,
            colour,
        )
    })
}

/// Vertical field of view of the tasks' sensor camera `base_camera` (90°).
pub const SENSOR_FOVY: f64 = std::f64::consts::FRAC_PI_2;
/// Vertical field of view of the tasks' human camera `render_camera` (1 rad).
pub const HUMAN_FOVY: f64 = 1.0;

/// The two cameras of ManiSkill's tabletop tasks, each `look_at(eye, target)`: the sensor
/// camera `base_camera` (128×128, [`SENSOR_FOVY`]) and the human camera `render_camera`
/// (512×512, [`HUMAN_FOVY`]).
pub fn tabletop_cameras(
    sensor: ([f64; 3], [f64; 3]),
    human: ([f64; 3], [f64; 3]),
) -> (CameraDef, CameraDef) {
    (
        CameraDef {
            name: "base_camera",
            eye: sensor.0,
            target: sensor.1,
            fovy: SENSOR_FOVY,
            size: (128, 128),
        },
        CameraDef {
            name: "render_camera",
            eye: human.0,
            target: human.1,
            fovy: HUMAN_FOVY,
            size: (512, 512),
        },
    )
}

/// A camera defined like ManiSkill's `look_at(eye, target)` with a vertical field of view.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraDef {
    /// Camera name.
    pub name: &'static str,
    /// Eye position.
    pub eye: [f64; 3],
    /// Target point.
    pub target: [f64; 3],
    /// Vertical field of view in radians.
    pub fovy: f64,
    /// Image width and height.
    pub size: (usize, usize),
}

/// Everything a task reads in one evaluation, resolved and computed by the env.
pub struct TaskCtx<'a> {
    /// The simulation state (post-step).
    pub data: &'a Data,
    /// Robot ids.
    pub robot: &'a RobotIds,
    /// Robot spec.
    pub spec: &'static RobotSpec,
    /// `agent.tcp_pose` position.
    pub tcp_pos: [f64; 3],
    /// `agent.tcp_pose` quaternion (w, x, y, z), raw.
    pub tcp_quat: [f64; 4],
    /// Robot qpos (ManiSkill order).
    pub qpos: &'a [f64],
    /// Robot qvel (ManiSkill order).
    pub qvel: &'a [f64],
    /// Contact forces on the two grasp fingers from the task's grasp object (world frame).
    pub finger_forces: &'a [[f64; 3]; 2],
}

impl TaskCtx<'_> {
    /// `agent.is_grasping(object)` with the forces the env computed (docs/robots.md §1.3);
    /// false for a robot without fingers.
    pub fn is_grasping(&self) -> bool {
        match (&self.spec.grasp, self.robot.fingers) {
            (Some(g), Some(fingers)) => is_grasping(g, self.data, fingers, self.finger_forces),
            _ => false,
        }
    }
    /// `agent.is_grasping(object, max_angle)` with a tighter angle (degrees) than the robot's
    /// own check (PegInsertionSide-v1's reward); false for a robot without fingers.
    pub fn is_grasping_within(&self, max_angle_deg: f64) -> bool {
        match (&self.spec.grasp, self.robot.fingers) {
            (Some(g), Some(fingers)) => {
                let g = GraspDef {
                    max_angle_deg,
                    ..g.clone()
                };
                is_grasping(&g, self.data, fingers, self.finger_forces)
            }
            _ => false,
        }
    }
    /// `agent.is_static(0.2)` with the robot's rule (docs/env.md §10).
    pub fn is_robot_static(&self) -> bool {
        self.spec
            .static_rule
            .is_static(self.qvel, ROBOT_STATIC_THRESHOLD)
    }
    /// Position of a body.
    pub fn body_pos(&self, body: BodyId) -> Vector3<f64> {
        body_pos(self.data, body)
    }
    /// Quaternion (w, x, y, z) of a body.
    pub fn body_quat(&self, body: BodyId) -> [f64; 4] {
        self.data.body_quat(body)
    }
    /// `agent.tcp.pose.p`: the TCP link's position.
    pub fn tcp_link_pos(&self) -> Vector3<f64> {
        self.robot
            .tcp_body
            .map(|b| body_pos(self.data, b))
            .unwrap_or_else(|| Vector3::from(self.tcp_pos))
    }
    /// `agent.tcp.pose`: the TCP link's position and raw quaternion (w, x, y, z); the
    /// `tcp_pose` of the robot where it has no TCP link (so100).
    pub fn tcp_link_pose(&self) -> (Vector3<f64>, [f64; 4]) {
        match self.robot.tcp_body {
            Some(b) => (self.body_pos(b), self.body_quat(b)),
            None => (Vector3::from(self.tcp_pos), self.tcp_quat),
        }
    }
    /// Linear and angular velocity (world) of a free body.
    pub fn body_velocity(&self, body: BodyId) -> (Vector3<f64>, Vector3<f64>) {
        let v = self.data.body_velocity(body.index());
        (
            Vector3::new(v[3], v[4], v[5]),
            Vector3::new(v[0], v[1], v[2]),
        )
    }
}

/// A task (the scene-specific part of an env).
pub trait Task: Send + std::fmt::Debug {
    /// Maximum dense reward (normalised reward = dense / this).
    fn max_reward(&self) -> f64;
    /// Adds the task's props and cameras to the scene.
    fn build(&self, scene: &mut Scene);
    /// The joint positions a task's own table scene poses the robot at after the common
    /// table scene has (PushT-v1's `WhiteTableSceneBuilder`), with fresh noise
    /// ([`crate::robots::RobotSpec::repose_qpos`]); `None` (most tasks): the common pose stays.
    fn robot_repose(&self) -> Option<&'static [f64]> {
        None
    }
    /// The standard deviation of [`Task::robot_repose`]'s draw when the task fixes it
    /// (PegInsertionSide-v1: 0.02); `None`: the env's `robot_init_qpos_noise`.
    fn repose_noise(&self) -> Option<f64> {
        None
    }
    /// Resolves the task's names to ids in the compiled model.
    fn resolve(&mut self, model: &Model) -> Result<(), MjError>;
    /// Whether the task's shapes change every episode: ManiSkill rebuilds its scene at every
    /// reset (`reconfiguration_freq = 1`) and [`Task::draw_geometry`] draws them. False (the
    /// default) for a task whose scene is built once.
    fn reconfigures(&self) -> bool {
        false
    }
    /// Draws the episode's shapes from the episode's numpy stream, as upstream's `_load_scene`
    /// draws them from `_batched_episode_rng`; [`Task::build`] builds the shapes last drawn.
    fn draw_geometry(&mut self, _numpy: &mut NumpyRandomState) {}
    /// The shapes last drawn, as numbers ([`Task::set_geometry`] takes them back); empty for a
    /// task whose scene never changes.
    fn geometry(&self) -> Vec<f64> {
        Vec::new()
    }
    /// Whether [`Task::set_geometry`] takes `values`: an error names a list of the wrong
    /// length or a value out of the task's ranges.
    fn check_geometry(&self, values: &[f64]) -> Result<(), String> {
        match values.is_empty() {
            true => Ok(()),
            false => Err(format!(
                "this task's shapes never change, but the state holds {} shape values",
                values.len()
            )),
        }
    }
    /// Takes shapes that [`Task::check_geometry`] accepted.
    fn set_geometry(&mut self, _values: &[f64]) {}
    /// Writes the shapes last drawn into the compiled physics model whose ids
    /// [`Task::resolve`] resolved, in place: the model then equals the one the scene of
    /// [`Task::build`] compiles to.
    fn apply_geometry(&self, _model: &mut Model) -> Result<(), MjError> {
        Ok(())
    }
    /// Body whose contacts with the fingers decide `is_grasping`.
    fn grasp_object(&self) -> BodyId;
    /// Places the objects for a new episode, drawing from `torch` in upstream order.
    fn initialize_episode(&mut self, data: &mut Data, torch: &mut TorchGenerator);
    /// `evaluate()` keys, in upstream insertion order (without `elapsed_steps`).
    fn info_keys(&self) -> &'static [&'static str];
    /// Computes `evaluate()` into `info` (aligned with [`Task::info_keys`]; bools as 0/1).
    fn evaluate(&self, ctx: &TaskCtx, info: &mut [f64]);
    /// Writes the observation extras (ManiSkill's `_get_obs_extra`), each named where it is
    /// written, in insertion order; `state` = the privileged keys too.
    fn observe_extra(&self, ctx: &TaskCtx, info: &[f64], state: bool, out: &mut ObsWriter);
    /// Dense reward.
    fn dense_reward(&self, ctx: &TaskCtx, info: &[f64]) -> f64;
    /// Sensor and human-render cameras.
    fn cameras(&self) -> (CameraDef, CameraDef);
    /// ManiSkill's names of the task's actors (MuJoCo bodies of the same name: free bodies
    /// for dynamic actors, mocap bodies for kinematic ones), in ManiSkill's scene order. The
    /// table (`table-workspace`) comes before them in every scene.
    fn actor_names(&self) -> &'static [&'static str];
    /// The info key of the grasp check (`is_grasped`, `is_peg_grasped`, `is_obj_grasped`).
    fn grasp_flag(&self) -> &'static str;
    /// Whether an info key is a boolean flag (PokeCube also reports two distances).
    fn bool_info(&self, key: &str) -> bool {
        self.info_keys().contains(&key)
    }
}

/// Position of a body.
pub fn body_pos(data: &Data, body: BodyId) -> Vector3<f64> {
    Vector3::from(data.body_pos(body))
}

/// Resolves a body id with an error naming it.
pub fn body_id(model: &Model, name: &str) -> Result<BodyId, MjError> {
    model.require_body(name)
}

/// qpos address of a body's free joint.
pub fn free_joint_qpos(model: &Model, body: &str) -> Result<usize, MjError> {
    Ok(model.joint_qpos_adr(model.require_joint(body)?))
}

/// Writes a free body's pose (position, quaternion wxyz) into qpos. (The env zeroes every
/// velocity at reset, as ManiSkill's `_clear_sim_state`.)
pub fn set_free_pose(data: &mut Data, qadr: usize, pos: [f64; 3], quat: [f64; 4]) {
    let q = data.qpos_mut();
    q[qadr..qadr + 3].copy_from_slice(&pos);
    q[qadr + 3..qadr + 7].copy_from_slice(&quat);
}

/// Writes a mocap body's pose.
/// (The tasks resolve only mocap bodies here; another body is left as it is.)
pub fn set_mocap_pose(model: &Model, data: &mut Data, body: BodyId, pos: [f64; 3], quat: [f64; 4]) {
    if let Some(m) = model.body_mocap(body) {
        data.set_mocap_pose(m, &Pose { pos, quat });
    }
}

/// quat(euler XYZ (0, 0, yaw)) standardised to w ≥ 0, computed in float32 like upstream.
pub fn yaw_quat_f32(yaw: f32) -> [f64; 4] {
    let (s, c) = ((yaw / 2.0).sin(), (yaw / 2.0).cos());
    let q = if c < 0.0 {
        [-c, 0.0, 0.0, -s]
    } else {
        [c, 0.0, 0.0, s]
    };
    [q[0] as f64, q[1] as f64, q[2] as f64, q[3] as f64]
}

/// Angle between two vectors as ManiSkill computes it: vectors with norm < 1e-6 are left
/// unnormalised, the dot product is clipped to [−1, 1] (a zero force gives 90°).
pub fn angle_between(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    let n = |v: &Vector3<f64>| if v.norm() < 1e-6 { *v } else { v.normalize() };
    n(a).dot(&n(b)).clamp(-1.0, 1.0).acos()
}

/// The grasp check of docs/robots.md §1.3 from the finger forces and the fingers' y axes.
pub fn is_grasping(
    g: &GraspDef,
    data: &Data,
    fingers: [BodyId; 2],
    forces: &[[f64; 3]; 2],
) -> bool {
    let mut ok = true;
    for (k, (&body, sign)) in fingers.iter().zip([g.finger1.1, g.finger2.1]).enumerate() {
        let f = Vector3::from(forces[k]);
        let dir = crate::robots::body_y_axis(data, body) * sign;
        let angle = angle_between(&dir, &f).to_degrees();
        ok &= f.norm() >= g.min_force && angle <= g.max_angle_deg;
    }
    ok
}

/// Net contact force (world frame) on each finger body from `object`, summed over the
/// contacts of the current state (the last physics substep); zero for a robot without
/// fingers (`None`). No allocation.
pub fn finger_forces(
    model: &Model,
    data: &Data,
    fingers: Option<[BodyId; 2]>,
    object: BodyId,
    out: &mut [[f64; 3]; 2],
) {
    *out = [[0.0; 3]; 2];
    let Some(fingers) = fingers else {
        return;
    };
    let geom_body = model.geom_bodyid();
    for i in 0..data.ncon() {
        let (g1, g2) = data.contact_geoms(i);
        let body = |g: usize| BodyId::from_index(geom_body[g] as usize);
        let (b1, b2) = (body(g1), body(g2));
        for (k, &finger) in fingers.iter().enumerate() {
            let sign = if b1 == finger && b2 == object {
                -1.0 // force on geom1 = −(force on geom2)
            } else if b2 == finger && b1 == object {
                1.0
            } else {
                continue;
            };
            let c = data.contact(i);
            let f = data.contact_force(i);
            for (axis, o) in out[k].iter_mut().enumerate() {
                // world force on geom2 = frameᵀ · f[0..3]
                *o += sign
                    * (c.frame[axis] * f[0] + c.frame[3 + axis] * f[1] + c.frame[6 + axis] * f[2]);
            }
        }
    }
}

/// `sapien_utils.look_at(eye, target, up=(0,0,1))` expressed as a MuJoCo camera frame
/// (MuJoCo cameras look along −z with +y up): returns the quaternion (w, x, y, z).
pub fn look_at_mujoco(eye: [f64; 3], target: [f64; 3]) -> [f64; 4] {
    let forward = (Vector3::from(target) - Vector3::from(eye)).normalize();
    let left = Vector3::z().cross(&forward).normalize();
    let up = forward.cross(&left);
    // MuJoCo camera axes: x = right = −left, y = up, z = −forward.
    let m = nalgebra::Matrix3::from_columns(&[-left, up, -forward]);
    let q = UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(m));
    [q.w, q.i, q.j, q.k]
}

/// Adds the task's two cameras to a scene.
pub fn add_cameras(scene: &mut Scene, cams: (CameraDef, CameraDef)) {
    for c in [cams.0, cams.1] {
        scene.add_camera(
            c.name,
            c.eye,
            look_at_mujoco(c.eye, c.target),
            c.fovy.to_degrees(),
        );
    }
}

#[cfg(test)]
mod evaluation_tests {
    use super::pick_cube::PickCubeEval;
    use super::poke_cube::PokeCubeEval;

    #[test]
    fn results_round_trip_through_the_info_slice() {
        let e = PokeCubeEval {
            success: false,
            is_cube_placed: true,
            is_peg_cube_fit: false,
            is_peg_grasped: true,
            angle_diff: 0.25,
            head_to_cube_dist: 0.125,
        };
        let mut info = [f64::NAN; 6];
        e.write(&mut info);
        assert_eq!(info, [0.0, 1.0, 0.0, 1.0, 0.25, 0.125]);
        assert_eq!(PokeCubeEval::read(&info), e);
        assert_eq!(
            PokeCubeEval::KEYS,
            [
                "success",
                "is_cube_placed",
                "is_peg_cube_fit",
                "is_peg_grasped",
                "angle_diff",
                "head_to_cube_dist"
            ]
        );
        assert!(PokeCubeEval::is_flag("is_peg_grasped"));
        assert!(!PokeCubeEval::is_flag("angle_diff"));
        assert!(!PokeCubeEval::is_flag("no_such_key"));
        assert!(PickCubeEval::KEYS.iter().all(|k| PickCubeEval::is_flag(k)));
    }
}
