//! Policies for rollouts: the scripted `solver`s of solvers.md §7 and the `random` and `zero`
//! baselines.
//!
//! The solvers are the EE-space scripted policies (control mode `pd_ee_delta_pos`): every step
//! `action = [clip((target − tcp)/0.1, −L, L), gripper]`, with phases checked in order and
//! falling through in the same step. "k steps" in a phase means exactly k actions issued in
//! that phase, counting the step on which it was entered (the spec's [audited] reading).
//! Positions are read from MuJoCo before each step, so they work in every observation mode.

pub mod joint_ik;
pub mod place_sphere;
pub mod poke_cube;
pub mod xarm6;

use nalgebra::Vector3;
use rand::{Rng, SeedableRng};

use crate::env::Env;
use crate::tasks::body_id;

pub mod fetch;
pub mod fetch_tasks;

/// The policy names `rollout` and `eval` accept.
pub const POLICIES: [&str; 3] = ["solver", "random", "zero"];

/// A policy: fills an action for the env's current state.
pub trait Policy: std::fmt::Debug {
    /// Called after every reset.
    fn reset(&mut self, env: &Env);
    /// Writes the next action into `action` (length = the env's action dimension).
    fn act(&mut self, env: &Env, action: &mut [f32]);
}

/// The control mode a policy needs with `robot` (`None`: any). The scripted solvers drive
/// the end effector (`pd_ee_delta_pos`; Fetch and the xArm6 also turn the gripper, in
/// `pd_ee_delta_pose`) where the robot has EE controllers; SO100 and
/// WidowX AI have none upstream, so their solvers command joint positions (`pd_joint_pos`)
/// from an IK of their own.
pub fn required_control_mode(policy: &str, robot: &str) -> Option<&'static str> {
    if policy != "solver" {
        return None;
    }
    Some(match robot {
        "so100" | "widowxai" => "pd_joint_pos",
        // Fetch must turn its gripper to reach the cube (solvers/fetch.rs).
        "fetch" => "pd_ee_delta_pose",
        // The xArm6 turns its gripper to the cube's faces (solvers/xarm6.rs).
        "xarm6_robotiq" => "pd_ee_delta_pose",
        _ => "pd_ee_delta_pos",
    })
}

/// Builds a policy by name for `env` (random: seeded with `seed`).
pub fn make_policy(name: &str, env: &Env, seed: u64) -> Result<Box<dyn Policy>, String> {
    match name {
        "zero" => Ok(Box::new(Zero)),
        "random" => Ok(Box::new(Random(rand::rngs::StdRng::seed_from_u64(seed)))),
        "solver" => solver(env),
        _ => Err(format!(
            "unknown policy {name:?}; valid policies: {}",
            POLICIES.join(", ")
        )),
    }
}

/// All-zero actions.
#[derive(Debug)]
pub struct Zero;

impl Policy for Zero {
    fn reset(&mut self, _env: &Env) {}
    fn act(&mut self, _env: &Env, action: &mut [f32]) {
        action.fill(0.0);
    }
}

/// Uniform actions in the action space's bounds (seeded).
#[derive(Debug)]
pub struct Random(rand::rngs::StdRng);

impl Policy for Random {
    fn reset(&mut self, _env: &Env) {}
    fn act(&mut self, env: &Env, action: &mut [f32]) {
        let space = env.action_space();
        for ((a, lo), hi) in action.iter_mut().zip(&space.low).zip(&space.high) {
            let (lo, hi) = (lo.max(-1e3), hi.min(1e3));
            *a = if hi > lo {
                self.0.random_range(lo..hi)
            } else {
                lo
            };
        }
    }
}

/// The (env id, robot) pairs that have a scripted solver.
pub const SOLVED: [(&str, &str); 11] = [
    ("PickCube-v1", "panda"),
    ("PickCube-v1", "fetch"),
    ("PickCube-v1", "xarm6_robotiq"),
    ("PickCube-v1", "so100"),
    ("PickCube-v1", "widowxai"),
    ("PickCubeSO100-v1", "so100"),
    ("PickCubeWidowXAI-v1", "widowxai"),
    ("PlaceSphere-v1", "panda"),
    ("PlaceSphere-v1", "fetch"),
    ("PokeCube-v1", "panda"),
    ("PokeCube-v1", "fetch"),
];

/// Which scripted solver fits an (env, robot) pair.
fn solver(env: &Env) -> Result<Box<dyn Policy>, String> {
    let robot = env.robot_spec().uid;
    let mode = env
        .config()
        .control_mode
        .as_deref()
        .unwrap_or("pd_joint_delta_pos");
    let required = required_control_mode("solver", robot).unwrap_or(mode);
    if mode != required {
        return Err(format!(
            "the scripted solver for {robot} drives {required}, but the env uses {mode}"
        ));
    }
    match (env.id(), robot) {
        ("PickCube-v1", "panda") => Ok(Box::new(PickCubeSolver::new(
            env,
            PANDA_GRIPPER,
            PICK_HOLD_PANDA,
        )?)),
        ("PickCube-v1", "xarm6_robotiq") => Ok(Box::new(xarm6::Xarm6PickCube::new(env)?)),
        ("PlaceSphere-v1", "panda") => Ok(Box::new(place_sphere::PlaceSphereSolver::new(
            env,
            PANDA_GRIPPER,
        )?)),
        ("PokeCube-v1", "panda") => Ok(Box::new(poke_cube::PokeCubeSolver::new(
            env,
            PANDA_GRIPPER,
        )?)),
        ("PickCube-v1" | "PickCubeSO100-v1", "so100") => Ok(Box::new(
            joint_ik::JointIkPickCube::new(env, joint_ik::SO100)?,
        )),
        ("PickCube-v1" | "PickCubeWidowXAI-v1", "widowxai") => Ok(Box::new(
            joint_ik::JointIkPickCube::new(env, joint_ik::WIDOWXAI)?,
        )),
        ("PickCube-v1", "fetch") => Ok(Box::new(fetch::FetchPickCube::new(env)?)),
        ("PlaceSphere-v1", "fetch") => Ok(Box::new(fetch_tasks::FetchPlaceSphere::new(env)?)),
        ("PokeCube-v1", "fetch") => Ok(Box::new(fetch_tasks::FetchPokeCube::new(env)?)),
        (id, r) => Err(format!(
            "no scripted solver for {id} with {r}; available: {}",
            SOLVED
                .iter()
                .map(|(e, r)| format!("{e} with {r}"))
                .collect::<Vec<_>>()
                .join(", ")
        )),
    }
}

