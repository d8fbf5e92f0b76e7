//! Robots: what ManiSkill defines per robot (docs/robots.md) on top of its URDF — joint roles,
//! drive gains, the TCP, the grasp check, keyframes and the table-scene placement — and the
//! ids a compiled scene resolves them to ([`RobotIds`]).
pub mod fetch;
pub mod panda;
pub mod panda_stick;
pub mod panda_wristcam;
pub mod so100;
pub mod widowxai;
pub mod xarm6_robotiq;

use std::sync::Arc;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use crate::controllers::{ControlMode, Controller, ControllerError, Drives, JointMap, PartSpec};
use crate::mjcf::urdf::{RobotDesc, RobotError as UrdfError};
use crate::mjcf::{Drive, LinkCamera, RobotOptions, SceneError};
use crate::models::ModelFileError;
use crate::mujoco::{BodyId, Data, MjError, Model, ObjType};
use crate::rng::NumpyRandomState;

/// Why a robot, its control mode or its table scene could not be resolved or built. Messages
/// name the bad value and, for a bad uid or mode, list the valid choices; the failure of a
/// lower layer is the error's source.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RobotError {
    /// An unknown robot uid.
    #[error("unknown robot {u:?}; valid robots: {valid}", u = crate::files::short(.uid))]
    UnknownRobot {
        /// The requested uid.
        uid: String,
        /// The valid uids.
        valid: String,
    },
    /// A control mode this robot does not have (or no control mode at all).
    #[error(
        "unknown control mode {m:?} for robot {robot}; valid modes: {valid}",
        m = crate::files::short(.mode)
    )]
    UnknownControlMode {
        /// The requested mode.
        mode: String,
        /// The robot's uid.
        robot: &'static str,
        /// The robot's control modes.
        valid: String,
    },
    /// The robot has no link of this name.
    #[error("robot has no link {0:?}")]
    NoLink(String),
    /// The robot's URDF or SRDF is not shipped or not text.
    #[error(transparent)]
    ModelFile(#[from] ModelFileError),
    /// The robot's URDF could not be parsed.
    #[error(transparent)]
    Urdf(#[from] UrdfError),
    /// The controller or its drives could not be built.
    #[error(transparent)]
    Controller(#[from] ControllerError),
    /// The robot could not be added to the scene.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// MuJoCo rejected the scene, or a body is missing from the model.
    #[error(transparent)]
    Mujoco(#[from] MjError),
}

/// The seven robots. Parsed once from a uid at the API edge ([`RobotId::parse`]); code that
/// depends on the robot matches on this exhaustively.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RobotId {
    /// Franka Emika Panda.
    Panda,
    /// The Panda arm with a stick in place of its gripper (PushT-v1's robot).
    PandaStick,
    /// The Panda with its wrist camera (PegInsertionSide-v1's robot).
    PandaWristCam,
    /// Fetch mobile manipulator.
    Fetch,
    /// UFactory xArm6 with a Robotiq 2F-85 gripper.
    Xarm6Robotiq,
    /// SO-ARM100.
    So100,
    /// Trossen WidowX AI.
    WidowxAi,
}

impl RobotId {
    /// Every robot, in ManiSkill's order of `SUPPORTED_ROBOTS`.
    pub const ALL: [RobotId; 7] = [
        RobotId::Panda,
        RobotId::PandaStick,
        RobotId::PandaWristCam,
        RobotId::Fetch,
        RobotId::Xarm6Robotiq,
        RobotId::So100,
        RobotId::WidowxAi,
    ];

    /// ManiSkill's uid.
    pub const fn uid(self) -> &'static str {
        match self {
            RobotId::Panda => "panda",
            RobotId::PandaStick => "panda_stick",
            RobotId::PandaWristCam => "panda_wristcam",
            RobotId::Fetch => "fetch",
            RobotId::Xarm6Robotiq => "xarm6_robotiq",
            RobotId::So100 => "so100",
            RobotId::WidowxAi => "widowxai",
        }
    }

    /// Parses a uid; the error lists the valid uids.
    pub fn parse(uid: &str) -> Result<RobotId, RobotError> {
        RobotId::ALL
            .into_iter()
            .find(|r| r.uid() == uid)
            .ok_or_else(|| RobotError::UnknownRobot {
                uid: uid.to_string(),
                valid: ROBOT_UIDS.join(", "),
            })
    }

    /// The robot's spec.
    pub fn spec(self) -> &'static RobotSpec {
        match self {
            RobotId::Panda => &panda::PANDA,
            RobotId::PandaStick => &panda_stick::PANDA_STICK,
            RobotId::PandaWristCam => &panda_wristcam::PANDA_WRISTCAM,
            RobotId::Fetch => &fetch::FETCH,
            RobotId::Xarm6Robotiq => &xarm6_robotiq::XARM6_ROBOTIQ,
            RobotId::So100 => &so100::SO100,
            RobotId::WidowxAi => &widowxai::WIDOWXAI,
        }
    }
}

