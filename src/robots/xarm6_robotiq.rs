//! UFactory xArm6 with a Robotiq 2F-85 gripper (docs/robots.md §4): 6 arm joints, a four-bar
//! linkage per finger with two loop closures, the right outer knuckle driving both sides.
use super::{GraspDef, InitNoise, RobotSpec, StaticRule, TcpDef};
use crate::controllers::{ControlMode, PartKind, PartSpec};
use crate::mjcf::{Connect, RobotOptions};

/// The `rest` keyframe (ManiSkill order: arm, then the gripper joints in breadth-first order).
pub const REST: [f64; 12] = [
    0.0, 0.22, -1.23, 0.0, 1.01, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
];

const ARM: [&str; 6] = ["joint1", "joint2", "joint3", "joint4", "joint5", "joint6"];
/// The gripper's control joint (mimic leader) and its follower.
const GRIPPER_CONTROL: &str = "right_outer_knuckle_joint";
const GRIPPER_FOLLOWER: &str = "left_outer_knuckle_joint";
/// The undriven joints of the linkage (ManiSkill's `gripper_passive`, 0 action dims).
pub const PASSIVE: [&str; 4] = [
    "left_inner_knuckle_joint",
    "right_inner_knuckle_joint",
    "left_inner_finger_joint",
    "right_inner_finger_joint",
];
const ARM_GAINS: (f64, f64, f64) = (1e4, 1e3, 100.0);
/// ManiSkill's active-gripper drive: stiffness, damping, force limit (docs/robots.md §4).
pub const MANISKILL_GRIPPER_GAINS: (f64, f64, f64) = (1e5, 2000.0, 0.1);
/// The drive mjskill installs on the knuckles: ManiSkill's force limit with a softer stiffness
/// and damping. It was needed under MuJoCo's implicit integrator (which linearised D = 2000
/// without the force clamp); with PhysX's drive law (`controllers::drive`) the upstream gains
/// work too, and this one still tracks ManiSkill's linkage closer (one-step knuckle error
/// 0.7–1.1e-2 rad against 1.0–1.5e-2; docs/physics.md). Both drives push with the full
/// 0.1 N·m except within F/kp of the target (1e-6 rad upstream, 0.02 rad here), so the squeeze
/// of a ±0.15 rad delta command is the same.
const GRIPPER_GAINS: (f64, f64, f64) = (GRIPPER_KP, GRIPPER_KD, MANISKILL_GRIPPER_GAINS.2);
/// Knuckle drive stiffness in MuJoCo (N·m/rad).
pub const GRIPPER_KP: f64 = 5.0;
/// Knuckle drive damping in MuJoCo (N·m·s/rad): the gripper closes in ~3 control steps
/// (measured: faster closing grasps PickCube's cube more reliably).
pub const GRIPPER_KD: f64 = 0.05;
/// Arm delta bound (rad) of the joint-delta modes.
const JOINT_DELTA: f32 = 0.1;
/// Gripper delta bound (rad) of the delta modes.
const GRIPPER_DELTA: f32 = 0.15;
/// Gripper range (rad) of the absolute modes: 0 open, 0.81 closed.
const GRIPPER_RANGE: (f32, f32) = (0.0, 0.81);
/// EE position / rotation delta bounds of the EE-delta modes.
const EE_DELTA: (f32, f32) = (-0.1, 0.1);
/// Bounds of the absolute `pd_ee_pose` mode.
const EE_POS_ABS: (f32, f32) = (-2.0, 2.0);
const EE_ROT_ABS: (f32, f32) = (-2.0 * std::f32::consts::PI, 2.0 * std::f32::consts::PI);
const EE_LINK: &str = "eef";

/// Links whose shapes never touch each other (ManiSkill sets collision-group-2 bit 31 on them).
pub const NO_SELF_COLLISION: [&str; 12] = [
    "right_inner_knuckle",
    "right_outer_knuckle",
    "left_inner_knuckle",
    "left_outer_knuckle",
    "right_inner_finger_pad",
    "left_inner_finger_pad",
    "right_outer_finger",
    "left_outer_finger",
    "robotiq_arg2f_base_link",
    "right_inner_finger",
    "left_inner_finger",
    "link5",
];

/// The loop closures (docs/robots.md §4): (inner knuckle, anchor in it, inner finger, anchor in it).
/// Both anchors coincide at q = 0, so MuJoCo's `connect` (anchor in the first body, the second
/// body's anchor derived at qpos0 = 0) reproduces both; a test checks the derived anchor.
pub const LOOP_CLOSURES: [(&str, [f64; 3], &str, [f64; 3]); 2] = [
    (
        "right_inner_knuckle",
        [-1.6048949e-08, 0.037600022, 0.043000020],
        "right_inner_finger",
        [1.3578170e-09, -0.017901104, 0.0065159947],
    ),
    (
        "left_inner_knuckle",
        [-1.8080145e-08, 0.037600014, 0.042999994],
        "left_inner_finger",
        [-1.4041154e-08, -0.017901093, 0.0065159872],
    ),
];

/// Armature (kg·m²) of the six linkage joints. The linkage links weigh 5–27 g (rotational
/// inertia ~1e-5 kg·m²); the robot-wide 0.1 would make the 0.1 N·m knuckle drive close the
/// gripper in ~1.3 s instead of a few control steps. See docs/physics.md.
pub const GRIPPER_ARMATURE: f64 = 3e-5;
/// Passive damping (N·m·s/rad) on the undriven linkage joints, which keeps the closed chain
/// from ringing under the stiff connect constraints.
pub const PASSIVE_DAMPING: f64 = 1e-3;

