//! The Panda with its wrist camera, `panda_wristcam` (docs/robots.md §2.2): ManiSkill's
//! `PandaWristCam` (`panda_v3.urdf`), the Panda's joints, gains, controllers and grasp check,
//! plus a RealSense body of 0.564 kg on the hand (`camera_link`, with a box collision) that
//! carries the 128×128 `hand_camera`. PegInsertionSide-v1's robot.

use super::{MountedCamera, RobotSpec};

/// The panda_wristcam's rest pose in ManiSkill's table scene: the Panda's, but the wrist
/// (joint 7) turned the other way, −π/4, so that the camera faces forward.
pub const REST: [f64; 9] = {
    let a = super::panda::ARM_REST;
    [a[0], a[1], a[2], a[3], a[4], a[5], -a[6], 0.04, 0.04]
};

/// ManiSkill's `hand_camera`: mounted on `camera_link` at its origin, 90° field of view.
const CAMERAS: [MountedCamera; 1] = [MountedCamera {
    name: "hand_camera",
    link: "camera_link",
    pos: [0.0, 0.0, 0.0],
    quat: [1.0, 0.0, 0.0, 0.0],
    fovy: std::f64::consts::FRAC_PI_2,
    size: (128, 128),
}];

/// The panda_wristcam as ManiSkill configures it: the Panda's spec with the v3 URDF, its rest
/// pose and the hand camera.
pub static PANDA_WRISTCAM: RobotSpec = RobotSpec {
    id: super::RobotId::PandaWristCam,
    urdf: "panda/panda_wristcam.urdf",
    srdf: "panda/panda_wristcam.srdf",
    table_qpos: &REST,
    cameras: &CAMERAS,
    ..super::panda::PANDA_SPEC
};
