//! The Fetch's state experts (docs/solvers.md §8.2, issue 55): PickCube-v1, PlaceSphere-v1 and
//! PokeCube-v1, in `pd_ee_delta_pose` through [`FetchArm`], each action a function of the state.
//!
//! They plan the TCP targets of the Fetch solvers (`fetch.rs`, `fetch_tasks.rs`) with the phase
//! read off the state, as the Panda's experts do (`expert.rs`), and keep the solvers' Fetch
//! rules where a solver decides them from its history:
//! * the gripper pitch for the grasp comes from where the object lies now (the solvers fix it
//!   at the reset), and the carry's pitch points from the shoulder at the carry target;
//! * PlaceSphere's settle and stall read the sphere's velocity from the state (its free
//!   joint's), where the solver compares its position with the last step's;
//! * PokeCube carries the peg's tail [`POKE_LIFT`] above the height the grasp leaves it at (the
//!   peg's resting centre plus the grasp point's lift), where the solver remembers the TCP's
//!   height at the grasp.
//!
//! The torso and base follow the solvers' commands, which are functions of the state already.
use nalgebra::Vector3;

use super::expert::Grip;
use super::fetch::{
    pick_pitch_and_height, CARRY_TORSO_GAIN, ROT_TOL as PICK_ROT_TOL, TORSO_CARRY, TORSO_PICK,
};
use super::fetch_arm::{
    descended_tilted, min_tcp_height, pitch_for_x, pitch_towards, ArmCommand, FetchArm, PITCH_FAR,
};
use super::fetch_tasks::{
    descended_on_peg, ALIGN_STALLED, FLOOR_LOWER_TO, FLOOR_RELEASE_BELOW, POKE_GRASP_OFFSET_X,
    POKE_LIFT, POKE_MIN_STEP, POKE_PRE_PUSH_TOL, POKE_PUSH_SHORT, POKE_ROT_TOL, RELEASE_ALIGN,
    RELEASE_BELOW_STALLED, RELEASE_SPEED, ROT_TOL as TASK_ROT_TOL, STALL_MOVE, TORSO_GAIN,
    TORSO_LOW,
};
use super::place_sphere::{ALIGN_TOL, CARRY_ABOVE_BIN, LIFT_TOL};
use super::poke_cube::{CUBE_HALF_DIAGONAL, PRE_PUSH_GAP, PUSH_LIMIT, PUSH_TOL};
use super::{body_id, body_xyz, Gripper, Policy, SolverError, APPROACH_HEIGHT, FETCH_GRIPPER};
use crate::env::Env;
use crate::mjcf::CONTROL_DT;
use crate::mujoco::{BodyId, ObjType};
use crate::tasks::place_sphere::{RADIUS, SHORT_SIDE_HALF};
use crate::tasks::poke_cube::{peg_head, GOAL_RADIUS, PEG_HALF_WIDTH};

/// The TCP is over the grasp point within this across the fingers (m, world y) and
/// [`OVER_ALONG`] along the tilted fingers (m, world x): the descent may start.
const OVER_ACROSS: f64 = 0.01;
const OVER_ALONG: f64 = 0.015;
/// The fingers are open enough to descend around the 4 cm object (m, finger gap; open: 0.1).
const OPEN_GAP: f64 = 0.06;
/// A gap below this without a grasp: closed on nothing, open again (m).
const MISSED_GAP: f64 = 0.03;
/// At the grasp point's height within this (m), over it and with the fingers closing or part
/// shut on the object (below [`OPEN_GAP`]): the gripper goes on closing, wherever the arm sags
/// while it does.
const CLOSING_HEIGHT: f64 = 0.01;
/// The sphere has stalled (the solver: two steps of less than [`STALL_MOVE`] each) below this
/// speed (m/s).
const STALL_SPEED: f64 = STALL_MOVE / CONTROL_DT;
/// The sphere is carried at least this high before it moves sideways (m over the bin origin),
/// and, once lowered into the bin's mouth, lowering goes on within [`LOWERING_XY`] (m): the
/// Panda expert's. (Rising as the Fetch's solver does, to a TCP 8 cm above the table, gave
/// fewer successes: 26 and 19 of seeds 7100–7129 from the reset and after 3 random actions,
/// against 27 and 23; and 5.5 cm: 18 and 19.)
const CLEAR_ABOVE_BIN: f64 = 0.045;
const LOWERING_XY: f64 = 0.006;
/// The sphere rests in the bin, not grasped (horizontal and vertical tolerance, m): let go and
/// hold still. The task's `is_obj_on_bin`, widened so that a settling sphere counts.
const IN_BIN_XY: f64 = 0.01;
const IN_BIN_Z: f64 = 0.01;
/// The peg's head is lined up with the cube (m, along y) and close behind it (m, along x, past
/// the pre-push point): the push goes on. The cube is this far inside the goal region (m)
/// before the arm stops pushing and holds still (the Fetch's push stops 6.2 cm short of the
/// goal, leaving the cube about 3.4 cm from it).
const PUSH_LINE_Y: f64 = 0.006;
const GOAL_MARGIN: f64 = 0.01;

