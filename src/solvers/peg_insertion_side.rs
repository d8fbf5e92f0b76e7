//! docs/solvers.md §7.9: the panda_wristcam's scripted PegInsertionSide solver
//! (`pd_ee_delta_pose`).
//!
//! ManiSkill's motion-planning solution (`motionplanning/panda/solutions/peg_insertion_side.py`)
//! grasps the lying peg top-down behind its centre, moves it in front of the hole lined up with
//! the hole's axis, corrects that pose three times from the peg's measured pose and pushes it in,
//! each a screw motion. This port keeps the grasp and the two poses but closes the loop on the
//! peg every step: each target is a pose of the peg (its centre on the hole's axis, its axes the
//! box's), turned into a hand target through the grip as it is now, so a peg that turned or
//! slid in the fingers still goes where it should. Three more departures: the lift already turns
//! the peg towards the hole's axis, and the carry adds up the errors the loaded arm leaves
//! (`pd_ee_delta_pose` moves from where the hand is, and a held peg's weight holds it a few
//! millimetres short).
//!
//! The third is for the episodes' sake in ManiSkill (docs/outcome-physics.md): the lift and the
//! carry speed up and slow down at most [`CARRY_ACCEL`] a step, because PhysX's fingers let the
//! peg tip head-down under a hard start (3–4°, which jams it at the hole's mouth); and once the
//! head has entered the mouth, the hand runs a small spiral about the hole's axis
//! ([`SEARCH_RADIUS`]) before it pushes. Here the peg is already in the mouth and the spiral
//! only leans it on the walls; replayed open loop in ManiSkill, where the peg sits a few
//! millimetres differently in PhysX's grip and meets the box's face beside the hole, the
//! spiral finds the hole, which forgives 3 mm.
//!
//! Measured (0.01 s step): 95/100 on seeds 0–99, 90 on 100–199, 91 on 5000–5099
//! (docs/solvers.md §9).
use nalgebra::{UnitQuaternion, Vector3};

use super::{
    body_id, body_quat, body_xyz, tcp_link_xyz, write_pos, write_rot, Gripper, Phases, Policy,
    SolverError, ACTION_SCALE, APPROACH_HEIGHT, APPROACH_TOL, DESCEND_TOL, PANDA_GRIPPER,
};
use crate::env::Env;
use crate::mujoco::BodyId;

/// The grip's smallest distance behind the peg's centre (m).
const GRASP_MIN_OFFSET: f64 = 0.02;
/// The grasp point's largest horizontal distance from the robot's base (m): further, the
/// top-down hand stalls short of it.
const REACH: f64 = 0.78;
/// The robot's base in the world (m), where the table scene puts it.
const BASE_XY: [f64; 2] = [-0.615, 0.0];

