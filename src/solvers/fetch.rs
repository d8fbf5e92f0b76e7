//! The scripted PickCube solver for Fetch (control mode `pd_ee_delta_pose`).
//!
//! It runs the phases of solvers.md §7.1 (above the cube, down to it, close for H steps,
//! carry to the goal) with Fetch-specific additions that its geometry requires:
//! * Fetch stands 1.05 m behind the table centre and, at its table pose, holds the gripper
//!   60° below the horizontal; with that orientation the arm cannot reach the cube spawn
//!   area at all (the wrist would need 0.75 m from the shoulder, the arm reaches 0.67 m). So
//!   the solver uses `pd_ee_delta_pose` and turns the gripper to a flatter pitch (45° for the
//!   nearest cubes down to 5° for the farthest), lowers the torso to 0.25 m while picking
//!   (bringing the shoulder down towards the table) and raises it again to carry, and drives
//!   the base 3.3 cm forward (its front is 3.8 cm from the table);
//! * every position target is pulled back within the arm's reach at the current pitch, so the
//!   IK keeps solving (an unreachable target makes the EE controller hold the arm still);
//! * while carrying, the gripper points along the line from the shoulder to the goal (the
//!   longest reach);
//! * the grasp point is raised above the cube centre so that the tilted fingers and palm stay
//!   clear of the table top, and a shortfall along the fingers (≤ 1.2 cm) is accepted;
//! * the carry target puts the cube centre (not the finger midpoint) at the goal.
//!
//! Measured: 96/100 successes on seeds 0–99 (first success at step 41 on average); the misses
//! are cubes in the far corners (x > 0.09 m), at the edge of the arm's reach.
//!
//! All commands are proportional and saturate at the action bounds; the body's head joints and
//! the base yaw are held.
use nalgebra::{UnitQuaternion, Vector3};

use super::{Gripper, Policy};
use crate::env::Env;
use crate::tasks::body_id;

/// Fetch: +1 opens (0.05 m), −1 closes (−0.01 m target).
pub const FETCH_GRIPPER: Gripper = Gripper {
    open: 1.0,
    close: -1.0,
};

/// Steps the gripper closes before lifting.
const HOLD: usize = 3;
/// Height of the approach point above the grasp point (m).
const APPROACH_HEIGHT: f64 = 0.05;
/// Approach tolerance (m).
const APPROACH_TOL: f64 = 0.01;
/// Descent tolerance across the fingers (y, z) and along them (x) (m).
const DESCEND_TOL: f64 = 0.004;
const DESCEND_TOL_ALONG: f64 = 0.012;
/// Orientation tolerance before descending (rad).
const ROT_TOL: f64 = 0.05;
/// Torso height while picking and while carrying (m; the table pose has 0.386, the limit
/// is 0.38615): low to reach down to the table, high to reach up to the goal.
const TORSO_PICK: f64 = 0.25;
const TORSO_CARRY: f64 = 0.386;
/// Arm lengths (m): shoulder-lift axis to wrist-flex axis when straight, and wrist-flex axis
/// to the TCP (models/fetch/fetch.urdf), with the margin kept from a straight arm.
const UPPER_REACH: f64 = 0.219 + 0.133 + 0.197 + 0.1245;
const WRIST_TO_TCP: f64 = 0.1385 + 0.16645;
const REACH_MARGIN: f64 = 0.012;
/// Gripper pitch limits while carrying (rad below the horizontal).
const CARRY_PITCH: (f64, f64) = (-0.2, 0.7);
/// Base travel towards the table (m).
const BASE_FORWARD: f64 = 0.033;
/// Proportional gain of the base: forward speed (m/s) per metre of error.
const BASE_GAIN: f64 = 4.0;
/// Gripper pitch below the horizontal for the nearest (x = −0.1) and farthest (x = 0.1) cubes.
const PITCH_NEAR: f64 = 45.0 * std::f64::consts::PI / 180.0;
const PITCH_FAR: f64 = 5.0 * std::f64::consts::PI / 180.0;
/// Clearance of the lowest finger or palm point above the table (m).
const CLEARANCE: f64 = 0.004;
/// Gripper geometry (gripper_link frame): finger box front-bottom corner and the palm box's
/// front-bottom corner (x forward, z up), from models/fetch/fetch.urdf.
const FINGER_FRONT: (f64, f64) = (0.031, -0.01315);
const PALM_FRONT: (f64, f64) = (-0.032, -0.0399);

