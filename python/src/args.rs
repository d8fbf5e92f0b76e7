//! The env contract of the Python classes: ManiSkill's keyword arguments ([`ENV_KWARGS`],
//! their defaults from [`EnvConfig::default`]) parsed into an [`EnvConfig`], and the checks
//! of seeds and counts, each a `ValueError` naming the argument and its valid range (a
//! `TypeError` for a value of the wrong type).
use mjskill::{EnvConfig, ObsMode, RewardMode};
use pyo3::exceptions::{PyOverflowError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict};

use crate::value_err;

/// An integer argument as a Python int, range-checked: a value outside `lo..=hi` (also one
/// beyond any fixed-width integer) is a `ValueError` `"{name} {value} is out of range:
/// {valid}"`; a non-integer stays a `TypeError`.
pub(crate) fn int_arg(
    value: &Bound<'_, PyAny>,
    name: &str,
    lo: i128,
    hi: i128,
    valid: &str,
) -> PyResult<i128> {
    let out_of_range = || {
        let shown = value
            .str()
            .map(|s| s.to_string())
            .unwrap_or_else(|_| "(an int too large to print)".into());
        PyValueError::new_err(format!("{name} {shown} is out of range: {valid}"))
    };
    match value.extract::<i128>() {
        Ok(v) if (lo..=hi).contains(&v) => Ok(v),
        Ok(_) => Err(out_of_range()),
        Err(e) if e.is_instance_of::<PyOverflowError>(value.py()) => Err(out_of_range()),
        Err(e) => Err(e),
    }
}

/// A seed argument (`None` or `0..=MAX_SEED`): an out-of-range seed is a `ValueError`
/// `"{name} {value} is out of range: seeds are 32-bit, 0..=4294967295"` (the message of
/// `EnvError::BadSeed`), anything but an int (a bool included) a `TypeError`. The one check
/// of seeds for Python: the classes call it and the Python wrappers through `check_seed`.
pub(crate) fn seed_arg(seed: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<Option<u64>> {
    let Some(s) = seed.filter(|s| !s.is_none()) else {
        return Ok(None);
    };
    not_a_bool(s, name, "an int or None")?;
    let valid = format!("seeds are 32-bit, 0..={}", mjskill::MAX_SEED);
    int_arg(s, name, 0, mjskill::MAX_SEED as i128, &valid)
        .map_err(|e| type_error_naming(s, name, "an int or None", e))
        .map(|v| Some(v as u64))
}

/// A `TypeError` `"{name} must be {what}, not {type} ({repr})"` for a bool (Python's bools
/// are ints, but a flag given for a number is a mistake).
fn not_a_bool(value: &Bound<'_, PyAny>, name: &str, what: &str) -> PyResult<()> {
    if value.is_instance_of::<PyBool>() {
        return Err(type_error(value, name, what));
    }
    Ok(())
}

/// `"{name} must be {what}, not {type} ({repr})"` as a `TypeError`.
pub(crate) fn type_error(value: &Bound<'_, PyAny>, name: &str, what: &str) -> PyErr {
    let ty = value
        .get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "object".into());
    let repr = value
        .repr()
        .map(|r| r.to_string())
        .unwrap_or_else(|_| "?".into());
    PyTypeError::new_err(format!("{name} must be {what}, not {ty} ({repr})"))
}

/// `e` as [`type_error`]'s message when it is a `TypeError` (the value is no int).
fn type_error_naming(value: &Bound<'_, PyAny>, name: &str, what: &str, e: PyErr) -> PyErr {
    if e.is_instance_of::<PyTypeError>(value.py()) {
        type_error(value, name, what)
    } else {
        e
    }
}

/// A count argument in `1..=MAX_NUM_ENVS` (`num_envs`, `num_threads`).
pub(crate) fn count_arg(value: &Bound<'_, PyAny>, name: &str) -> PyResult<usize> {
    not_a_bool(value, name, "an int")?;
    let valid = format!(
        "1..={} (each env owns its MuJoCo model and data; more threads than envs are clamped)",
        mjskill::MAX_NUM_ENVS
    );
    int_arg(value, name, 1, mjskill::MAX_NUM_ENVS as i128, &valid)
        .map_err(|e| type_error_naming(value, name, "an int", e))
        .map(|v| v as usize)
}

/// ManiSkill's env keyword arguments, the one declaration for `Env`, `VecEnv` and
/// `record_episodes` (which take them as `**kwargs`) and for the Python classes (which read
/// them, with their defaults, as `ENV_KWARGS`).
const ENV_KWARGS: [&str; 9] = [
    "robot_uids",
    "obs_mode",
    "control_mode",
    "reward_mode",
    "max_episode_steps",
    "robot_init_qpos_noise",
    "sim_freq",
    "reconfiguration_freq",
    "pinch_solver",
];

/// Episode length that means "no limit" (`max_episode_steps` of envs whose time limit is
/// applied outside the native env): the largest one.
pub(crate) const UNLIMITED_EPISODE_STEPS: u32 = u32::MAX;