/// Height of the lift before the peg is turned and carried (m above the grasp).
const LIFT: f64 = 0.05;
/// The lift is done this close to its height (m).
const LIFT_TOL: f64 = 0.01;
/// The hand's orientation error at which it may start down to the grasp point (rad): it goes
/// on turning as it descends...
const DESCEND_ROT_TOL: f64 = 0.3;
/// ... and closes within this of the grasp orientation (rad).
const ROT_TOL: f64 = 0.05;
/// In front of the hole: the peg's head this far before the hole's mouth (m).
const STANDOFF: f64 = 0.015;
/// Lined up in front of the hole: the peg's head and centre within this of the hole's axis
/// (m), its centre within this of the standoff point...
const LINE_UP_TOL: f64 = 0.0015;
/// ... and its axes within this of the box's (rad).
const LINE_UP_ROT_TOL: f64 = 0.015;
/// How far past the hole's centre the head is pushed (m).
const PUSH_PAST: f64 = 0.01;
/// The push advances the peg's centre at most this far along the hole's axis per step (m),
/// and only while the head is within [`PUSH_LATERAL_TOL`] of the axis.
const PUSH_STEP: f64 = 0.01;
const PUSH_LATERAL_TOL: f64 = 0.002;
/// Largest position action while lining up and pushing in (a unit is 0.1 m).
const FINE_LIMIT: f64 = 0.15;
/// Steps the gripper closes before the peg is lifted.
const CLOSE_STEPS: usize = 5;
/// Integral gain of the carry (per step): the loaded arm settles a few millimetres and
/// hundredths of a radian short of each `pd_ee_delta_pose` target, so the errors that remain
/// are added up and commanded on top.
const INTEGRAL_GAIN: f64 = 0.3;
/// Bounds of those sums (m, rad).
const INTEGRAL_MAX: (f64, f64) = (0.02, 0.1);
/// The lift's and the carry's largest change of speed (m per step, per step): they start at
/// most this fast, speed up by at most this each step, and slow down to arrive as a body
/// braking at this rate would (`v ≤ √(2·a·d)`)...
const CARRY_ACCEL: f64 = 0.01;
/// ... but never below this speed (m per step), nor above the action's 0.1 m.
const CARRY_MIN_SPEED: f64 = 0.004;
/// The largest turn of the lift and the carry before the integral is added (rad per step).
const CARRY_MAX_TURN: f64 = 0.1;
/// How far past the hole's mouth the peg's head is taken before the search (m): in ManiSkill's
/// replays, where the head meets the box's face beside the hole, this presses it on the face...
const ENTER: f64 = 0.006;
/// ... within this (m) or after this many steps.
const ENTER_TOL: f64 = 0.003;
const ENTER_STEPS: usize = 4;
/// The search: an Archimedean spiral about the hole's axis in the box's y–z plane, out to this
/// radius (m), ...
const SEARCH_RADIUS: f64 = 0.008;
/// ... this far between turns (m; the hole is 6 mm wider than the peg), ...
const SEARCH_PITCH: f64 = 0.005;
/// ... covered at this speed (m of arc per step).
const SEARCH_SPEED: f64 = 0.004;

/// The search spiral's offset from the hole's axis at search step `k`, in the plane of the
/// box's unit `y` and `z` axes: its radius and the offset.
fn spiral(k: usize, y: Vector3<f64>, z: Vector3<f64>) -> (f64, Vector3<f64>) {
    let b = SEARCH_PITCH / std::f64::consts::TAU;
    // Arc length b·θ²/2 of the spiral r = b·θ.
    let theta = (2.0 * k as f64 * SEARCH_SPEED / b).sqrt();
    let r = b * theta;
    (r, r * theta.cos() * y + r * theta.sin() * z)
}

/// Steps of the search: the spiral's points within [`SEARCH_RADIUS`].
fn search_steps() -> usize {
    (0..)
        .take_while(|&k| spiral(k, Vector3::y(), Vector3::z()).0 <= SEARCH_RADIUS)
        .count()
}

/// The grip's distance behind the centre `peg` of a peg of half length `l` lying along `axis`:
/// ManiSkill's `max(0.05, L/2 + 0.01)`, but nearer the centre where that would put the grasp
/// point beyond [`REACH`] of the base.
fn grasp_offset(peg: Vector3<f64>, axis: Vector3<f64>, l: f64) -> f64 {
    let far = (0.5 * l + 0.01).max(0.05);
    let base = Vector3::new(BASE_XY[0], BASE_XY[1], peg.z);
    let reach = |d: f64| ((peg - d * axis) - base).xy().norm() <= REACH;
    // The largest offset in reach, in millimetre steps down to the smallest.
    (0..)
        .map(|k| far - 0.001 * k as f64)
        .take_while(|&d| d >= GRASP_MIN_OFFSET)
        .find(|&d| reach(d))
        .unwrap_or(GRASP_MIN_OFFSET)
}

/// The panda_wristcam's PegInsertionSide solver: 0–2 the grasp, 3 lift, 4 line up in front of
/// the hole, 5 enter its mouth, 6 search, 7 push in, 8 hold.
#[derive(Debug)]
pub struct PegInsertionSideSolver {
    peg: BodyId,
    box_body: BodyId,
    hand: BodyId,
    fingers: [BodyId; 2],
    phases: Phases,
    /// The episode's peg half length, radius and hole offset (y, z) in the box's frame.
    half_length: f64,
    hole: [f64; 2],
    /// The hand orientation for the grasp: fingers across the peg.
    down: UnitQuaternion<f64>,
    /// The lift's height (m).
    lift_z: f64,
    /// The episode's grip distance behind the peg's centre (m).
    offset: f64,
    /// The summed position and rotation errors of the carry (m, rad).
    bias: (Vector3<f64>, Vector3<f64>),
    /// The last step's commanded speed of the lift or the carry (m per step).
    speed: f64,
    /// Steps of the search ([`search_steps`]).
    search_steps: usize,
}

