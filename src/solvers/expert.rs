//! Experts that label any state, for DAgger (issue 55): the action depends on the env's
//! current state alone, never on what the expert did before.
//!
//! The scripted solvers (`--policy solver`, [`super::make_policy`]) run phases whose
//! "k steps" count their own actions and never go back, so asked along a learner's path they
//! label the phase their history says, not the one the state shows.
//! An expert here reads its phase off the state each time: whether the object is grasped
//! (the task's own grasp flag), where the TCP is against the object, how far the gripper is
//! open, where the object is against its goal. Any state, reached by anyone, gets the action
//! that continues the task from it, so [`StateExpert::label`] can be asked along a learner's
//! path, in any order, any number of times.
//!
//! In another control mode of the robot the expert's actions are converted as the solvers'
//! are ([`super::ModeConverted`], a shadow env synced to the state each call, so still a
//! function of the state): joint position targets come out within π of the current angle on
//! continuous joints.
//!
//! Pairs ([`STATE_EXPERTS`]): PickCube-v1, PlaceSphere-v1 and PokeCube-v1 with the Panda and
//! with the Fetch (`fetch_expert.rs`, in `pd_ee_delta_pose`), and PickCube-v1 (with
//! PickCubeSO100-v1 and PickCubeWidowXAI-v1) with the SO100 and the WidowX AI
//! (`joint_ik::JointIkPickCubeExpert`, in `pd_joint_pos`); any other is a clear error naming the
//! pair and the ones that have an expert.
use nalgebra::Vector3;

use super::fetch_expert::{FetchPickCubeExpert, FetchPlaceSphereExpert, FetchPokeCubeExpert};
use super::joint_ik::{self, JointIkPickCubeExpert};
use super::{
    body_id, body_xyz, ee_action, tcp_link_xyz, tcp_xyz, Gripper, ModeConverted, Policy,
    SolverError, APPROACH_HEIGHT, PANDA_GRIPPER,
};
use crate::env::{Env, EnvLabeller, VecEnv};
use crate::mujoco::BodyId;
use crate::tasks::place_sphere::{RADIUS, SHORT_SIDE_HALF};
use crate::tasks::poke_cube::{peg_head, GOAL_RADIUS};

// The solvers' own distances, heights and limits (each named once, in the solver's file).
use super::place_sphere::{ALIGN_TOL, CARRY_ABOVE_BIN, LIFT_TOL, LOWER_TO, RELEASE_BELOW};
use super::poke_cube::{
    CUBE_HALF_DIAGONAL, GRASP_OFFSET_X, PRE_PUSH_GAP, PUSH_LIMIT, PUSH_SHORT_OF_GOAL,
};

/// The (env id, robot) pairs that have a state expert, in its own control mode.
pub const STATE_EXPERTS: [(&str, &str, &str); 10] = [
    ("PickCube-v1", "panda", "pd_ee_delta_pos"),
    ("PlaceSphere-v1", "panda", "pd_ee_delta_pos"),
    ("PokeCube-v1", "panda", "pd_ee_delta_pos"),
    ("PickCube-v1", "fetch", "pd_ee_delta_pose"),
    ("PlaceSphere-v1", "fetch", "pd_ee_delta_pose"),
    ("PokeCube-v1", "fetch", "pd_ee_delta_pose"),
    ("PickCube-v1", "so100", "pd_joint_pos"),
    ("PickCubeSO100-v1", "so100", "pd_joint_pos"),
    ("PickCube-v1", "widowxai", "pd_joint_pos"),
    ("PickCubeWidowXAI-v1", "widowxai", "pd_joint_pos"),
];

/// The TCP is over the object within this (m, horizontal): the descent may start.
const OVER_XY: f64 = 0.01;
/// The TCP is at the grasp point within this (m): the gripper closes.
const AT_GRASP: f64 = 0.006;
/// Panda: the fingers are open enough to descend around a 4 cm object (m, finger gap).
const OPEN_GAP: f64 = 0.06;
/// Panda: a gap below this without a grasp closed on nothing (m): open again.
const MISSED_GAP: f64 = 0.03;
/// A grasped object is held once the fingers close slower than this (m/s, the gap's rate);
/// until then the gripper goes on closing where it is (the solvers' three closing steps,
/// read off the fingers' motion: a cube grasped across its diagonal stops them at 5.7 cm).
const HELD_SPEED: f64 = 0.02;

/// An expert that labels any state with the action that continues the task from it.
pub trait StateExpert: std::fmt::Debug + Send {
    /// Writes the expert's action for `env`'s current state into `action` (the env's action
    /// dimension). A function of the state: the same state gives the same action, bit for bit.
    fn label(&mut self, env: &Env, action: &mut [f32]) -> Result<(), SolverError>;
}