/// Robot uids, as ManiSkill spells them ([`RobotId::ALL`]).
pub const ROBOT_UIDS: [&str; 7] = [
    RobotId::ALL[0].uid(),
    RobotId::ALL[1].uid(),
    RobotId::ALL[2].uid(),
    RobotId::ALL[3].uid(),
    RobotId::ALL[4].uid(),
    RobotId::ALL[5].uid(),
    RobotId::ALL[6].uid(),
];

/// Control modes of an arm with joint, velocity and EE controllers (Panda, panda_stick, xArm6), in
/// upstream's order, default first.
pub const ARM_EE_MODES: [ControlMode; 11] = [
    ControlMode::PdJointDeltaPos,
    ControlMode::PdJointPos,
    ControlMode::PdEeDeltaPos,
    ControlMode::PdEeDeltaPose,
    ControlMode::PdEePose,
    ControlMode::PdJointTargetDeltaPos,
    ControlMode::PdEeTargetDeltaPos,
    ControlMode::PdEeTargetDeltaPose,
    ControlMode::PdJointVel,
    ControlMode::PdJointPosVel,
    ControlMode::PdJointDeltaPosVel,
];

/// Control modes of a joint-position-only arm (SO100, WidowX AI), default first.
pub const JOINT_POS_MODES: [ControlMode; 3] = [
    ControlMode::PdJointDeltaPos,
    ControlMode::PdJointPos,
    ControlMode::PdJointTargetDeltaPos,
];

/// Armature (kg·m² or kg) of every robot joint not listed otherwise. PhysX has none and the
/// drives need none for stability (`controllers::drive` is implicit); a hundredth steadies
/// the lightest wrist links at MuJoCo's explicit 0.01 s step (measured against ManiSkill's
/// one-step motion: WidowX AI wrist error 9.7e-4 → 4.5e-4 rad, Panda unchanged).
pub const ARMATURE: f64 = 0.01;

/// Armature of the gripper joints (unless the robot sets its own): as the arm's. (With the
/// contacts a finger pushes into folded into its drive, `controllers::drive`, a light finger
/// no longer needs added inertia to hold a grasp; with 0.1 kg the Panda's motion-planning
/// grasps left the cube 0.35–0.40 mm from ManiSkill's at step 50, with 0.01 kg 0.16–0.31 mm.)
pub const GRIPPER_ARMATURE: f64 = 0.01;

