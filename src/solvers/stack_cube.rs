//! docs/solvers.md §7.6: the scripted StackCube solvers, the Panda's (`pd_ee_delta_pos`) and
//! the Fetch's (`pd_ee_delta_pose`, through [`FetchArm`]).
//!
//! ManiSkill's motion-planning solution (`motionplanning/panda/solutions/stack_cube.py`) as
//! EE-space phases, the way the PickCube and PlaceSphere solvers port theirs: above cube A,
//! down to it, close, lift, carry cube A over cube B, lower it onto cube B, open, retreat.
//! ManiSkill's solution plans with screw motions and ends with the gripper opening on cube B;
//! here every phase's target is cube A's position ([`StackPlan`]), turned into a TCP target by
//! the offset TCP − cube A of the current step, so that a cube that shifted in the grip still
//! lands where it should. Like ManiSkill's solution (its grasp pose from cube A's bounding
//! box), the Panda turns its gripper about the vertical so that the fingers close on two faces
//! of cube A (`pd_ee_delta_pose`): closed on two edges, the cube turns in mjskill's grip but not
//! in PhysX's, and 14 of 50 episodes replayed in ManiSkill released it 2–5 cm off cube B's axis
//! (docs/outcome-physics.md).
//!
//! The lift is relative to cube B (cube A's bottom [`LIFT_CLEAR`] above cube B's top) instead
//! of ManiSkill's 10 cm, and cube A is released [`RELEASE_ABOVE`] above its resting height.
//!
//! The Fetch picks as its PickCube solver does (`fetch.rs`: the pitch and grasp height for
//! cube A's distance, at least [`FETCH_MIN_PITCH`]; the tilted descent check; the finger
//! midpoint as its TCP) and keeps that pitch while it carries: turning the gripper would tilt
//! the held cube, which must land flat. It leaves the torso where it is, comes down on cube A
//! inside a cone, and ends the carry within 1 cm of cube B.
//!
//! Measured (0.01 s step): Panda 98/100 on seeds 0–99 (98 on 100–199); Fetch 43/100 (48). The
//! Fetch's misses are mostly reach: StackCube's cubes lie anywhere in x ∈ [−0.2, 0.2] (PickCube's
//! in [−0.1, 0.1]), and in 34 of 100 seeds one of them lies beyond x = 0.07, where the Fetch's
//! tilted gripper stalls (its TCP reaches x ≈ 0.10 at the table with the gripper level, less
//! when tilted or lifted); the rest run out of the 50 steps (the wrist turns slowly).
use nalgebra::{UnitQuaternion, Vector3};

use super::body_id;
use super::fetch::{approached_tilted, pick_pitch_and_height, GRASP};
use super::fetch_arm::{min_tcp_height, ArmCommand, FetchArm};
use super::xarm6::quarter_turn;
use super::{
    body_quat, body_xyz, tcp_link_xyz, tcp_xyz, write_pos, write_rot, Grasp, Gripper, Phases,
    Policy, ACTION_SCALE, APPROACH_HEIGHT, APPROACH_TOL,
};
use crate::env::Env;
use crate::mujoco::BodyId;
use crate::tasks::stack_cube::StackCube;

/// While carried, cube A's bottom is this far above cube B's top (m).
const LIFT_CLEAR: f64 = 0.03;
/// The lift ends (and the carry, still rising, begins) once cube A's bottom is this far above
/// cube B's top (m): it then passes over cube B's edge.
const LIFT_DONE: f64 = 0.01;
/// Horizontal alignment of cube A over cube B that ends the carry (m).
const ALIGN_TOL: f64 = 0.003;
/// Cube A is released once its centre is within this above its resting height on cube B (m).
const RELEASE_ABOVE: f64 = 0.003;
/// Cube A is released only once centred over cube B within this (m): released off-centre in
/// PhysX it slid off cube B in 2 of 50 replays of an earlier version.
const RELEASE_ALIGN: f64 = 0.008;
/// Steps the gripper opens while holding still.
const OPEN_STEPS: usize = 4;
/// Retreat height above the release pose (m).
const RETREAT: f64 = 0.05;

/// Orientation tolerance before the Panda leaves the approach (rad).
const PANDA_ROT_TOL: f64 = 0.05;

