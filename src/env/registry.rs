//! The registry: which env ids exist, their robots and tasks, and how an env's scene is
//! built from them.
use serde::Serialize;

use super::{EnvError, ObsMode, RewardMode, SimConfig, MAX_EPISODE_STEPS};
use crate::mjcf::Mjcf;
use crate::robots::{RobotId, RobotSpec, TableScene};
use crate::tasks::Task;

/// The registered envs. Parsed once from an id at the API edge ([`EnvId::parse`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EnvId {
    /// `PickCube-v1`.
    PickCube,
    /// `PickCubeSO100-v1`.
    PickCubeSo100,
    /// `PickCubeWidowXAI-v1`.
    PickCubeWidowxAi,
    /// `PlaceSphere-v1`.
    PlaceSphere,
    /// `PokeCube-v1`.
    PokeCube,
    /// `PushCube-v1`.
    PushCube,
    /// `PullCube-v1`.
    PullCube,
    /// `StackCube-v1`.
    StackCube,
    /// `LiftPegUpright-v1`.
    LiftPegUpright,
    /// `PushT-v1`.
    PushT,
    /// `PegInsertionSide-v1`.
    PegInsertionSide,
}

impl EnvId {
    /// Every env, in the registry's order.
    pub const ALL: [EnvId; 11] = [
        EnvId::PickCube,
        EnvId::PickCubeSo100,
        EnvId::PickCubeWidowxAi,
        EnvId::PlaceSphere,
        EnvId::PokeCube,
        EnvId::PushCube,
        EnvId::PullCube,
        EnvId::StackCube,
        EnvId::LiftPegUpright,
        EnvId::PushT,
        EnvId::PegInsertionSide,
    ];

    /// The id as ManiSkill registers it.
    pub const fn id(self) -> &'static str {
        match self {
            EnvId::PickCube => "PickCube-v1",
            EnvId::PickCubeSo100 => "PickCubeSO100-v1",
            EnvId::PickCubeWidowxAi => "PickCubeWidowXAI-v1",
            EnvId::PlaceSphere => "PlaceSphere-v1",
            EnvId::PokeCube => "PokeCube-v1",
            EnvId::PushCube => "PushCube-v1",
            EnvId::PullCube => "PullCube-v1",
            EnvId::StackCube => "StackCube-v1",
            EnvId::LiftPegUpright => "LiftPegUpright-v1",
            EnvId::PushT => "PushT-v1",
            EnvId::PegInsertionSide => "PegInsertionSide-v1",
        }
    }

    /// Parses an env id; the error lists the valid ids.
    pub fn parse(id: &str) -> Result<EnvId, EnvError> {
        EnvId::ALL
            .into_iter()
            .find(|e| e.id() == id)
            .ok_or_else(|| {
                EnvError::UnknownEnv(id.to_string(), EnvId::ALL.map(EnvId::id).join(", "))
            })
    }

    /// The env's registration.
    pub fn spec(self) -> &'static EnvSpec {
        &REGISTRY[self as usize]
    }
}

/// A registered env.
#[derive(Debug, Clone)]
pub struct EnvSpec {
    /// Env id.
    pub id: EnvId,
    /// Supported robots (the first is the default).
    pub robots: &'static [RobotId],
    /// Steps until truncation.
    pub max_episode_steps: u32,
    pub(super) make_task: fn(RobotId) -> Box<dyn Task>,
}

/// Public description of a registered env, for listings.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EnvInfo {
    /// Env id.
    pub id: &'static str,
    /// Default robot.
    pub default_robot: &'static str,
    /// Supported robots with their control modes (default first).
    pub robots: Vec<(&'static str, Vec<&'static str>)>,
    /// Observation modes.
    pub obs_modes: Vec<&'static str>,
    /// Reward modes.
    pub reward_modes: Vec<&'static str>,
    /// Steps until truncation.
    pub max_episode_steps: u32,
}

fn pick_cube(robot: RobotId) -> Box<dyn Task> {
    Box::new(crate::tasks::pick_cube::PickCube::new(robot))
}

