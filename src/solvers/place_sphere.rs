//! docs/solvers.md §7.2: the EE-space scripted PlaceSphere policy (`pd_ee_delta_pos`).
//!
//! Above the sphere, down to it, close, lift to 8 cm, carry the sphere over the bin, lower
//! it until it is just above the floor, open, retreat. Positions are the TCP **link**
//! (`agent.tcp.pose.p`, the task's TCP) and the sphere and bin centres, read before each
//! step. Robot-generic: the gripper commands are a parameter and the TCP is the robot's TCP
//! link, so the same phases drive any two-finger robot with an EE controller.
//!
//! Thresholds and step counts are the spec's; MuJoCo needs no deviation from them. A robot
//! whose arm still creeps when the lowering ends (Fetch) may add a settle phase before the
//! release ([`PlaceSphereSolver::release_speed`]): a sphere let go while it moves keeps
//! rolling in the bin.
//! Measured (0.01 s step): 100/100 on seeds 0–99 (first success at step 34.2 on average) and
//! on 100–199 (34.7). A released sphere that is still moving keeps rolling to and fro between
//! the wall edges: MuJoCo's condim-3 contacts have no rolling resistance and PhysX's angular
//! damping of free bodies is not emulated (docs/physics.md, "Not emulated").
use nalgebra::Vector3;

use super::body_id;
use super::{body_xyz, ee_action, tcp_link_xyz, Grasp, Gripper, Phases, Policy};
use crate::env::Env;
use crate::mujoco::BodyId;

/// Carrying height of the TCP (m) and its tolerance.
const LIFT_Z: f64 = 0.08;
pub(super) const LIFT_TOL: f64 = 0.01;
/// Height of the sphere centre over the bin origin while carrying (m).
pub(super) const CARRY_ABOVE_BIN: f64 = 0.06;
/// Horizontal alignment of sphere and bin before lowering (m).
pub(super) const ALIGN_TOL: f64 = 0.003;
/// Lowering target of the sphere centre above the bin origin (m), and the height at which
/// the sphere is released.
pub(super) const LOWER_TO: f64 = 0.0255;
pub(super) const RELEASE_BELOW: f64 = 0.0285;
/// Steps the gripper opens while holding still.
const OPEN_STEPS: usize = 4;
/// Retreat height above the release pose (m).
const RETREAT: f64 = 0.03;

/// The PlaceSphere policy.
#[derive(Debug)]
pub struct PlaceSphereSolver {
    sphere: BodyId,
    bin: BodyId,
    grasp: Grasp,
    /// Height of the grasp point above the sphere centre (m; 0 for a top-down gripper).
    pub grasp_lift: f64,
    /// Horizontal sphere-to-bin distance the release also waits for (m; the Panda's spec
    /// phases do not wait: infinite).
    pub release_align: f64,
    /// Horizontal sphere-to-bin distance that ends the carry (m; the spec's 3 mm).
    pub align_tol: f64,
    /// Height of the sphere centre over the bin origin below which it is released (m; the
    /// spec's 2.85 cm).
    pub release_below: f64,
    /// Highest sphere speed at which it is released (m/s): the settle phase holds the
    /// lowered sphere until it is slower (the spec's phases have none: infinite, the phase
    /// falls through at once).
    pub release_speed: f64,
    /// Lowering target of the sphere centre over the bin origin (m; the spec's 2.55 cm).
    pub lower_to: f64,
    /// Sphere position at the previous step (its speed for [`Self::release_speed`]).
    last_sphere: Option<Vector3<f64>>,
    phases: Phases,
}

impl PlaceSphereSolver {
    /// Resolves the sphere and bin bodies of a PlaceSphere env.
    pub fn new(env: &Env, gripper: Gripper) -> Result<Self, super::SolverError> {
        Ok(PlaceSphereSolver {
            sphere: body_id(env.model(), "sphere")?,
            bin: body_id(env.model(), "bin")?,
            grasp: Grasp::new(gripper),
            grasp_lift: 0.0,
            release_align: f64::INFINITY,
            align_tol: ALIGN_TOL,
            release_below: RELEASE_BELOW,
            release_speed: f64::INFINITY,
            lower_to: LOWER_TO,
            last_sphere: None,
            phases: Phases::default(),
        })
    }

    /// The same phases with another descent check (e.g. a tilted gripper's).
    pub fn with_descent(mut self, descended: fn(Vector3<f64>, Vector3<f64>) -> bool) -> Self {
        self.grasp.descended = descended;
        self
    }

    /// The current phase: 0–5 as docs/solvers.md §7.2, 6 the settle (hold until the sphere is
    /// slower than [`Self::release_speed`]; skipped by the spec's phases), 7 and 8 the spec's
    /// 6 (open) and 7 (retreat).
    pub fn phase(&self) -> usize {
        self.phases.phase
    }

    /// The TCP target and gripper action for this step (phases advance with fall-through);
    /// `ready`: whether the robot may leave the approach (e.g. its gripper is turned).
    pub fn plan(&mut self, env: &Env, tcp: Vector3<f64>, ready: bool) -> (Vector3<f64>, f32) {
        let sphere = body_xyz(env, self.sphere);
        let grasp = sphere + Vector3::new(0.0, 0.0, self.grasp_lift);
        let bin = body_xyz(env, self.bin);
        let g = self.grasp;
        let (open, close) = (g.gripper.open, g.gripper.close);
        let (release_align, align_tol) = (self.release_align, self.align_tol);
        let release_below = self.release_below;
        let speed = self.last_sphere.map_or(f64::INFINITY, |l| {
            (sphere - l).norm() / crate::mjcf::CONTROL_DT
        });
        self.last_sphere = Some(sphere);
        let release_speed = self.release_speed;
        let lower_to = self.lower_to;
        self.phases.run(|phase, steps| {
            let (target, grip, done) = match phase {
                0..=2 => g.phase(phase, steps, grasp, tcp, ready),
                3 => (
                    Vector3::new(tcp.x, tcp.y, LIFT_Z),
                    close,
                    (tcp.z - LIFT_Z).abs() < LIFT_TOL,
                ),
                4 => {
                    let mut grip_offset = tcp - sphere;
                    grip_offset.z = 0.0;
                    let t = bin + Vector3::new(0.0, 0.0, CARRY_ABOVE_BIN) + grip_offset;
                    (t, close, (sphere.xy() - bin.xy()).norm() < align_tol)
                }
                5 => (
                    tcp + (bin + Vector3::new(0.0, 0.0, lower_to) - sphere),
                    close,
                    sphere.z - bin.z < release_below
                        && (sphere.xy() - bin.xy()).norm() < release_align,
                ),
                6 => (tcp, close, speed < release_speed),
                7 => (tcp, open, steps >= OPEN_STEPS),
                _ => (tcp + Vector3::new(0.0, 0.0, RETREAT), open, false),
            };
            ((target, grip), done)
        })
    }
}

impl Policy for PlaceSphereSolver {
    fn reset(&mut self, _env: &Env) {
        self.phases.reset();
        self.last_sphere = None;
    }

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        let tcp = tcp_link_xyz(env);
        let (target, grip) = self.plan(env, tcp, true);
        ee_action(target, tcp, 1.0, grip, action);
    }
}
