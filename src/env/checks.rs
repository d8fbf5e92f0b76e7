//! Checks of values that come from outside the env: seeds, restored states and configuration
//! bounds. Every error names the bad field or value and the valid range.

use super::{EnvError, EnvState};
use crate::mujoco::Model;

/// Largest seed: ManiSkill's seeds (numpy's `RandomState`, torch's `manual_seed` as
/// ManiSkill uses it) are 32-bit, so seeds are `0..=MAX_SEED`. [`super::Env::reset`] reduces a
/// larger seed mod 2³² (documented); [`super::Env::try_reset`] and the command line reject
/// it.
pub const MAX_SEED: u64 = u32::MAX as u64;

/// Largest `robot_init_qpos_noise` (std-dev in radians/metres; ManiSkill's default is 0.02):
/// beyond it the initial joint positions leave every joint range many times over.
pub const MAX_QPOS_NOISE: f64 = 1.0;

/// Largest magnitude of a restored physics value (all but `ctrl` and `qfrc_applied`). MuJoCo
/// treats positions, velocities and accelerations beyond 1e10 as diverged (`mjMAXVAL`) and
/// resets, so no state of a running env exceeds it. Forces are not bounded by MuJoCo: `ctrl`
/// (gain × target) and `qfrc_applied` (the drives' position correction, `M c / h²`, which a
/// target thousands of radians off drives past 1e10 for a step) only have to be finite.
pub const MAX_STATE_VALUE: f64 = 1e10;

/// Largest magnitude of a restored controller target: the largest f32, as actions are f32
/// (absolute-target modes take them unclipped, as upstream) and targets are observed as f32.
/// `ctrl` (gain × target) only has to be finite.
pub const MAX_TARGET_VALUE: f64 = f32::MAX as f64;

/// Checks that `seed` is a 32-bit ManiSkill seed.
pub fn check_seed(seed: u64) -> Result<(), EnvError> {
    if seed > MAX_SEED {
        return Err(EnvError::BadSeed(seed));
    }
    Ok(())
}

/// Checks `robot_init_qpos_noise`: finite and in `0..=MAX_QPOS_NOISE`.
pub fn check_qpos_noise(sigma: f64) -> Result<(), EnvError> {
    if !(sigma.is_finite() && (0.0..=MAX_QPOS_NOISE).contains(&sigma)) {
        return Err(EnvError::BadQposNoise(sigma));
    }
    Ok(())
}

/// The name of entry `i` of the physics state vector of `model` ([`crate::mujoco::Data::get_state`]
/// layout: time, qpos, qvel, act, ctrl, qacc_warmstart, qfrc_applied, xfrc_applied, mocap_pos,
/// mocap_quat).
pub fn physics_field(model: &Model, i: usize) -> String {
    let parts = [
        ("time", 1),
        ("qpos", model.nq()),
        ("qvel", model.nv()),
        ("act", model.na()),
        ("ctrl", model.nu()),
        ("qacc_warmstart", model.nv()),
        ("qfrc_applied", model.nv()),
        ("xfrc_applied", 6 * model.nbody()),
        ("mocap_pos", 3 * model.nmocap()),
        ("mocap_quat", 4 * model.nmocap()),
    ];
    let mut start = 0;
    for (name, n) in parts {
        if i < start + n {
            return if name == "time" {
                "physics[0] (time)".into()
            } else {
                format!("physics[{i}] ({name}[{}])", i - start)
            };
        }
        start += n;
    }
    format!("physics[{i}]")
}

/// The first non-finite number of a state (physics, controller targets, finger forces), with
/// its field name; `None` when every number is finite.
pub fn first_non_finite(s: &EnvState) -> Option<(String, f64)> {
    let find = |name: &str, v: &[f64]| {
        v.iter()
            .position(|x| !x.is_finite())
            .map(|i| (format!("{name}[{i}]"), v[i]))
    };
    find("physics", &s.physics)
        .or_else(|| find("controller", &s.controller))
        .or_else(|| find("finger_forces", s.finger_forces.as_flattened()))
}