/// The own control mode of the state expert of (`env_id`, `robot`), if the pair has one.
pub fn expert_mode(env_id: &str, robot: &str) -> Option<&'static str> {
    STATE_EXPERTS
        .iter()
        .find(|(e, r, _)| *e == env_id && *r == robot)
        .map(|&(_, _, mode)| mode)
}

/// The state expert of `env`'s (env, robot) pair, in `env`'s control mode (converted from the
/// expert's own where they differ).
pub fn state_expert(env: &Env) -> Result<Box<dyn StateExpert>, SolverError> {
    let robot = env.robot_spec().uid();
    let Some(mode) = expert_mode(env.id(), robot) else {
        return Err(SolverError::NoStateExpert {
            env: env.id(),
            robot,
            available: STATE_EXPERTS
                .iter()
                .map(|(e, r, _)| format!("{e} with {r}"))
                .collect::<Vec<_>>()
                .join(", "),
        });
    };
    if env.control_mode() == mode {
        return native(env).map(|p| Box::new(Labeller(p)) as Box<dyn StateExpert>);
    }
    let converted = ModeConverted::new(env, mode, native)?;
    Ok(Box::new(Labeller(Box::new(converted))))
}

/// Gives every env of `vec` its pair's state expert ([`state_expert`]) as its labeller
/// ([`VecEnv::set_labellers`]), for [`VecEnv::expert_actions`] and labelled rollouts
/// ([`crate::env::RolloutBuffers::labels`]). A pair without an expert is
/// [`SolverError::NoStateExpert`], with nothing set. An expert converted to another control
/// mode keeps a shadow env of its own, so each env's labeller holds one.
pub fn set_state_experts(vec: &mut VecEnv) -> Result<(), SolverError> {
    vec.set_labellers(|env| {
        state_expert(env).map(|e| Box::new(ExpertLabeller(e)) as Box<dyn EnvLabeller>)
    })
}

/// A [`StateExpert`] as the vector env's [`EnvLabeller`].
#[derive(Debug)]
struct ExpertLabeller(Box<dyn StateExpert>);

impl EnvLabeller for ExpertLabeller {
    fn label(&mut self, env: &Env, action: &mut [f32]) -> Result<(), String> {
        self.0.label(env, action).map_err(|e| e.to_string())
    }
}

/// The expert of `env`'s pair in its own mode, as a [`Policy`] whose `act` reads only the state.
fn native(env: &Env) -> Result<Box<dyn Policy>, SolverError> {
    match (env.id(), env.robot_spec().uid()) {
        (_, "so100") => Ok(Box::new(JointIkPickCubeExpert::new(env, joint_ik::SO100)?)),
        (_, "widowxai") => Ok(Box::new(JointIkPickCubeExpert::new(
            env,
            joint_ik::WIDOWXAI,
        )?)),
        ("PickCube-v1", "fetch") => Ok(Box::new(FetchPickCubeExpert::new(env)?)),
        ("PlaceSphere-v1", "fetch") => Ok(Box::new(FetchPlaceSphereExpert::new(env)?)),
        ("PokeCube-v1", "fetch") => Ok(Box::new(FetchPokeCubeExpert::new(env)?)),
        ("PickCube-v1", _) => Ok(Box::new(PickCubeExpert::new(env, PANDA_GRIPPER)?)),
        ("PokeCube-v1", _) => Ok(Box::new(PokeCubeExpert::new(env, PANDA_GRIPPER)?)),
        _ => Ok(Box::new(PlaceSphereExpert::new(env, PANDA_GRIPPER)?)),
    }
}

/// A history-free policy as a [`StateExpert`].
#[derive(Debug)]
struct Labeller(Box<dyn Policy>);

impl StateExpert for Labeller {
    fn label(&mut self, env: &Env, action: &mut [f32]) -> Result<(), SolverError> {
        self.0.try_act(env, action)
    }
}

/// What every grasping expert reads off the state: the TCP, the gripper's gap, the grasp flag.
#[derive(Debug, Clone, Copy)]
pub(super) struct Grip {
    pub(super) gripper: Gripper,
    /// qpos addresses of the two finger joints (their sum is the gap).
    fingers: [usize; 2],
    /// Their dof addresses (the gap's rate).
    finger_dofs: [usize; 2],
}