/// The Fetch's approach point above the grasp point (m; the Panda's 5 cm cost the Fetch, whose
/// arm dives while the wrist still turns, a climb back and a slow descent).
const FETCH_APPROACH_HEIGHT: f64 = 0.03;
/// The Fetch's approach cone: its approach point is raised by this times its horizontal
/// distance (the arm's swing otherwise sweeps the table and knocks the cubes away).
const FETCH_APPROACH_CONE: f64 = 1.0;
/// The Fetch's carry ends within this of cube B's centre (m): its arm overshoots and settles
/// slowly, and the lowering centres cube A on the way down.
const FETCH_ALIGN_TOL: f64 = 0.01;
/// The Fetch's gripper pitch is at least this (rad below the horizontal): the wrist turns from
/// the table pose's 60° at only ≈ 0.045 rad per step, and a flatter pitch costs steps that the
/// stack needs.
const FETCH_MIN_PITCH: f64 = 30.0 * std::f64::consts::PI / 180.0;
/// The Fetch carries cube A lower than the Panda (m above cube B's top): at the edge of its
/// reach every centimetre of height costs reach.
const FETCH_LIFT_CLEAR: f64 = 0.015;
/// Orientation tolerance before the Fetch leaves the approach (rad): it finishes turning
/// during the descent.
const FETCH_ROT_TOL: f64 = 0.05;
/// Shortest position command of the Fetch's descent and lowering (action units).
const FETCH_MIN_STEP: f64 = 0.1;

/// The phases of both robots, planned in cube A's position: 0–2 the grasp, 3 lift, 4 carry,
/// 5 lower, 6 open, 7 retreat.
#[derive(Debug)]
pub struct StackPlan {
    cube_a: BodyId,
    cube_b: BodyId,
    grasp: Grasp,
    /// Whether the approach above the grasp point is done (target, tcp).
    approached: fn(Vector3<f64>, Vector3<f64>) -> bool,
    /// Height of the grasp point above cube A's centre (m; 0 for a top-down gripper).
    grasp_lift: f64,
    /// Height of the approach point above the grasp point (m).
    approach_height: f64,
    /// Horizontal alignment of cube A over cube B that ends the carry (m).
    align_tol: f64,
    /// While carried, cube A's bottom is this far above cube B's top (m).
    lift_clear: f64,
    /// The approach point is raised by this times the TCP's horizontal distance from it (0:
    /// straight to it), so that the gripper comes down on the cube from above instead of
    /// sweeping the table.
    approach_cone: f64,
    phases: Phases,
}

/// The approach is done within [`APPROACH_TOL`] (the top-down Panda).
fn approached(target: Vector3<f64>, tcp: Vector3<f64>) -> bool {
    (target - tcp).norm() < APPROACH_TOL
}

impl StackPlan {
    /// Resolves the cubes of a StackCube env.
    fn new(env: &Env, grasp: Grasp) -> Result<Self, super::SolverError> {
        Ok(StackPlan {
            cube_a: body_id(env.model(), "cubeA")?,
            cube_b: body_id(env.model(), "cubeB")?,
            grasp,
            approached,
            grasp_lift: 0.0,
            approach_height: APPROACH_HEIGHT,
            approach_cone: 0.0,
            align_tol: ALIGN_TOL,
            lift_clear: LIFT_CLEAR,
            phases: Phases::default(),
        })
    }

    /// The TCP target and gripper action for this step (phases advance with fall-through);
    /// `ready`: whether the robot may leave the approach (e.g. its gripper is turned).
    pub fn plan(&mut self, env: &Env, tcp: Vector3<f64>, ready: bool) -> (Vector3<f64>, f32) {
        let a = body_xyz(env, self.cube_a);
        let b = body_xyz(env, self.cube_b);
        let rest = StackCube::goal(b);
        let carry_z = rest.z + self.lift_clear;
        let grasp_point = a + Vector3::new(0.0, 0.0, self.grasp_lift);
        let (g, approached, align_tol) = (self.grasp, self.approached, self.align_tol);
        let cone = self.approach_cone * (grasp_point.xy() - tcp.xy()).norm();
        let above = Vector3::new(0.0, 0.0, self.approach_height + cone);
        let (open, close) = (g.gripper.open, g.gripper.close);
        // The TCP target that moves cube A to `cube` (the grip's offset kept).
        let holding = |cube: Vector3<f64>| tcp + (cube - a);
        self.phases.run(|phase, steps| {
            let (target, grip, done) = match phase {
                0 => {
                    let t = grasp_point + above;
                    (t, open, ready && approached(t, tcp))
                }
                1..=2 => g.phase(phase, steps, grasp_point, tcp, ready),
                3 => (
                    holding(Vector3::new(a.x, a.y, carry_z)),
                    close,
                    a.z > rest.z + LIFT_DONE,
                ),
                4 => (
                    holding(Vector3::new(b.x, b.y, carry_z)),
                    close,
                    (a.xy() - b.xy()).norm() < align_tol,
                ),
                5 => (
                    holding(rest),
                    close,
                    a.z - rest.z < RELEASE_ABOVE && (a.xy() - b.xy()).norm() < RELEASE_ALIGN,
                ),
                6 => (tcp, open, steps >= OPEN_STEPS),
                _ => (tcp + Vector3::new(0.0, 0.0, RETREAT), open, false),
            };
            ((target, grip), done)
        })
    }
}

