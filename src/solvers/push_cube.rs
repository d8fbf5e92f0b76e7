//! Scripted PushCube-v1 and PullCube-v1 solvers: ManiSkill's motion-planning solutions
//! (`push_cube.py`, `pull_cube.py`) ported to EE-space phases. Pulling is pushing from the
//! cube's far side, so one planner ([`Slide`]) serves both tasks with the Panda, sliding
//! along `+x` (push) or `−x` (pull):
//!
//! 0. above the start point: `gap` behind the cube (on the side away from the goal),
//!    [`APPROACH_HEIGHT`] above the slide height;
//! 1. down to the start point;
//! 2. slide along x, on the line of the cube's initial y, until the TCP is `contact` short of
//!    the goal centre, the action limited (a fast push launches the cube); then hold.
//!
//! The gripper is half open while sliding ([`PANDA_PUSH_GRIP`]): both fingers touch the
//! cube's face, and the cube slides straight. With closed fingers (ManiSkill's solutions
//! close the gripper) the single contact turned the cube by up to 40° and it drifted 5–10 cm
//! sideways, out of the goal, in 12 of 50 episodes.
//!
//! ManiSkill's solutions reach `obj ∓ 0.05` at the cube's height in one screw motion and then
//! move the TCP to `goal − 0.12` (push) or `goal + 0.05` (pull). The push's end point leaves
//! the cube's centre about 9 cm from the goal centre, 1 cm inside the 10 cm success radius,
//! so the port aims the cube at the goal centre instead; it also approaches from above, so
//! that the fingers never sweep over the cube.
//!
//! The Panda ([`PandaSlide`], `pd_ee_delta_pos`) slides with its TCP at the cube's centre
//! height. The Fetch (`pd_ee_delta_pose`, through [`FetchArm`]) reaches only x ≈ 0.10 with
//! its TCP at the table ([`FETCH_CUBE_REACH_X`]): [`FetchPush`] pushes with the fingers' front
//! and flings the cube towards the farthest goals; [`FetchPull`] cannot get its fingers behind
//! most cubes, so it grasps the cube (as its PickCube solver does) and draws it back.
//!
//! Both robots' pushes reach only so far along the table (the Panda's TCP x ≈ 0.16, the
//! Fetch's 0.10), short of the farthest goals (x up to 0.3, the cube's centre needed at 0.2):
//! for those the slide is faster ([`SlideGeometry::reach`]), and the cube slides on by itself.
//!
//! Measured (0.01 s step, `mjskill eval --episodes 100`, seeds 0–99 / 100–199 / 5000–5099):
//! Panda PushCube 100 / 100 / 99, PullCube 100 / 100 / 100; Fetch PushCube 96 / 96 / 93 (the
//! misses are cubes at x > 0.09, whose goals lie beyond the fling, or in the far corners, where
//! the tilted gripper stalls above the table) and PullCube 100 / 99 / 98 (docs/solvers.md §9).
use nalgebra::Vector3;

use super::body_id;
use super::fetch::{approached_tilted, pick_pitch_and_height, GRASP, ROT_TOL, TORSO_PICK};
use super::fetch_arm::{
    descended_tilted, min_tcp_height, pitch_for_x, ArmCommand, FetchArm, PITCH_FAR,
};
use super::{
    body_xyz, ee_action, tcp_link_xyz, Phases, Policy, SolverError, APPROACH_HEIGHT, APPROACH_TOL,
    DESCEND_TOL,
};
use crate::env::Env;
use crate::mujoco::BodyId;
use crate::tasks::push_cube::{CUBE_HALF_SIZE, GOAL_RADIUS};

/// Action limit while sliding the cube.
const SLIDE_LIMIT: f64 = 0.2;

/// Where the TCP goes relative to the cube, per robot and task.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SlideGeometry {
    /// Start point: TCP-to-cube-centre distance along the slide direction (m).
    pub gap: f64,
    /// Slide end: the TCP stops this far short of the goal centre (m), so that the cube in
    /// front of the fingers ends at the centre.
    pub contact: f64,
    /// TCP height while sliding (m).
    pub height: f64,
    /// Action limit while sliding.
    pub limit: f64,
    /// Pushing: the farthest x to which the fingers push the cube's centre (m, the arm's
    /// reach). A goal whose radius, less [`FLICK_MARGIN`], starts beyond it gets a faster
    /// slide, `limit + flick_gain · (shortfall in m)`, and the cube slides on by itself.
    pub reach: f64,
    /// Action limit added per metre of shortfall beyond `reach`.
    pub flick_gain: f64,
}

