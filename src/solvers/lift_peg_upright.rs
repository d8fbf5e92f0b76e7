//! docs/solvers.md §7.7: the Panda's scripted LiftPegUpright solver (`pd_ee_delta_pose`).
//!
//! ManiSkill's motion-planning solution (`motionplanning/panda/solutions/lift_peg_upright.py`)
//! grasps the lying peg top-down 0.1 m from its centre with the gripper closed only to −0.6,
//! lifts it, turns the hand 36° so that the loosely held peg swings towards the vertical, lowers
//! it and lets go. This port keeps the grasp, the loose grip and the swing as EE-space phases
//! and closes the loop on the peg: from the lift on it turns the hand by the rotation that takes
//! the peg's axis to the vertical, and lowers the peg onto its end once upright, where it is
//! held.
//!
//! Once the peg stands within 0.1 rad of upright the fingers let go, and it rights itself.
//! Measured (0.01 s step, with the scene's no-slip pass): 93/100 on seeds 0–99 (95 on
//! 100–199). Replayed open loop in ManiSkill, 46, 49 and 48 of 50 episodes end the same
//! (seeds 0–49, 1000–1049, 2000–2049; 9 of 50 before the pass, when the loosely held peg
//! crept round in MuJoCo's fingers; docs/solvers.md §7.7, §9).
//!
//! The Fetch's solver ([`FetchLiftPeg`]) cannot turn the peg with its hand (its gripper
//! pitches ≈ 0.01 rad per step while holding it), so it lets the peg turn in a loose grip as
//! it lifts, lowers it onto its lower end, moves the hand over that end and lets go once it
//! leans less than 0.25 rad and the hand has stopped, where it rights itself; pegs beyond
//! x = 0.07 are first dragged back along the table. Its fingers meet the peg's faces at an
//! angle, and ease once if the lifted peg has not swung. Measured: 96/100 on seeds 0–99 (90
//! on 100–199, 91 on 200–299; 915, 894 and 925 of 1000 on the held-out 7000–7999, 9000–9999
//! and 11000–11999; before the angle and the ease: 91, 81, 83 and 798 of 7000–7999).
//! Replayed open loop in ManiSkill (seeds 1000–1049, as joint targets): 0 of 50 succeed
//! there and 6 end the same (docs/solvers.md §7.7).
use std::f64::consts::{FRAC_PI_2, PI};

use nalgebra::{UnitQuaternion, Vector3};

use super::fetch::{
    approached_tilted, pick_pitch_and_height, CARRY_TORSO_GAIN, GRASP, ROT_TOL as FETCH_ROT_TOL,
    TORSO_CARRY, TORSO_PICK,
};
use super::fetch_arm::{ArmCommand, FetchArm};
use super::{
    body_id, body_quat, body_xyz, tcp_link_xyz, tcp_xyz, write_pos, write_rot, Grasp, Gripper,
    Phases, Policy, ACTION_SCALE, CLOSE_STEPS, FETCH_GRIPPER,
};
use crate::env::Env;
use crate::mujoco::BodyId;
use crate::tasks::lift_peg_upright::{PEG_HALF_LENGTH, PEG_HALF_WIDTH};

