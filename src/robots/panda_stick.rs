//! The Panda arm with a stick in place of its gripper, `panda_stick` (docs/robots.md §2.1):
//! the Panda's 7 arm joints, no fingers; its tool is a 0.1 m cylinder of radius 8 mm under the
//! hand whose tip is the TCP link `panda_hand_tcp`, 0.15 m below the hand. PushT-v1's robot.

use super::panda::{arm_part, ARM, ARM_GAINS};
use super::{InitNoise, RobotSpec, StaticRule, TcpDef};
use crate::controllers::{ControlMode, PartSpec};

/// The `rest` keyframe of ManiSkill's `PandaStick` (the Panda's arm rest pose): where the
/// common table scene puts it, before the noise. (PushT-v1, its one task, poses it again:
/// `tasks::push_t::ROBOT_QPOS`.)
pub const REST: [f64; 7] = super::panda::ARM_REST;

/// The TCP link: the stick's tip.
const TCP: &str = super::panda::TCP;

/// The panda_stick's control modes (ManiSkill's order, default first): the Panda's arm modes.
pub const CONTROL_MODES: [ControlMode; 11] = super::ARM_EE_MODES;

/// The parts of a panda_stick control mode: the Panda's arm part alone, as the one entry of
/// ManiSkill's controller dict (`dict(arm=...)`: its state keys read `arm.target_qpos`).
pub fn parts(mode: ControlMode) -> Option<Vec<PartSpec>> {
    Some(vec![arm_part(mode)?.keyed()])
}

/// The panda_stick as ManiSkill configures it.
pub static PANDA_STICK: RobotSpec = RobotSpec {
    id: super::RobotId::PandaStick,
    urdf: "panda/panda_stick.urdf",
    srdf: "panda/panda_stick.srdf",
    arm_joints: &ARM,
    gripper_joints: &[],
    arm_gains: ARM_GAINS,
    gripper_gains: ARM_GAINS,
    finger_friction: (&[], crate::mjcf::DEFAULT_FRICTION),
    tcp: TcpDef::Link(TCP),
    tcp_link: Some(TCP),
    // No fingers: ManiSkill's `PandaStick` does not implement `is_grasping`.
    grasp: None,
    // Upstream's `is_static` drops the last two entries of qvel as the Panda's does (there
    // the fingers), so joints 6 and 7 are not checked.
    static_rule: StaticRule::Arm(5),
    table_pose: ([-0.615, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]),
    table_qpos: &REST,
    init_noise: InitNoise::All,
    control_modes: &CONTROL_MODES,
    parts,
    cameras: &[],
    customize: |_| {},
    clear_of_world: &["panda_link1", "panda_link2", "panda_link3"],
};