/// How far inside the goal radius a pushed cube must get (m) for the slide not to flick it.
const FLICK_MARGIN: f64 = 0.03;

/// Panda, both tasks: ManiSkill's 5 cm start gap; the fingertips (2 cm across in x) touch the
/// cube with the TCP 3 cm from its centre; the TCP at the cube's centre height. At the table
/// its TCP reaches x ≈ 0.16, so the cube's centre ≈ 0.19; goals at x ≈ 0.3 need the cube
/// flung the last 3 cm.
const PANDA_GEOMETRY: SlideGeometry = SlideGeometry {
    gap: 0.05,
    contact: CUBE_HALF_SIZE + 0.01,
    height: CUBE_HALF_SIZE,
    limit: SLIDE_LIMIT,
    reach: 0.19,
    flick_gain: 10.0,
};

/// Panda gripper action while sliding: finger targets 1.5 cm each side of the TCP (the
/// action maps −1…1 to −0.01…0.04 m), so both fingers touch the cube's 4 cm face and the
/// cube slides straight instead of turning about a single contact.
const PANDA_PUSH_GRIP: f32 = 0.0;

/// The phases of the module docs for one episode.
#[derive(Debug)]
pub(crate) struct Slide {
    cube: BodyId,
    goal: BodyId,
    /// +1 pushes the cube along +x (PushCube), −1 pulls it along −x (PullCube).
    dir: f64,
    geometry: SlideGeometry,
    phases: Phases,
    /// The cube's y when the slide began (the slide's line).
    start_y: Option<f64>,
}

impl Slide {
    /// Resolves the cube and goal of a PushCube or PullCube env.
    pub fn new(env: &Env, geometry: SlideGeometry) -> Result<Self, SolverError> {
        let dir = match env.id() {
            "PullCube-v1" => -1.0,
            _ => 1.0,
        };
        Ok(Slide {
            cube: body_id(env.model(), "cube")?,
            goal: body_id(env.model(), "goal_region")?,
            dir,
            geometry,
            phases: Phases::default(),
            start_y: None,
        })
    }

    /// Back to phase 0 (episode start).
    pub fn reset(&mut self) {
        self.phases.reset();
        self.start_y = None;
    }

    /// The action limit of the slide to `goal` (see [`SlideGeometry::reach`]).
    fn slide_limit(&self, goal: Vector3<f64>) -> f64 {
        let g = &self.geometry;
        let shortfall = goal.x - GOAL_RADIUS + FLICK_MARGIN - g.reach;
        if self.dir > 0.0 && shortfall > 0.0 {
            (g.limit + g.flick_gain * shortfall).min(1.0)
        } else {
            g.limit
        }
    }

    /// The TCP target and position action limit for this step (phases advance with
    /// fall-through); `ready`: whether the robot may leave the approach (e.g. its gripper is
    /// turned); `descended(target, tcp)` ends the descent.
    pub fn plan(
        &mut self,
        env: &Env,
        tcp: Vector3<f64>,
        ready: bool,
        descended: impl Fn(Vector3<f64>, Vector3<f64>) -> bool,
    ) -> (Vector3<f64>, f64) {
        let (cube, goal) = (body_xyz(env, self.cube), body_xyz(env, self.goal));
        let SlideGeometry {
            gap,
            contact,
            height,
            ..
        } = self.geometry;
        let limit = self.slide_limit(goal);
        let start = Vector3::new(cube.x - self.dir * gap, cube.y, height);
        let y0 = *self.start_y.get_or_insert(cube.y);
        let end = Vector3::new(goal.x - self.dir * contact, y0, height);
        self.phases.run(|phase, _| match phase {
            0 => {
                let t = start + Vector3::new(0.0, 0.0, APPROACH_HEIGHT);
                ((t, 1.0), ready && (t - tcp).norm() < APPROACH_TOL)
            }
            1 => ((start, 1.0), descended(start, tcp)),
            _ => ((end, limit), false),
        })
    }
}

