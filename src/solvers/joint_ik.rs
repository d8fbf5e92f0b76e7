//! Scripted PickCube solver for robots without end-effector controllers (SO100, WidowX AI;
//! docs/solvers.md §8): an IK of its own on the robot's URDF chain turns the phase targets of
//! docs/solvers.md §7.1 into `pd_joint_pos` actions.
//!
//! The IK works on a *grasp point* fixed in the gripper (the spot between the jaws where the
//! cube centre ends up) and a top-down grasp frame: it minimises, by damped least squares
//! with a numerical Jacobian over the arm joints,
//! `[p − p*; w·(a − (0, 0, −1)); w·(c · n)]` — grasp-point position, approach axis `a` pointing
//! down, closing axis `c` perpendicular to `n` (the horizontal normal of the chosen cube face
//! axis) — then refines the position alone with minimum-norm Gauss–Newton steps. Where a
//! top-down approach is out of reach (SO100's far cubes) the weighted stage settles on the
//! closest tilt and the position stays exact. Joint values are clamped to their limits.
//!
//! Phases (checked in order with fall-through, as §7.1): 0 above the cube (open), 1 down to the
//! cube (open), 2 close for a few steps, 3 carry: the grasp point goes to
//! `goal + (grasp point − cube)`, so that the cube centre, not the grasp point, lands on the
//! goal; once it is within [`AT_GOAL_TOL`] of that target the gripper takes the robot's
//! `at_goal` targets (the SO100 eases its squeeze there). Every step the IK target moves at most
//! [`MAX_STEP`] from the current grasp point.
//! Positions are read from MuJoCo before the step; nothing is allocated per step.
use nalgebra::{Isometry3, Quaternion, SMatrix, SVector, UnitQuaternion, Vector3};

use super::body_id;
use super::{body_xyz, Phases, Policy, APPROACH_TOL, DESCEND_TOL};
use crate::controllers::ik::Chain;
use crate::env::Env;
use crate::mujoco::{BodyId, ObjType};

/// Most arm joints an IK chain may have.
const MAX_ARM: usize = 6;
/// Rows of the IK error: position 3, approach 3, closing 1.
const ROWS: usize = 7;
/// Largest distance (m) between the grasp point and the IK target of one step.
pub const MAX_STEP: f64 = 0.04;
/// Weight of the orientation rows against position (m per unit).
const ORIENTATION_WEIGHT: f64 = 0.05;
/// Damping of the least-squares steps (Jacobian entries are ~0.1 m/rad).
const DAMPING: f64 = 1e-4;
/// Largest joint change of one IK iteration (rad or m).
const MAX_DQ: f64 = 0.2;
/// Iterations of the weighted stage and of the position refinement.
const ITERS: (usize, usize) = (30, 10);
/// Finite-difference step of the numerical Jacobian (rad or m).
const FD: f64 = 1e-6;
/// Steps after which the descent gives up on [`DESCEND_TOL`] and closes anyway.
const DESCEND_MAX_STEPS: usize = 12;
/// Distance (m) of the grasp point from its carry target within which the gripper takes the
/// robot's `at_goal` targets.
pub const AT_GOAL_TOL: f64 = 0.01;
/// With [`JointIkPickCube::leading`]: the approach is done once the commanded grasp point is
/// within [`APPROACH_TOL`] of the approach point and the measured one within this (m).
const LEAD_APPROACH_TOL: f64 = 0.02;
/// With [`JointIkPickCube::leading`]: the descent is done once the commanded grasp point is
/// within [`DESCEND_TOL`] of the grasp point and the measured one within this (m).
const LEAD_DESCEND_TOL: f64 = 0.008;
/// With [`JointIkPickCube::leading`]: the weight of the approach-axis rows (instead of
/// [`ORIENTATION_WEIGHT`]). Nearly free, the IK keeps the gripper near the tilt it comes
/// with: the top-down grasp of a far cube costs up to a radian of elbow and shoulder, 20
/// steps at 0.05 rad per step (the SO100's solver in `pd_joint_target_delta_pos`: 84 % of
/// seeds 10000–10099 with 0.05, 98 % with this).
const LEAD_APPROACH_WEIGHT: f64 = 0.001;