/// Within this of the TCP (m), with the gripper part shut (between [`MISSED_GAP`] and
/// [`OPEN_GAP`]), the object is in the hand: the grasp flag alone flickers while the Fetch
/// starts a carry (its torso rising under the held object), and an expert that reads it as a
/// lost grasp opens the hand and drops the object.
const IN_HAND: f64 = 0.04;

/// Whether the object at `point` (its centre, or the grasp point on a long one) is held: in
/// the part-shut hand and the fingers no longer closing on it.
fn holds(grip: &Grip, env: &Env, point: Vector3<f64>, tcp: Vector3<f64>) -> bool {
    let gap = grip.gap(env);
    gap > MISSED_GAP && gap < OPEN_GAP && (point - tcp).norm() < IN_HAND && !grip.closing(env)
}

/// The TCP target and gripper action that bring the Fetch's open, tilted gripper onto `point`
/// and close it there, from wherever the TCP and gripper are; `ready`: the gripper is turned
/// to its pitch; `descended`: the solver's check that the TCP has reached the grasp point.
fn grasp(
    grip: &Grip,
    env: &Env,
    (point, tcp): (Vector3<f64>, Vector3<f64>),
    ready: bool,
    descended: fn(Vector3<f64>, Vector3<f64>) -> bool,
) -> (Vector3<f64>, f32) {
    let Gripper { open, close } = grip.gripper;
    let gap = grip.gap(env);
    let above = point + Vector3::new(0.0, 0.0, APPROACH_HEIGHT);
    let e = point - tcp;
    let over = e.y.abs() < OVER_ACROSS && e.x.abs() < OVER_ALONG;
    let closing = over && e.z.abs() < CLOSING_HEIGHT && (gap < OPEN_GAP || grip.closing(env));
    if gap < MISSED_GAP {
        (above, open)
    } else if descended(point, tcp) || closing {
        (point, close)
    } else if over && ready && gap > OPEN_GAP {
        (point, open)
    } else {
        (above, open)
    }
}

/// PickCube: grasp the cube with the tilted gripper and the torso lowered, carry it to the goal
/// with the torso raised.
#[derive(Debug)]
pub(crate) struct FetchPickCubeExpert {
    cube: BodyId,
    goal: BodyId,
    grip: Grip,
    arm: FetchArm,
}

impl FetchPickCubeExpert {
    /// Resolves the cube, goal, fingers and arm of a PickCube env with the Fetch.
    pub(crate) fn new(env: &Env) -> Result<Self, SolverError> {
        Ok(FetchPickCubeExpert {
            cube: body_id(env.model(), "cube")?,
            goal: body_id(env.model(), "goal_site")?,
            grip: Grip::new(env, FETCH_GRIPPER)?,
            arm: FetchArm::new(env)?,
        })
    }
}

impl Policy for FetchPickCubeExpert {
    fn reset(&mut self, _env: &Env) {}

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        let tcp = self.arm.gripper_xyz(env);
        let cube = body_xyz(env, self.cube);
        let cmd = if holds(&self.grip, env, cube, tcp) {
            let target = body_xyz(env, self.goal) + (tcp - cube);
            ArmCommand {
                target,
                tcp,
                pitch: pitch_towards(self.arm.shoulder_xyz(env), target),
                torso: TORSO_CARRY,
                torso_gain: CARRY_TORSO_GAIN,
                grip: self.grip.gripper.close,
                limit: 1.0,
                min_step: 0.0,
            }
        } else {
            let (pitch, lift) = pick_pitch_and_height(cube);
            let ready = self.arm.rot_err(env, pitch) < PICK_ROT_TOL;
            let point = cube + Vector3::new(0.0, 0.0, lift);
            let (target, grip) = grasp(&self.grip, env, (point, tcp), ready, descended_tilted);
            ArmCommand {
                target,
                tcp,
                pitch,
                torso: TORSO_PICK,
                torso_gain: 1.0,
                grip,
                limit: 1.0,
                min_step: 0.0,
            }
        };
        self.arm.drive(env, cmd, action);
    }
}

