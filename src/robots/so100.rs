//! SO-100 arm (docs/robots.md §5): 5 arm joints and a revolute moving jaw, all driven by one
//! joint-position controller (no arm/gripper split).
use std::f64::consts::FRAC_PI_2;

use super::{GraspDef, InitNoise, RobotSpec, StaticRule, TcpDef};
use crate::controllers::{ControlMode, PartKind, PartSpec};

/// Joints in ManiSkill order (5 arm joints, then the gripper).
pub const JOINTS: [&str; 6] = [
    "shoulder_pan",
    "shoulder_lift",
    "elbow_flex",
    "wrist_flex",
    "wrist_roll",
    "gripper",
];

/// Table-scene initial qpos (docs/tasks.md §0.2) before noise.
pub const TABLE_QPOS: [f64; 6] = [0.0, 0.0, 0.0, FRAC_PI_2, FRAC_PI_2, 0.0];

/// Drive (stiffness, damping, force limit) of every joint.
const GAINS: (f64, f64, f64) = (1e3, 1e2, 100.0);
/// Delta bound (rad) of the arm joints in the joint-delta modes.
const ARM_DELTA: f32 = 0.05;
/// Delta bound (rad) of the gripper joint in the joint-delta modes.
const GRIPPER_DELTA: f32 = 0.2;

/// Fixed_Jaw_tip in the Fixed_Jaw frame.
pub const FIXED_JAW_TIP: [f64; 3] = [0.01, -0.097, 0.0];
/// Moving_Jaw_tip in the Moving_Jaw frame.
pub const MOVING_JAW_TIP: [f64; 3] = [-0.01, -0.073, 0.0];

/// SO100 control modes (docs/robots.md §5), default first.
pub const CONTROL_MODES: [ControlMode; 3] = super::JOINT_POS_MODES;

/// The parts of an SO100 control mode: always one part over all six joints.
pub fn parts(mode: ControlMode) -> Option<Vec<PartSpec>> {
    let delta = |use_target| {
        let bounds = [[ARM_DELTA; 5].as_slice(), &[GRIPPER_DELTA]].concat();
        PartKind::joint_delta_per(bounds, use_target)
    };
    let kind = match mode {
        ControlMode::PdJointDeltaPos => delta(false),
        ControlMode::PdJointTargetDeltaPos => delta(true),
        ControlMode::PdJointPos => PartKind::joint_absolute(),
        _ => return None,
    };
    Some(vec![PartSpec::new("arm", &JOINTS, kind, GAINS)])
}

/// Armature (kg·m²) of the jaw. With the default gripper armature the 20 g jaw, pinching the
/// cube against the fixed jaw with its stiff drive, rattles the grasp loose at the 0.01 s
/// step (scripted-solver success 13 %); 0.1 holds it (100 %), and the jaw still follows
/// ManiSkill's to 3.3e-4 rad at step 1 (docs/agreement.md).
const JAW_ARMATURE: f64 = 0.1;

/// Contact impedance of the jaws (constant; MuJoCo's `solimp`). PhysX's SO100 jaw does not stop
/// where it meets the cube: it sinks into it and follows its drive target to within a few
/// milliradians (target −0.85 rad: −0.848; −0.9: −0.897, the jaw about 8 mm inside the
/// cube, still holding it), with a grip of only ~10 N at −0.8, and passes through it at −1.0,
/// dropping the cube (docs/outcome-physics.md, "The SO100's yielding jaw"). MuJoCo's default
/// hard impedance stops the jaw at the cube (−0.82 for any target) and holds the cube under
/// any squeeze. A constant impedance of 0.993 makes the jaw contacts a spring of a few N/mm
/// on a cube, as PhysX's.
pub const JAW_SOLIMP: [f64; 3] = [0.993, 0.993, 0.001];

/// Penetration (m) at which the moving jaw lets go of the cube it has sunk into. With
/// [`JAW_SOLIMP`] the jaw reaches ManiSkill's angles for the same targets, and MuJoCo's
/// jaw–cube contact is 2.7 mm deep at −0.917 rad (PhysX still holds the cube there) and 3.15
/// mm at −0.937 (PhysX has dropped it).
pub const JAW_RELEASE_DEPTH: f64 = 0.0031;

/// The SO100 as ManiSkill configures it.
pub static SO100: RobotSpec = RobotSpec {
    id: super::RobotId::So100,
    urdf: "so100/so100.urdf",
    srdf: "so100/so100.srdf",
    arm_joints: JOINTS.split_at(5).0,
    gripper_joints: JOINTS.split_at(5).1,
    arm_gains: GAINS,
    gripper_gains: GAINS,
    finger_friction: (&["Fixed_Jaw", "Moving_Jaw"], 2.0),
    tcp: TcpDef::JawTips {
        tip1: ("Fixed_Jaw", FIXED_JAW_TIP),
        tip2: ("Moving_Jaw", MOVING_JAW_TIP),
        orientation: "Fixed_Jaw",
    },
    tcp_link: None,
    grasp: Some(GraspDef {
        max_angle_deg: 110.0,
        ..GraspDef::new(("Fixed_Jaw", 1.0), ("Moving_Jaw", -1.0))
    }),
    static_rule: StaticRule::Arm(5),
    table_pose: (
        [-0.725, 0.0, 0.0],
        [
            std::f64::consts::FRAC_1_SQRT_2,
            0.0,
            0.0,
            std::f64::consts::FRAC_1_SQRT_2,
        ],
    ),
    table_qpos: &TABLE_QPOS,
    init_noise: InitNoise::All,
    control_modes: &CONTROL_MODES,
    parts,
    cameras: &[],
    clear_of_world: &["Upper_Arm"],
    customize: |o| {
        o.armature.push(("gripper".to_string(), JAW_ARMATURE));
        for jaw in ["Fixed_Jaw", "Moving_Jaw"] {
            o.contact_solimp.push((jaw.to_string(), JAW_SOLIMP));
        }
        o.gripper_release_depth = Some(JAW_RELEASE_DEPTH);
    },
};