/// The grip is this far from the peg's centre, towards its +x end (m; ManiSkill's 0.1) ...
const GRASP_OFFSET: f64 = 0.1;
/// ... but no further forward than this (m): beyond it the top-down hand stalls short of the
/// peg (8 of seeds 0–99, pegs at x > 0.08).
const GRASP_MAX_X: f64 = 0.17;
/// Height of the TCP for the turn (m): the peg's lower end clears the table once upright.
const TURN_HEIGHT: f64 = GRASP_OFFSET + PEG_HALF_LENGTH + 0.05;
/// The lift is done this close under [`TURN_HEIGHT`] (m).
const LIFT_TOL: f64 = 0.02;
/// The gripper action that holds the peg loosely enough to swing (ManiSkill's −0.6).
const LOOSE_GRIP: f32 = -0.6;
/// The peg's axis within this of the vertical ends the turn (rad).
const UPRIGHT_TOL: f64 = 0.03;
/// Orientation tolerance of the approach (rad).
const ROT_TOL: f64 = 0.05;
/// The lowering ends with the peg's centre this close to its upright height (m).
const LOWER_TOL: f64 = 0.002;
/// From the turn on, the fingers open while the peg stands on the table (its centre within
/// [`STANDING_TOL`] of its upright height, m) leaning less than this (rad), and close again
/// should it lean further: let go, a peg standing on its end rights itself in PhysX as in
/// MuJoCo, where one held on is turned by the hand as each simulator's grip allows. Its
/// episodes replayed in ManiSkill end the same in 46, 49 and 48 of 50 (seeds 0–49,
/// 1000–1049, 2000–2049; ManiSkill 47, 47 and 48 successes), 39, 41 and 41 held to the end;
/// the solver's own successes 93, 92 and 93 of seeds 0–99, 1000–1099, 2000–2099 (95, 92 and
/// 94 held; 95, 92, 94 letting go below 0.08 rad, 90, 89, 90 below 0.12).
const RELEASE_TILT: f64 = 0.1;
const STANDING_TOL: f64 = 0.004;

/// The Panda's LiftPegUpright solver: 0–2 the grasp, 3 lift, 4 turn, 5 lower, 6 hold (the
/// hand turns the peg's axis to the vertical from phase 3 on, and the fingers let go while
/// the peg stands nearly upright: [`RELEASE_TILT`]).
#[derive(Debug)]
pub struct PandaLiftPeg {
    peg: BodyId,
    hand: BodyId,
    fingers: [BodyId; 2],
    grasp: Grasp,
    phases: Phases,
    /// The hand orientation for the grasp: fingers across the peg.
    down: UnitQuaternion<f64>,
    /// This episode's grip offset from the peg's centre along +x (m).
    offset: f64,
}

impl PandaLiftPeg {
    /// Resolves the peg and the hand of a LiftPegUpright env with the Panda.
    pub fn new(env: &Env, gripper: Gripper) -> Result<Self, super::SolverError> {
        let robot = env.robot();
        Ok(PandaLiftPeg {
            peg: body_id(env.model(), "peg")?,
            hand: robot.body("panda_hand_tcp")?,
            fingers: [
                robot.body("panda_leftfinger")?,
                robot.body("panda_rightfinger")?,
            ],
            grasp: Grasp::new(gripper),
            phases: Phases::default(),
            down: UnitQuaternion::identity(),
            offset: GRASP_OFFSET,
        })
    }
}

/// The smallest turn about the vertical that puts a closing axis at angle `axis` (rad, in
/// the xy plane; a line, so modulo π) along world y.
fn turn_to_y(axis: f64) -> f64 {
    (FRAC_PI_2 - axis + FRAC_PI_2).rem_euclid(PI) - FRAC_PI_2
}

impl Policy for PandaLiftPeg {
    fn reset(&mut self, env: &Env) {
        self.phases.reset();
        self.offset = GRASP_OFFSET.min(GRASP_MAX_X - body_xyz(env, self.peg).x);
        let axis = body_xyz(env, self.fingers[0]) - body_xyz(env, self.fingers[1]);
        let turn = turn_to_y(axis.y.atan2(axis.x));
        self.down =
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), turn) * body_quat(env, self.hand);
    }

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        let tcp = tcp_link_xyz(env);
        let peg = body_xyz(env, self.peg);
        let hand = body_quat(env, self.hand);
        let grasp_point = peg + Vector3::new(self.offset, 0.0, 0.0);
        let down_err = (self.down * hand.inverse()).scaled_axis();
        // The turn that stands the held peg's axis vertical (closed loop on the peg).
        let axis = body_quat(env, self.peg) * Vector3::x();
        let vertical = Vector3::new(0.0, 0.0, axis.z.signum());
        let upright_err = UnitQuaternion::rotation_between(&axis, &vertical)
            .map_or(Vector3::zeros(), |q| q.scaled_axis());
        let g = self.grasp;
        let close = LOOSE_GRIP;
        let (target, grip) = self.phases.run(|phase, steps| {
            let (target, grip, done) = match phase {
                0..=1 => g.phase(phase, steps, grasp_point, tcp, down_err.norm() < ROT_TOL),
                2 => (grasp_point, close, steps >= CLOSE_STEPS),
                3 => {
                    let t = Vector3::new(tcp.x, tcp.y, TURN_HEIGHT);
                    (t, close, tcp.z > TURN_HEIGHT - LIFT_TOL)
                }
                4 => (tcp, close, upright_err.norm() < UPRIGHT_TOL),
                5 => {
                    let dz = PEG_HALF_LENGTH - peg.z;
                    (
                        tcp + Vector3::new(0.0, 0.0, dz),
                        close,
                        dz.abs() < LOWER_TOL,
                    )
                }
                _ => (tcp, close, false),
            };
            ((target, grip), done)
        });
        let rot_err = if self.phases.phase >= 3 {
            upright_err
        } else {
            down_err
        };
        let standing = (peg.z - PEG_HALF_LENGTH).abs() < STANDING_TOL;
        let release = self.phases.phase >= 4 && standing && upright_err.norm() < RELEASE_TILT;
        write_pos((target - tcp) / ACTION_SCALE, 1.0, action);
        write_rot(rot_err, action);
        action[6] = if release {
            self.grasp.gripper.open
        } else {
            grip
        };
    }
}