/// PlaceSphere: grasp the sphere, lift it clear of the bin's walls, carry it over the bin, lower
/// it, hold it until it is still and centred within 1 mm (or stalled at the edge of the reach),
/// let go and hold still. The torso is not driven.
#[derive(Debug)]
pub(crate) struct FetchPlaceSphereExpert {
    sphere: BodyId,
    bin: BodyId,
    /// dof address of the sphere's free joint (its linear velocity, world frame).
    sphere_dof: usize,
    grip: Grip,
    arm: FetchArm,
}

impl FetchPlaceSphereExpert {
    /// Resolves the sphere, bin, fingers and arm of a PlaceSphere env with the Fetch.
    pub(crate) fn new(env: &Env) -> Result<Self, SolverError> {
        let m = env.model();
        Ok(FetchPlaceSphereExpert {
            sphere: body_id(m, "sphere")?,
            bin: body_id(m, "bin")?,
            sphere_dof: m.jnt_dofadr()[m.require_id(ObjType::Joint, "sphere")?] as usize,
            grip: Grip::new(env, FETCH_GRIPPER)?,
            arm: FetchArm::new(env)?,
        })
    }
}

impl Policy for FetchPlaceSphereExpert {
    fn reset(&mut self, _env: &Env) {}

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        let tcp = self.arm.gripper_xyz(env);
        let sphere = body_xyz(env, self.sphere);
        let bin = body_xyz(env, self.bin);
        let v = &env.data().qvel()[self.sphere_dof..self.sphere_dof + 3];
        let speed = Vector3::new(v[0], v[1], v[2]).norm();
        let Gripper { open, close } = self.grip.gripper;
        let rel = sphere - bin;
        let xy = rel.xy().norm();
        let held = holds(&self.grip, env, sphere, tcp);
        // The solvers' tolerances, loosened once the held sphere has stalled short of the bin
        // centre (the farthest bins, at the edge of the arm's reach).
        let stalled = held && speed < STALL_SPEED;
        let (align, release_align, release_below) = if stalled {
            (ALIGN_STALLED, ALIGN_STALLED, RELEASE_BELOW_STALLED)
        } else {
            (ALIGN_TOL, RELEASE_ALIGN, FLOOR_RELEASE_BELOW)
        };
        let lowering = xy < LOWERING_XY.max(align) && rel.z < CARRY_ABOVE_BIN - LIFT_TOL;
        let (target, grip, pitch) = if held {
            let (target, grip) = if rel.z < release_below && xy < release_align {
                // Lowered: hold until the sphere is still, then let go.
                (tcp, if speed < RELEASE_SPEED { open } else { close })
            } else if xy < align || lowering {
                (
                    tcp + (bin + Vector3::new(0.0, 0.0, FLOOR_LOWER_TO) - sphere),
                    close,
                )
            } else if rel.z < CLEAR_ABOVE_BIN {
                let up = Vector3::new(0.0, 0.0, CARRY_ABOVE_BIN - rel.z);
                (tcp + up, close)
            } else {
                let mut offset = tcp - sphere;
                offset.z = 0.0;
                (
                    bin + Vector3::new(0.0, 0.0, CARRY_ABOVE_BIN) + offset,
                    close,
                )
            };
            (
                target,
                grip,
                pitch_towards(self.arm.shoulder_xyz(env), target),
            )
        } else if xy < IN_BIN_XY && (rel.z - RADIUS - SHORT_SIDE_HALF).abs() < IN_BIN_Z {
            // Placed: let go and hold still.
            (tcp, open, pitch_towards(self.arm.shoulder_xyz(env), tcp))
        } else {
            let pitch = pitch_for_x(sphere.x, PITCH_FAR);
            let ready = self.arm.rot_err(env, pitch) < TASK_ROT_TOL;
            let point = sphere + Vector3::new(0.0, 0.0, (min_tcp_height(pitch) - RADIUS).max(0.0));
            let (target, grip) = grasp(&self.grip, env, (point, tcp), ready, descended_tilted);
            (target, grip, pitch)
        };
        let cmd = ArmCommand {
            target,
            tcp,
            pitch,
            torso: self.arm.torso(env),
            torso_gain: TORSO_GAIN,
            grip,
            limit: 1.0,
            min_step: 0.0,
        };
        self.arm.drive(env, cmd, action);
    }
}

