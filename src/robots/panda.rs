//! Franka Emika Panda (robots.md §2): 7 arm joints, two mimic-coupled prismatic fingers.
use std::f64::consts::PI;

use super::{GraspDef, InitNoise, RobotSpec, StaticRule, TcpDef};
use crate::controllers::{PartKind, PartSpec};

/// The Panda's rest keyframe (ManiSkill order).
pub const REST: [f64; 9] = [
    0.0,
    PI / 8.0,
    0.0,
    -5.0 * PI / 8.0,
    0.0,
    3.0 * PI / 4.0,
    PI / 4.0,
    0.04,
    0.04,
];

const ARM: [&str; 7] = [
    "panda_joint1",
    "panda_joint2",
    "panda_joint3",
    "panda_joint4",
    "panda_joint5",
    "panda_joint6",
    "panda_joint7",
];
const ARM_GAINS: (f64, f64, f64) = (1e3, 1e2, 100.0);
const GRIPPER_GAINS: (f64, f64, f64) = (1e3, 1e2, 100.0);
/// Arm delta bound (rad) of the joint-delta modes.
const JOINT_DELTA: f32 = 0.1;
/// EE position delta bound (m) and rotation delta bound (rad) of the EE-delta modes.
const EE_DELTA: (f32, f32) = (-0.1, 0.1);
/// Bounds of the absolute `pd_ee_pose` mode.
const EE_POS_ABS: (f32, f32) = (-2.0, 2.0);
const EE_ROT_ABS: (f32, f32) = (-2.0 * std::f32::consts::PI, 2.0 * std::f32::consts::PI);

/// Panda control modes (robots.md §2), default first.
pub const CONTROL_MODES: [&str; 11] = [
    "pd_joint_delta_pos",
    "pd_joint_pos",
    "pd_ee_delta_pos",
    "pd_ee_delta_pose",
    "pd_ee_pose",
    "pd_joint_target_delta_pos",
    "pd_ee_target_delta_pos",
    "pd_ee_target_delta_pose",
    "pd_joint_vel",
    "pd_joint_pos_vel",
    "pd_joint_delta_pos_vel",
];

fn gripper() -> PartSpec {
    PartSpec {
        name: "gripper",
        joints: vec!["panda_finger_joint1"],
        followers: vec![("panda_finger_joint2", "panda_finger_joint1", 1.0, 0.0)],
        kind: PartKind::JointPos {
            use_delta: false,
            use_target: false,
            normalize: true,
            low: Some(vec![-0.01]),
            high: Some(vec![0.04]),
        },
        gains: GRIPPER_GAINS,
    }
}

fn arm(kind: PartKind, gains: (f64, f64, f64)) -> PartSpec {
    PartSpec {
        name: "arm",
        joints: ARM.to_vec(),
        followers: vec![],
        kind,
        gains,
    }
}

fn joint_delta(use_target: bool) -> PartKind {
    PartKind::JointPos {
        use_delta: true,
        use_target,
        normalize: true,
        low: Some(vec![-JOINT_DELTA; 7]),
        high: Some(vec![JOINT_DELTA; 7]),
    }
}

fn ee(rotation: bool, use_target: bool) -> PartKind {
    PartKind::Ee {
        rotation,
        use_delta: true,
        use_target,
        pos: EE_DELTA,
        rot: EE_DELTA,
        ee_link: "panda_hand_tcp",
        root_link: None,
    }
}

/// The parts of a Panda control mode.
pub fn parts(mode: &str) -> Option<Vec<PartSpec>> {
    let arm = match mode {
        "pd_joint_delta_pos" => arm(joint_delta(false), ARM_GAINS),
        "pd_joint_target_delta_pos" => arm(joint_delta(true), ARM_GAINS),
        "pd_joint_pos" => arm(
            PartKind::JointPos {
                use_delta: false,
                use_target: false,
                normalize: false,
                low: None,
                high: None,
            },
            ARM_GAINS,
        ),
        "pd_ee_delta_pos" => arm(ee(false, false), ARM_GAINS),
        "pd_ee_delta_pose" => arm(ee(true, false), ARM_GAINS),
        "pd_ee_target_delta_pos" => arm(ee(false, true), ARM_GAINS),
        "pd_ee_target_delta_pose" => arm(ee(true, true), ARM_GAINS),
        "pd_ee_pose" => arm(
            PartKind::Ee {
                rotation: true,
                use_delta: false,
                use_target: false,
                pos: EE_POS_ABS,
                rot: EE_ROT_ABS,
                ee_link: "panda_hand_tcp",
                root_link: None,
            },
            ARM_GAINS,
        ),
        "pd_joint_vel" => arm(
            PartKind::JointVel {
                low: -1.0,
                high: 1.0,
            },
            (0.0, ARM_GAINS.1, ARM_GAINS.2),
        ),
        "pd_joint_pos_vel" => arm(
            PartKind::JointPosVel {
                use_delta: false,
                normalize: false,
                pos: (0.0, 0.0),
                vel: (-1.0, 1.0),
            },
            ARM_GAINS,
        ),
        "pd_joint_delta_pos_vel" => arm(
            PartKind::JointPosVel {
                use_delta: true,
                normalize: true,
                pos: (-JOINT_DELTA, JOINT_DELTA),
                vel: (-1.0, 1.0),
            },
            ARM_GAINS,
        ),
        _ => return None,
    };
    Some(vec![arm, gripper()])
}

/// The Panda as ManiSkill configures it.
pub static PANDA: RobotSpec = RobotSpec {
    uid: "panda",
    urdf: "panda/panda.urdf",
    srdf: "panda/panda.srdf",
    arm_joints: &ARM,
    gripper_joints: &["panda_finger_joint1", "panda_finger_joint2"],
    arm_gains: ARM_GAINS,
    gripper_gains: GRIPPER_GAINS,
    finger_friction: (&["panda_leftfinger", "panda_rightfinger"], 2.0),
    tcp: TcpDef::Link("panda_hand_tcp"),
    tcp_link: Some("panda_hand_tcp"),
    grasp: GraspDef {
        finger1: ("panda_leftfinger", 1.0),
        finger2: ("panda_rightfinger", -1.0),
        min_force: 0.5,
        max_angle_deg: 85.0,
    },
    static_rule: StaticRule::Arm(7),
    table_pose: ([-0.615, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]),
    table_qpos: &REST,
    init_noise: InitNoise::AllButLast(2),
    control_modes: &CONTROL_MODES,
    parts,
    customize: |_| {},
};