/// What the solver needs to know about a robot.
#[derive(Debug, Clone, Copy)]
pub struct JointIkRobot {
    /// Link carrying the grasp point.
    pub link: &'static str,
    /// Grasp point in that link's frame.
    pub point: [f64; 3],
    /// Link axis that should point down (the approach direction).
    pub approach: [f64; 3],
    /// Link axis along which the gripper closes.
    pub closing: [f64; 3],
    /// Number of arm joints: the first entries of qpos and of the `pd_joint_pos` action.
    pub n_arm: usize,
    /// (action index, value) pairs that open the gripper.
    pub open: &'static [(usize, f32)],
    /// (action index, value) pairs that close it.
    pub close: &'static [(usize, f32)],
    /// (action index, value) pairs that replace `close` once the cube is at the goal (within
    /// [`AT_GOAL_TOL`]); empty to keep `close`.
    pub at_goal: &'static [(usize, f32)],
    /// Height of the approach point above the cube centre (m).
    pub approach_height: f64,
    /// Height of the grasp point above the cube centre when closing (m).
    pub grasp_height: f64,
    /// Steps the gripper closes before lifting.
    pub hold: usize,
}

/// SO100 jaw target (rad) once the cube is at the goal: a lighter squeeze than the −0.8 of the
/// grasp and carry. In ManiSkill the −0.8 squeeze wedges the 25 mm cube between the jaws: the
/// arm drives stall up to 0.04 rad off their targets while PhysX reports 0.1–0.3 rad/s of arm
/// velocity on an arm that does not move, so `is_robot_static` (0.2 rad/s) fails in about a
/// third of the held episodes. At −0.785 the cube stays grasped in both simulators and the
/// reported velocity stays near 0.1 rad/s (docs/outcome-physics.md).
pub const SO100_AT_GOAL_GRIP: f32 = -0.785;

/// SO100: the grasp point sits between the jaw tips on Fixed_Jaw (the jaw points along its
/// local −y and closes along x); gripper joint 0 = open, −0.8 = closed (absolute rad). The jaw
/// closes for 8 steps before the lift: PhysX's jaw, whose collision hulls are thinner than
/// mjskill's fitted boxes, reaches a tilted cube about two steps later than mjskill's, and a
/// lift after 6 steps left the cube behind in ManiSkill (4 of 20 replays).
pub const SO100: JointIkRobot = JointIkRobot {
    link: "Fixed_Jaw",
    point: [-0.0075, -0.092, 0.0],
    approach: [0.0, -1.0, 0.0],
    closing: [1.0, 0.0, 0.0],
    n_arm: 5,
    open: &[(5, 0.0)],
    close: &[(5, -0.8)],
    at_goal: &[(5, SO100_AT_GOAL_GRIP)],
    approach_height: 0.04,
    grasp_height: 0.006,
    hold: 8,
};

/// Carriage target (m) the WidowX AI closes to on PickCube's 36 mm cube (carriages at 18 mm):
/// a squeeze of kp · 8 mm ≈ 8 N instead of 18 N. ManiSkill couples the two carriages with a
/// PhysX fixed tendon (stiffness 1e5) whose tension under the squeeze (about 1.7 × the grip
/// force) also loads the wrist: at 18 N, joint_4 sits 0.03 rad off its target and PhysX reports
/// kp/kd × that deflection, 0.3 rad/s, as its velocity, so `is_robot_static` never holds
/// (1 success in 50 replays). At 8 N the reported wrist velocity stays near 0.1 rad/s.
pub const WIDOWXAI_GRIP: f32 = 0.010;

