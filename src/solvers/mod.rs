//! Policies for rollouts: the scripted `solver`s of docs/solvers.md §7, the `random` and `zero`
//! baselines, and trained policies from policy files ([`onnx`], docs/training.md).
//!
//! The solvers are the EE-space scripted policies (control mode `pd_ee_delta_pos`): every step
//! `action = [clip((target − tcp)/0.1, −L, L), gripper]`, with phases checked in order and
//! falling through in the same step. "k steps" in a phase means exactly k actions issued in
//! that phase, counting the step on which it was entered (the spec's \[audited\] reading).
//! Positions are read from MuJoCo before each step, so they work in every observation mode.

mod convert;
mod evaluate;
pub mod expert;
pub(crate) mod fetch;
pub(crate) mod fetch_arm;
pub(crate) mod fetch_expert;
pub(crate) mod fetch_tasks;
pub(crate) mod joint_ik;
pub(crate) mod lift_peg_upright;
pub mod mlp;
pub mod noise;
#[cfg(feature = "onnx")]
pub mod onnx;
#[cfg(feature = "onnx")]
pub(crate) mod onnx_guard;
pub(crate) mod peg_insertion_side;
pub(crate) mod pick_cube;
pub(crate) mod place_sphere;
pub(crate) mod poke_cube;
pub(crate) mod push_cube;
pub(crate) mod push_t;
pub(crate) mod stack_cube;
pub(crate) mod xarm6;

pub use convert::ModeConverted;
use convert::Shadow;
pub use evaluate::{
    check_seed_range, evaluate, evaluate_spec, make_env, run_episode, EpisodeResult, EvalError,
    EvalReport, PolicySpec, DEFAULT_ENV,
};
pub use expert::{set_state_experts, state_expert, StateExpert, STATE_EXPERTS};
pub use mlp::{GaussianMlp, MlpError, MAX_LAYER_ELEMENTS};
pub use noise::{ActionNoise, NoiseError};
#[cfg(feature = "onnx")]
pub use onnx::{OnnxPolicy, PolicyFile, PolicyFileError, PolicyMeta};

use nalgebra::{UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};

use crate::controllers::ControllerError;
use crate::env::Env;
use crate::mujoco::BodyId;
use crate::mujoco::MjError;
use crate::robots::{RobotError, RobotId};