/// How the tool-centre point is defined (docs/robots.md: "TCP").
#[derive(Debug, Clone, PartialEq)]
pub enum TcpDef {
    /// The pose of a link (a site named `tcp` is placed at its origin).
    Link(&'static str),
    /// Fetch: the midpoint of two finger links with the element-wise average of their
    /// quaternions (not renormalised).
    FingerMidpoint(&'static str, &'static str),
    /// SO100: midpoint of two tip points (link, offset) with the orientation of a third link.
    JawTips {
        /// First tip: link and offset in the link frame.
        tip1: (&'static str, [f64; 3]),
        /// Second tip.
        tip2: (&'static str, [f64; 3]),
        /// Link whose orientation the TCP takes.
        orientation: &'static str,
    },
}

/// The grasp check of docs/robots.md §1.3.
#[derive(Debug, Clone, PartialEq)]
pub struct GraspDef {
    /// First finger link and the sign of its local y axis that is its opening direction.
    pub finger1: (&'static str, f64),
    /// Second finger link and its opening-direction sign.
    pub finger2: (&'static str, f64),
    /// Minimum contact force (N).
    pub min_force: f64,
    /// Maximum angle between opening direction and force (degrees).
    pub max_angle_deg: f64,
}

impl GraspDef {
    /// The two fingers (link, opening-direction sign) with ManiSkill's default thresholds:
    /// 0.5 N and 85°.
    pub const fn new(finger1: (&'static str, f64), finger2: (&'static str, f64)) -> GraspDef {
        GraspDef {
            finger1,
            finger2,
            min_force: 0.5,
            max_angle_deg: 85.0,
        }
    }
}

/// Which joints get initial-pose noise in the table scene (docs/tasks.md §0.2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum InitNoise {
    /// Draw `n_dof` normals, keep noise on all joints.
    All,
    /// Draw `n_dof` normals, then overwrite the last `k` joints with their rest value.
    AllButLast(usize),
    /// No draw at all.
    None,
}

/// `agent.is_static(threshold)` per robot (docs/env.md §10).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StaticRule {
    /// max |qvel[..n]| ≤ threshold over the first `n` dofs (the arm).
    Arm(usize),
    /// Fetch, as upstream: `qvel[3..n_dof−2] ≤ threshold` and `qvel[0..3] ≤ base_threshold`
    /// element-wise with a **signed** comparison (large negative velocities count as static;
    /// an upstream bug kept for parity).
    FetchSigned {
        /// Threshold of the base dofs (0.05).
        base_threshold: f64,
    },
}

impl StaticRule {
    /// Whether the robot with velocities `qvel` (ManiSkill order) is static.
    pub fn is_static(&self, qvel: &[f64], threshold: f64) -> bool {
        match *self {
            StaticRule::Arm(n) => qvel[..n].iter().all(|v| v.abs() <= threshold),
            StaticRule::FetchSigned { base_threshold } => {
                let n = qvel.len();
                qvel[3..n - 2].iter().all(|&v| v <= threshold)
                    && qvel[..3].iter().all(|&v| v <= base_threshold)
            }
        }
    }
}

/// A camera mounted on a robot link (ManiSkill's `_sensor_configs` with `mount=link`): the
/// pose is SAPIEN's camera frame (x forward, y left, z up) in the link frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MountedCamera {
    /// Camera name (the key of `obs["sensor_data"]`).
    pub name: &'static str,
    /// The link the camera is mounted on.
    pub link: &'static str,
    /// Position in the link frame.
    pub pos: [f64; 3],
    /// Orientation (w, x, y, z) of SAPIEN's camera frame in the link frame.
    pub quat: [f64; 4],
    /// Vertical field of view in radians.
    pub fovy: f64,
    /// Image width and height.
    pub size: (usize, usize),
}

impl MountedCamera {
    /// The MuJoCo camera's orientation (w, x, y, z) in the link frame: the mount rotation
    /// composed with the map from SAPIEN's camera frame to MuJoCo's (x right = −left,
    /// y up, z backward = −forward), as the tasks' `look_at` does for world cameras.
    pub fn mujoco_quat(&self) -> [f64; 4] {
        let q = self.quat;
        let mount =
            UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]));
        let m = nalgebra::Matrix3::new(0.0, 0.0, -1.0, -1.0, 0.0, 0.0, 0.0, 1.0, 0.0);
        let sapien_to_mujoco =
            UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(m));
        let r = mount * sapien_to_mujoco;
        [r.w, r.i, r.j, r.k]
    }
}

/// The gripper's convex collision parts next to a robot's URDF (read by
/// [`RobotSpec::convex_parts`]).
pub const CONVEX_PARTS_FILE: &str = "convex_parts.json";

/// Robots whose fingers collide through boxes in ManiSkill's own URDF too (the Panda's four
/// per finger): their convex parts are the model's finger boxes, with no file.
pub const BOX_FINGER_ROBOTS: &[&str] = &["panda", "panda_wristcam"];

