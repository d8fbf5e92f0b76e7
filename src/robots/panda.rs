//! Franka Emika Panda (docs/robots.md §2): 7 arm joints, two mimic-coupled prismatic fingers.
use std::f64::consts::PI;

use super::{GraspDef, InitNoise, RobotSpec, StaticRule, TcpDef};
use crate::controllers::{ControlMode, PartKind, PartSpec};

/// The arm's part of the rest keyframe (ManiSkill order), which `panda_stick` shares.
pub const ARM_REST: [f64; 7] = [
    0.0,
    PI / 8.0,
    0.0,
    -5.0 * PI / 8.0,
    0.0,
    3.0 * PI / 4.0,
    PI / 4.0,
];

/// The Panda's rest keyframe (ManiSkill order): the arm's, the fingers open.
pub const REST: [f64; 9] = [
    ARM_REST[0],
    ARM_REST[1],
    ARM_REST[2],
    ARM_REST[3],
    ARM_REST[4],
    ARM_REST[5],
    ARM_REST[6],
    0.04,
    0.04,
];

/// The arm joints (ManiSkill order).
pub const ARM: [&str; 7] = [
    "panda_joint1",
    "panda_joint2",
    "panda_joint3",
    "panda_joint4",
    "panda_joint5",
    "panda_joint6",
    "panda_joint7",
];
/// Arm drive: stiffness, damping, force limit.
pub const ARM_GAINS: (f64, f64, f64) = (1e3, 1e2, 100.0);
const GRIPPER_GAINS: (f64, f64, f64) = (1e3, 1e2, 100.0);
/// Arm delta bound (rad) of the joint-delta modes.
const JOINT_DELTA: f32 = 0.1;
/// EE position delta bound (m) and rotation delta bound (rad) of the EE-delta modes.
const EE_DELTA: (f32, f32) = (-0.1, 0.1);
/// Bounds of the absolute `pd_ee_pose` mode.
const EE_POS_ABS: (f32, f32) = (-2.0, 2.0);
const EE_ROT_ABS: (f32, f32) = (-2.0 * std::f32::consts::PI, 2.0 * std::f32::consts::PI);
/// Gripper range (m) of the normalised absolute finger action.
const GRIPPER_RANGE: (f32, f32) = (-0.01, 0.04);
/// The TCP / EE link.
pub const TCP: &str = "panda_hand_tcp";

/// Panda control modes (docs/robots.md §2), default first.
pub const CONTROL_MODES: [ControlMode; 11] = super::ARM_EE_MODES;

/// The Panda arm's part of a control mode (ManiSkill's arm controllers, shared by the Panda and
/// the panda_stick: same joints, gains, bounds and EE link name `panda_hand_tcp`).
pub fn arm_part(mode: ControlMode) -> Option<PartSpec> {
    let ee = |rotation, use_target| PartKind::ee_delta(TCP, None, rotation, use_target, EE_DELTA);
    let kind = match mode {
        ControlMode::PdJointDeltaPos => PartKind::joint_delta(7, JOINT_DELTA, false),
        ControlMode::PdJointTargetDeltaPos => PartKind::joint_delta(7, JOINT_DELTA, true),
        ControlMode::PdJointPos => PartKind::joint_absolute(),
        ControlMode::PdEeDeltaPos => ee(false, false),
        ControlMode::PdEeDeltaPose => ee(true, false),
        ControlMode::PdEeTargetDeltaPos => ee(false, true),
        ControlMode::PdEeTargetDeltaPose => ee(true, true),
        ControlMode::PdEePose => PartKind::ee_pose(TCP, None, EE_POS_ABS, EE_ROT_ABS),
        ControlMode::PdJointVel => PartKind::joint_vel(1.0),
        ControlMode::PdJointPosVel => PartKind::joint_pos_vel(false, 1.0),
        ControlMode::PdJointDeltaPosVel => PartKind::joint_delta_pos_vel(JOINT_DELTA, 1.0),
        _ => return None,
    };
    Some(PartSpec::new("arm", &ARM, kind, ARM_GAINS))
}

/// The parts of a Panda control mode: arm, then the mimic-coupled gripper.
pub fn parts(mode: ControlMode) -> Option<Vec<PartSpec>> {
    let gripper = PartSpec::new(
        "gripper",
        &["panda_finger_joint1"],
        PartKind::joint_range(1, GRIPPER_RANGE, true),
        GRIPPER_GAINS,
    )
    .with_follower("panda_finger_joint2", "panda_finger_joint1", 1.0, 0.0);
    Some(vec![arm_part(mode)?, gripper])
}

/// The Panda as ManiSkill configures it.
pub static PANDA: RobotSpec = PANDA_SPEC;

/// [`PANDA`]'s value, which the Panda's variants (`panda_wristcam`) start from.
pub(crate) const PANDA_SPEC: RobotSpec = RobotSpec {
    id: super::RobotId::Panda,
    urdf: "panda/panda.urdf",
    srdf: "panda/panda.srdf",
    arm_joints: &ARM,
    gripper_joints: &["panda_finger_joint1", "panda_finger_joint2"],
    arm_gains: ARM_GAINS,
    gripper_gains: GRIPPER_GAINS,
    finger_friction: (&["panda_leftfinger", "panda_rightfinger"], 2.0),
    tcp: TcpDef::Link(TCP),
    tcp_link: Some(TCP),
    grasp: Some(GraspDef::new(
        ("panda_leftfinger", 1.0),
        ("panda_rightfinger", -1.0),
    )),
    static_rule: StaticRule::Arm(7),
    table_pose: ([-0.615, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]),
    table_qpos: &REST,
    init_noise: InitNoise::AllButLast(2),
    control_modes: &CONTROL_MODES,
    parts,
    cameras: &[],
    customize: |_| {},
    clear_of_world: &["panda_link1", "panda_link2", "panda_link3"],
};