/// Gripper commands (open, close) of a robot's normalised gripper action.
#[derive(Debug, Clone, Copy)]
pub struct Gripper {
    /// Action value that opens.
    pub open: f32,
    /// Action value that closes.
    pub close: f32,
}

/// Panda: +1 opens (0.04 m), −1 closes (−0.01 m target).
pub const PANDA_GRIPPER: Gripper = Gripper {
    open: 1.0,
    close: -1.0,
};

/// xArm6 + Robotiq in `pd_ee_delta_pos`: the gripper action is a ±0.15 rad knuckle delta, so
/// −1 opens and +1 closes (solvers.md §7.1; the `solver` policy uses `xarm6::Xarm6PickCube`).
pub const XARM6_GRIPPER: Gripper = Gripper {
    open: -1.0,
    close: 1.0,
};

/// Position error scale of the EE-space policies (m per unit action).
const ACTION_SCALE: f64 = 0.1;

/// Writes `clip((target − tcp)/0.1, −limit, limit)` and the gripper value.
fn ee_action(
    target: Vector3<f64>,
    tcp: Vector3<f64>,
    limit: f64,
    gripper: f32,
    action: &mut [f32],
) {
    for k in 0..3 {
        action[k] = ((target[k] - tcp[k]) / ACTION_SCALE).clamp(-limit, limit) as f32;
    }
    action[3] = gripper;
}

/// solvers.md §7.1: above the cube, down to it, close for H steps, carry to the goal.
#[derive(Debug)]
pub struct PickCubeSolver {
    cube: usize,
    goal: usize,
    gripper: Gripper,
    /// Steps to hold the closing gripper before lifting.
    hold: usize,
    phase: usize,
    steps_in_phase: usize,
}

/// Lift-off height above the cube for the approach (m).
const PICK_APPROACH_HEIGHT: f64 = 0.05;
/// Approach tolerance (m).
const PICK_APPROACH_TOL: f64 = 0.01;
/// Descent tolerance (m).
const PICK_DESCEND_TOL: f64 = 0.004;
/// Panda: steps the gripper closes before lifting.
pub const PICK_HOLD_PANDA: usize = 3;
/// xArm6 + Robotiq: steps the gripper closes before lifting (0.15 rad per step).
pub const PICK_HOLD_XARM6: usize = 8;

impl PickCubeSolver {
    /// Resolves the cube and goal bodies of a PickCube env; `hold` is the number of steps the
    /// gripper closes before the lift.
    pub fn new(env: &Env, gripper: Gripper, hold: usize) -> Result<Self, String> {
        Ok(PickCubeSolver {
            cube: body_id(env.model(), "cube")?,
            goal: body_id(env.model(), "goal_site")?,
            gripper,
            hold,
            phase: 0,
            steps_in_phase: 0,
        })
    }
}

fn body_xyz(env: &Env, body: usize) -> Vector3<f64> {
    Vector3::from_column_slice(&env.data().xpos()[3 * body..3 * body + 3])
}

/// `agent.tcp.pose.p`: the TCP link's position (PlaceSphere, PokeCube), or `tcp_pose` for a
/// robot without a TCP link.
fn tcp_link_xyz(env: &Env) -> Vector3<f64> {
    match env.robot().tcp_body {
        Some(b) => body_xyz(env, b),
        None => Vector3::from(env.robot().tcp_pose(env.data()).0),
    }
}

impl Policy for PickCubeSolver {
    fn reset(&mut self, _env: &Env) {
        self.phase = 0;
        self.steps_in_phase = 0;
    }

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        let tcp = Vector3::from(env.robot().tcp_pose(env.data()).0);
        let cube = body_xyz(env, self.cube);
        let goal = body_xyz(env, self.goal);
        loop {
            let (target, grip) = match self.phase {
                0 => (
                    cube + Vector3::new(0.0, 0.0, PICK_APPROACH_HEIGHT),
                    self.gripper.open,
                ),
                1 => (cube, self.gripper.open),
                2 => (cube, self.gripper.close),
                _ => (goal, self.gripper.close),
            };
            let done = match self.phase {
                0 => (target - tcp).norm() < PICK_APPROACH_TOL,
                1 => (target - tcp).norm() < PICK_DESCEND_TOL,
                2 => self.steps_in_phase >= self.hold,
                _ => false,
            };
            if done {
                self.phase += 1;
                self.steps_in_phase = 0;
                continue;
            }
            self.steps_in_phase += 1;
            ee_action(target, tcp, 1.0, grip, action);
            return;
        }
    }
}