/// Everything mjskill knows about one robot besides its URDF.
#[derive(Debug, Clone)]
pub struct RobotSpec {
    /// Which robot this is (its uid: [`RobotSpec::uid`]).
    pub id: RobotId,
    /// URDF path inside `models/`.
    pub urdf: &'static str,
    /// SRDF path inside `models/`.
    pub srdf: &'static str,
    /// Arm joints (ManiSkill order).
    pub arm_joints: &'static [&'static str],
    /// Gripper joints: (control joint, followers).
    pub gripper_joints: &'static [&'static str],
    /// Arm drive: stiffness, damping, force limit.
    pub arm_gains: (f64, f64, f64),
    /// Gripper drive: stiffness, damping, force limit.
    pub gripper_gains: (f64, f64, f64),
    /// Links with their own material friction (PhysX static = dynamic value).
    pub finger_friction: (&'static [&'static str], f64),
    /// TCP definition (`agent.tcp_pose`, used by PickCube).
    pub tcp: TcpDef,
    /// The TCP link (`agent.tcp`, used by PokeCube and PlaceSphere); None for so100.
    pub tcp_link: Option<&'static str>,
    /// Grasp check parameters; `None` for a robot without fingers (panda_stick, whose
    /// `is_grasping` ManiSkill leaves unimplemented): it never grasps.
    pub grasp: Option<GraspDef>,
    /// The `is_static` rule.
    pub static_rule: StaticRule,
    /// Root pose in the table scene: position and quaternion (w, x, y, z).
    pub table_pose: ([f64; 3], [f64; 4]),
    /// Initial qpos in the table scene (ManiSkill order).
    pub table_qpos: &'static [f64],
    /// Noise rule of the table scene.
    pub init_noise: InitNoise,
    /// Control modes, the default (ManiSkill's first) first.
    pub control_modes: &'static [ControlMode],
    /// The parts of a control mode (None for an unknown mode).
    pub parts: fn(ControlMode) -> Option<Vec<PartSpec>>,
    /// Cameras mounted on the robot's links, rendered in the visual obs modes besides the
    /// task's sensor camera (empty for most robots).
    pub cameras: &'static [MountedCamera],
    /// Robot-specific scene options on top of [`RobotSpec::options`]' defaults: loop
    /// closures, extra collision exclusions, links that ignore the ground, per-joint armature
    /// or damping of undriven joints.
    pub customize: fn(&mut RobotOptions),
    /// Links that cannot come within 2 cm of the table top or the floor at any joint position
    /// in range (checked by sampling, `src/tests/clearance.rs`): their contacts with the world
    /// are excluded ([`RobotOptions::clear_of_world`]).
    pub clear_of_world: &'static [&'static str],
}

