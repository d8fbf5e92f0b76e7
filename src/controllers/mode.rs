//! Control modes by name: every mode any robot offers, parsed once at the API edge. Which
//! modes a robot has, and what their parts are, is the robot's business (`robots/`).

/// A control mode (ManiSkill's `control_mode` names).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ControlMode {
    /// `pd_joint_delta_pos`.
    PdJointDeltaPos,
    /// `pd_joint_pos`.
    PdJointPos,
    /// `pd_ee_delta_pos`.
    PdEeDeltaPos,
    /// `pd_ee_delta_pose`.
    PdEeDeltaPose,
    /// `pd_ee_pose`.
    PdEePose,
    /// `pd_joint_target_delta_pos`.
    PdJointTargetDeltaPos,
    /// `pd_ee_target_delta_pos`.
    PdEeTargetDeltaPos,
    /// `pd_ee_target_delta_pose`.
    PdEeTargetDeltaPose,
    /// `pd_joint_vel`.
    PdJointVel,
    /// `pd_joint_pos_vel`.
    PdJointPosVel,
    /// `pd_joint_delta_pos_vel`.
    PdJointDeltaPosVel,
    /// `pd_joint_delta_pos_stiff_body` (Fetch).
    PdJointDeltaPosStiffBody,
}

impl ControlMode {
    /// Every mode.
    pub const ALL: [ControlMode; 12] = [
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
        ControlMode::PdJointDeltaPosStiffBody,
    ];

    /// ManiSkill's name of the mode.
    pub const fn name(self) -> &'static str {
        match self {
            ControlMode::PdJointDeltaPos => "pd_joint_delta_pos",
            ControlMode::PdJointPos => "pd_joint_pos",
            ControlMode::PdEeDeltaPos => "pd_ee_delta_pos",
            ControlMode::PdEeDeltaPose => "pd_ee_delta_pose",
            ControlMode::PdEePose => "pd_ee_pose",
            ControlMode::PdJointTargetDeltaPos => "pd_joint_target_delta_pos",
            ControlMode::PdEeTargetDeltaPos => "pd_ee_target_delta_pos",
            ControlMode::PdEeTargetDeltaPose => "pd_ee_target_delta_pose",
            ControlMode::PdJointVel => "pd_joint_vel",
            ControlMode::PdJointPosVel => "pd_joint_pos_vel",
            ControlMode::PdJointDeltaPosVel => "pd_joint_delta_pos_vel",
            ControlMode::PdJointDeltaPosStiffBody => "pd_joint_delta_pos_stiff_body",
        }
    }

    /// The mode of a name (None for a name no robot has; the robot's error lists its modes).
    pub fn from_name(name: &str) -> Option<ControlMode> {
        ControlMode::ALL.into_iter().find(|m| m.name() == name)
    }
}

impl std::fmt::Display for ControlMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_are_distinct() {
        for m in ControlMode::ALL {
            assert_eq!(ControlMode::from_name(m.name()), Some(m));
        }
        let mut names: Vec<&str> = ControlMode::ALL.iter().map(|m| m.name()).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), ControlMode::ALL.len());
        assert_eq!(ControlMode::from_name("pd_joint_delta"), None);
    }
}
