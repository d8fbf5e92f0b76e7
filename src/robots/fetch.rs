//! Fetch mobile manipulator (docs/robots.md §3): a virtual planar base (x, y, yaw), a torso lift,
//! a pan/tilt head, a 7-dof arm (three continuous roll joints) and two prismatic fingers.
//!
//! Control modes have four parts in upstream order: arm, gripper, body (head pan, head tilt,
//! torso lift) and base ([forward speed, yaw rate] → velocity drives of the virtual joints).
//! Two modes differ from upstream on purpose (see docs/physics.md, "Per robot"):
//! * `pd_joint_pos_vel`: upstream normalises the absolute arm positions to the joint limits,
//!   which are ±inf for the continuous joints and yields NaN targets; mjskill normalises the
//!   limited joints and takes the continuous joints' positions as is (not clipped).
//! * the EE modes fail to construct upstream; mjskill implements the intended controller: IK
//!   of the 7 arm joints for `gripper_link` with poses relative to `torso_lift_link`.
use std::f64::consts::PI;

use super::{GraspDef, InitNoise, MountedCamera, RobotSpec, StaticRule, TcpDef};
use crate::controllers::{ControlMode, PartKind, PartSpec};
use crate::mjcf::RobotOptions;

/// Fetch's initial qpos in the table scene (ManiSkill's breadth-first order, docs/robots.md §3).
pub const TABLE_QPOS: [f64; 15] = [
    0.0,
    0.0,
    0.0,
    0.386,
    0.0,
    0.0,
    0.0,
    -PI / 4.0,
    0.0,
    PI / 4.0,
    0.0,
    PI / 3.0,
    0.0,
    0.015,
    0.015,
];

/// Joint names in ManiSkill's qpos order (breadth-first; docs/robots.md §3 table).
#[cfg(test)]
pub const JOINT_ORDER: [&str; 15] = [
    "root_x_axis_joint",
    "root_y_axis_joint",
    "root_z_rotation_joint",
    "torso_lift_joint",
    "head_pan_joint",
    "shoulder_pan_joint",
    "head_tilt_joint",
    "shoulder_lift_joint",
    "upperarm_roll_joint",
    "elbow_flex_joint",
    "forearm_roll_joint",
    "wrist_flex_joint",
    "wrist_roll_joint",
    "r_gripper_finger_joint",
    "l_gripper_finger_joint",
];

const ARM: [&str; 7] = [
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "upperarm_roll_joint",
    "elbow_flex_joint",
    "forearm_roll_joint",
    "wrist_flex_joint",
    "wrist_roll_joint",
];
/// Body joints in the order of the body controller's action.
const BODY: [&str; 3] = ["head_pan_joint", "head_tilt_joint", "torso_lift_joint"];
/// Virtual base joints (x, y, yaw).
const BASE: [&str; 3] = [
    "root_x_axis_joint",
    "root_y_axis_joint",
    "root_z_rotation_joint",
];
const ARM_GAINS: (f64, f64, f64) = (1e3, 1e2, 100.0);
const GRIPPER_GAINS: (f64, f64, f64) = (1e3, 1e2, 100.0);
const BODY_GAINS: (f64, f64, f64) = (1e3, 1e2, 100.0);
/// `pd_joint_delta_pos_stiff_body`'s body drive.
const STIFF_BODY_GAINS: (f64, f64, f64) = (1e5, 1e5, 1e5);
/// Base velocity drive: stiffness 0, damping 1000, force limit 500.
const BASE_GAINS: (f64, f64, f64) = (0.0, 1000.0, 500.0);
/// Base yaw-rate bound (rad/s): upstream's literal 3.14, not π.
#[allow(clippy::approx_constant)]
pub const YAW_RATE_MAX: f32 = 3.14;
/// Arm/body delta bound (rad or m) of the joint-delta modes.
const JOINT_DELTA: f32 = 0.1;
/// EE position and rotation delta bounds of the EE-delta modes.
const EE_DELTA: (f32, f32) = (-0.1, 0.1);
/// The EE link and the frame EE poses are expressed in (upstream `root_link_name`).
const EE_LINK: &str = "gripper_link";
const EE_ROOT: &str = "torso_lift_link";
/// Finger range (m) of the normalised absolute gripper action.
const GRIPPER_RANGE: (f32, f32) = (-0.01, 0.05);

/// Fetch control modes (docs/robots.md §3), default first.
pub const CONTROL_MODES: [ControlMode; 11] = [
    ControlMode::PdJointDeltaPos,
    ControlMode::PdJointPos,
    ControlMode::PdJointTargetDeltaPos,
    ControlMode::PdJointVel,
    ControlMode::PdJointPosVel,
    ControlMode::PdJointDeltaPosVel,
    ControlMode::PdJointDeltaPosStiffBody,
    ControlMode::PdEeDeltaPos,
    ControlMode::PdEeDeltaPose,
    ControlMode::PdEeTargetDeltaPos,
    ControlMode::PdEeTargetDeltaPose,
];