/// Why a policy could not be built for an env.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolverError {
    /// An unknown policy name.
    #[error("unknown policy {name:?}; valid policies: {valid}")]
    UnknownPolicy {
        /// The requested name.
        name: String,
        /// The valid names.
        valid: String,
    },
    /// The env's control mode is not the one the scripted solver drives, and the solver's
    /// actions cannot be converted to it ([`ModeConverted`]).
    #[error(
        "the scripted solver for {robot} drives {required}, and its actions cannot be \
         converted to the env's {mode}: {why}"
    )]
    WrongControlMode {
        /// The robot.
        robot: &'static str,
        /// The mode the solver drives.
        required: String,
        /// The env's mode.
        mode: String,
        /// Why the conversion is refused.
        why: String,
    },
    /// No scripted solver for this (env, robot) pair.
    #[error("no scripted solver for {env} with {robot}; available: {available}")]
    NoSolver {
        /// The env id.
        env: &'static str,
        /// The robot.
        robot: &'static str,
        /// The solved pairs.
        available: String,
    },
    /// No state expert ([`expert`]) for this (env, robot) pair.
    #[error("no state expert for {env} with {robot}; available: {available}")]
    NoStateExpert {
        /// The env id.
        env: &'static str,
        /// The robot.
        robot: &'static str,
        /// The pairs that have one.
        available: String,
    },
    /// The Fetch solvers need the 15-dof Fetch.
    #[error("the Fetch solvers need the 15-dof Fetch")]
    FetchDof,
    /// A robot link or description the solver needs is missing.
    #[error(transparent)]
    Robot(#[from] RobotError),
    /// The solver's IK chain could not be built.
    #[error(transparent)]
    Controller(#[from] ControllerError),
    /// A task body the solver needs is missing from the model.
    #[error(transparent)]
    Mujoco(#[from] MjError),
    /// A policy file could not be loaded, fitted to the env or run.
    #[cfg(feature = "onnx")]
    #[error(transparent)]
    PolicyFile(#[from] PolicyFileError),
    /// A policy file given to an mjskill built without its `onnx` feature.
    #[error(
        "{path}: policy files need mjskill's `onnx` feature, which this build leaves out \
         (build with the default features, or add `--features onnx`)"
    )]
    PolicyFilesDisabled {
        /// The policy file's path.
        path: String,
    },
}

/// The policy names `rollout` and `eval` accept: the scripted solver, the state expert (its
/// action a function of the state, docs/solvers.md §8.2; the pairs in [`STATE_EXPERTS`]),
/// uniform random and all-zero actions.
pub const POLICIES: [&str; 4] = ["solver", "expert", "random", "zero"];

/// A policy: fills an action for the env's current state.
pub trait Policy: std::fmt::Debug + Send {
    /// Called after every reset.
    fn reset(&mut self, env: &Env);
    /// Writes the next action into `action` (length = the env's action dimension).
    fn act(&mut self, env: &Env, action: &mut [f32]);
    /// As [`Policy::act`], for the episode loops: a policy that can fail at run time (a
    /// policy file's runtime) returns its error here.
    fn try_act(&mut self, env: &Env, action: &mut [f32]) -> Result<(), SolverError> {
        self.act(env, action);
        Ok(())
    }
}

/// The control mode a policy needs in env `env_id` with `robot` (`None`: any). The scripted
/// solvers drive the end effector (`pd_ee_delta_pos`; Fetch and the xArm6 also turn the
/// gripper, in `pd_ee_delta_pose`, and so does the Panda in StackCube-v1 and LiftPegUpright-v1)
/// where the robot has EE controllers; SO100 and WidowX AI have none upstream, so their
/// solvers command joint positions (`pd_joint_pos`) from an IK of their own. Fetch's
/// LiftPegUpright-v1 solver commands joint positions too: it rolls its wrist as a joint target
/// and turns its end-effector commands into joint targets through a `pd_ee_delta_pose` shadow
/// env.
pub fn required_control_mode(policy: &str, env_id: &str, robot: &str) -> Option<&'static str> {
    if policy == "expert" {
        // The state expert's own mode; a pair without one needs none (building the policy
        // reports it).
        return expert::expert_mode(env_id, robot);
    }
    if policy != "solver" {
        return None;
    }
    // An unknown robot needs no mode: building the env reports it.
    let robot = RobotId::parse(robot).ok()?;
    Some(match robot {
        RobotId::So100 | RobotId::WidowxAi => "pd_joint_pos",
        // Fetch rolls its wrist half a turn in joint space to stand the peg (its other
        // commands are end-effector deltas turned into joint targets;
        // solvers/lift_peg_upright.rs).
        RobotId::Fetch if env_id == LIFT_PEG_UPRIGHT => "pd_joint_pos",
        // Fetch must turn its gripper to reach the cube (solvers/fetch.rs); the xArm6 turns
        // its gripper to the cube's faces (solvers/xarm6.rs), and so does the Panda to stack
        // (solvers/stack_cube.rs) and to stand the peg up (solvers/lift_peg_upright.rs).
        RobotId::Fetch | RobotId::Xarm6Robotiq => "pd_ee_delta_pose",
        RobotId::Panda if env_id == STACK_CUBE || env_id == LIFT_PEG_UPRIGHT => "pd_ee_delta_pose",
        RobotId::Panda => "pd_ee_delta_pos",
        // The pusher sets the stick's tip where it wants it (solvers/push_t.rs).
        RobotId::PandaStick => "pd_ee_pose",
        // The peg is turned to the hole's axis (solvers/peg_insertion_side.rs).
        RobotId::PandaWristCam => "pd_ee_delta_pose",
    })
}

/// Builds a built-in policy by name for `env` (random: seeded with `seed`); policy files:
/// [`PolicySpec`].
pub fn make_policy(name: &str, env: &Env, seed: u64) -> Result<Box<dyn Policy>, SolverError> {
    match name {
        "zero" => Ok(Box::new(Zero)),
        "random" => Ok(Box::new(Random(rand::rngs::StdRng::seed_from_u64(seed)))),
        "solver" => solver(env),
        "expert" => Ok(Box::new(ExpertPolicy(state_expert(env)?))),
        _ => Err(SolverError::UnknownPolicy {
            name: name.to_string(),
            valid: format!("{}, or a policy file (FILE.onnx)", POLICIES.join(", ")),
        }),
    }
}

/// The state expert ([`state_expert`]) as a policy (`--policy expert`): demonstrations whose
/// every action is the label DAgger asks the same expert for, so cloning and DAgger learn from
/// one teacher.
#[derive(Debug)]
pub struct ExpertPolicy(Box<dyn StateExpert>);