/// WidowX AI: the grasp point is the middle of the fingertip pads, 13 mm behind
/// ee_gripper_link (the gripper points along link x and closes along y). The arm part's 7th
/// entry (the left carriage, overridden by the gripper part) repeats the gripper target; the
/// gripper action is normalised: +1 = 0.044 m open, −1 = 0 m closed. The gripper closes to
/// [`WIDOWXAI_GRIP`], not to 0 (docs/outcome-physics.md).
pub const WIDOWXAI: JointIkRobot = JointIkRobot {
    link: "ee_gripper_link",
    point: [-0.013, 0.0, 0.0],
    approach: [1.0, 0.0, 0.0],
    closing: [0.0, 1.0, 0.0],
    n_arm: 6,
    open: &[(6, 0.044), (7, 1.0)],
    close: &[(6, WIDOWXAI_GRIP), (7, 2.0 * WIDOWXAI_GRIP / 0.044 - 1.0)],
    at_goal: &[],
    approach_height: 0.05,
    grasp_height: 0.0,
    hold: 4,
};

/// The description of a robot whose PickCube solver is this IK (`None` for the others).
pub fn for_robot(uid: &str) -> Option<JointIkRobot> {
    match uid {
        "so100" => Some(SO100),
        "widowxai" => Some(WIDOWXAI),
        _ => None,
    }
}

type Jac = SMatrix<f64, ROWS, MAX_ARM>;

/// The PickCube policy for SO100 and WidowX AI in `pd_joint_pos`.
#[derive(Debug)]
pub struct JointIkPickCube {
    robot: JointIkRobot,
    chain: Chain,
    base: Isometry3<f64>,
    limits: [(f64, f64); MAX_ARM],
    cube: BodyId,
    goal: BodyId,
    phases: Phases,
    /// Horizontal unit normal to the cube face axis the gripper closes along (fixed per
    /// episode at the first step).
    closing_normal: Option<Vector3<f64>>,
    /// Measured qpos and the IK solution (ManiSkill order).
    q: Vec<f64>,
    q_ik: Vec<f64>,
    /// Whether the phases end on the commanded joint targets ([`JointIkPickCube::leading`]).
    lead: bool,
    /// The drive targets (ManiSkill order; the measured qpos for undriven joints).
    q_cmd: Vec<f64>,
}

impl JointIkPickCube {
    /// Builds the solver for a PickCube env whose robot is described by `robot`.
    pub fn new(env: &Env, robot: JointIkRobot) -> Result<Self, super::SolverError> {
        let spec = env.robot_spec();
        let desc = spec.description()?;
        let arm: Vec<&str> = env.robot().joints.names[..robot.n_arm]
            .iter()
            .map(|s| s.as_str())
            .collect();
        let chain = Chain::new(&desc, robot.link, &arm)?;
        let mut limits = [(0.0, 0.0); MAX_ARM];
        for (l, r) in limits
            .iter_mut()
            .zip(&env.robot().joints.limits[..robot.n_arm])
        {
            *l = *r;
        }
        let n = env.robot().joints.len();
        Ok(JointIkPickCube {
            robot,
            chain,
            base: spec.table_base(),
            limits,
            cube: body_id(env.model(), "cube")?,
            goal: body_id(env.model(), "goal_site")?,
            phases: Phases::default(),
            closing_normal: None,
            q: vec![0.0; n],
            q_ik: vec![0.0; n],
            lead: false,
            q_cmd: vec![0.0; n],
        })
    }

    /// The solver for a mode whose joint targets move at a bounded rate
    /// (`pd_joint_target_delta_pos`, 0.05 rad per step on the SO100's arm): the arm trails
    /// its targets by about 0.07 rad while they move and takes three or four steps to settle
    /// after they stop. Waiting for the measured grasp point at the approach and descent
    /// tolerances spends those steps at every phase, so here a phase ends once the
    /// *commanded* grasp point (the drive targets' forward kinematics) is within the phase's
    /// tolerance and the measured one within a looser one ([`LEAD_APPROACH_TOL`],
    /// [`LEAD_DESCEND_TOL`]); the arm settles while the next phase starts.
    pub fn leading(mut self) -> Self {
        self.lead = true;
        self
    }