/// The parts of a Fetch control mode (arm, gripper, body, base).
pub fn parts(mode: ControlMode) -> Option<Vec<PartSpec>> {
    let ee = |rotation, use_target| {
        PartKind::ee_delta(EE_LINK, Some(EE_ROOT), rotation, use_target, EE_DELTA)
    };
    let kind = match mode {
        ControlMode::PdJointDeltaPos | ControlMode::PdJointDeltaPosStiffBody => {
            PartKind::joint_delta(7, JOINT_DELTA, false)
        }
        ControlMode::PdJointTargetDeltaPos => PartKind::joint_delta(7, JOINT_DELTA, true),
        ControlMode::PdJointPos => PartKind::joint_absolute(),
        ControlMode::PdJointVel => PartKind::joint_vel(1.0),
        ControlMode::PdJointPosVel => PartKind::joint_pos_vel(true, 1.0),
        ControlMode::PdJointDeltaPosVel => PartKind::joint_delta_pos_vel(JOINT_DELTA, 1.0),
        ControlMode::PdEeDeltaPos => ee(false, false),
        ControlMode::PdEeDeltaPose => ee(true, false),
        ControlMode::PdEeTargetDeltaPos => ee(false, true),
        ControlMode::PdEeTargetDeltaPose => ee(true, true),
        _ => return None,
    };
    let gripper = PartSpec::new(
        "gripper",
        &["l_gripper_finger_joint"],
        PartKind::joint_range(1, GRIPPER_RANGE, true),
        GRIPPER_GAINS,
    )
    .with_follower("r_gripper_finger_joint", "l_gripper_finger_joint", 1.0, 0.0);
    let body = if mode == ControlMode::PdJointDeltaPosStiffBody {
        PartSpec::new("body", &BODY, PartKind::joint_absolute(), STIFF_BODY_GAINS)
    } else {
        let kind = PartKind::joint_delta(3, JOINT_DELTA, false);
        PartSpec::new("body", &BODY, kind, BODY_GAINS)
    };
    let base = PartKind::base_forward_vel((-1.0, 1.0), (-YAW_RATE_MAX, YAW_RATE_MAX));
    Some(vec![
        PartSpec::new("arm", &ARM, kind, ARM_GAINS),
        gripper,
        body,
        PartSpec::new("base", &BASE, base, BASE_GAINS),
    ])
}

/// Fetch's two cameras (docs/robots.md §3 "robot cameras"): 128×128, fovy 2 rad (near 0.01 and
/// far 100 are the renderer's clip planes, shared by every camera).
pub const CAMERAS: [MountedCamera; 2] = [
    MountedCamera {
        name: "fetch_head",
        link: "head_camera_link",
        pos: [0.0, 0.0, 0.0],
        quat: [1.0, 0.0, 0.0, 0.0],
        fovy: 2.0,
        size: (128, 128),
    },
    MountedCamera {
        name: "fetch_hand",
        link: "gripper_link",
        pos: [-0.1, 0.0, 0.1],
        quat: [1.0, 0.0, 0.0, 0.0],
        fovy: 2.0,
        size: (128, 128),
    },
];

/// Fetch's scene options: the wheels never touch the ground (upstream puts them and the
/// ground in one collision group, docs/robots.md §3).
fn customize(opts: &mut RobotOptions) {
    opts.no_ground_contact = vec!["l_wheel_link".into(), "r_wheel_link".into()];
}

/// Fetch as ManiSkill configures it.
pub static FETCH: RobotSpec = RobotSpec {
    id: super::RobotId::Fetch,
    urdf: "fetch/fetch.urdf",
    srdf: "fetch/fetch.srdf",
    arm_joints: &ARM,
    gripper_joints: &["l_gripper_finger_joint", "r_gripper_finger_joint"],
    arm_gains: ARM_GAINS,
    gripper_gains: GRIPPER_GAINS,
    finger_friction: (&["l_gripper_finger_link", "r_gripper_finger_link"], 2.0),
    tcp: TcpDef::FingerMidpoint("l_gripper_finger_link", "r_gripper_finger_link"),
    tcp_link: Some("gripper_link"),
    grasp: Some(GraspDef::new(
        ("l_gripper_finger_link", -1.0),
        ("r_gripper_finger_link", 1.0),
    )),
    static_rule: StaticRule::FetchSigned {
        base_threshold: 0.05,
    },
    table_pose: ([-1.05, 0.0, -0.91964293], [1.0, 0.0, 0.0, 0.0]),
    table_qpos: &TABLE_QPOS,
    init_noise: InitNoise::None,
    control_modes: &CONTROL_MODES,
    parts,
    cameras: &CAMERAS,
    customize,
    clear_of_world: &[],
};