impl Policy for ExpertPolicy {
    fn reset(&mut self, _env: &Env) {}

    /// The expert's label; where labelling fails (only a converted expert's shadow env can),
    /// zeros. The episode loops call [`Policy::try_act`], which returns that error instead.
    fn act(&mut self, env: &Env, action: &mut [f32]) {
        if self.0.label(env, action).is_err() {
            action.fill(0.0);
        }
    }

    fn try_act(&mut self, env: &Env, action: &mut [f32]) -> Result<(), SolverError> {
        self.0.label(env, action)
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

/// The (env id, robot) pairs that have a scripted solver (the arms of `solver`'s match).
pub const SOLVED: [(&str, &str); 22] = [
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
    ("PushCube-v1", "panda"),
    ("PushCube-v1", "fetch"),
    ("PullCube-v1", "panda"),
    ("PullCube-v1", "fetch"),
    ("StackCube-v1", "panda"),
    ("StackCube-v1", "fetch"),
    ("StackCube-v1", "panda_wristcam"),
    ("LiftPegUpright-v1", "panda"),
    ("LiftPegUpright-v1", "fetch"),
    ("PegInsertionSide-v1", "panda_wristcam"),
    ("PushT-v1", "panda_stick"),
];

/// The accumulating joint-target mode, whose targets move at most one action bound per step.
const TARGET_DELTA: &str = "pd_joint_target_delta_pos";

/// The envs whose Panda solver turns the gripper (`pd_ee_delta_pose`).
const STACK_CUBE: &str = "StackCube-v1";
const LIFT_PEG_UPRIGHT: &str = "LiftPegUpright-v1";

/// The registered (env id, robot) pairs that have no scripted solver yet (none today; a new
/// pair lands here until its solver does): `--policy solver` answers them with
/// [`SolverError::NoSolver`], and the tests that replay a solver episode per pair skip them.
/// Together with [`SOLVED`], every registered pair.
pub const UNSOLVED: [(&str, &str); 0] = [];

/// Boxes a freshly built solver.
fn boxed<P: Policy + 'static>(
    policy: Result<P, SolverError>,
) -> Result<Box<dyn Policy>, SolverError> {
    Ok(Box::new(policy?))
}

/// Which scripted solver fits an (env, robot) pair.
fn solver(env: &Env) -> Result<Box<dyn Policy>, SolverError> {
    let robot = env.robot_spec().uid();
    let mode = env.control_mode();
    let required = required_control_mode("solver", env.id(), robot).unwrap_or(mode);
    if let (TARGET_DELTA, Some(r)) = (mode, joint_ik::for_robot(robot)) {
        // Targets that move at a bounded rate: the phases end on the commanded targets and
        // the gripper keeps its tilt (docs/solvers.md §8.1).
        return boxed(ModeConverted::new(env, required, |shadow| {
            boxed(joint_ik::JointIkPickCube::new(shadow, r).map(|s| s.leading()))
        }));
    }
    if mode != required {
        return boxed(ModeConverted::new(env, required, native_solver));
    }
    native_solver(env)
}

/// The scripted solver of `env`'s (env, robot) pair, in the env's mode (the solver's own).
fn native_solver(env: &Env) -> Result<Box<dyn Policy>, SolverError> {
    let robot = env.robot_spec().uid();
    match (env.id(), robot) {
        ("PickCube-v1", "panda") => boxed(pick_cube::PickCubeSolver::new(
            env,
            Gripper {
                close: pick_cube::PANDA_CLOSE,
                ..PANDA_GRIPPER
            },
        )),
        ("PickCube-v1", "fetch") => boxed(fetch::FetchPickCube::new(env)),
        ("PickCube-v1", "xarm6_robotiq") => boxed(xarm6::Xarm6PickCube::new(env)),
        ("PickCube-v1" | "PickCubeSO100-v1", "so100") => {
            boxed(joint_ik::JointIkPickCube::new(env, joint_ik::SO100))
        }
        ("PickCube-v1" | "PickCubeWidowXAI-v1", "widowxai") => {
            boxed(joint_ik::JointIkPickCube::new(env, joint_ik::WIDOWXAI))
        }
        ("PlaceSphere-v1", "panda") => {
            boxed(place_sphere::PlaceSphereSolver::new(env, PANDA_GRIPPER))
        }
        ("PlaceSphere-v1", "fetch") => boxed(fetch_tasks::FetchPlaceSphere::new(env)),
        ("PokeCube-v1", "panda") => boxed(poke_cube::PokeCubeSolver::new(env, PANDA_GRIPPER)),
        ("PokeCube-v1", "fetch") => boxed(fetch_tasks::FetchPokeCube::new(env)),
        ("PushCube-v1" | "PullCube-v1", "panda") => boxed(push_cube::PandaSlide::new(env)),
        ("PushCube-v1", "fetch") => boxed(push_cube::FetchPush::new(env)),
        ("PullCube-v1", "fetch") => boxed(push_cube::FetchPull::new(env)),
        ("StackCube-v1", "panda" | "panda_wristcam") => {
            boxed(stack_cube::PandaStackCube::new(env, PANDA_GRIPPER))
        }
        ("StackCube-v1", "fetch") => boxed(stack_cube::FetchStackCube::new(env)),
        ("LiftPegUpright-v1", "panda") => {
            boxed(lift_peg_upright::PandaLiftPeg::new(env, PANDA_GRIPPER))
        }
        ("LiftPegUpright-v1", "fetch") => boxed(lift_peg_upright::FetchLiftPeg::new(env)),
        ("PegInsertionSide-v1", "panda_wristcam") => {
            boxed(peg_insertion_side::PegInsertionSideSolver::new(env))
        }
        ("PushT-v1", "panda_stick") => boxed(push_t::PushTSolver::new(env)),
        (env, robot) => Err(SolverError::NoSolver {
            env,
            robot,
            available: SOLVED
                .iter()
                .map(|(e, r)| format!("{e} with {r}"))
                .collect::<Vec<_>>()
                .join(", "),
        }),
    }
}

/// Gripper commands (open, close) of a robot's gripper action.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Gripper {
    /// Action value that opens.
    pub open: f32,
    /// Action value that closes.
    pub close: f32,
}

