//! Errors of building controllers, drives and IK chains for a robot.
use crate::mujoco::MjError;

/// Why a controller, its drives, its joint map or an IK chain could not be built. Messages
/// name the bad value; a MuJoCo lookup failure is the [`MjError`] source.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ControllerError {
    /// A part names a joint the robot does not have as an active joint.
    #[error("no active joint {0:?}")]
    NoActiveJoint(String),
    /// A mimic follower's control joint is not one of its part's joints.
    #[error("mimic control joint {joint:?} is not in part {part}")]
    MimicControl {
        /// The control joint.
        joint: &'static str,
        /// The part.
        part: &'static str,
    },
    /// Mimic followers on a part that is not a joint position part.
    #[error("part {0} has mimic followers but is not a joint position part")]
    MimicKind(&'static str),
    /// A forward-velocity base without exactly the 3 joints x, y, yaw.
    #[error("a forward-velocity base needs the 3 joints x, y, yaw, got {0}")]
    BaseJoints(usize),
    /// The EE link of an IK chain does not exist.
    #[error("robot has no link {0:?}")]
    NoLink(String),
    /// The root link of an IK chain does not exist.
    #[error("robot has no link {0:?} (IK root)")]
    NoIkRoot(String),
    /// The IK root is not an ancestor of the EE link.
    #[error("IK root link {root:?} is not an ancestor of {ee:?}")]
    NotAncestor {
        /// The root link.
        root: String,
        /// The EE link.
        ee: String,
    },
    /// The chain has more movable joints than the IK supports.
    #[error("chain to {ee} has {movable} joints; at most {max} supported")]
    ChainTooLong {
        /// The EE link.
        ee: String,
        /// Movable joints on the chain.
        movable: usize,
        /// The supported maximum.
        max: usize,
    },
    /// An arm joint is not on the chain to the EE link.
    #[error("arm joint {joint:?} is not on the chain to {ee}")]
    OffChain {
        /// The arm joint.
        joint: String,
        /// The EE link.
        ee: String,
    },
    /// A joint or actuator is missing from the compiled model.
    #[error(transparent)]
    Model(#[from] MjError),
}