/// The Panda's StackCube solver (`pd_ee_delta_pose`): it turns the gripper about the vertical
/// so that the fingers close on two faces of cube A, as ManiSkill's solution does.
#[derive(Debug)]
pub struct PandaStackCube {
    plan: StackPlan,
    /// The hand (the TCP link) and the two fingers.
    hand: BodyId,
    fingers: [BodyId; 2],
    /// The hand orientation to keep for this episode (world frame).
    want: UnitQuaternion<f64>,
}

impl PandaStackCube {
    /// Resolves the cubes and the hand of a StackCube env with the Panda.
    pub fn new(env: &Env, gripper: Gripper) -> Result<Self, super::SolverError> {
        let robot = env.robot();
        Ok(PandaStackCube {
            plan: StackPlan::new(env, Grasp::new(gripper))?,
            hand: robot.body("panda_hand_tcp")?,
            fingers: [
                robot.body("panda_leftfinger")?,
                robot.body("panda_rightfinger")?,
            ],
            want: UnitQuaternion::identity(),
        })
    }
}

impl Policy for PandaStackCube {
    fn reset(&mut self, env: &Env) {
        self.plan.phases.reset();
        // The closing axis (finger to finger) and cube A's x axis, as angles in the xy plane:
        // the smallest turn that puts the fingers on two faces.
        let axis = body_xyz(env, self.fingers[0]) - body_xyz(env, self.fingers[1]);
        let cube_x = body_quat(env, self.plan.cube_a) * Vector3::x();
        let turn = quarter_turn(axis.y.atan2(axis.x), cube_x.y.atan2(cube_x.x));
        self.want =
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), turn) * body_quat(env, self.hand);
    }

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        let tcp = tcp_link_xyz(env);
        let rot_err = (self.want * body_quat(env, self.hand).inverse()).scaled_axis();
        let ready = rot_err.norm() < PANDA_ROT_TOL;
        let (target, grip) = self.plan.plan(env, tcp, ready);
        write_pos((target - tcp) / ACTION_SCALE, 1.0, action);
        write_rot(rot_err, action);
        action[6] = grip;
    }
}

/// The Fetch's StackCube solver (`pd_ee_delta_pose`).
#[derive(Debug)]
pub struct FetchStackCube {
    plan: StackPlan,
    arm: FetchArm,
    /// Gripper pitch for this episode (cube A's).
    pitch: f64,
}

impl FetchStackCube {
    /// Resolves the bodies of a StackCube env with Fetch.
    pub fn new(env: &Env) -> Result<Self, super::SolverError> {
        let mut plan = StackPlan::new(env, GRASP)?;
        plan.approached = approached_tilted;
        plan.approach_height = FETCH_APPROACH_HEIGHT;
        plan.approach_cone = FETCH_APPROACH_CONE;
        plan.align_tol = FETCH_ALIGN_TOL;
        plan.lift_clear = FETCH_LIFT_CLEAR;
        Ok(FetchStackCube {
            plan,
            arm: FetchArm::new(env)?,
            pitch: 0.0,
        })
    }
}

impl Policy for FetchStackCube {
    fn reset(&mut self, env: &Env) {
        self.plan.phases.reset();
        let a = body_xyz(env, self.plan.cube_a);
        let (pitch, _) = pick_pitch_and_height(a);
        self.pitch = pitch.max(FETCH_MIN_PITCH);
        self.plan.grasp_lift = (min_tcp_height(self.pitch) - a.z).max(0.0);
    }

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        // The finger midpoint (`tcp_pose`), as the Fetch's PickCube solver: its grasp height is
        // that point's.
        let tcp = tcp_xyz(env);
        let ready = self.arm.rot_err(env, self.pitch) < FETCH_ROT_TOL;
        let (target, grip) = self.plan.plan(env, tcp, ready);
        // The descent and the lowering end with small commands, which the arm's sag swallows.
        let min_step = match self.plan.phases.phase {
            1 | 5 => FETCH_MIN_STEP,
            _ => 0.0,
        };
        let cmd = ArmCommand {
            target,
            tcp,
            pitch: self.pitch,
            torso: self.arm.torso(env),
            torso_gain: 1.0,
            grip,
            limit: 1.0,
            min_step,
        };
        self.arm.drive(env, cmd, action);
    }
}