/// Panda: +1 opens (0.04 m), −1 closes (−0.01 m target).
pub(crate) const PANDA_GRIPPER: Gripper = Gripper {
    open: 1.0,
    close: -1.0,
};

/// Fetch: +1 opens (0.05 m), −1 closes (−0.01 m target).
pub(crate) const FETCH_GRIPPER: Gripper = Gripper {
    open: 1.0,
    close: -1.0,
};

/// xArm6 + Robotiq in `pd_ee_delta_pose`: the absolute gripper (docs/robots.md §4) takes target
/// 0 rad (open) and 0.81 rad (closed).
pub(crate) const XARM6_ABS_GRIPPER: Gripper = Gripper {
    open: 0.0,
    close: 0.81,
};

/// Height of the approach point above the grasp point (m; the grasp phases of docs/solvers.md §7).
pub(crate) const APPROACH_HEIGHT: f64 = 0.05;
/// Approach tolerance (m).
pub(crate) const APPROACH_TOL: f64 = 0.01;
/// Descent tolerance (m).
pub(crate) const DESCEND_TOL: f64 = 0.004;
/// Steps the gripper closes before the object is moved (Panda, Fetch).
pub(crate) const CLOSE_STEPS: usize = 3;

/// Position error scale of the EE-space policies (m per unit action).
const ACTION_SCALE: f64 = 0.1;
/// Rotation per unit action of `pd_ee_delta_pose` (rad; upstream scales by rot_lower = −0.1,
/// docs/controllers.md §1, so +1 turns −0.1 rad).
const ROT_SCALE: f64 = -0.1;

/// Phase bookkeeping of the scripted solvers: phases are checked in order and fall through
/// within one step; "k steps in a phase" counts the actions issued in it, including the one
/// of the step on which it was entered.
#[derive(Debug, Default, Clone, Copy)]
pub(crate) struct Phases {
    /// The current phase.
    pub phase: usize,
    /// Actions issued in the current phase.
    pub steps: usize,
}

impl Phases {
    /// Back to phase 0 (episode start).
    pub fn reset(&mut self) {
        *self = Phases::default();
    }

    /// Runs one step: `plan(phase, steps)` gives this step's output and whether the phase is
    /// done; done phases are left (falling through to the next in the same step) until one
    /// is not, whose output is returned and counted as an action of that phase.
    pub fn run<T>(&mut self, mut plan: impl FnMut(usize, usize) -> (T, bool)) -> T {
        loop {
            let (out, done) = plan(self.phase, self.steps);
            if done {
                self.phase += 1;
                self.steps = 0;
                continue;
            }
            self.steps += 1;
            return out;
        }
    }
}