impl RobotSpec {
    /// ManiSkill's uid of the robot.
    pub fn uid(&self) -> &'static str {
        self.id.uid()
    }

    /// The gripper's convex collision parts (`models/<uid>/convex_parts.json`), resolved in
    /// `model`: `(body, jaw, part)` with jaw 0 for the first link the file names and 1 for
    /// the second. The robots of [`BOX_FINGER_ROBOTS`] take their grasp fingers' collision
    /// boxes instead (jaw 0 the first finger). `Ok(None)`: the robot has none. Errors name
    /// the file and what is wrong.
    pub fn convex_parts(
        &self,
        model: &Model,
    ) -> Result<Option<Vec<crate::controllers::tgs::JawPart>>, String> {
        use crate::controllers::convex::{ConvexPart, ConvexPartsFile};
        if BOX_FINGER_ROBOTS.contains(&self.uid()) {
            return self.finger_box_parts(model).map(Some);
        }
        let path = format!("{}/{}", self.uid(), CONVEX_PARTS_FILE);
        let Ok(text) = crate::models::text(&path) else {
            return Ok(None);
        };
        let file: ConvexPartsFile =
            serde_json::from_str(text).map_err(|e| format!("models/{path}: {e}"))?;
        let mut links: Vec<&str> = Vec::new();
        let mut out = Vec::with_capacity(file.parts.len());
        for p in &file.parts {
            let body = model
                .id(ObjType::Body, &p.link)
                .ok_or_else(|| format!("models/{path}: no link {:?} in the model", p.link))?;
            let jaw = match links.iter().position(|l| *l == p.link) {
                Some(k) => k,
                None => {
                    links.push(&p.link);
                    links.len() - 1
                }
            };
            if jaw > 1 {
                return Err(format!(
                    "models/{path}: parts on {} links ({}); a gripper has two jaws",
                    links.len(),
                    links.join(", ")
                ));
            }
            out.push((
                body,
                jaw,
                ConvexPart::new(p).map_err(|e| format!("models/{path}: {e}"))?,
            ));
        }
        Ok(Some(out))
    }

    /// The collision boxes of the two grasp fingers in `model`, as convex parts.
    fn finger_box_parts(
        &self,
        model: &Model,
    ) -> Result<Vec<crate::controllers::tgs::JawPart>, String> {
        use crate::controllers::convex::ConvexPart;
        let grasp = self
            .grasp
            .as_ref()
            .ok_or_else(|| format!("{} has no grasp fingers", self.uid()))?;
        let mut out = Vec::new();
        for (jaw, link) in [grasp.finger1.0, grasp.finger2.0].into_iter().enumerate() {
            let body = model
                .id(ObjType::Body, link)
                .ok_or_else(|| format!("no finger link {link:?} in the model"))?;
            let before = out.len();
            for g in 0..model.ngeom() {
                if model.geom_bodyid()[g] as usize != body
                    || model.geom_group()[g] != crate::mjcf::GROUP_COLLISION
                {
                    continue;
                }
                if model.geom_type()[g] != crate::mujoco::GEOM_BOX {
                    return Err(format!("{link}'s collision geom {g} is not a box"));
                }
                let size = &model.geom_size()[3 * g..3 * g + 3];
                let p = &model.geom_pos()[3 * g..3 * g + 3];
                let q = &model.geom_quat()[4 * g..4 * g + 4];
                let rot = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                    q[0], q[1], q[2], q[3],
                ))
                .to_rotation_matrix()
                .into_inner();
                let part = ConvexPart::from_box(
                    link,
                    [size[0], size[1], size[2]],
                    Vector3::new(p[0], p[1], p[2]),
                    rot,
                )
                .map_err(|e| e.to_string())?;
                out.push((body, jaw, part));
            }
            if out.len() == before {
                return Err(format!("finger link {link:?} has no collision boxes"));
            }
        }
        Ok(out)
    }

    /// The root pose in the table scene.
    pub fn table_base(&self) -> Isometry3<f64> {
        let (p, q) = self.table_pose;
        Isometry3::from_parts(
            Translation3::new(p[0], p[1], p[2]),
            UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3])),
        )
    }

    /// The initial joint positions of a table-scene reset (docs/tasks.md §0.2): `table_qpos`
    /// plus this robot's noise rule ([`InitNoise`]) drawn from the numpy episode stream
    /// (`N(0, sigma)`, into `noise`), then rounded to float32 as PhysX stores joint positions.
    /// `noise` and `qpos` have the robot's dof; nothing is allocated.
    pub fn init_qpos(
        &self,
        numpy: &mut NumpyRandomState,
        sigma: f64,
        noise: &mut [f64],
        qpos: &mut [f64],
    ) {
        qpos.copy_from_slice(self.table_qpos);
        let keep = match self.init_noise {
            InitNoise::None => 0,
            InitNoise::All => noise.len(),
            InitNoise::AllButLast(k) => noise.len() - k,
        };
        if self.init_noise != InitNoise::None {
            numpy.fill_normal(0.0, sigma, noise);
        }
        for (q, z) in qpos.iter_mut().zip(noise.iter()).take(keep) {
            *q += z;
        }
        for q in qpos.iter_mut() {
            *q = *q as f32 as f64;
        }
    }

    /// A task's table scene that poses the robot again after the common one (PushT-v1's
    /// `WhiteTableSceneBuilder` with the panda_stick, PegInsertionSide-v1 with the
    /// panda_wristcam): `qpos` becomes `base` plus a second `N(0, sigma)` draw on every joint
    /// (into `noise`), rounded to float32; joints that the common pose keeps noise-free (the
    /// Panda's fingers, [`InitNoise::AllButLast`]) are set to `base` again, as upstream
    /// overwrites them. `base`, `noise` and `qpos` have the robot's dof; nothing is allocated.
    pub fn repose_qpos(
        &self,
        numpy: &mut NumpyRandomState,
        sigma: f64,
        base: &[f64],
        noise: &mut [f64],
        qpos: &mut [f64],
    ) {
        numpy.fill_normal(0.0, sigma, noise);
        let keep = match self.init_noise {
            InitNoise::AllButLast(k) => noise.len() - k,
            InitNoise::None | InitNoise::All => noise.len(),
        };
        for (k, ((q, b), z)) in qpos.iter_mut().zip(base).zip(noise.iter()).enumerate() {
            *q = if k < keep { b + z } else { *b } as f32 as f64;
        }
    }

    /// Loads and parses this robot's URDF and SRDF from `models/`.
    pub fn description(&self) -> Result<RobotDesc, RobotError> {
        let urdf = crate::models::text(self.urdf)?;
        let srdf = crate::models::text(self.srdf).ok();
        Ok(RobotDesc::parse(urdf, srdf, self.urdf)?)
    }

    /// Scene options for this robot placed at `base` with the given drives.
    pub fn options(&self, base: Isometry3<f64>, drives: Vec<Drive>) -> RobotOptions {
        let mut sites = Vec::new();
        if let Some(l) = self.tcp_link {
            sites.push(("tcp".to_string(), l.to_string(), [0.0; 3]));
        }
        let mut opts = RobotOptions {
            base,
            drives,
            default_armature: ARMATURE,
            material_friction: self
                .finger_friction
                .0
                .iter()
                .map(|l| (l.to_string(), self.finger_friction.1))
                .collect(),
            sites,
            cameras: self
                .cameras
                .iter()
                .map(|c| LinkCamera {
                    name: c.name.to_string(),
                    link: c.link.to_string(),
                    pos: c.pos,
                    quat: c.mujoco_quat(),
                    fovy_deg: c.fovy.to_degrees(),
                })
                .collect(),
            ..RobotOptions::default()
        };
        opts.clear_of_world = self.clear_of_world.iter().map(|l| l.to_string()).collect();
        (self.customize)(&mut opts);
        for j in self.gripper_joints {
            if !opts.armature.iter().any(|(n, _)| n == j) {
                opts.armature.push((j.to_string(), GRIPPER_ARMATURE));
            }
        }
        opts
    }

    /// The control mode named `mode` with its parts; the error (an unknown name or a mode
    /// this robot lacks) lists this robot's control modes.
    pub fn control_mode(&self, mode: &str) -> Result<(ControlMode, Vec<PartSpec>), RobotError> {
        ControlMode::from_name(mode)
            .and_then(|m| Some((m, (self.parts)(m)?)))
            .ok_or_else(|| RobotError::UnknownControlMode {
                mode: mode.to_string(),
                robot: self.uid(),
                valid: self
                    .control_modes
                    .iter()
                    .map(|m| m.name())
                    .collect::<Vec<_>>()
                    .join(", "),
            })
    }

    /// Drives with this robot's default gains on every arm and gripper joint.
    pub fn default_drives(&self) -> Vec<Drive> {
        let mk = |j: &&str, g: (f64, f64, f64)| Drive {
            joint: j.to_string(),
            kp: g.0,
            kd: g.1,
            force_limit: g.2,
        };
        self.arm_joints
            .iter()
            .map(|j| mk(j, self.arm_gains))
            .chain(
                self.gripper_joints
                    .iter()
                    .map(|j| mk(j, self.gripper_gains)),
            )
            .collect()
    }
}