/// The Fetch grips the peg this far from its centre, on the robot's side (m).
const FETCH_GRASP_OFFSET: f64 = 0.1;
/// The Fetch's approach point above the grasp point (m), raised by [`FETCH_APPROACH_CONE`]
/// times the TCP's horizontal distance from it, as the Fetch's StackCube approach ...
const FETCH_APPROACH_HEIGHT: f64 = 0.03;
const FETCH_APPROACH_CONE: f64 = 1.0;
/// ... and by this times the torso's travel still to come down to [`TORSO_PICK`]: the torso
/// drops at full speed while the arm dives, and without it the TCP overshot the approach
/// point by 3–4 cm and the palm knocked the peg away (7 of seeds 0–99 never lifted; 26, 10
/// and 0 with 0.5, 1 and 1.5).
const FETCH_APPROACH_TORSO: f64 = 1.5;
/// The approach is also done once the diving arm is already below the approach point within
/// this of the grasp point horizontally (m): climbing back costs 8 of the 50 steps.
const FETCH_DIVE_TOL: f64 = 0.01;
/// Shortest position command of the descent (action units).
const FETCH_MIN_STEP: f64 = 0.1;
/// The Fetch's grip (normalised finger target; −1 closes): light enough that the lifted peg
/// turns in the fingers towards hanging, firm enough to carry it (−0.3 drops it more often,
/// −0.5 holds it rigidly: 26, 52 and 6 % of seeds 0–49).
const FETCH_LOOSE_GRIP: f32 = -0.4;
/// TCP height of the lift (m above the table).
const FETCH_LIFT_HEIGHT: f64 = 0.26;
/// The gripper's pitch from the lift on (rad below the horizontal): about the pick's, so the
/// hand barely turns while the peg swings (successes of seeds 0–99 with the release: 53, 57,
/// 61, 69 and 41 with 0.3, 0.45, 0.6, 0.75 and 0.9).
const FETCH_LIFT_PITCH: f64 = 0.75;
/// The lift ends once the peg hangs within this of the vertical (rad) ...
const FETCH_STAND_TILT: f64 = 0.6;
/// ... or after this many steps: a peg that stopped turning short of it (held in the air in
/// 7–13 of 100 seeds) is stood on the table all the same.
const FETCH_LIFT_STEPS: usize = 16;
/// A peg lying this far from the vertical (rad) in the stand phase has dropped: hold still.
const FETCH_DROPPED_TILT: f64 = 1.2;
/// The stand phase lets go once the peg is within this of the vertical (rad) with its lowest
/// corner within [`FETCH_RELEASE_FOOT`] of the table (m): a 0.24 × 0.05 box standing on an
/// edge rights itself onto its end below atan(0.025 / 0.12) ≈ 0.2 rad, and the opening
/// fingers carry it a little further. Successes of seeds 0–99: 61 releasing at 0.2 against 56
/// holding on (before the other changes), 77 and 79 at 0.2 and 0.25 with them.
const FETCH_RELEASE_TILT: f64 = 0.25;
const FETCH_RELEASE_FOOT: f64 = 0.005;
/// ... and the TCP moved less than this in the last step (m): let go while the hand still
/// moves over the foot (about 3 cm a step), the peg rights itself past the vertical and rocks;
/// held until the hand has stopped, it stands nearer the vertical and stays. Seeds 0–99 and
/// 100–199, successes at any step / upright at step 50: 91/23, 81/20 without it; 91/38, 81/35
/// at 0.02; 91/67, 81/54 at 0.015; 91/86, 81/77 at 0.01; 91/89, 81/79 at 0.0075; 91/90,
/// 81/79 at 0.005; 91/89, 81/79 at 0.003 and 0.002; 90/88, 81/79 at 0.001. Seeds 0–999 and
/// 1000–1999: 808/209, 811/214 without it; 816/765, 815/766 at 0.01; 816/786, 814/793 at
/// 0.0075; 816/798, 812/797 at 0.005; 816/796, 812/798 at 0.003.
const FETCH_RELEASE_SPEED: f64 = 0.005;
/// Pegs whose centre lies beyond this x at the start (m) are first dragged back along the
/// table: their lower end otherwise stands ahead of the hand's reach. Successes of seeds 0–999
/// and 1000–1999 (with the lowering of [`FETCH_STAND_FOOT_AIR`]): 771/765, 780/776, 803/800,
/// 803/805 and 805/802 from 0.04, 0.05, 0.06, 0.07 and 0.08 (dragged to −0.02 from 0.06 on);
/// 769/768 without the drag.
const FETCH_DRAG_FROM_X: f64 = 0.07;
/// ... until the peg's centre is within [`FETCH_DRAG_TOL`] of this x (m). Seeds 0–999 and
/// 1000–1999 from 0.06: 782/774, 790/787, 803/800, 794/794 and 795/786 to 0.02, 0, −0.02,
/// −0.04 and −0.06.
const FETCH_DRAG_TO_X: f64 = -0.02;
const FETCH_DRAG_TOL: f64 = 0.01;
/// The drag gives up after this many steps (it takes 3–5).
const FETCH_DRAG_STEPS: usize = 12;
/// The drag's grip (−1 closes): firm, so the peg slides on the table rather than in the
/// fingers. Seeds 0–999 and 1000–1999: 798/805, 808/811 and 803/805 with −0.6, −0.8 and −1.
const FETCH_DRAG_GRIP: f32 = -0.8;
/// After the drag the fingers ease to this for one step and close to [`FETCH_LOOSE_GRIP`] for
/// [`CLOSE_STEPS`] (a fresh loose grasp): kept at the firm grip's squeeze, or just switched
/// to −0.4, the lifted peg turns little and stands leaning (761/749 switching to −0.4 after a
/// −1 drag, 774/764 dragging at −0.4; 723/741 opening fully to 1 for the step).
const FETCH_REGRASP_EASE: f32 = 0.0;
/// The stand phase first only lowers the peg while its lowest corner is more than this above
/// the table (m), then moves the hand over the lower end: moved over the lower end in the air,
/// the rigidly held peg travelled with the hand to its reach and stood leaning, or swung past
/// the vertical and slipped out. Successes of seeds 0–99, 100–199, 200–299, 300–399 (before
/// the drag): 79/76/72/67 moving at once, 82/77/72/72, 86/78/75/73, 88/81/77/72,
/// 87/80/75/73, 87/81/76/73 and 75/76/70/63 with 0.015, 0.02, 0.025, 0.03, 0.04 and 0.06;
/// 0–999 and 1000–1999 with the drag: 793/792, 803/805 and 803/803 with 0.02, 0.025 and 0.03
/// (moving a third of the way over in the air instead of standing still: 4–10 fewer of 100).
const FETCH_STAND_FOOT_AIR: f64 = 0.025;

