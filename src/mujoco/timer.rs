//! MuJoCo's own profiling timers (`mjData.timer`).
//!
//! MuJoCo times the stages of `mj_step` (collision, constraint construction, solver, ...)
//! only while the process-wide callback `mjcb_time` is set. [`enable_timers`] sets it once for
//! the process; from then on every [`super::Data`] accumulates, per stage, the seconds spent and
//! the number of calls, read with [`super::Data::timer`] and cleared with
//! [`super::Data::clear_timers`]. The callback costs two clock reads per timed stage, so the
//! env leaves it unset; `mjskill bench --profile` sets it.
use std::sync::OnceLock;
use std::time::Instant;

use mujoco_sys as sys;

/// The stages MuJoCo 2.2 times (`mjtTimer`), in its order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Timer {
    /// `mj_step` as a whole (not timed by `mj_step1` / `mj_step2`).
    Step,
    /// `mj_forward` as a whole.
    Forward,
    /// `mj_inverse` as a whole.
    Inverse,
    /// `mj_fwdPosition`: kinematics, inertia, collision, constraint construction.
    Position,
    /// `mj_fwdVelocity`: velocity-dependent forces (bias, passive, damping).
    Velocity,
    /// `mj_fwdActuation`: actuator forces.
    Actuation,
    /// `mj_fwdAcceleration`: the unconstrained acceleration (applied forces, `M⁻¹`).
    Acceleration,
    /// `mj_fwdConstraint`: the constraint solver.
    Constraint,
    /// Kinematics, centres of mass, tendons, transmissions (part of `Position`).
    PosKinematics,
    /// Joint-space inertia and its factorisation (part of `Position`).
    PosInertia,
    /// Collision detection, broad and narrow phase (part of `Position`).
    PosCollision,
    /// Constraint construction: Jacobians, impedances (part of `Position`).
    PosMake,
    /// Constraint projection, `J M⁻¹ Jᵀ` (part of `Position`).
    PosProject,
}

impl Timer {
    /// Every stage, in MuJoCo's order.
    pub const ALL: [Timer; 13] = [
        Timer::Step,
        Timer::Forward,
        Timer::Inverse,
        Timer::Position,
        Timer::Velocity,
        Timer::Actuation,
        Timer::Acceleration,
        Timer::Constraint,
        Timer::PosKinematics,
        Timer::PosInertia,
        Timer::PosCollision,
        Timer::PosMake,
        Timer::PosProject,
    ];

    /// The stage's index in `mjData.timer`.
    pub(crate) fn index(self) -> usize {
        let t = match self {
            Timer::Step => sys::mjtTimer__mjTIMER_STEP,
            Timer::Forward => sys::mjtTimer__mjTIMER_FORWARD,
            Timer::Inverse => sys::mjtTimer__mjTIMER_INVERSE,
            Timer::Position => sys::mjtTimer__mjTIMER_POSITION,
            Timer::Velocity => sys::mjtTimer__mjTIMER_VELOCITY,
            Timer::Actuation => sys::mjtTimer__mjTIMER_ACTUATION,
            Timer::Acceleration => sys::mjtTimer__mjTIMER_ACCELERATION,
            Timer::Constraint => sys::mjtTimer__mjTIMER_CONSTRAINT,
            Timer::PosKinematics => sys::mjtTimer__mjTIMER_POS_KINEMATICS,
            Timer::PosInertia => sys::mjtTimer__mjTIMER_POS_INERTIA,
            Timer::PosCollision => sys::mjtTimer__mjTIMER_POS_COLLISION,
            Timer::PosMake => sys::mjtTimer__mjTIMER_POS_MAKE,
            Timer::PosProject => sys::mjtTimer__mjTIMER_POS_PROJECT,
        };
        t as usize
    }

    /// A short snake_case name (`pos_collision`), as reports print it.
    pub fn name(self) -> &'static str {
        match self {
            Timer::Step => "step",
            Timer::Forward => "forward",
            Timer::Inverse => "inverse",
            Timer::Position => "position",
            Timer::Velocity => "velocity",
            Timer::Actuation => "actuation",
            Timer::Acceleration => "acceleration",
            Timer::Constraint => "constraint",
            Timer::PosKinematics => "pos_kinematics",
            Timer::PosInertia => "pos_inertia",
            Timer::PosCollision => "pos_collision",
            Timer::PosMake => "pos_make",
            Timer::PosProject => "pos_project",
        }
    }
}

/// One stage's accumulated time.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TimerStat {
    /// Seconds spent in the stage since the timers were last cleared.
    pub seconds: f64,
    /// Calls of the stage since then.
    pub calls: u64,
}

static EPOCH: OnceLock<Instant> = OnceLock::new();

/// Seconds since the first call: the clock MuJoCo's timers read.
unsafe extern "C" fn now() -> sys::mjtNum {
    EPOCH.get_or_init(Instant::now).elapsed().as_secs_f64()
}

/// Starts MuJoCo's stage timers for the whole process (idempotent): every `Data` accumulates
/// from its next step on.
pub fn enable_timers() {
    static ONCE: OnceLock<()> = OnceLock::new();
    ONCE.get_or_init(|| {
        EPOCH.get_or_init(Instant::now);
        // SAFETY: `mjcb_time` is a plain function-pointer global that MuJoCo only reads; it is
        // written once, here, under a OnceLock, and `now` is a valid `mjfTime` for the life of
        // the process (it reads a process-wide Instant and cannot unwind).
        unsafe { sys::mjcb_time = Some(now) };
    });
}