/// Looks up a robot spec by uid; the error lists the valid uids.
pub fn spec(uid: &str) -> Result<&'static RobotSpec, RobotError> {
    Ok(RobotId::parse(uid)?.spec())
}

/// Resolved form of [`TcpDef`].
#[derive(Debug, Clone, PartialEq)]
pub enum TcpIds {
    /// A body's pose.
    Body(BodyId),
    /// Midpoint of two bodies, element-wise quaternion average.
    Midpoint(BodyId, BodyId),
    /// Midpoint of two offset points, orientation of a third body.
    Tips((BodyId, [f64; 3]), (BodyId, [f64; 3]), BodyId),
}

/// A robot's ids in a compiled model, resolved once when an env is built.
#[derive(Debug, Clone)]
pub struct RobotIds {
    /// The active joints (ManiSkill order): addresses, names, limits, actuators.
    pub joints: JointMap,
    /// Body ids of all robot links.
    pub bodies: Vec<BodyId>,
    /// Body of the root link (fixed to the world at the robot's table pose).
    pub root_body: BodyId,
    /// Body id per URDF link name lookup (name, id).
    pub link_bodies: Vec<(String, BodyId)>,
    /// The `tcp` site (at the TCP link's origin), when the robot has a TCP link.
    #[cfg_attr(not(test), allow(dead_code))] // read by the tests
    pub tcp_site: Option<usize>,
    /// Body of the TCP link.
    pub tcp_body: Option<BodyId>,
    /// Bodies and offsets that define `tcp_pose` (see [`TcpDef`]).
    pub tcp_parts: TcpIds,
    /// Body ids of the two grasp fingers (`None` for a robot without fingers).
    pub fingers: Option<[BodyId; 2]>,
    /// Weight m·g (N) of every body that moves and is not the robot's (the props), which
    /// [`RobotIds::apply_gravity`] applies: the scene's gravity is switched off
    /// ([`crate::mjcf`]).
    pub prop_weights: Vec<(BodyId, f64)>,
}