    /// World grasp point, approach axis and closing axis for the full qpos `q`.
    pub fn frame(&self, q: &[f64]) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
        let t = self.base * self.chain.fk(q);
        let r = &self.robot;
        (
            (t * nalgebra::Point3::from(r.point)).coords,
            t.rotation * Vector3::from(r.approach),
            t.rotation * Vector3::from(r.closing),
        )
    }

    fn error(&self, q: &[f64], target: &Vector3<f64>, n: &Vector3<f64>) -> SVector<f64, ROWS> {
        let (p, a, c) = self.frame(q);
        let dp = p - target;
        let wa = if self.lead {
            LEAD_APPROACH_WEIGHT
        } else {
            ORIENTATION_WEIGHT
        };
        let da = (a - Vector3::new(0.0, 0.0, -1.0)) * wa;
        SVector::<f64, ROWS>::from_column_slice(&[
            dp.x,
            dp.y,
            dp.z,
            da.x,
            da.y,
            da.z,
            c.dot(n) * ORIENTATION_WEIGHT,
        ])
    }

    fn jacobian(
        &mut self,
        target: &Vector3<f64>,
        n: &Vector3<f64>,
        e0: &SVector<f64, ROWS>,
    ) -> Jac {
        let mut jac = Jac::zeros();
        for k in 0..self.robot.n_arm {
            let keep = self.q_ik[k];
            self.q_ik[k] = keep + FD;
            let e = self.error(&self.q_ik, target, n);
            self.q_ik[k] = keep;
            jac.set_column(k, &((e - e0) / FD));
        }
        jac
    }

    /// Moves the arm joints of `q_ik` by `−dq` (shortened to [`MAX_DQ`]) within their limits;
    /// returns the length of the step taken before the limits.
    fn descend(&mut self, mut dq: SVector<f64, MAX_ARM>) -> f64 {
        let norm = dq.norm();
        if norm > MAX_DQ {
            dq *= MAX_DQ / norm;
        }
        for k in 0..self.robot.n_arm {
            let (lo, hi) = self.limits[k];
            self.q_ik[k] = (self.q_ik[k] - dq[k]).clamp(lo, hi);
        }
        dq.norm()
    }

    /// Solves for the arm joints (written into `q_ik`, starting from `q`) that put the grasp
    /// point at `target` with the gripper top-down and closing perpendicular to `n`.
    fn solve(&mut self, target: &Vector3<f64>, n: &Vector3<f64>) {
        self.q_ik.copy_from_slice(&self.q);
        for _ in 0..ITERS.0 {
            let e = self.error(&self.q_ik, target, n);
            let jac = self.jacobian(target, n, &e);
            let jtj =
                jac.transpose() * jac + SMatrix::<f64, MAX_ARM, MAX_ARM>::identity() * DAMPING;
            let Some(ch) = jtj.cholesky() else { break };
            let dq = ch.solve(&(jac.transpose() * e));
            if self.descend(dq) < 1e-9 {
                break;
            }
        }
        for _ in 0..ITERS.1 {
            let e = self.error(&self.q_ik, target, n);
            let jac = self.jacobian(target, n, &e);
            let jp = jac.fixed_rows::<3>(0).into_owned();
            let jjt = jp * jp.transpose() + nalgebra::Matrix3::identity() * DAMPING;
            let Some(ch) = jjt.cholesky() else { break };
            let ep = e.fixed_rows::<3>(0).into_owned();
            self.descend(jp.transpose() * ch.solve(&ep));
            if ep.norm() < 1e-6 {
                break;
            }
        }
    }

    /// Writes the IK solution's arm joints into the action's first entries.
    fn arm_action(&self, action: &mut [f32]) {
        for (a, q) in action.iter_mut().zip(&self.q_ik).take(self.robot.n_arm) {
            *a = *q as f32;
        }
    }

    fn gripper(&self, action: &mut [f32], close: bool, at_goal: bool) {
        let set = match (close, at_goal) {
            (false, _) => self.robot.open,
            (true, true) if !self.robot.at_goal.is_empty() => self.robot.at_goal,
            (true, _) => self.robot.close,
        };
        for &(i, v) in set {
            action[i] = v;
        }
    }
}