/// The descent is done within [`DESCEND_TOL`].
fn descended(target: Vector3<f64>, tcp: Vector3<f64>) -> bool {
    (target - tcp).norm() < DESCEND_TOL
}

/// PushCube / PullCube with the Panda (`pd_ee_delta_pos`).
#[derive(Debug)]
pub struct PandaSlide {
    slide: Slide,
}

impl PandaSlide {
    /// Resolves the bodies of a PushCube or PullCube env.
    pub fn new(env: &Env) -> Result<Self, SolverError> {
        Ok(PandaSlide {
            slide: Slide::new(env, PANDA_GEOMETRY)?,
        })
    }
}

impl Policy for PandaSlide {
    fn reset(&mut self, _env: &Env) {
        self.slide.reset();
    }

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        let tcp = tcp_link_xyz(env);
        let (target, limit) = self.slide.plan(env, tcp, true, descended);
        ee_action(target, tcp, limit, PANDA_PUSH_GRIP, action);
    }
}

/// Fetch: the fingers' front reaches this far ahead of `gripper_link` at the pitches used
/// (m, along x; models/fetch/fetch.urdf's finger box front corner, 3.1 cm, tilted).
const FETCH_FINGER_REACH: f64 = 0.031;
/// Fetch: free space between the fingers and the cube at the start point (m).
const FETCH_START_CLEARANCE: f64 = 0.02;
/// Fetch gripper action while sliding: finger targets 1.5 cm each side of the TCP (the
/// action maps −1…1 to −0.01…0.05 m), as the Panda's ([`PANDA_PUSH_GRIP`]).
const FETCH_PUSH_GRIP: f32 = -1.0 / 6.0;
/// Fetch: action limit while sliding.
const FETCH_SLIDE_LIMIT: f64 = 0.7;
/// Fetch: the farthest x to which its fingers push the cube's centre (m): its TCP reaches
/// x ≈ 0.10 at the table (the shoulder 0.867 m behind the table centre, the arm's 0.666 m and
/// the gripper's 0.305 m held level), the fingers 3 cm further, the cube's centre 2 cm more.
const FETCH_CUBE_REACH_X: f64 = 0.14;
/// Fetch: action limit added per metre the goal lies beyond the reach ([`SlideGeometry`]).
const FETCH_FLICK_GAIN: f64 = 3.5;

/// Fetch: torso height while sliding (m; the table pose has 0.386): low, for the reach along
/// the table.
const FETCH_TORSO: f64 = 0.22;
/// Fetch: torso command per unit error.
const FETCH_TORSO_GAIN: f64 = 0.5;
/// Fetch: orientation tolerance before leaving the approach (rad).
const FETCH_ROT_TOL: f64 = 0.1;

/// PushCube with the Fetch (`pd_ee_delta_pose`): the gripper held at the pitch for the cube's
/// distance, the torso lowered once the approach is done, the fingers' front pushing the
/// cube's back face; a goal beyond [`FETCH_CUBE_REACH_X`] gets a faster slide
/// ([`FETCH_FLICK_GAIN`]) and the cube slides on by itself.
#[derive(Debug)]
pub struct FetchPush {
    slide: Slide,
    arm: FetchArm,
    cube: BodyId,
    pitch: f64,
}

impl FetchPush {
    /// Resolves the bodies of a PushCube env with Fetch.
    pub fn new(env: &Env) -> Result<Self, SolverError> {
        Ok(FetchPush {
            slide: Slide::new(env, Self::geometry(PITCH_FAR))?,
            arm: FetchArm::new(env)?,
            cube: body_id(env.model(), "cube")?,
            pitch: PITCH_FAR,
        })
    }

    /// The geometry at gripper pitch `pitch`: the fingers' front touches the cube's back face.
    fn geometry(pitch: f64) -> SlideGeometry {
        let contact = CUBE_HALF_SIZE + FETCH_FINGER_REACH * pitch.cos();
        SlideGeometry {
            gap: contact + FETCH_START_CLEARANCE,
            contact,
            height: min_tcp_height(pitch),
            limit: FETCH_SLIDE_LIMIT,
            reach: FETCH_CUBE_REACH_X,
            flick_gain: FETCH_FLICK_GAIN,
        }
    }
}