/// A task body's id in the env's model (the task layer's lookup).
fn body_id(model: &crate::mujoco::Model, name: &str) -> Result<BodyId, SolverError> {
    Ok(crate::tasks::body_id(model, name)?)
}

/// A body's world position, read from MuJoCo.
pub(crate) fn body_xyz(env: &Env, body: BodyId) -> Vector3<f64> {
    Vector3::from(env.data().body_pos(body))
}

/// A body's world orientation, read from MuJoCo (renormalised: the solvers' rotations).
pub(crate) fn body_quat(env: &Env, body: BodyId) -> UnitQuaternion<f64> {
    env.data().body_pose(body).rotation_renormalized()
}

/// `agent.tcp.pose.p`: the TCP link's position (PlaceSphere, PokeCube), or `tcp_pose` for a
/// robot without a TCP link.
fn tcp_link_xyz(env: &Env) -> Vector3<f64> {
    match env.robot().tcp_body {
        Some(b) => body_xyz(env, b),
        None => tcp_xyz(env),
    }
}

/// The robot's TCP position (`tcp_pose`).
fn tcp_xyz(env: &Env) -> Vector3<f64> {
    Vector3::from(env.robot().tcp_pose(env.data()).0)
}

/// The descent onto the grasp point is done: within [`DESCEND_TOL`] (Panda, xArm6).
fn descended(target: Vector3<f64>, tcp: Vector3<f64>) -> bool {
    (target - tcp).norm() < DESCEND_TOL
}

/// Phases 0–2 that every EE-space solver starts with (docs/solvers.md §7): above the grasp point
/// (open), down to it (open), close for `hold` steps.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Grasp {
    /// The robot's gripper commands.
    pub gripper: Gripper,
    /// Whether the descent to the grasp point is done (target, tcp).
    pub descended: fn(Vector3<f64>, Vector3<f64>) -> bool,
    /// Steps the gripper closes before the object is moved.
    pub hold: usize,
}

impl Grasp {
    /// The spec's grasp: descent within [`DESCEND_TOL`], [`CLOSE_STEPS`] closing steps.
    pub fn new(gripper: Gripper) -> Self {
        Grasp {
            gripper,
            descended,
            hold: CLOSE_STEPS,
        }
    }

    /// Target, gripper action and done flag of grasp phase `phase` (0–2) after `steps`
    /// actions in it, for grasp point `point`; `ready`: whether the robot may leave the
    /// approach (e.g. its gripper is turned).
    pub fn phase(
        &self,
        phase: usize,
        steps: usize,
        point: Vector3<f64>,
        tcp: Vector3<f64>,
        ready: bool,
    ) -> (Vector3<f64>, f32, bool) {
        let Gripper { open, close } = self.gripper;
        match phase {
            0 => {
                let t = point + Vector3::new(0.0, 0.0, APPROACH_HEIGHT);
                (t, open, ready && (t - tcp).norm() < APPROACH_TOL)
            }
            1 => (point, open, (self.descended)(point, tcp)),
            _ => (point, close, steps >= self.hold),
        }
    }
}

/// Writes the position action `clip(step, −limit, limit)` into `action[0..3]`, where `step`
/// is a position error already divided by [`ACTION_SCALE`].
fn write_pos(step: Vector3<f64>, limit: f64, action: &mut [f32]) {
    for k in 0..3 {
        action[k] = step[k].clamp(-limit, limit) as f32;
    }
}

/// Writes `clip((target − tcp)/0.1, −limit, limit)` and the gripper value (`pd_ee_delta_pos`).
fn ee_action(
    target: Vector3<f64>,
    tcp: Vector3<f64>,
    limit: f64,
    gripper: f32,
    action: &mut [f32],
) {
    write_pos((target - tcp) / ACTION_SCALE, limit, action);
    action[3] = gripper;
}

/// Writes the rotation action of `pd_ee_delta_pose` into `action[3..6]` for an orientation
/// error `rot_err` (scaled axis, rad): divided by [`ROT_SCALE`] and scaled down to norm ≤ 1.
fn write_rot(rot_err: Vector3<f64>, action: &mut [f32]) {
    let mut r = rot_err / ROT_SCALE;
    if r.norm() > 1.0 {
        r /= r.norm();
    }
    action[3..6].copy_from_slice(&[r.x as f32, r.y as f32, r.z as f32]);
}
