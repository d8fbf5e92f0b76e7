//! The Fetch's arm, torso and base driven towards a gripper position and pitch through
//! `pd_ee_delta_pose` ([`FetchArm`]), and the gripper geometry the Fetch solvers of every task
//! share (`fetch.rs`, `fetch_tasks.rs`): the pitch for an object's distance, the TCP height
//! that keeps the tilted fingers and palm clear of the table, the descent check of the tilted
//! gripper, and targets clamped to the arm's reach.
use nalgebra::{UnitQuaternion, Vector3};

use super::{body_quat, body_xyz, write_pos, write_rot, ACTION_SCALE, DESCEND_TOL};
use crate::env::Env;
use crate::mujoco::BodyId;

/// Arm lengths (m): shoulder-lift axis to wrist-flex axis when straight, and wrist-flex axis
/// to the TCP (models/fetch/fetch.urdf), with the margin kept from a straight arm. With the
/// 0.01 s step the targets at the edge of the reach need it small: 1.2 cm left PokeCube's
/// farthest goals (peg x ≥ 0.09) and PlaceSphere's farthest bins a few mm out of reach, 8 mm
/// reaches them and the IK still solves (PickCube: the same successes either way, seeds 0–399).
const UPPER_REACH: f64 = 0.219 + 0.133 + 0.197 + 0.1245;
const WRIST_TO_TCP: f64 = 0.1385 + 0.16645;
const REACH_MARGIN: f64 = 0.008;
/// Gripper pitch limits while carrying (rad below the horizontal).
const CARRY_PITCH: (f64, f64) = (-0.2, 0.7);
/// Base travel towards the table (m).
const BASE_FORWARD: f64 = 0.033;
/// Proportional gain of the base: forward speed (m/s) per metre of error.
const BASE_GAIN: f64 = 4.0;
/// Gripper pitch below the horizontal for the nearest (x = −0.1) and farthest (x = 0.1) cubes.
pub(super) const PITCH_NEAR: f64 = 45.0 * std::f64::consts::PI / 180.0;
pub(super) const PITCH_FAR: f64 = 5.0 * std::f64::consts::PI / 180.0;
/// Clearance of the lowest finger or palm point above the table (m).
const CLEARANCE: f64 = 0.004;
/// Gripper geometry (gripper_link frame): finger box front-bottom corner and the palm box's
/// front-bottom corner (x forward, z up), from models/fetch/fetch.urdf.
const FINGER_FRONT: (f64, f64) = (0.031, -0.01315);
const PALM_FRONT: (f64, f64) = (-0.032, -0.0399);
/// Descent tolerance along the tilted fingers (x, m; across them: [`DESCEND_TOL`]).
const DESCEND_TOL_ALONG: f64 = 0.012;

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
    gripper_link: BodyId,
    shoulder: BodyId,
    q: [f64; 15],
}

/// One command of [`FetchArm::drive`].
#[derive(Debug, Clone, Copy)]
pub struct ArmCommand {
    /// Target of the TCP (`tcp`'s frame point) in world coordinates.
    pub target: Vector3<f64>,
    /// Current TCP position.
    pub tcp: Vector3<f64>,
    /// Gripper pitch wanted (rad below the horizontal; yaw and roll 0; [`FetchArm::drive_to`]
    /// takes any orientation).
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
    pub fn new(env: &Env) -> Result<Self, super::SolverError> {
        if env.robot().joints.len() != 15 {
            return Err(super::SolverError::FetchDof);
        }
        Ok(FetchArm {
            gripper_link: env.robot().body("gripper_link")?,
            shoulder: env.robot().body("shoulder_lift_link")?,
            q: [0.0; 15],
        })
    }

    /// `gripper_link`'s position (`agent.tcp.pose.p` of Fetch).
    pub fn gripper_xyz(&self, env: &Env) -> Vector3<f64> {
        body_xyz(env, self.gripper_link)
    }