/// This step's IK target on the way from the grasp point `p` to `target`: at most [`MAX_STEP`]
/// from `p`.
fn toward(p: Vector3<f64>, target: Vector3<f64>) -> Vector3<f64> {
    let d = target - p;
    if d.norm() > MAX_STEP {
        p + d * (MAX_STEP / d.norm())
    } else {
        target
    }
}

/// The cube face axis (world, horizontal) the gripper should close along: of the cube's x
/// and y axes, the one closer to the current closing axis. Returns its horizontal normal.
fn closing_normal(env: &Env, cube: BodyId, closing: &Vector3<f64>) -> Vector3<f64> {
    let m = env.data().body_mat(cube);
    face_normal(
        Vector3::new(m[0], m[3], m[6]),
        Vector3::new(m[1], m[4], m[7]),
        closing,
    )
}

/// [`closing_normal`] for a cube whose x and y axes (world) are `x` and `y`.
fn face_normal(x: Vector3<f64>, y: Vector3<f64>, closing: &Vector3<f64>) -> Vector3<f64> {
    let ax = Vector3::new(x.x, x.y, 0.0).normalize();
    let ay = Vector3::new(y.x, y.y, 0.0).normalize();
    let d = if ax.dot(closing).abs() >= ay.dot(closing).abs() {
        ax
    } else {
        ay
    };
    Vector3::new(-d.y, d.x, 0.0)
}

impl Policy for JointIkPickCube {
    fn reset(&mut self, _env: &Env) {
        self.phases.reset();
        self.closing_normal = None;
    }

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        env.robot().joints.qpos(env.data(), &mut self.q);
        let (p, _, c) = self.frame(&self.q);
        let cube = body_xyz(env, self.cube);
        let goal = body_xyz(env, self.goal);
        let n = *self
            .closing_normal
            .get_or_insert_with(|| closing_normal(env, self.cube, &c));
        let r = self.robot;
        let p_cmd = if self.lead {
            for (k, q) in self.q_cmd.iter_mut().enumerate() {
                *q = env.drives().joint_target(k).map_or(self.q[k], |t| t.0);
            }
            Some(self.frame(&self.q_cmd).0)
        } else {
            None
        };
        let (target, close) = self.phases.run(|phase, steps| {
            let (target, close) = match phase {
                0 => (cube + Vector3::new(0.0, 0.0, r.approach_height), false),
                1 => (cube + Vector3::new(0.0, 0.0, r.grasp_height), false),
                2 => (p, true),
                _ => (goal + (p - cube), true),
            };
            let err = (target - p).norm();
            // (tolerance of the measured point, of the commanded one)
            let within = |tol: f64, lead_tol: f64| match p_cmd {
                Some(pc) => err < lead_tol && (target - pc).norm() < tol,
                None => err < tol,
            };
            let done = match phase {
                0 => within(APPROACH_TOL, LEAD_APPROACH_TOL),
                1 => within(DESCEND_TOL, LEAD_DESCEND_TOL) || steps >= DESCEND_MAX_STEPS,
                2 => steps >= r.hold,
                _ => false,
            };
            ((target, close), done)
        });
        // While closing, the arm keeps its last targets.
        if self.phases.phase != 2 {
            self.solve(&toward(p, target), &n);
        }
        self.arm_action(action);
        let at_goal = self.phases.phase >= 3 && (target - p).norm() < AT_GOAL_TOL;
        self.gripper(action, close, at_goal);
    }
}