impl PegInsertionSideSolver {
    /// Resolves the peg, the box and the hand of a PegInsertionSide env.
    pub fn new(env: &Env) -> Result<Self, SolverError> {
        let robot = env.robot();
        Ok(PegInsertionSideSolver {
            peg: body_id(env.model(), "peg")?,
            box_body: body_id(env.model(), "box_with_hole")?,
            hand: robot.body("panda_hand_tcp")?,
            fingers: [
                robot.body("panda_leftfinger")?,
                robot.body("panda_rightfinger")?,
            ],
            phases: Phases::default(),
            half_length: 0.0,
            hole: [0.0; 2],
            down: UnitQuaternion::identity(),
            lift_z: 0.0,
            offset: 0.0,
            bias: (Vector3::zeros(), Vector3::zeros()),
            speed: 0.0,
            search_steps: search_steps(),
        })
    }

    /// The hand's position and rotation targets that carry the held peg to centre `centre`
    /// with rotation `rot`, through the grip as it is now (peg and hand turn together about
    /// the TCP).
    fn carry(
        &self,
        env: &Env,
        centre: Vector3<f64>,
        rot: UnitQuaternion<f64>,
    ) -> (Vector3<f64>, Vector3<f64>) {
        let (peg, tcp) = (body_xyz(env, self.peg), tcp_link_xyz(env));
        let turn = rot * body_quat(env, self.peg).inverse();
        (centre - turn * (peg - tcp), turn.scaled_axis())
    }
}