impl RobotIds {
    /// Resolves the ids of `robot` in `model`. Errors name what is missing.
    pub fn resolve(
        model: &Model,
        robot: &RobotDesc,
        spec: &RobotSpec,
    ) -> Result<RobotIds, RobotError> {
        let mut r = RobotIds {
            joints: JointMap::resolve(model, robot)?,
            bodies: Vec::new(),
            root_body: BodyId::default(),
            link_bodies: Vec::new(),
            tcp_site: model.id(ObjType::Site, "tcp"),
            tcp_body: None,
            tcp_parts: TcpIds::Body(BodyId::default()),
            fingers: None,
            prop_weights: Vec::new(),
        };
        for l in &robot.links {
            let b = model.require_body(&l.name)?;
            r.bodies.push(b);
            r.link_bodies.push((l.name.clone(), b));
        }
        r.prop_weights = crate::mjcf::prop_weights(model, &r.bodies);
        r.root_body = r.body(&robot.links[robot.root].name)?;
        r.fingers = match &spec.grasp {
            Some(g) => Some([r.body(g.finger1.0)?, r.body(g.finger2.0)?]),
            None => None,
        };
        r.tcp_body = spec.tcp_link.map(|l| r.body(l)).transpose()?;
        r.tcp_parts = match &spec.tcp {
            TcpDef::Link(l) => TcpIds::Body(r.body(l)?),
            TcpDef::FingerMidpoint(a, b) => TcpIds::Midpoint(r.body(a)?, r.body(b)?),
            TcpDef::JawTips {
                tip1,
                tip2,
                orientation,
            } => TcpIds::Tips(
                (r.body(tip1.0)?, tip1.1),
                (r.body(tip2.0)?, tip2.1),
                r.body(orientation)?,
            ),
        };
        Ok(r)
    }

    /// Body id of a robot link.
    pub fn body(&self, link: &str) -> Result<BodyId, RobotError> {
        self.link_bodies
            .iter()
            .find(|(n, _)| n == link)
            .map(|(_, b)| *b)
            .ok_or_else(|| RobotError::NoLink(link.to_string()))
    }

    /// Gravity as ManiSkill has it, on the props and not on the robot's links: sets
    /// `xfrc_applied` to the props' weights (m·g downward at each centre of mass) and to zero
    /// everywhere else. `xfrc_applied` persists across steps, so this is needed once per
    /// reset, and after a state is set (a state saved before the scene's gravity was
    /// switched off holds upward forces on the robot's links instead).
    pub fn apply_gravity(&self, data: &mut Data) {
        crate::mjcf::apply_weights(data, &self.prop_weights);
    }

    /// `agent.tcp_pose` (PickCube's TCP) as position and raw quaternion (w, x, y, z).
    pub fn tcp_pose(&self, data: &Data) -> ([f64; 3], [f64; 4]) {
        let pos = |b: BodyId| data.body_pos(b);
        let quat = |b: BodyId| data.body_quat(b);
        match &self.tcp_parts {
            TcpIds::Body(b) => (pos(*b), quat(*b)),
            TcpIds::Midpoint(a, b) => {
                let (pa, pb, qa, qb) = (pos(*a), pos(*b), quat(*a), quat(*b));
                (
                    [
                        (pa[0] + pb[0]) / 2.0,
                        (pa[1] + pb[1]) / 2.0,
                        (pa[2] + pb[2]) / 2.0,
                    ],
                    [
                        (qa[0] + qb[0]) / 2.0,
                        (qa[1] + qb[1]) / 2.0,
                        (qa[2] + qb[2]) / 2.0,
                        (qa[3] + qb[3]) / 2.0,
                    ],
                )
            }
            TcpIds::Tips((a, oa), (b, ob), o) => {
                let ta = Self::body_pose(data, *a) * nalgebra::Point3::from(*oa);
                let tb = Self::body_pose(data, *b) * nalgebra::Point3::from(*ob);
                let m = nalgebra::center(&ta, &tb);
                ([m.x, m.y, m.z], quat(*o))
            }
        }
    }

    /// Pose of a body in the world.
    pub fn body_pose(data: &Data, body: BodyId) -> Isometry3<f64> {
        data.body_pose(body).isometry()
    }
}