/// The gripper is open enough to descend around the cube: this fraction of the way from its
/// `close` target to its `open` one (the first gripper entry of [`JointIkRobot`]).
const EXPERT_OPEN_ENOUGH: f64 = 0.9;
/// Not grasping, away from the grasp point, and shut past this fraction: closed on nothing,
/// so open again, rising to the approach height.
const EXPERT_SHUT: f64 = 0.5;
/// A grasped cube is held once the gripper closes slower than this (fraction of its range
/// per second); until then, over the cube, it goes on closing where it is, as the solver's
/// `hold` steps do.
const EXPERT_HELD_RATE: f64 = 0.25;

/// The descent onto the cube goes down to the grasp point within this (m, horizontal) of
/// the cube, and further off no lower than [`EXPERT_CONE`] times the excess above it: the
/// SO100's fixed jaw, descending 7 mm off, lands on the cube's top (the solver reaches its
/// approach point first and centres while it descends).
const EXPERT_OVER_XY: f64 = 0.004;
/// Height allowed above the grasp point per metre off the cube (see [`EXPERT_OVER_XY`]).
const EXPERT_CONE: f64 = 5.0;
/// The gripper descends onto the cube only with its closing axis this close to a face axis
/// (the cosine to the face's normal): turned further, the open jaws land on top of it.
const EXPERT_ALIGNED: f64 = 0.15;
/// The IK from the measured joints misses its target by more than this (m): it is tried again
/// from the robot's table pose, and the closer of the two solutions is taken.
const EXPERT_RESTART: f64 = 0.002;

/// The state expert of PickCube for the SO100 and the WidowX AI (docs/solvers.md §8.2): the
/// [`JointIkPickCube`] solver's targets, IK and grip, with its phase read off the state each
/// call instead of counted: the cube held (the task's grasp flag, the gripper no longer
/// closing) → carry it to the goal (easing the SO100's jaw there); grasped but still closing,
/// or the grasp point reached → close, the arm still; the gripper shut on nothing → open and
/// rise; over the cube, turned to its faces, with the gripper open → descend, within a cone
/// that centres the gripper first; otherwise → the approach point above the cube. The face
/// axis to close along is the one nearer to the table pose's closing axis (as the solver's
/// first step picks it), the cube's pose is read from its free joint in the state, and the IK
/// starts from the measured joints, so the label is a function of the state. (The grasp flag
/// is the env's last evaluation, part of its state.)
#[derive(Debug)]
pub struct JointIkPickCubeExpert {
    ik: JointIkPickCube,
    /// qpos address of the cube's free joint: its pose is read from the state itself (the
    /// body's rotation matrix can differ in the last bit between a state reached by a step
    /// and the same state set).
    cube_qpos: usize,
    /// The robot's table pose (ManiSkill order): the IK's second start when the first, from
    /// the measured joints, stops short (an arm thrown into an odd configuration).
    rest: Vec<f64>,
    /// The first start's solution, kept while the second is tried.
    first: Vec<f64>,
    /// The closing axis (world) of the table pose: of the cube's two face axes, the gripper
    /// closes along the one nearer to it, as the solver picks at its first step. Chosen by the
    /// wrist's current axis instead, the choice flips near 45° and the wrist chases it.
    rest_closing: Vector3<f64>,
    /// qpos and dof address of the gripper joint the `open` and `close` targets name first.
    grip_qpos: usize,
    grip_dof: usize,
}

impl JointIkPickCubeExpert {
    /// Builds the expert for a PickCube env whose robot is described by `robot`.
    pub fn new(env: &Env, robot: JointIkRobot) -> Result<Self, super::SolverError> {
        let ik = JointIkPickCube::new(env, robot)?;
        let k = robot.open[0].0;
        let joints = &env.robot().joints;
        let rest = env.robot_spec().table_qpos.to_vec();
        let m = env.model();
        let cube_qpos = m.jnt_qposadr()[m.require_id(ObjType::Joint, "cube")?] as usize;
        let rest_closing = ik.frame(&rest).2;
        Ok(JointIkPickCubeExpert {
            rest_closing,
            cube_qpos,
            first: vec![0.0; ik.q.len()],
            rest,
            ik,
            grip_qpos: joints.qpos_adr[k],
            grip_dof: joints.dof_adr[k],
        })
    }