/// The finger pads (material friction 2.0, PhysX patch radius 0.1 m).
const PADS: [&str; 2] = ["left_inner_finger_pad", "right_inner_finger_pad"];
/// PhysX torsional patch radius of the pad material (m).
const PAD_PATCH_RADIUS: f64 = 0.1;
/// The pads' friction against default-material objects (PhysX average of 2.0 and 0.3).
const PAD_FRICTION_AVG: f64 = (2.0 + crate::mjcf::DEFAULT_FRICTION) / 2.0;

/// xArm6 control modes (docs/robots.md §4), default first.
pub const CONTROL_MODES: [ControlMode; 11] = super::ARM_EE_MODES;

/// The parts of an xArm6 control mode: the arm, then the active gripper (the right outer
/// knuckle takes the action, the left one mimics it ×1 + 0). The passive linkage joints
/// (ManiSkill's 0-dim `gripper_passive`: stiffness 0, damping 0) take no action and get no
/// drive. The gripper is absolute (radians in [0, 0.81], not normalised, not clipped) or a
/// normalised ±0.15 rad delta from the measured position, as upstream pairs it per mode.
pub fn parts(mode: ControlMode) -> Option<Vec<PartSpec>> {
    let ee =
        |rotation, use_target| PartKind::ee_delta(EE_LINK, None, rotation, use_target, EE_DELTA);
    let (kind, absolute_gripper) = match mode {
        ControlMode::PdJointDeltaPos => (PartKind::joint_delta(6, JOINT_DELTA, false), false),
        ControlMode::PdJointTargetDeltaPos => (PartKind::joint_delta(6, JOINT_DELTA, true), false),
        ControlMode::PdJointPos => (PartKind::joint_absolute(), true),
        ControlMode::PdEeDeltaPos => (ee(false, false), false),
        // Upstream pairs the EE delta pose with the absolute gripper (docs/robots.md §4).
        ControlMode::PdEeDeltaPose => (ee(true, false), true),
        ControlMode::PdEeTargetDeltaPos => (ee(false, true), false),
        ControlMode::PdEeTargetDeltaPose => (ee(true, true), false),
        ControlMode::PdEePose => (
            PartKind::ee_pose(EE_LINK, None, EE_POS_ABS, EE_ROT_ABS),
            true,
        ),
        ControlMode::PdJointVel => (PartKind::joint_vel(1.0), true),
        ControlMode::PdJointPosVel => (PartKind::joint_pos_vel(false, 1.0), true),
        ControlMode::PdJointDeltaPosVel => (PartKind::joint_delta_pos_vel(JOINT_DELTA, 1.0), false),
        _ => return None,
    };
    let gripper_kind = if absolute_gripper {
        PartKind::joint_range(1, GRIPPER_RANGE, false)
    } else {
        PartKind::joint_delta(1, GRIPPER_DELTA, false)
    };
    let gripper = PartSpec::new(
        "gripper_active",
        &[GRIPPER_CONTROL],
        gripper_kind,
        GRIPPER_GAINS,
    )
    .with_follower(GRIPPER_FOLLOWER, GRIPPER_CONTROL, 1.0, 0.0);
    Some(vec![PartSpec::new("arm", &ARM, kind, ARM_GAINS), gripper])
}

/// Scene options of the xArm6: loop closures, the bit-31 exclusion group, and the linkage's
/// armature and damping.
fn customize(opts: &mut RobotOptions) {
    for (l1, a1, l2, _) in LOOP_CLOSURES {
        opts.connects.push(Connect {
            link1: l1.to_string(),
            link2: l2.to_string(),
            anchor: a1,
        });
    }
    opts.stiff_connect = true;
    for pad in PADS {
        opts.torsional_friction
            .push((pad.to_string(), PAD_FRICTION_AVG * PAD_PATCH_RADIUS));
        opts.firm_contact.push(pad.to_string());
    }
    for (i, a) in NO_SELF_COLLISION.iter().enumerate() {
        for b in &NO_SELF_COLLISION[i + 1..] {
            opts.extra_excludes.push((a.to_string(), b.to_string()));
        }
    }
    for j in [GRIPPER_CONTROL, GRIPPER_FOLLOWER].iter().chain(&PASSIVE) {
        opts.armature.push((j.to_string(), GRIPPER_ARMATURE));
    }
    for j in PASSIVE {
        opts.damping.push((j.to_string(), PASSIVE_DAMPING));
    }
}

/// The xArm6 + Robotiq as ManiSkill configures it.
pub static XARM6_ROBOTIQ: RobotSpec = RobotSpec {
    id: super::RobotId::Xarm6Robotiq,
    urdf: "xarm6_robotiq/xarm6_robotiq.urdf",
    srdf: "xarm6_robotiq/xarm6_robotiq.srdf",
    arm_joints: &ARM,
    gripper_joints: &[GRIPPER_FOLLOWER, GRIPPER_CONTROL],
    arm_gains: ARM_GAINS,
    gripper_gains: GRIPPER_GAINS,
    finger_friction: (&PADS, 2.0),
    tcp: TcpDef::Link(EE_LINK),
    tcp_link: Some(EE_LINK),
    grasp: Some(GraspDef::new(
        ("left_inner_finger_pad", 1.0),
        ("right_inner_finger_pad", 1.0),
    )),
    static_rule: StaticRule::Arm(6),
    table_pose: ([-0.522, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]),
    table_qpos: &REST,
    init_noise: InitNoise::All,
    control_modes: &CONTROL_MODES,
    parts,
    cameras: &[],
    customize,
    clear_of_world: &["link1"],
};