/// The Fetch's gripper turns this far about the vertical from the peg's axis (rad), so that its
/// fingers meet the peg's side faces at an angle: closed squarely on them (yaw 0) the lifted
/// peg stayed level in 41 % of the episodes whose peg lay within 1 mrad of square to the
/// fingers after the grasp, against 14 % of the others. Successes of seeds 0–2999, measured
/// before the task's no-slip pass (with [`FETCH_SWING_EASE`]): 2620, 2703 and 2653 with 0.05, 0.055 and 0.06 (without the ease:
/// 2428 at 0, 2487, 2631, 2601, 2566, 2650 and 2593 from 0.035 to 0.06 by 0.005; 2568, 2624,
/// 2522 and 2632 at −0.055, −0.06, −0.065 and −0.07).
const FETCH_GRASP_YAW: f64 = 0.055;
/// A peg still more than [`FETCH_SWING_TILT`] from the vertical after this many steps of the
/// lift (rad) has not swung: the fingers ease to [`FETCH_SWING_EASE`] for one step, which lets
/// it turn, then close to [`FETCH_LOOSE_GRIP`] again. Successes of seeds 0–2999 (with the
/// yaw, before the no-slip pass): 2509, 2703 and 2675 easing at step 5, 6 and 7; 2686, 2703 and 2691 from 0.6, 0.7
/// and 0.8 rad; 2703 and 2714 easing to 0 and 0.3.
const FETCH_SWING_STEP: usize = 6;
const FETCH_SWING_TILT: f64 = 0.7;
const FETCH_SWING_EASE: f32 = 0.3;