fn place_sphere(_robot: RobotId) -> Box<dyn Task> {
    Box::new(crate::tasks::place_sphere::PlaceSphere::new())
}

fn poke_cube(_robot: RobotId) -> Box<dyn Task> {
    Box::new(crate::tasks::poke_cube::PokeCube::new())
}

fn push_cube(_robot: RobotId) -> Box<dyn Task> {
    Box::new(crate::tasks::push_cube::PushCube::new())
}

fn pull_cube(_robot: RobotId) -> Box<dyn Task> {
    Box::new(crate::tasks::pull_cube::PullCube::new())
}

fn stack_cube(_robot: RobotId) -> Box<dyn Task> {
    Box::new(crate::tasks::stack_cube::StackCube::new())
}

fn lift_peg_upright(_robot: RobotId) -> Box<dyn Task> {
    Box::new(crate::tasks::lift_peg_upright::LiftPegUpright::new())
}

fn push_t(_robot: RobotId) -> Box<dyn Task> {
    Box::new(crate::tasks::push_t::PushT::new())
}

/// ManiSkill's `PUSH_T_MAX_EPISODE_STEPS`: PushT-v1 is registered with 100 steps.
const PUSH_T_MAX_EPISODE_STEPS: u32 = 100;

fn peg_insertion_side(_robot: RobotId) -> Box<dyn Task> {
    Box::new(crate::tasks::peg_insertion_side::PegInsertionSide::new())
}

/// PegInsertionSide-v1 is registered with 100 steps.
const PEG_INSERTION_SIDE_MAX_EPISODE_STEPS: u32 = 100;

static REGISTRY: [EnvSpec; 11] = [
    EnvSpec {
        id: EnvId::PickCube,
        robots: &[
            RobotId::Panda,
            RobotId::Fetch,
            RobotId::Xarm6Robotiq,
            RobotId::So100,
            RobotId::WidowxAi,
        ],
        max_episode_steps: MAX_EPISODE_STEPS,
        make_task: pick_cube,
    },
    EnvSpec {
        id: EnvId::PickCubeSo100,
        robots: &[RobotId::So100],
        max_episode_steps: MAX_EPISODE_STEPS,
        make_task: pick_cube,
    },
    EnvSpec {
        id: EnvId::PickCubeWidowxAi,
        robots: &[RobotId::WidowxAi],
        max_episode_steps: MAX_EPISODE_STEPS,
        make_task: pick_cube,
    },
    EnvSpec {
        id: EnvId::PlaceSphere,
        robots: &[RobotId::Panda, RobotId::Fetch],
        max_episode_steps: MAX_EPISODE_STEPS,
        make_task: place_sphere,
    },
    EnvSpec {
        id: EnvId::PokeCube,
        robots: &[RobotId::Panda, RobotId::Fetch],
        max_episode_steps: MAX_EPISODE_STEPS,
        make_task: poke_cube,
    },
    EnvSpec {
        id: EnvId::PushCube,
        robots: &[RobotId::Panda, RobotId::Fetch],
        max_episode_steps: MAX_EPISODE_STEPS,
        make_task: push_cube,
    },
    EnvSpec {
        id: EnvId::PullCube,
        robots: &[RobotId::Panda, RobotId::Fetch],
        max_episode_steps: MAX_EPISODE_STEPS,
        make_task: pull_cube,
    },
    EnvSpec {
        id: EnvId::StackCube,
        robots: &[RobotId::Panda, RobotId::Fetch, RobotId::PandaWristCam],
        max_episode_steps: MAX_EPISODE_STEPS,
        make_task: stack_cube,
    },
    EnvSpec {
        id: EnvId::LiftPegUpright,
        robots: &[RobotId::Panda, RobotId::Fetch],
        max_episode_steps: MAX_EPISODE_STEPS,
        make_task: lift_peg_upright,
    },
    EnvSpec {
        id: EnvId::PushT,
        robots: &[RobotId::PandaStick],
        max_episode_steps: PUSH_T_MAX_EPISODE_STEPS,
        make_task: push_t,
    },
    EnvSpec {
        id: EnvId::PegInsertionSide,
        robots: &[RobotId::PandaWristCam],
        max_episode_steps: PEG_INSERTION_SIDE_MAX_EPISODE_STEPS,
        make_task: peg_insertion_side,
    },
];