/// Position error scale (m per unit action).
const POS_SCALE: f64 = 0.1;
/// Rotation per unit action (rad; upstream scales by rot_lower = −0.1, hence the sign).
const ROT_SCALE: f64 = -0.1;

/// solvers.md §7.1 for Fetch.
#[derive(Debug)]
pub struct FetchPickCube {
    cube: usize,
    goal: usize,
    arm: FetchArm,
    phase: usize,
    steps_in_phase: usize,
    /// Gripper pitch and grasp height above the cube centre for this episode.
    pitch: f64,
    grasp_height: f64,
    /// TCP − cube centre when the grasp closed (carried to the goal).
    hold_offset: Vector3<f64>,
}

impl FetchPickCube {
    /// Resolves the bodies of a PickCube env with Fetch.
    pub fn new(env: &Env) -> Result<Self, String> {
        Ok(FetchPickCube {
            cube: body_id(env.model(), "cube")?,
            goal: body_id(env.model(), "goal_site")?,
            arm: FetchArm::new(env)?,
            phase: 0,
            steps_in_phase: 0,
            pitch: PITCH_NEAR,
            grasp_height: 0.0,
            hold_offset: Vector3::zeros(),
        })
    }
}

fn xyz(env: &Env, body: usize) -> Vector3<f64> {
    Vector3::from_column_slice(&env.data().xpos()[3 * body..3 * body + 3])
}

/// Height of the TCP above the table that keeps fingers and palm `CLEARANCE` above it at
/// gripper pitch `pitch` (rad below the horizontal).
pub fn min_tcp_height(pitch: f64) -> f64 {
    let low = |(x, z): (f64, f64)| -x * pitch.sin() + z * pitch.cos();
    CLEARANCE - low(FINGER_FRONT).min(low(PALM_FRONT))
}