impl Policy for PegInsertionSideSolver {
    fn reset(&mut self, env: &Env) {
        self.phases.reset();
        self.bias = (Vector3::zeros(), Vector3::zeros());
        self.speed = 0.0;
        let shapes = env.task().geometry();
        self.half_length = shapes[0];
        self.hole = [shapes[2], shapes[3]];
        // The smallest turn about the vertical that lays the fingers' axis across the peg.
        let peg_axis = body_quat(env, self.peg) * Vector3::x();
        let fingers = body_xyz(env, self.fingers[0]) - body_xyz(env, self.fingers[1]);
        let want = peg_axis.y.atan2(peg_axis.x) + std::f64::consts::FRAC_PI_2;
        let turn = (want - fingers.y.atan2(fingers.x) + std::f64::consts::FRAC_PI_2)
            .rem_euclid(std::f64::consts::PI)
            - std::f64::consts::FRAC_PI_2;
        self.down =
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), turn) * body_quat(env, self.hand);
        self.lift_z = body_xyz(env, self.peg).z + LIFT;
        self.offset = grasp_offset(body_xyz(env, self.peg), peg_axis, self.half_length);
    }

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        let tcp = tcp_link_xyz(env);
        let peg = body_xyz(env, self.peg);
        let peg_rot = body_quat(env, self.peg);
        let hand = body_quat(env, self.hand);
        let l = self.half_length;
        let grasp_point = peg + peg_rot * Vector3::new(-self.offset, 0.0, 0.0);
        let down_err = (self.down * hand.inverse()).scaled_axis();
        // The hole: its centre, its axis (the box's x) and the box's rotation, the peg's goal.
        let box_rot = body_quat(env, self.box_body);
        let axis = box_rot * Vector3::x();
        let hole =
            body_xyz(env, self.box_body) + box_rot * Vector3::new(0.0, self.hole[0], self.hole[1]);
        let goal = hole - l * axis;
        // The head's and the centre's distances from the hole's axis.
        let off_axis = |p: Vector3<f64>| {
            let d = p - hole;
            (d - d.dot(&axis) * axis).norm()
        };
        let head = peg + peg_rot * Vector3::new(l, 0.0, 0.0);
        let standoff = goal - (l + STANDOFF) * axis;
        let (in_front, in_front_rot) = self.carry(env, standoff, box_rot);
        // The push: the peg's centre back on the axis, and a little further along it.
        let along = (peg - goal).dot(&axis);
        let advance = match off_axis(head) < PUSH_LATERAL_TOL {
            true => (PUSH_PAST - along).clamp(0.0, PUSH_STEP),
            false => 0.0,
        };
        let pushed_centre = goal + (along + advance) * axis;
        let (pushed, pushed_rot) = self.carry(env, pushed_centre, box_rot);
        // The head [`ENTER`] past the mouth (the box is as long as the peg), and the search's
        // point about it for this step (the phase's step count, or 0 on entering the phase).
        let entered_centre = goal - (l - ENTER) * axis;
        let (entered, entered_rot) = self.carry(env, entered_centre, box_rot);
        let head_in = (head - hole).dot(&axis) + l;
        let k = match self.phases.phase {
            6 => self.phases.steps,
            _ => 0,
        };
        let offset = match k < self.search_steps {
            true => spiral(k, box_rot * Vector3::y(), box_rot * Vector3::z()).1,
            false => Vector3::zeros(),
        };
        let (searched, searched_rot) = self.carry(env, entered_centre + offset, box_rot);
        let search_steps = self.search_steps;
        let lined_up = off_axis(head) < LINE_UP_TOL
            && off_axis(peg) < LINE_UP_TOL
            && (peg - standoff).norm() < 2.0 * LINE_UP_TOL
            && in_front_rot.norm() < LINE_UP_ROT_TOL;
        let success = env.info().success();
        let Gripper { open, close } = PANDA_GRIPPER;
        let above = grasp_point + Vector3::new(0.0, 0.0, APPROACH_HEIGHT);
        let turned = down_err.norm();
        let (target, rot, grip, limit) = self.phases.run(|phase, steps| {
            let (out, done) = match phase {
                // Above the grasp point, then down to it while the hand still turns.
                0 => {
                    let near = (above - tcp).norm() < APPROACH_TOL;
                    (
                        (above, down_err, open, 1.0),
                        near && turned < DESCEND_ROT_TOL,
                    )
                }
                1 => {
                    let done = (grasp_point - tcp).norm() < DESCEND_TOL && turned < ROT_TOL;
                    ((grasp_point, down_err, open, 1.0), done)
                }
                2 => ((grasp_point, down_err, close, 1.0), steps >= CLOSE_STEPS),
                // The lift, the peg already turning towards the hole's axis.
                3 => {
                    let t = Vector3::new(tcp.x, tcp.y, self.lift_z);
                    (
                        (t, in_front_rot, close, 1.0),
                        tcp.z > self.lift_z - LIFT_TOL,
                    )
                }
                4 => ((in_front, in_front_rot, close, 1.0), lined_up),
                5 => (
                    (entered, entered_rot, close, FINE_LIMIT),
                    head_in > ENTER - ENTER_TOL || steps >= ENTER_STEPS,
                ),
                6 => (
                    (searched, searched_rot, close, FINE_LIMIT),
                    steps >= search_steps,
                ),
                7 => ((pushed, pushed_rot, close, FINE_LIMIT), success),
                _ => ((pushed, pushed_rot, close, FINE_LIMIT), false),
            };
            (out, done)
        });
        let (mut pos_err, mut rot) = (target - tcp, rot);
        if self.phases.phase == 3 || self.phases.phase == 4 {
            let speed = (self.speed + CARRY_ACCEL)
                .min((2.0 * CARRY_ACCEL * pos_err.norm()).sqrt())
                .max(CARRY_MIN_SPEED)
                .min(ACTION_SCALE * limit);
            if pos_err.norm() > speed {
                pos_err *= speed / pos_err.norm();
            }
            self.speed = pos_err.norm();
            if rot.norm() > CARRY_MAX_TURN {
                rot *= CARRY_MAX_TURN / rot.norm();
            }
        }
        // The integral, but not while searching: the spiral's points are taken as they are.
        if self.phases.phase >= 4 && self.phases.phase != 6 {
            let clamp = |v: Vector3<f64>, max: f64| v * (max / v.norm().max(max));
            self.bias.0 = clamp(self.bias.0 + INTEGRAL_GAIN * pos_err, INTEGRAL_MAX.0);
            self.bias.1 = clamp(self.bias.1 + INTEGRAL_GAIN * rot, INTEGRAL_MAX.1);
            pos_err += self.bias.0;
            rot += self.bias.1;
        }
        write_pos(pos_err / ACTION_SCALE, limit, action);
        write_rot(rot, action);
        action[6] = grip;
    }
}