/// The Fetch's LiftPegUpright solver (`pd_ee_delta_pose` through [`FetchArm`]): 0–2 the
/// grasp (tilted, as its PickCube), 3 drag a far peg back along the table with a firm grip,
/// 4 grasp it loosely afresh (3 and 4 only for pegs beyond [`FETCH_DRAG_FROM_X`]), 5 lift
/// until the loosely held peg hangs, 6 lower it onto its lower end, then move the hand above
/// that end, 7 let go once it leans little enough to right itself and the hand has stopped.
#[derive(Debug)]
pub struct FetchLiftPeg {
    peg: BodyId,
    arm: FetchArm,
    phases: Phases,
    /// Gripper pitch and grasp height above the peg's centre for this episode.
    pitch: f64,
    grasp_height: f64,
    /// Whether this episode's peg is dragged back first (phases 3–4).
    drag: bool,
    /// The TCP's position at the previous step (its speed decides the release).
    prev_tcp: Vector3<f64>,
}

impl FetchLiftPeg {
    /// Resolves the peg and the Fetch's arm of a LiftPegUpright env.
    pub fn new(env: &Env) -> Result<Self, super::SolverError> {
        Ok(FetchLiftPeg {
            peg: body_id(env.model(), "peg")?,
            arm: FetchArm::new(env)?,
            phases: Phases::default(),
            pitch: 0.0,
            grasp_height: 0.0,
            drag: false,
            prev_tcp: Vector3::zeros(),
        })
    }
}

/// The grasp point's offset from the peg's centre, on the robot's side.
fn fetch_grasp_offset() -> Vector3<f64> {
    Vector3::new(-FETCH_GRASP_OFFSET, 0.0, 0.0)
}

/// Height of the peg's lowest corner above the table (m) for its centre `peg` and
/// orientation `q`.
fn peg_foot(peg: Vector3<f64>, q: UnitQuaternion<f64>) -> f64 {
    let r = q.to_rotation_matrix();
    let m = r.matrix();
    peg.z
        - (PEG_HALF_LENGTH * m[(2, 0)].abs()
            + PEG_HALF_WIDTH * m[(2, 1)].abs()
            + PEG_HALF_WIDTH * m[(2, 2)].abs())
}