impl Grip {
    pub(super) fn new(env: &Env, gripper: Gripper) -> Result<Self, SolverError> {
        let joints = &env.robot().joints;
        let spec = env.robot_spec();
        let ks: Vec<usize> = (0..joints.len())
            .filter(|&k| spec.gripper_joints.contains(&joints.names[k].as_str()))
            .collect();
        let [k0, k1] = <[usize; 2]>::try_from(ks).map_err(|k| SolverError::NoStateExpert {
            env: env.id(),
            robot: spec.uid(),
            available: format!("robots with two finger joints (this one has {})", k.len()),
        })?;
        Ok(Grip {
            gripper,
            fingers: [joints.qpos_adr[k0], joints.qpos_adr[k1]],
            finger_dofs: [joints.dof_adr[k0], joints.dof_adr[k1]],
        })
    }

    pub(super) fn gap(&self, env: &Env) -> f64 {
        let q = env.data().qpos();
        q[self.fingers[0]] + q[self.fingers[1]]
    }

    /// The object is grasped (the task's flag) and the gripper has closed on it.
    pub(super) fn holds(&self, env: &Env) -> bool {
        env.info().flag(env.grasp_info_key()) && !self.closing(env)
    }

    /// The fingers are still closing ([`HELD_SPEED`] or faster).
    pub(super) fn closing(&self, env: &Env) -> bool {
        let v = env.data().qvel();
        -(v[self.finger_dofs[0]] + v[self.finger_dofs[1]]) >= HELD_SPEED
    }

    /// The TCP target and gripper action that bring an open gripper onto the grasp point
    /// `point` and close it there, from wherever the TCP and gripper are.
    fn grasp(&self, env: &Env, point: Vector3<f64>, tcp: Vector3<f64>) -> (Vector3<f64>, f32) {
        let Gripper { open, close } = self.gripper;
        let gap = self.gap(env);
        let over = (tcp.xy() - point.xy()).norm() < OVER_XY;
        if gap < MISSED_GAP {
            // Closed on nothing: open, rising to the approach height.
            (point + Vector3::new(0.0, 0.0, APPROACH_HEIGHT), open)
        } else if over && (tcp - point).norm() < AT_GRASP {
            (point, close)
        } else if over && gap > OPEN_GAP {
            (point, open)
        } else {
            (point + Vector3::new(0.0, 0.0, APPROACH_HEIGHT), open)
        }
    }
}

/// PickCube: grasp the cube from above, carry it to the goal.
#[derive(Debug)]
pub(crate) struct PickCubeExpert {
    cube: BodyId,
    goal: BodyId,
    grip: Grip,
}

impl PickCubeExpert {
    /// Resolves the cube, goal and finger joints of a PickCube env.
    pub(crate) fn new(env: &Env, gripper: Gripper) -> Result<Self, SolverError> {
        Ok(PickCubeExpert {
            cube: body_id(env.model(), "cube")?,
            goal: body_id(env.model(), "goal_site")?,
            grip: Grip::new(env, gripper)?,
        })
    }
}

impl Policy for PickCubeExpert {
    fn reset(&mut self, _env: &Env) {}

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        let tcp = tcp_xyz(env);
        let cube = body_xyz(env, self.cube);
        // Carried at the solver's speed (`pick_cube::CARRY_SPEED`), for the same reason.
        let (target, grip, limit) = if self.grip.holds(env) {
            let close = self.grip.gripper.close;
            (
                body_xyz(env, self.goal),
                close,
                super::pick_cube::CARRY_SPEED,
            )
        } else {
            let (target, grip) = self.grip.grasp(env, cube, tcp);
            (target, grip, 1.0)
        };
        ee_action(target, tcp, limit, grip, action);
    }
}

/// PlaceSphere: grasp the sphere, lift it clear of the bin's walls, carry it over the bin,
/// lower it onto the floor, let go and hold still.
#[derive(Debug)]
pub(crate) struct PlaceSphereExpert {
    sphere: BodyId,
    bin: BodyId,
    grip: Grip,
}

/// The sphere is carried at least this high before it moves sideways (m over the bin origin).
const CLEAR_ABOVE_BIN: f64 = 0.045;
/// Once lowered into the bin's mouth, lowering goes on (and the release happens) within this
/// (m, horizontal; the bin leaves 5 mm around the sphere).
const LOWERING_XY: f64 = 0.006;
/// The sphere rests in the bin (not grasped): horizontal and vertical tolerances (m), the
/// task's `is_obj_on_bin`, widened so that a sphere settling after the release counts.
const IN_BIN_XY: f64 = 0.01;
const IN_BIN_Z: f64 = 0.01;

impl PlaceSphereExpert {
    /// Resolves the sphere, bin and finger joints of a PlaceSphere env.
    pub(crate) fn new(env: &Env, gripper: Gripper) -> Result<Self, SolverError> {
        Ok(PlaceSphereExpert {
            sphere: body_id(env.model(), "sphere")?,
            bin: body_id(env.model(), "bin")?,
            grip: Grip::new(env, gripper)?,
        })
    }
}