impl Policy for FetchPush {
    fn reset(&mut self, env: &Env) {
        self.slide.reset();
        let cube = body_xyz(env, self.cube);
        self.pitch = pitch_for_x(cube.x, PITCH_FAR);
        self.slide.geometry = Self::geometry(self.pitch);
    }

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        let tcp = self.arm.gripper_xyz(env);
        let ready = self.arm.rot_err(env, self.pitch) < FETCH_ROT_TOL;
        let (target, limit) = self.slide.plan(env, tcp, ready, descended_tilted);
        let cmd = ArmCommand {
            target,
            tcp,
            pitch: self.pitch,
            // The torso goes down once the approach is done: lowering it while the gripper
            // turns drives the TCP below the approach point and costs 10 steps.
            torso: if self.slide.phases.phase == 0 {
                self.arm.torso(env)
            } else {
                FETCH_TORSO
            },
            torso_gain: FETCH_TORSO_GAIN,
            grip: FETCH_PUSH_GRIP,
            limit,
            min_step: 0.0,
        };
        self.arm.drive(env, cmd, action);
    }
}

/// Fetch, PullCube: the cube's centre is carried this far above the table while it is drawn
/// back (m), so that it does not drag.
const FETCH_PULL_LIFT: f64 = 0.01;

/// PullCube with the Fetch (`pd_ee_delta_pose`): its TCP reaches x ≈ 0.10 at the table
/// ([`FETCH_CUBE_REACH_X`]), too short to hook its fingers behind most cubes, so it grasps
/// the cube as its PickCube solver does (`fetch.rs`: the tilted gripper's pitch for the cube's
/// distance, the lowered torso) and draws it back to the goal centre, just above the table.
#[derive(Debug)]
pub struct FetchPull {
    cube: BodyId,
    goal: BodyId,
    arm: FetchArm,
    phases: Phases,
    pitch: f64,
    grasp_height: f64,
    /// TCP − cube centre when the grasp closed (carried to the goal).
    hold_offset: Vector3<f64>,
}

impl FetchPull {
    /// Resolves the bodies of a PullCube env with Fetch.
    pub fn new(env: &Env) -> Result<Self, SolverError> {
        Ok(FetchPull {
            cube: body_id(env.model(), "cube")?,
            goal: body_id(env.model(), "goal_region")?,
            arm: FetchArm::new(env)?,
            phases: Phases::default(),
            pitch: PITCH_FAR,
            grasp_height: 0.0,
            hold_offset: Vector3::zeros(),
        })
    }
}

impl Policy for FetchPull {
    fn reset(&mut self, env: &Env) {
        self.phases.reset();
        let cube = body_xyz(env, self.cube);
        (self.pitch, self.grasp_height) = pick_pitch_and_height(cube);
    }

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        let tcp = self.arm.gripper_xyz(env);
        let (cube, goal) = (body_xyz(env, self.cube), body_xyz(env, self.goal));
        let grasp = cube + Vector3::new(0.0, 0.0, self.grasp_height);
        let ready = self.arm.rot_err(env, self.pitch) < ROT_TOL;
        let hold_offset = &mut self.hold_offset;
        let carry = Vector3::new(goal.x, goal.y, CUBE_HALF_SIZE + FETCH_PULL_LIFT);
        let (target, grip) = self.phases.run(|phase, steps| match phase {
            0..=2 => {
                let (t, grip, mut done) = GRASP.phase(phase, steps, grasp, tcp, ready);
                if phase == 0 {
                    done = ready && approached_tilted(t, tcp);
                }
                if phase == 2 && done {
                    *hold_offset = tcp - cube;
                }
                ((t, grip), done)
            }
            _ => ((carry + *hold_offset, GRASP.gripper.close), false),
        });
        let cmd = ArmCommand {
            target,
            tcp,
            pitch: self.pitch,
            torso: TORSO_PICK,
            torso_gain: 1.0,
            grip,
            limit: 1.0,
            min_step: 0.0,
        };
        self.arm.drive(env, cmd, action);
    }
}