pub(super) fn env_spec(id: &str) -> Result<&'static EnvSpec, EnvError> {
    Ok(EnvId::parse(id)?.spec())
}

/// The default robot of a registered env.
pub fn default_robot(env_id: &str) -> Result<&'static str, EnvError> {
    Ok(env_spec(env_id)?.robots[0].uid())
}

/// Every registered env id with its robots, their control modes, and the modes.
pub fn registry() -> Vec<EnvInfo> {
    REGISTRY
        .iter()
        .map(|e| EnvInfo {
            id: e.id.id(),
            default_robot: e.robots[0].uid(),
            robots: e
                .robots
                .iter()
                .map(|r| {
                    let modes = r.spec().control_modes.iter().map(|m| m.name()).collect();
                    (r.uid(), modes)
                })
                .collect(),
            obs_modes: ObsMode::ALL.iter().map(|(n, _)| *n).collect(),
            reward_modes: RewardMode::ALL.iter().map(|(n, _)| *n).collect(),
            max_episode_steps: e.max_episode_steps,
        })
        .collect()
}

pub(super) fn resolve_robot(
    spec: &EnvSpec,
    robot: Option<&str>,
) -> Result<&'static RobotSpec, EnvError> {
    let id = match robot {
        Some(uid) => RobotId::parse(uid)?,
        None => spec.robots[0],
    };
    if !spec.robots.contains(&id) {
        return Err(EnvError::UnsupportedRobot {
            env: spec.id.id().into(),
            robot: id.uid().into(),
            valid: spec
                .robots
                .iter()
                .map(|r| r.uid())
                .collect::<Vec<_>>()
                .join(", "),
        });
    }
    Ok(id.spec())
}

/// Builds the MJCF of an env's scene for `robot` with its default control mode.
pub fn scene_mjcf(env_id: &str, robot: &str) -> Result<Mjcf, EnvError> {
    let spec = env_spec(env_id)?;
    let rs = resolve_robot(spec, Some(robot))?;
    let task = (spec.make_task)(rs.id);
    let scene = build_scene(
        spec,
        rs,
        rs.control_modes[0].name(),
        SimConfig::default(),
        task.as_ref(),
    )?;
    Ok(scene.mjcf)
}

/// The env's scene: the robot's table scene named `<env id>-<robot>` with the task's props.
pub(super) fn build_scene(
    spec: &EnvSpec,
    rs: &'static RobotSpec,
    control_mode: &str,
    sim: SimConfig,
    task: &dyn Task,
) -> Result<TableScene, EnvError> {
    // An unknown mode is the user's error (it lists the valid modes); anything else is a build
    // failure.
    rs.control_mode(control_mode)
        .map_err(EnvError::UnknownControlMode)?;
    TableScene::build(
        rs,
        &format!("{}-{}", spec.id.id(), rs.uid()),
        control_mode,
        sim.timestep(),
        |scene| task.build(scene),
    )
    .map_err(EnvError::Robot)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_env_id_finds_its_own_registration() {
        for id in EnvId::ALL {
            assert_eq!(id.spec().id, id);
            assert_eq!(EnvId::parse(id.id()), Ok(id));
        }
        assert_eq!(
            EnvId::parse("PickCube-v2").unwrap_err().to_string(),
            "unknown env id \"PickCube-v2\"; valid env ids: PickCube-v1, PickCubeSO100-v1, \
             PickCubeWidowXAI-v1, PlaceSphere-v1, PokeCube-v1, PushCube-v1, PullCube-v1, \
             StackCube-v1, LiftPegUpright-v1, PushT-v1, PegInsertionSide-v1"
        );
    }
}