/// Pulls `target` towards `shoulder` until the wrist (the TCP minus the gripper length along
/// the pitch direction) is within the arm's reach minus a margin: the IK then still solves and
/// the arm moves as close as it can, instead of failing and holding still.
fn clamp_to_reach(target: Vector3<f64>, shoulder: Vector3<f64>, pitch: f64) -> Vector3<f64> {
    let dir = Vector3::new(pitch.cos(), 0.0, -pitch.sin());
    let fits = |s: f64| {
        let t = shoulder + s * (target - shoulder);
        (t - WRIST_TO_TCP * dir - shoulder).norm() <= UPPER_REACH - REACH_MARGIN
    };
    if fits(1.0) {
        return target;
    }
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..30 {
        let mid = 0.5 * (lo + hi);
        if fits(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    shoulder + lo * (target - shoulder)
}

/// The Fetch's arm, torso and base driven towards a gripper position and pitch through
/// `pd_ee_delta_pose` (12 actions): shared by the Fetch solvers of every task.
#[derive(Debug)]
pub struct FetchArm {
    gripper_link: usize,
    shoulder: usize,
    q: [f64; 15],
}

/// One command of [`FetchArm::drive`].
#[derive(Debug, Clone, Copy)]
pub struct ArmCommand {
    /// Target of the TCP (`tcp`'s frame point) in world coordinates.
    pub target: Vector3<f64>,
    /// Current TCP position.
    pub tcp: Vector3<f64>,
    /// Gripper pitch wanted (rad below the horizontal; yaw and roll 0).
    pub pitch: f64,
    /// Torso height target (m).
    pub torso: f64,
    /// Torso command per unit error (1: the whole error in one step).
    pub torso_gain: f64,
    /// Gripper action.
    pub grip: f32,
    /// Position action limit (≤ 1).
    pub limit: f64,
    /// Shortest position command (action units; 0: purely proportional).
    pub min_step: f64,
}

impl FetchArm {
    /// Resolves the Fetch's bodies.
    pub fn new(env: &Env) -> Result<Self, String> {
        if env.robot().qpos_adr.len() != 15 {
            return Err("the Fetch solvers need the 15-dof Fetch".into());
        }
        Ok(FetchArm {
            gripper_link: env.robot().body("gripper_link")?,
            shoulder: env.robot().body("shoulder_lift_link")?,
            q: [0.0; 15],
        })
    }

    /// `gripper_link`'s position (`agent.tcp.pose.p` of Fetch).
    pub fn gripper_xyz(&self, env: &Env) -> Vector3<f64> {
        xyz(env, self.gripper_link)
    }

    /// The shoulder-lift link's position (the arm's reach centre).
    pub fn shoulder_xyz(&self, env: &Env) -> Vector3<f64> {
        xyz(env, self.shoulder)
    }

    fn gripper_quat(&self, env: &Env) -> UnitQuaternion<f64> {
        let g = &env.data().xquat()[4 * self.gripper_link..4 * self.gripper_link + 4];
        UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(g[0], g[1], g[2], g[3]))
    }

    /// The torso lift joint's position (m).
    pub fn torso(&self, env: &Env) -> f64 {
        env.data().qpos()[env.robot().qpos_adr[3]]
    }

    /// Orientation error (rad) of the gripper from `pitch`.
    pub fn rot_err(&self, env: &Env, pitch: f64) -> f64 {
        let want = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), pitch);
        (want * self.gripper_quat(env).inverse()).angle()
    }

    /// Writes the 12 actions: the position (clamped to the reach at the current pitch), the
    /// rotation towards `cmd.pitch`, the gripper, the head held, the torso towards
    /// `cmd.torso`, the base towards `BASE_FORWARD` with yaw 0.
    pub fn drive(&mut self, env: &Env, cmd: ArmCommand, action: &mut [f32]) {
        let data = env.data();
        env.robot().qpos(data, &mut self.q);
        let cur = self.gripper_quat(env);
        let want = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), cmd.pitch);
        let rot_err = (want * cur.inverse()).scaled_axis();
        // Keep the target within reach at the gripper's current pitch (the IK keeps the
        // orientation up to one rotation step): with the table pose's steep pitch most
        // targets ahead are out of reach and the IK would fail (the arm then holds still).
        let x_axis = cur * Vector3::x();
        let cur_pitch = (-x_axis.z).atan2(x_axis.x.hypot(x_axis.y));
        let target = clamp_to_reach(cmd.target, self.shoulder_xyz(env), cur_pitch);
        // Small steps are lost to the arm's sag under gravity: commands shorter than
        // `cmd.min_step` are stretched to it.
        let mut step = (target - cmd.tcp) / POS_SCALE;
        let n = step.norm();
        if n > 1e-9 && n < cmd.min_step {
            step *= cmd.min_step / n;
        }
        for k in 0..3 {
            action[k] = step[k].clamp(-cmd.limit, cmd.limit) as f32;
        }
        let mut r = rot_err / ROT_SCALE;
        if r.norm() > 1.0 {
            r /= r.norm();
        }
        action[3..6].copy_from_slice(&[r.x as f32, r.y as f32, r.z as f32]);
        action[6] = cmd.grip;
        // Body: hold the head, move the torso (Δ ±0.1 m per unit action).
        action[7] = 0.0;
        action[8] = 0.0;
        action[9] = (cmd.torso_gain * (cmd.torso - self.q[3]) / 0.1).clamp(-1.0, 1.0) as f32;
        // Base: forward speed (±1 m/s) towards BASE_FORWARD, yaw rate (±3.14 rad/s) to 0.
        action[10] = (BASE_GAIN * (BASE_FORWARD - self.q[0])).clamp(-1.0, 1.0) as f32;
        action[11] = (-BASE_GAIN * self.q[2] / crate::robots::fetch::YAW_RATE_MAX as f64)
            .clamp(-1.0, 1.0) as f32;
    }
}