impl Policy for PlaceSphereExpert {
    fn reset(&mut self, _env: &Env) {}

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        let tcp = tcp_link_xyz(env);
        let sphere = body_xyz(env, self.sphere);
        let bin = body_xyz(env, self.bin);
        let Gripper { open, close } = self.grip.gripper;
        let rel = sphere - bin;
        let xy = rel.xy().norm();
        let lowering = xy < LOWERING_XY && rel.z < CARRY_ABOVE_BIN - LIFT_TOL;
        let (target, grip) = if self.grip.holds(env) {
            if xy < LOWERING_XY && rel.z < RELEASE_BELOW {
                (tcp, open)
            } else if xy < ALIGN_TOL || lowering {
                (
                    tcp + (bin + Vector3::new(0.0, 0.0, LOWER_TO) - sphere),
                    close,
                )
            } else if rel.z < CLEAR_ABOVE_BIN {
                (
                    Vector3::new(tcp.x, tcp.y, tcp.z + (CARRY_ABOVE_BIN - rel.z)),
                    close,
                )
            } else {
                let mut offset = tcp - sphere;
                offset.z = 0.0;
                (
                    bin + Vector3::new(0.0, 0.0, CARRY_ABOVE_BIN) + offset,
                    close,
                )
            }
        } else if rel.xy().norm() < IN_BIN_XY && (rel.z - RADIUS - SHORT_SIDE_HALF).abs() < IN_BIN_Z
        {
            // Placed: let go and hold still.
            (tcp, open)
        } else {
            self.grip.grasp(env, sphere, tcp)
        };
        ee_action(target, tcp, 1.0, grip, action);
    }
}

/// PokeCube: grasp the peg 8 cm behind its centre, bring its head just behind the cube, push
/// the cube into the goal region along x, and hold still there.
#[derive(Debug)]
pub(crate) struct PokeCubeExpert {
    cube: BodyId,
    peg: BodyId,
    goal: BodyId,
    grip: Grip,
}

/// The head is lined up with the cube (m, along y) and close behind it (m, along x, past the
/// pre-push point): the push goes on.
const PUSH_LINE_Y: f64 = 0.006;
const PUSH_BEHIND_TOL: f64 = 0.006;
/// The cube is this far inside the goal region (m) before the arm stops pushing and holds
/// still (success needs it static).
const GOAL_MARGIN: f64 = 0.02;

impl PokeCubeExpert {
    /// Resolves the cube, peg, goal and finger joints of a PokeCube env.
    pub(crate) fn new(env: &Env, gripper: Gripper) -> Result<Self, SolverError> {
        Ok(PokeCubeExpert {
            cube: body_id(env.model(), "cube")?,
            peg: body_id(env.model(), "peg")?,
            goal: body_id(env.model(), "goal_region")?,
            grip: Grip::new(env, gripper)?,
        })
    }
}

impl Policy for PokeCubeExpert {
    fn reset(&mut self, _env: &Env) {}

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        let tcp = tcp_link_xyz(env);
        let (cube, peg, goal) = (
            body_xyz(env, self.cube),
            body_xyz(env, self.peg),
            body_xyz(env, self.goal),
        );
        if !self.grip.holds(env) {
            let (target, grip) =
                self.grip
                    .grasp(env, peg + Vector3::new(GRASP_OFFSET_X, 0.0, 0.0), tcp);
            ee_action(target, tcp, 1.0, grip, action);
            return;
        }
        let close = self.grip.gripper.close;
        let head = peg_head(peg);
        let pre_x = cube.x - CUBE_HALF_DIAGONAL - PRE_PUSH_GAP;
        let lined_up = (head.y - cube.y).abs() < PUSH_LINE_Y
            && head.x > pre_x - PUSH_BEHIND_TOL
            && head.x < cube.x;
        let (want, limit) = if (cube.xy() - goal.xy()).norm() < GOAL_RADIUS - GOAL_MARGIN {
            (head, 1.0)
        } else if lined_up {
            (
                Vector3::new(goal.x - PUSH_SHORT_OF_GOAL, cube.y, head.z),
                PUSH_LIMIT,
            )
        } else {
            (Vector3::new(pre_x, cube.y, head.z), 1.0)
        };
        // Move the TCP horizontally by the head's error: the grasp holds the peg rigidly.
        let target = Vector3::new(tcp.x + want.x - head.x, tcp.y + want.y - head.y, tcp.z);
        ee_action(target, tcp, limit, close, action);
    }
}