    /// How far the gripper is open (0 at its `close` target, 1 at `open`) and the rate of that
    /// fraction (1/s).
    fn opening(&self, env: &Env) -> (f64, f64) {
        let (open, close) = (
            f64::from(self.ik.robot.open[0].1),
            f64::from(self.ik.robot.close[0].1),
        );
        let q = env.data().qpos()[self.grip_qpos];
        let v = env.data().qvel()[self.grip_dof];
        ((q - close) / (open - close), v / (open - close))
    }
}

impl Policy for JointIkPickCubeExpert {
    fn reset(&mut self, _env: &Env) {}

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        let (opening, rate) = self.opening(env);
        let s = &mut self.ik;
        env.robot().joints.qpos(env.data(), &mut s.q);
        let (p, _, c) = s.frame(&s.q);
        let qc = &env.data().qpos()[self.cube_qpos..self.cube_qpos + 7];
        let cube = Vector3::new(qc[0], qc[1], qc[2]);
        let rot = UnitQuaternion::from_quaternion(Quaternion::new(qc[3], qc[4], qc[5], qc[6]));
        let goal = body_xyz(env, s.goal);
        let n = face_normal(rot * Vector3::x(), rot * Vector3::y(), &self.rest_closing);
        let r = s.robot;
        let grasp = cube + Vector3::new(0.0, 0.0, r.grasp_height);
        let above = cube + Vector3::new(0.0, 0.0, r.approach_height);
        let over = (p.xy() - cube.xy()).norm() < APPROACH_TOL;
        // The grasp flag with an open gripper is the last episode's (a reset does not
        // refresh the contacts, docs/env.md).
        let grasped = env.info().flag(env.grasp_info_key()) && opening < EXPERT_OPEN_ENOUGH;
        let closing = rate < -EXPERT_HELD_RATE;
        let held = grasped && !closing;
        // (grasp-point target, close, the arm stands where it is)
        let (target, close, still) = if held {
            (goal + (p - cube), true, false)
        } else if over && (grasped || closing || (p - grasp).norm() < DESCEND_TOL) {
            // Closing on the cube, which the closing gripper may push a little: go on.
            (p, true, true)
        } else if opening < EXPERT_SHUT {
            (Vector3::new(p.x, p.y, p.z.max(above.z)), false, false)
        } else if over && c.dot(&n).abs() < EXPERT_ALIGNED && opening > EXPERT_OPEN_ENOUGH {
            // Descend, no lower than a cone over the cube allows: centred first.
            let off = (p.xy() - cube.xy()).norm();
            let h = (EXPERT_CONE * (off - EXPERT_OVER_XY)).clamp(0.0, r.approach_height);
            (grasp + Vector3::new(0.0, 0.0, h), false, false)
        } else {
            (above, false, false)
        };
        if still {
            s.q_ik.copy_from_slice(&s.q);
        } else {
            let step = toward(p, target);
            s.solve(&step, &n);
            let miss = (s.frame(&s.q_ik).0 - step).norm();
            if miss > EXPERT_RESTART {
                self.first.copy_from_slice(&s.q_ik);
                s.q[..r.n_arm].copy_from_slice(&self.rest[..r.n_arm]);
                s.solve(&step, &n);
                if (s.frame(&s.q_ik).0 - step).norm() >= miss {
                    s.q_ik.copy_from_slice(&self.first);
                }
            }
        }
        s.arm_action(action);
        let at_goal = held && (target - p).norm() < AT_GOAL_TOL;
        s.gripper(action, close, at_goal);
    }
}