/// `{name: default}` of [`ENV_KWARGS`], the defaults being [`EnvConfig::default`]'s
/// (`max_episode_steps` None: the env's registered length).
pub(crate) fn env_kwargs_defaults(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let c = EnvConfig::default();
    let d = PyDict::new(py);
    d.set_item(ENV_KWARGS[0], c.robot)?;
    d.set_item(ENV_KWARGS[1], c.obs_mode.name())?;
    d.set_item(ENV_KWARGS[2], c.control_mode)?;
    d.set_item(ENV_KWARGS[3], c.reward_mode.name())?;
    d.set_item(ENV_KWARGS[4], c.max_episode_steps)?;
    d.set_item(ENV_KWARGS[5], c.robot_init_qpos_noise)?;
    d.set_item(ENV_KWARGS[6], c.sim.sim_freq)?;
    d.set_item(ENV_KWARGS[7], c.reconfiguration_freq)?;
    d.set_item(ENV_KWARGS[8], c.sim.pinch_solver.name())?;
    Ok(d)
}

/// A wrong-typed argument as a `TypeError` naming it (`e`: the extraction's error).
fn arg_type_error(value: &Bound<'_, PyAny>, name: &str, e: PyErr) -> PyErr {
    PyTypeError::new_err(format!("argument '{name}': {}", e.value(value.py())))
}

/// A string argument; anything else is a `TypeError` naming it.
fn str_arg(value: &Bound<'_, PyAny>, name: &str) -> PyResult<String> {
    value
        .extract::<String>()
        .map_err(|e| arg_type_error(value, name, e))
}

/// A float argument (ints accepted); anything else is a `TypeError` naming it.
fn f64_arg(value: &Bound<'_, PyAny>, name: &str) -> PyResult<f64> {
    value
        .extract::<f64>()
        .map_err(|e| arg_type_error(value, name, e))
}

/// The [`EnvConfig`] for ManiSkill's keyword arguments ([`ENV_KWARGS`]; `None` or absent is
/// the default; `max_episode_steps` and `sim_freq` as Python ints, range-checked). Any other
/// keyword is a `TypeError` naming `callee`, as Python's own for an unexpected keyword.
pub(crate) fn config(kwargs: Option<&Bound<'_, PyDict>>, callee: &str) -> PyResult<EnvConfig> {
    let mut cfg = EnvConfig::default();
    let Some(kwargs) = kwargs else {
        return Ok(cfg);
    };
    for (key, value) in kwargs.iter() {
        let key: String = key.extract()?;
        if value.is_none() && key != "obs_mode" && key != "reward_mode" {
            continue;
        }
        match key.as_str() {
            "robot_uids" => cfg.robot = Some(str_arg(&value, &key)?),
            "obs_mode" => {
                let mode = str_arg(&value, &key)?;
                cfg.obs_mode = ObsMode::parse(&mode).map_err(value_err)?;
            }
            "control_mode" => cfg.control_mode = Some(str_arg(&value, &key)?),
            "reward_mode" => {
                let mode = str_arg(&value, &key)?;
                cfg.reward_mode = RewardMode::parse(&mode).map_err(value_err)?;
            }
            "max_episode_steps" => {
                // -1 is gymnasium's "no time limit" (gym.make's max_episode_steps=-1), here too.
                let max = UNLIMITED_EPISODE_STEPS;
                let valid =
                    format!("an episode needs at least one step (1..={max}), or -1 for no limit");
                let steps = int_arg(&value, &key, -1, max as i128, &valid)?;
                if steps == 0 {
                    return Err(PyValueError::new_err(format!(
                        "{key} 0 is out of range: {valid}"
                    )));
                }
                cfg.max_episode_steps = Some(if steps == -1 { max } else { steps as u32 });
            }
            "robot_init_qpos_noise" => cfg.robot_init_qpos_noise = f64_arg(&value, &key)?,
            "sim_freq" => {
                let valid = format!(
                    "use a multiple of the control frequency {c} Hz between {c} and 100000 \
                     (e.g. 100, 200, 500)",
                    c = mjskill::CONTROL_FREQ
                );
                // Beyond u32 here; within it, SimConfig's own check names the valid rates.
                cfg.sim.sim_freq = int_arg(&value, &key, 0, u32::MAX as i128, &valid)? as u32;
            }
            "pinch_solver" => {
                let name = str_arg(&value, &key)?;
                cfg.sim.pinch_solver = mjskill::PinchSolver::parse(&name).map_err(value_err)?;
            }
            "reconfiguration_freq" => {
                let valid = "resets between redraws of a task's per-episode shapes: 0 (never \
                             after construction), 1 (every reset), ..., or None (ManiSkill's \
                             default: 1 for one env, 0 for a batch)";
                cfg.reconfiguration_freq =
                    Some(int_arg(&value, &key, 0, u32::MAX as i128, valid)? as u32);
            }
            _ => {
                return Err(PyTypeError::new_err(format!(
                    "{callee}() got an unexpected keyword argument '{key}' (valid: {})",
                    ENV_KWARGS.join(", ")
                )))
            }
        }
    }
    Ok(cfg)
}