impl Policy for FetchLiftPeg {
    fn reset(&mut self, env: &Env) {
        self.phases.reset();
        let peg = body_xyz(env, self.peg);
        (self.pitch, self.grasp_height) = pick_pitch_and_height(peg + fetch_grasp_offset());
        self.drag = peg.x > FETCH_DRAG_FROM_X;
        self.prev_tcp = tcp_xyz(env);
    }

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        let tcp = tcp_xyz(env);
        let peg = body_xyz(env, self.peg);
        let grasp = peg + fetch_grasp_offset() + Vector3::new(0.0, 0.0, self.grasp_height);
        let q = body_quat(env, self.peg);
        let axis = q * Vector3::x();
        let tilt = axis.z.abs().min(1.0).acos();
        let foot = peg_foot(peg, q);
        let lifting = self.phases.phase >= 5;
        let drag = self.drag;
        let pitch = if lifting {
            FETCH_LIFT_PITCH
        } else {
            self.pitch
        };
        let ready = self.arm.rot_err_yawed(env, pitch, FETCH_GRASP_YAW) < FETCH_ROT_TOL;
        let torso_to_come = (self.arm.torso(env) - TORSO_PICK).max(0.0);
        let close = FETCH_LOOSE_GRIP;
        let resting = (tcp - self.prev_tcp).norm() < FETCH_RELEASE_SPEED;
        self.prev_tcp = tcp;
        let (target, grip) = self.phases.run(|phase, steps| match phase {
            0..=2 => {
                let (mut t, mut grip, mut done) = GRASP.phase(phase, steps, grasp, tcp, ready);
                if phase == 0 {
                    let cone = FETCH_APPROACH_CONE * (grasp.xy() - tcp.xy()).norm();
                    let above = FETCH_APPROACH_HEIGHT + cone + FETCH_APPROACH_TORSO * torso_to_come;
                    t = grasp + Vector3::new(0.0, 0.0, above);
                    let dived = (tcp.xy() - grasp.xy()).norm() < FETCH_DIVE_TOL && tcp.z < t.z;
                    done = ready && (approached_tilted(t, tcp) || dived);
                }
                if phase == 2 {
                    grip = close;
                }
                ((t, grip), done)
            }
            3 => {
                // Drag the peg back at grasp height.
                let t = Vector3::new(tcp.x + FETCH_DRAG_TO_X - peg.x, grasp.y, grasp.z);
                let done =
                    !drag || peg.x < FETCH_DRAG_TO_X + FETCH_DRAG_TOL || steps >= FETCH_DRAG_STEPS;
                ((t, FETCH_DRAG_GRIP), done)
            }
            4 => {
                // Ease the grip, then close loosely afresh, in place.
                let t = Vector3::new(tcp.x, grasp.y, grasp.z);
                let grip = if steps == 0 {
                    FETCH_REGRASP_EASE
                } else {
                    close
                };
                ((t, grip), !drag || steps > CLOSE_STEPS)
            }
            5 => {
                let t = Vector3::new(tcp.x, grasp.y, FETCH_LIFT_HEIGHT);
                let done = tilt < FETCH_STAND_TILT || steps >= FETCH_LIFT_STEPS;
                let level = steps == FETCH_SWING_STEP && tilt > FETCH_SWING_TILT;
                ((t, if level { FETCH_SWING_EASE } else { close }), done)
            }
            6 if tilt > FETCH_DROPPED_TILT => ((tcp, close), false),
            6 => {
                // The peg's centre to its standing height; once its lower end is down, the
                // hand above that end.
                let down = if axis.z > 0.0 { -axis } else { axis };
                let bottom = peg + down * PEG_HALF_LENGTH;
                let xy = if foot > FETCH_STAND_FOOT_AIR {
                    tcp.xy()
                } else {
                    bottom.xy()
                };
                let t = Vector3::new(xy.x, xy.y, tcp.z + PEG_HALF_LENGTH - peg.z);
                let done = tilt < FETCH_RELEASE_TILT && foot < FETCH_RELEASE_FOOT && resting;
                ((t, close), done)
            }
            // Let go: the peg rights itself onto its end.
            _ => ((tcp, FETCH_GRIPPER.open), false),
        });
        let cmd = ArmCommand {
            target,
            tcp,
            pitch,
            yaw: FETCH_GRASP_YAW,
            torso: if lifting { TORSO_CARRY } else { TORSO_PICK },
            torso_gain: if lifting { CARRY_TORSO_GAIN } else { 1.0 },
            grip,
            limit: 1.0,
            min_step: if self.phases.phase == 1 {
                FETCH_MIN_STEP
            } else {
                0.0
            },
        };
        self.arm.drive(env, cmd, action);
    }
}
