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
//! The Fetch's solver ([`FetchLiftPeg`], `pd_joint_pos`) grips the peg firmly, tilted as its
//! PickCube, lifts it and rolls its wrist half a turn: the peg, turned with the hand, now
//! hangs below the fingers, and the hand turns it upright, stands it on its end and lets go.
//! Measured: 100/100 on seeds 0–99, 100–199, 1000–1099 and 2000–2099, 1000 of 1000 on the
//! held-out 7000–7999. Replayed open loop in ManiSkill, 50 of 50 episodes end the same (seeds
//! 1000–1049; docs/solvers.md §7.7).
use std::f64::consts::{FRAC_PI_2, PI};

use nalgebra::{UnitQuaternion, Vector3};

use super::fetch::{
    approached_tilted, pick_pitch_and_height, CARRY_TORSO_GAIN, GRASP, ROT_TOL as FETCH_ROT_TOL,
    TORSO_CARRY, TORSO_PICK,
};
use super::fetch_arm::{ArmCommand, FetchArm};
use super::{
    body_id, body_quat, body_xyz, tcp_link_xyz, tcp_xyz, write_pos, write_rot, Grasp, Gripper,
    Phases, Policy, Shadow, ACTION_SCALE, CLOSE_STEPS, FETCH_GRIPPER,
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

/// The Fetch grips the peg this far from its centre, on the robot's side (m): rolled over, the
/// far 0.22 m of the peg hang below the fingers.
const FETCH_GRASP_OFFSET: f64 = 0.1;
/// The Fetch's approach point above the grasp point (m), raised by [`FETCH_APPROACH_CONE`]
/// times the TCP's horizontal distance from it, as the Fetch's StackCube approach ...
const FETCH_APPROACH_HEIGHT: f64 = 0.03;
const FETCH_APPROACH_CONE: f64 = 1.0;
/// ... and by this times the torso's travel still to come down to [`TORSO_PICK`]: the torso
/// drops at full speed while the arm dives, and without it the TCP overshot the approach
/// point by 3–4 cm and the palm knocked the peg away (measured with the loose-grip solver of
/// 30 November: 7 of seeds 0–99 never lifted; 26, 10 and 0 with 0.5, 1 and 1.5).
const FETCH_APPROACH_TORSO: f64 = 1.5;
/// The approach is also done once the diving arm is already below the approach point within
/// this of the grasp point horizontally (m): climbing back costs 8 of the 50 steps.
const FETCH_DIVE_TOL: f64 = 0.01;
/// Shortest position command of the descent (action units).
const FETCH_MIN_STEP: f64 = 0.1;
/// The Fetch's grip (−1 closes): firm, so that the peg turns with the hand in PhysX and MuJoCo
/// alike. Successes of seeds 3000–3499: 500, 498 and 316 with −1, −0.8 and −0.6.
const FETCH_GRIP: f32 = -1.0;
/// TCP height of the lift (m above the table): the rolled peg's lower end, 0.22 m below the
/// fingers, clears the table. 500 of seeds 3000–3499 with 0.25, 0.27 and 0.3.
const FETCH_ROLL_HEIGHT: f64 = 0.27;
/// The lift is done this close under [`FETCH_ROLL_HEIGHT`] (m) ...
const FETCH_LIFT_TOL: f64 = 0.02;
/// ... or after this many steps; the roll gives up after as many.
const FETCH_PHASE_STEPS: usize = 10;
/// The lift takes the TCP back to at most this x (m): a peg gripped at a flat pitch (far
/// pegs: 0.5 rad) needs the gripper pitched to about 1.07 rad to stand, and further forward
/// the wrist is then out of reach (the turn stalls 0.1–0.27 rad short). Successes of seeds
/// 0–99: 85 without, 93, 100, 100 and 100 at −0.08, −0.1, −0.12 and −0.14; of 3000–3499: 497,
/// 500 and 500 at −0.1, −0.12 and −0.15.
const FETCH_STAND_X: f64 = -0.12;
/// The roll: the wrist turns half a turn about the gripper's axis, its target this much
/// further each step (rad). Half a turn reflects the peg about the gripper's axis, so a peg
/// gripped at pitch p hangs 2p below the horizontal: upright for the near pegs' 45°, 0.3–0.6
/// rad short for the far ones, which the hand then turns. Successes of seeds 3000–3499: 500,
/// 500, 431 and 43 with 0.4, 0.8, 1.6 and 3.2 (a wrist flung round shakes the peg loose).
const FETCH_ROLL_STEP: f64 = 0.8;
/// The roll is done within this of half a turn (rad).
const FETCH_ROLL_TOL: f64 = 0.1;
/// The wrist roll: its index in the Fetch's `pd_joint_pos` action (the arm's seventh joint) and
/// among the robot's joints (docs/robots.md).
const FETCH_WRIST_ROLL_ACTION: usize = 6;
const FETCH_WRIST_ROLL_JOINT: usize = 12;
/// While the rolled peg leans more than this (rad) its lowest corner is held
/// [`FETCH_FOOT_CLEAR`] above the table (m); then it is stood on its end.
const FETCH_STAND_TILT: f64 = 0.1;
const FETCH_FOOT_CLEAR: f64 = 0.01;
/// With the peg's lowest corner within this of the table (m), the hand moves at most
/// [`FETCH_SLOW_LIMIT`] of the action range (1 cm) a step.
const FETCH_SLOW_FOOT: f64 = 0.03;
const FETCH_SLOW_LIMIT: f64 = 0.1;
/// The fingers let go once the peg stands ([`STANDING_TOL`]) within [`RELEASE_TILT`] of
/// upright and the TCP moved less than this in the last step (m): let go while the hand still
/// moves down, the peg is slammed onto its end and topples after its success (seeds 0–99,
/// before [`FETCH_STAND_X`]: 85 successes, 62 upright at step 50; at rest, with the slowed
/// descent and the hand held still afterwards: 85 and 85).
const FETCH_RELEASE_SPEED: f64 = 0.005;

/// The Fetch's LiftPegUpright solver (`pd_joint_pos`): 0–2 the grasp (tilted, as its
/// PickCube, firm), 3 lift (back to [`FETCH_STAND_X`]), 4 roll the wrist half a turn (the
/// peg now hangs below the fingers), 5 turn the peg upright and stand it on its end; the
/// fingers let go once it stands upright and the hand has stopped.
///
/// Its arm commands are [`FetchArm`]'s end-effector deltas, turned into joint targets by a
/// shadow env in `pd_ee_delta_pose` ([`Shadow`], as [`super::ModeConverted`] does); only the roll is set
/// in joint space, where the wrist turns in a few steps rather than the 60 that the
/// end-effector mode's 0.1 rad bound and the arm's lag would take.
#[derive(Debug)]
pub struct FetchLiftPeg {
    peg: BodyId,
    arm: FetchArm,
    /// The same env in `pd_ee_delta_pose`, synchronised every step.
    shadow: Shadow,
    phases: Phases,
    /// Gripper pitch and grasp height above the peg's centre for this episode.
    pitch: f64,
    grasp_height: f64,
    /// The wrist roll's position when the roll started (rad).
    roll_from: f64,
    /// Whether the fingers have let go of the standing peg.
    released: bool,
    /// The TCP's position at the previous step (its speed decides the release).
    prev_tcp: Vector3<f64>,
}

impl FetchLiftPeg {
    /// The Fetch's solver for `env`, which must be in `pd_joint_pos` (its roll is a joint
    /// target).
    pub fn new(env: &Env) -> Result<Self, super::SolverError> {
        if env.control_mode() != "pd_joint_pos" {
            return Err(super::SolverError::WrongControlMode {
                robot: env.robot_spec().uid(),
                required: "pd_joint_pos".to_string(),
                mode: env.control_mode().to_string(),
                why: "the wrist's roll is set as a joint target".to_string(),
            });
        }
        Ok(FetchLiftPeg {
            peg: body_id(env.model(), "peg")?,
            arm: FetchArm::new(env)?,
            shadow: Shadow::new(env, "pd_ee_delta_pose")?,
            phases: Phases::default(),
            pitch: 0.0,
            grasp_height: 0.0,
            roll_from: 0.0,
            released: false,
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

/// One step's plan of [`FetchLiftPeg`]: the TCP target, the gripper action, the gripper
/// orientation wanted (None: the grasp pitch) and the wrist roll's joint target (None: the
/// end-effector command's).
type FetchPlan = (Vector3<f64>, f32, Option<UnitQuaternion<f64>>, Option<f64>);

impl Policy for FetchLiftPeg {
    fn reset(&mut self, env: &Env) {
        self.phases.reset();
        let peg = body_xyz(env, self.peg);
        (self.pitch, self.grasp_height) = pick_pitch_and_height(peg + fetch_grasp_offset());
        self.released = false;
        self.prev_tcp = tcp_xyz(env);
    }

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        if self.try_act(env, action).is_err() {
            action.fill(0.0);
        }
    }

    fn try_act(&mut self, env: &Env, action: &mut [f32]) -> Result<(), super::SolverError> {
        self.shadow.sync(env)?;
        let s = &self.shadow.env;
        let tcp = tcp_xyz(s);
        let peg = body_xyz(s, self.peg);
        let grasp = peg + fetch_grasp_offset() + Vector3::new(0.0, 0.0, self.grasp_height);
        let q = body_quat(s, self.peg);
        let axis = q * Vector3::x();
        let tilt = axis.z.abs().min(1.0).acos();
        let foot = peg_foot(peg, q);
        let roll = s.data().qpos()[s.robot().joints.qpos_adr[FETCH_WRIST_ROLL_JOINT]];
        if self.phases.phase < 4 {
            self.roll_from = roll;
        }
        let roll_from = self.roll_from;
        let ready = self.arm.rot_err(s, self.pitch) < FETCH_ROT_TOL;
        let torso_to_come = (self.arm.torso(s) - TORSO_PICK).max(0.0);
        let hand = self.arm.gripper_quat(s);
        // The turn that stands the rolled peg's lower half straight down.
        let down = if axis.z > 0.0 { -axis } else { axis };
        let upright = UnitQuaternion::rotation_between(&down, &-Vector3::z())
            .unwrap_or_else(UnitQuaternion::identity);
        let (target, grip, goal, roll_target): FetchPlan =
            self.phases.run(|phase, steps| match phase {
                0..=2 => {
                    let (mut t, mut grip, mut done) = GRASP.phase(phase, steps, grasp, tcp, ready);
                    if phase == 0 {
                        let cone = FETCH_APPROACH_CONE * (grasp.xy() - tcp.xy()).norm();
                        let above =
                            FETCH_APPROACH_HEIGHT + cone + FETCH_APPROACH_TORSO * torso_to_come;
                        t = grasp + Vector3::new(0.0, 0.0, above);
                        let dived = (tcp.xy() - grasp.xy()).norm() < FETCH_DIVE_TOL && tcp.z < t.z;
                        done = ready && (approached_tilted(t, tcp) || dived);
                    }
                    if phase == 2 {
                        grip = FETCH_GRIP;
                    }
                    ((t, grip, None, None), done)
                }
                3 => {
                    let t = Vector3::new(tcp.x.min(FETCH_STAND_X), grasp.y, FETCH_ROLL_HEIGHT);
                    let done =
                        tcp.z > FETCH_ROLL_HEIGHT - FETCH_LIFT_TOL || steps >= FETCH_PHASE_STEPS;
                    ((t, FETCH_GRIP, None, None), done)
                }
                4 => {
                    let turned = (roll - (roll_from + PI)).abs() < FETCH_ROLL_TOL;
                    let r = roll_from + (FETCH_ROLL_STEP * (steps + 1) as f64).min(PI);
                    let done = turned || steps >= FETCH_PHASE_STEPS;
                    ((tcp, FETCH_GRIP, Some(hand), Some(r)), done)
                }
                _ => {
                    let clear = if tilt > FETCH_STAND_TILT {
                        FETCH_FOOT_CLEAR
                    } else {
                        0.0
                    };
                    let t = Vector3::new(tcp.x.min(FETCH_STAND_X), tcp.y, tcp.z + clear - foot);
                    ((t, FETCH_GRIP, Some(upright * hand), None), false)
                }
            });
        let standing = (peg.z - PEG_HALF_LENGTH).abs() < STANDING_TOL;
        let resting = (tcp - self.prev_tcp).norm() < FETCH_RELEASE_SPEED;
        self.prev_tcp = tcp;
        self.released |= self.phases.phase >= 5 && standing && tilt < RELEASE_TILT && resting;
        let (target, grip) = if self.released {
            (tcp, FETCH_GRIPPER.open)
        } else {
            (target, grip)
        };
        let lifting = self.phases.phase >= 3;
        let slow = self.phases.phase >= 5 && foot < FETCH_SLOW_FOOT;
        let cmd = ArmCommand {
            target,
            tcp,
            pitch: self.pitch,
            torso: if lifting { TORSO_CARRY } else { TORSO_PICK },
            torso_gain: if lifting { CARRY_TORSO_GAIN } else { 1.0 },
            grip,
            limit: if slow { FETCH_SLOW_LIMIT } else { 1.0 },
            min_step: if self.phases.phase == 1 {
                FETCH_MIN_STEP
            } else {
                0.0
            },
        };
        match goal {
            Some(g) => self.arm.drive_to(s, cmd, g, &mut self.shadow.action),
            None => self.arm.drive(s, cmd, &mut self.shadow.action),
        }
        self.shadow.step_into(env, action)?;
        if let Some(r) = roll_target {
            action[FETCH_WRIST_ROLL_ACTION] = r as f32;
        }
        Ok(())
    }
}