/// PokeCube: grasp the peg near its tail with the flattest gripper, carry the tail lifted, bring
/// the head just behind the cube with the torso lowered, push the cube into the goal region
/// along x, and hold still there.
#[derive(Debug)]
pub(crate) struct FetchPokeCubeExpert {
    cube: BodyId,
    peg: BodyId,
    goal: BodyId,
    grip: Grip,
    arm: FetchArm,
}

impl FetchPokeCubeExpert {
    /// Resolves the cube, peg, goal, fingers and arm of a PokeCube env with the Fetch.
    pub(crate) fn new(env: &Env) -> Result<Self, SolverError> {
        Ok(FetchPokeCubeExpert {
            cube: body_id(env.model(), "cube")?,
            peg: body_id(env.model(), "peg")?,
            goal: body_id(env.model(), "goal_region")?,
            grip: Grip::new(env, FETCH_GRIPPER)?,
            arm: FetchArm::new(env)?,
        })
    }
}

impl Policy for FetchPokeCubeExpert {
    fn reset(&mut self, _env: &Env) {}

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        let tcp = self.arm.gripper_xyz(env);
        let (cube, peg, goal) = (
            body_xyz(env, self.cube),
            body_xyz(env, self.peg),
            body_xyz(env, self.goal),
        );
        // The flattest pitch: the longest reach along the table.
        let pitch = pitch_for_x(f64::INFINITY, PITCH_FAR);
        let lift = (min_tcp_height(pitch) - PEG_HALF_WIDTH).max(0.0);
        let ready = self.arm.rot_err(env, pitch) < POKE_ROT_TOL;
        let mut cmd = ArmCommand {
            target: tcp,
            tcp,
            pitch,
            torso: self.arm.torso(env),
            torso_gain: TORSO_GAIN,
            grip: self.grip.gripper.close,
            limit: 1.0,
            min_step: POKE_MIN_STEP,
        };
        let point = peg + Vector3::new(POKE_GRASP_OFFSET_X, 0.0, lift);
        if !holds(&self.grip, env, point, tcp) {
            (cmd.target, cmd.grip) = grasp(&self.grip, env, (point, tcp), ready, descended_on_peg);
            self.arm.drive(env, cmd, action);
            return;
        }
        let head = peg_head(peg);
        let pre_x = cube.x - CUBE_HALF_DIAGONAL - PRE_PUSH_GAP;
        let lined_up = (head.y - cube.y).abs() < PUSH_LINE_Y
            && head.x > pre_x - POKE_PRE_PUSH_TOL
            && head.x < cube.x;
        let push = Vector3::new(goal.x - POKE_PUSH_SHORT, cube.y, head.z);
        // Done: the cube inside the goal region, or the head at the push's end (the solver's
        // last phase).
        let placed = (cube.xy() - goal.xy()).norm() < GOAL_RADIUS - GOAL_MARGIN
            || (lined_up && head.x > push.x - PUSH_TOL);
        let (want, limit) = if placed {
            (head, 0.0)
        } else if lined_up {
            (push, PUSH_LIMIT)
        } else {
            (Vector3::new(pre_x, cube.y, head.z), 1.0)
        };
        // The tail lifted above its resting grasp height; the head moved by its error (the
        // grasp holds the peg rigidly).
        cmd.target = Vector3::new(
            tcp.x + want.x - head.x,
            tcp.y + want.y - head.y,
            PEG_HALF_WIDTH + lift + POKE_LIFT,
        );
        cmd.limit = limit;
        if placed {
            // Hold still: no command at all (a short one would be stretched to the minimum
            // step, and the robot would not come to rest).
            cmd.target = tcp;
        } else {
            cmd.torso = TORSO_LOW;
        }
        self.arm.drive(env, cmd, action);
    }
}