/// Gripper pitch for an object at table x (rad below the horizontal): steep near the robot,
/// flat far from it.
pub fn pitch_for_x(x: f64) -> f64 {
    let s = ((x + 0.1) / 0.2).clamp(0.0, 1.0);
    PITCH_NEAR + (PITCH_FAR - PITCH_NEAR) * s
}

/// Pitch that points the gripper from the shoulder at `target` (the longest reach).
pub fn pitch_towards(shoulder: Vector3<f64>, target: Vector3<f64>) -> f64 {
    let d = target - shoulder;
    (-d.z)
        .atan2(d.x.hypot(d.y))
        .clamp(CARRY_PITCH.0, CARRY_PITCH.1)
}

impl Policy for FetchPickCube {
    fn reset(&mut self, env: &Env) {
        self.phase = 0;
        self.steps_in_phase = 0;
        let cube = xyz(env, self.cube);
        self.pitch = pitch_for_x(cube.x);
        self.grasp_height = (min_tcp_height(self.pitch) - cube.z).max(0.0);
    }

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        let tcp = Vector3::from(env.robot().tcp_pose(env.data()).0);
        let cube = xyz(env, self.cube);
        let goal = xyz(env, self.goal);
        let grasp = cube + Vector3::new(0.0, 0.0, self.grasp_height);
        let carrying = self.phase >= 3;
        let pitch = if carrying {
            pitch_towards(self.arm.shoulder_xyz(env), goal + self.hold_offset)
        } else {
            self.pitch
        };
        let rot_err = self.arm.rot_err(env, pitch);
        let (target, grip) = loop {
            let (target, grip) = match self.phase {
                0 => (
                    grasp + Vector3::new(0.0, 0.0, APPROACH_HEIGHT),
                    FETCH_GRIPPER.open,
                ),
                1 => (grasp, FETCH_GRIPPER.open),
                2 => (grasp, FETCH_GRIPPER.close),
                _ => (goal + self.hold_offset, FETCH_GRIPPER.close),
            };
            let done = match self.phase {
                0 => (target - tcp).norm() < APPROACH_TOL && rot_err < ROT_TOL,
                // Along the fingers (≈ x) a shortfall does not matter: the 6 cm fingers still
                // straddle the cube when the arm stops at the edge of its reach.
                1 => descended(target, tcp),
                2 => self.steps_in_phase >= HOLD,
                _ => false,
            };
            if done {
                if self.phase == 2 {
                    self.hold_offset = tcp - cube;
                }
                self.phase += 1;
                self.steps_in_phase = 0;
                continue;
            }
            self.steps_in_phase += 1;
            break (target, grip);
        };
        let torso = if carrying { TORSO_CARRY } else { TORSO_PICK };
        let cmd = ArmCommand {
            target,
            tcp,
            pitch,
            torso,
            torso_gain: 1.0,
            grip,
            limit: 1.0,
            min_step: 0.0,
        };
        self.arm.drive(env, cmd, action);
    }
}

/// The descent is done: within `DESCEND_TOL` across the fingers, `DESCEND_TOL_ALONG` along.
pub fn descended(target: Vector3<f64>, tcp: Vector3<f64>) -> bool {
    let e = target - tcp;
    e.y.hypot(e.z) < DESCEND_TOL && e.x.abs() < DESCEND_TOL_ALONG
}
