//! The registry: which env ids exist, their robots and tasks, and how an env's scene is
//! built from them.
use serde::Serialize;

use super::{EnvError, ObsMode, RewardMode, SimConfig, MAX_EPISODE_STEPS};
use crate::mjcf::Mjcf;
use crate::robots::{RobotId, RobotSpec, TableScene};
use crate::tasks::Task;

/// A registered env.
#[derive(Debug, Clone)]
pub struct EnvSpec {
    /// Env id.
    pub id: &'static str,
    /// Supported robots (the first is the default).
    pub robots: &'static [&'static str],
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

static REGISTRY: [EnvSpec; 5] = [
    EnvSpec {
        id: "PickCube-v1",
        robots: &["panda", "fetch", "xarm6_robotiq", "so100", "widowxai"],
        max_episode_steps: MAX_EPISODE_STEPS,
        make_task: pick_cube,
    },
    EnvSpec {
        id: "PickCubeSO100-v1",
        robots: &["so100"],
        max_episode_steps: MAX_EPISODE_STEPS,
        make_task: pick_cube,
    },
    EnvSpec {
        id: "PickCubeWidowXAI-v1",
        robots: &["widowxai"],
        max_episode_steps: MAX_EPISODE_STEPS,
        make_task: pick_cube,
    },
    EnvSpec {
        id: "PlaceSphere-v1",
        robots: &["panda", "fetch"],
        max_episode_steps: MAX_EPISODE_STEPS,
        make_task: place_sphere,
    },
    EnvSpec {
        id: "PokeCube-v1",
        robots: &["panda", "fetch"],
        max_episode_steps: MAX_EPISODE_STEPS,
        make_task: poke_cube,
    },
];

pub(super) fn env_spec(id: &str) -> Result<&'static EnvSpec, EnvError> {
    REGISTRY.iter().find(|e| e.id == id).ok_or_else(|| {
        EnvError::UnknownEnv(
            id.to_string(),
            REGISTRY.iter().map(|e| e.id).collect::<Vec<_>>().join(", "),
        )
    })
}

/// The default robot of a registered env.
pub fn default_robot(env_id: &str) -> Result<&'static str, EnvError> {
    Ok(env_spec(env_id)?.robots[0])
}

/// Every registered env id with its robots, their control modes, and the modes.
pub fn registry() -> Vec<EnvInfo> {
    REGISTRY
        .iter()
        .map(|e| EnvInfo {
            id: e.id,
            default_robot: e.robots[0],
            robots: e
                .robots
                .iter()
                .map(|r| {
                    (
                        *r,
                        crate::robots::spec(r)
                            .map(|s| s.control_modes.to_vec())
                            .unwrap_or_default(),
                    )
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
    let uid = robot.unwrap_or(spec.robots[0]);
    crate::robots::spec(uid).map_err(EnvError::Build)?;
    if !spec.robots.contains(&uid) {
        return Err(EnvError::UnsupportedRobot {
            env: spec.id.into(),
            robot: uid.into(),
            valid: spec.robots.join(", "),
        });
    }
    crate::robots::spec(uid).map_err(EnvError::Build)
}

/// Builds the MJCF of an env's scene for `robot` with its default control mode.
pub fn scene_mjcf(env_id: &str, robot: &str) -> Result<Mjcf, String> {
    let spec = env_spec(env_id).map_err(|e| e.to_string())?;
    let rs = resolve_robot(spec, Some(robot)).map_err(|e| e.to_string())?;
    let task = (spec.make_task)(rs.id);
    let scene = build_scene(
        spec,
        rs,
        rs.control_modes[0],
        SimConfig::default(),
        task.as_ref(),
    )
    .map_err(|e| e.to_string())?;
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
        .map_err(EnvError::UnknownMode)?;
    TableScene::build(
        rs,
        &format!("{}-{}", spec.id, rs.uid()),
        control_mode,
        sim.timestep(),
        |scene| task.build(scene),
    )
    .map_err(EnvError::Build)
}