    /// The shoulder-lift link's position (the arm's reach centre).
    pub fn shoulder_xyz(&self, env: &Env) -> Vector3<f64> {
        body_xyz(env, self.shoulder)
    }

    /// The torso lift joint's position (m).
    pub fn torso(&self, env: &Env) -> f64 {
        env.data().qpos()[env.robot().joints.qpos_adr[3]]
    }

    /// The gripper's orientation (world).
    pub fn gripper_quat(&self, env: &Env) -> UnitQuaternion<f64> {
        body_quat(env, self.gripper_link)
    }

    /// Orientation error (rad) of the gripper from `pitch`.
    pub fn rot_err(&self, env: &Env, pitch: f64) -> f64 {
        (pitched(pitch) * self.gripper_quat(env).inverse()).angle()
    }

    /// Writes the 12 actions: the position (clamped to the reach at the current pitch), the
    /// rotation towards `cmd.pitch`, the gripper, the head held, the torso towards
    /// `cmd.torso`, the base towards `BASE_FORWARD` with yaw 0.
    pub fn drive(&mut self, env: &Env, cmd: ArmCommand, action: &mut [f32]) {
        self.drive_to(env, cmd, pitched(cmd.pitch), action);
    }

    /// [`FetchArm::drive`] towards the gripper orientation `goal` (world) instead of
    /// `cmd.pitch`.
    pub fn drive_to(
        &mut self,
        env: &Env,
        cmd: ArmCommand,
        goal: UnitQuaternion<f64>,
        action: &mut [f32],
    ) {
        let data = env.data();
        env.robot().joints.qpos(data, &mut self.q);
        let cur = self.gripper_quat(env);
        let rot_err = (goal * cur.inverse()).scaled_axis();
        // Keep the target within reach at the gripper's current pitch (the IK keeps the
        // orientation up to one rotation step): with the table pose's steep pitch most
        // targets ahead are out of reach and the IK would fail (the arm then holds still).
        let x_axis = cur * Vector3::x();
        let cur_pitch = (-x_axis.z).atan2(x_axis.x.hypot(x_axis.y));
        let target = clamp_to_reach(cmd.target, self.shoulder_xyz(env), cur_pitch);
        // Small steps are lost to the arm's sag under gravity: commands shorter than
        // `cmd.min_step` are stretched to it.
        let mut step = (target - cmd.tcp) / ACTION_SCALE;
        let n = step.norm();
        if n > 1e-9 && n < cmd.min_step {
            step *= cmd.min_step / n;
        }
        write_pos(step, cmd.limit, action);
        write_rot(rot_err, action);
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

/// The gripper orientation with pitch `pitch` (rad below the horizontal), yaw and roll 0.
fn pitched(pitch: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::y_axis(), pitch)
}

/// Gripper pitch for an object at table x (rad below the horizontal): steep ([`PITCH_NEAR`])
/// near the robot, flat (`far`) far from it.
pub fn pitch_for_x(x: f64, far: f64) -> f64 {
    let s = ((x + 0.1) / 0.2).clamp(0.0, 1.0);
    PITCH_NEAR + (far - PITCH_NEAR) * s
}

/// Pitch that points the gripper from the shoulder at `target` (the longest reach).
pub fn pitch_towards(shoulder: Vector3<f64>, target: Vector3<f64>) -> f64 {
    let d = target - shoulder;
    (-d.z)
        .atan2(d.x.hypot(d.y))
        .clamp(CARRY_PITCH.0, CARRY_PITCH.1)
}

/// The descent of the tilted gripper is done: within [`DESCEND_TOL`] across the fingers (y, z),
/// [`DESCEND_TOL_ALONG`] along them (x).
pub fn descended_tilted(target: Vector3<f64>, tcp: Vector3<f64>) -> bool {
    let e = target - tcp;
    e.y.hypot(e.z) < DESCEND_TOL && e.x.abs() < DESCEND_TOL_ALONG
}