/// Checks the values of a state before [`super::Env::set_state`] applies it (its ids and
/// sizes are checked there): every number finite; physics values (but `ctrl` and
/// `qfrc_applied`) and finger forces within ±[`MAX_STATE_VALUE`], controller targets within ±[`MAX_TARGET_VALUE`];
/// time ≥ 0; `elapsed_steps` below `u32::MAX` (the next step adds one); neither RNG stream in
/// the all-zero state MT19937 never leaves. Every state [`super::Env::get_state`] returns
/// passes.
pub fn check_state_values(model: &Model, s: &EnvState) -> Result<(), EnvError> {
    let bad = |field: String, value: f64, why: String| {
        Err(EnvError::BadState(format!("{field} = {value} {why}")))
    };
    let range = |max: f64| format!("is out of range (|value| ≤ {max:e})");
    let ctrl = 1 + model.nq() + model.nv() + model.na();
    let ctrl = ctrl..ctrl + model.nu();
    let applied = ctrl.end + model.nv();
    let applied = applied..applied + model.nv();
    for (i, &x) in s.physics.iter().enumerate() {
        if !x.is_finite() {
            return bad(physics_field(model, i), x, "is not finite".into());
        }
        if x.abs() > MAX_STATE_VALUE && !ctrl.contains(&i) && !applied.contains(&i) {
            return bad(physics_field(model, i), x, range(MAX_STATE_VALUE));
        }
    }
    if let Some(&t) = s.physics.first() {
        if t < 0.0 {
            return bad(physics_field(model, 0), t, "is negative (time ≥ 0)".into());
        }
    }
    for (name, v, max) in [
        ("controller", s.controller.as_slice(), MAX_TARGET_VALUE),
        (
            "finger_forces",
            s.finger_forces.as_flattened(),
            MAX_STATE_VALUE,
        ),
    ] {
        for (i, &x) in v.iter().enumerate() {
            if !x.is_finite() {
                return bad(format!("{name}[{i}]"), x, "is not finite".into());
            }
            if x.abs() > max {
                return bad(format!("{name}[{i}]"), x, range(max));
            }
        }
    }
    if s.elapsed_steps == u32::MAX {
        return Err(EnvError::BadState(format!(
            "elapsed_steps = {} is out of range (0..={})",
            s.elapsed_steps,
            u32::MAX - 1
        )));
    }
    if s.numpy.is_degenerate() {
        return Err(EnvError::BadState(
            "numpy RNG state is all zero (MT19937 never leaves it)".into(),
        ));
    }
    if s.torch_global.is_degenerate() {
        return Err(EnvError::BadState(
            "torch_global RNG state is all zero (MT19937 never leaves it)".into(),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::env::{make, EnvConfig};

    #[test]
    fn applied_forces_past_1e10_restore_and_diverged_positions_do_not() {
        // A converted Fetch solver's target 1.3e5 rad off (seed 958 of a noisy recording)
        // drove the base's position correction to 1.28e10 for one step; the env ran on, so the
        // state must restore. A position that large is MuJoCo's divergence and is refused.
        let mut e = make(
            "PickCube-v1",
            EnvConfig {
                robot: Some("fetch".into()),
                ..Default::default()
            },
        )
        .unwrap();
        let m = e.model().clone();
        let applied = 1 + m.nq() + m.nv() + m.na() + m.nu() + m.nv();
        let mut s = e.get_state();
        s.physics[applied + 2] = 1.2802614361197283e10;
        e.set_state(&s).unwrap();
        assert_eq!(e.get_state().physics[applied + 2], 1.2802614361197283e10);
        s.physics[applied + 2] = f64::INFINITY;
        assert!(e
            .set_state(&s)
            .unwrap_err()
            .to_string()
            .contains("qfrc_applied[2]"));
        let mut s = e.get_state();
        s.physics[1] = 1.28e10;
        let err = e.set_state(&s).unwrap_err().to_string();
        assert!(
            err.contains("qpos[0]") && err.contains("out of range"),
            "{err}"
        );
    }
}