/// A robot in the table scene (plus whatever a task or test adds): the compiled model, the
/// robot's ids, the MJCF, and the controller of the chosen control mode with
/// its drives. Built by [`TableScene::build`], the one scene builder (envs, tests and
/// `export-mjcf` all use it).
#[derive(Debug)]
pub struct TableScene {
    /// The compiled physics model: the scene without its drawn-only geoms
    /// ([`crate::mjcf::Scene::finish_with_physics`]).
    pub model: Arc<Model>,
    /// Resolved ids.
    pub ids: RobotIds,
    /// The generated MJCF, every geom included (what `export-mjcf` writes and the renderer
    /// draws; [`TableScene::render_model`] compiles it).
    pub mjcf: crate::mjcf::Mjcf,
    /// The controller of the scene's control mode.
    pub controller: Controller,
    /// The drives of that controller (targets at zero until set).
    pub drives: Drives,
}

impl TableScene {
    /// Builds the scene named `name` at physics timestep `timestep` (s): the table, this robot
    /// at its table pose with the drives of control mode `mode`, then whatever `extra` adds (a
    /// task's props and cameras). Errors name what failed (an unknown mode lists the robot's
    /// modes).
    pub fn build(
        spec: &RobotSpec,
        name: &str,
        mode: &str,
        timestep: f64,
        extra: impl FnOnce(&mut crate::mjcf::Scene),
    ) -> Result<TableScene, RobotError> {
        let desc = spec.description()?;
        let (mode, parts) = spec.control_mode(mode)?;
        let controller = Controller::new(mode, parts, &desc)?;
        let drive_list = controller.drives(&desc);
        let mut scene = crate::mjcf::Scene::new(name, timestep);
        scene.add_table_scene();
        let options = spec.options(spec.table_base(), drive_list.clone());
        scene.add_robot(&desc, &options, &|file| {
            crate::models::file_near(spec.urdf, file).map(<[u8]>::to_vec)
        })?;
        extra(&mut scene);
        let (mjcf, physics) = scene.finish_with_physics();
        let model = Arc::new(physics.compile()?);
        let ids = RobotIds::resolve(&model, &desc, spec)?;
        let drives = Drives::new(
            &model,
            &drive_list,
            &ids.joints.names,
            spec.gripper_joints,
            options.gripper_release_depth,
        )?;
        Ok(TableScene {
            model,
            ids,
            mjcf,
            controller,
            drives,
        })
    }
}

impl TableScene {
    /// Compiles [`TableScene::mjcf`], the scene with every geom: the model a renderer draws.
    /// Its bodies, joints, mocap bodies and cameras are the physics model's, so a physics
    /// state carries over to it (qpos, mocap poses); its geoms are a superset.
    pub fn render_model(&self) -> Result<Model, RobotError> {
        let render = self.mjcf.compile()?;
        let m = &self.model;
        let same = render.nbody() == m.nbody()
            && render.nq() == m.nq()
            && render.nmocap() == m.nmocap()
            && render.ncam() == m.ncam();
        if !same {
            return Err(RobotError::Mujoco(MjError::Invalid(
                "the render model's bodies, joints or cameras differ from the physics model's"
                    .to_string(),
            )));
        }
        Ok(render)
    }
}

/// The table scene of this robot alone with the drives of its default control mode, plus
/// whatever `extra` adds (used by tests and `export-mjcf`), at the default physics timestep.
pub fn table_scene_with(
    spec: &RobotSpec,
    extra: impl FnOnce(&mut crate::mjcf::Scene),
) -> Result<TableScene, RobotError> {
    table_scene_at(spec, crate::mjcf::TIMESTEP, extra)
}

/// [`table_scene_with`] at physics timestep `timestep` (s).
pub fn table_scene_at(
    spec: &RobotSpec,
    timestep: f64,
    extra: impl FnOnce(&mut crate::mjcf::Scene),
) -> Result<TableScene, RobotError> {
    TableScene::build(
        spec,
        spec.uid(),
        spec.control_modes[0].name(),
        timestep,
        extra,
    )
}

/// The MJCF of `robot`'s table scene alone, with the drives of its default control mode (what
/// `mjskill export-mjcf --robot` writes). Errors: an unknown uid (listing the valid ones).
pub fn robot_scene_mjcf(robot: &str) -> Result<crate::mjcf::Mjcf, RobotError> {
    Ok(table_scene_with(spec(robot)?, |_| {})?.mjcf)
}

/// Unit vector helper: the local y axis of a body in world coordinates.
pub fn body_y_axis(data: &Data, body: BodyId) -> Vector3<f64> {
    let m = data.body_mat(body);
    Vector3::new(m[1], m[4], m[7])
}
