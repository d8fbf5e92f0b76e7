//! `mjskill._native`: the PyO3 extension under the `mjskill` Python package.
//!
//! Two classes wrap the Rust API: `PyEnv` (one [`mjskill::Env`]) and `PyVecEnv` (a
//! [`mjskill::VecEnv`]); `record_episodes` writes a recording (`.mcap`) of given seeds
//! and actions. The gymnasium classes (`mjskill.MjskillEnv`, `mjskill.MjskillVectorEnv`) are
//! plain Python on top, because a PyO3 class cannot subclass `gymnasium.Env`.
//!
//! Every Rust error becomes a Python `ValueError` carrying the Rust message (which names the
//! bad value and the valid choices); a failed render is a `RuntimeError`. The GIL is released
//! while an env steps, resets or renders. Each class holds its env behind a `Mutex`, so a
//! Python object can be shared between threads: calls from several threads run one at a time.
//! The lock is never waited for while holding the GIL (`lock_without_gil`): a thread that
//! holds the lock may need the GIL to finish its call, so waiting with the GIL would deadlock.
//!
//! Integer arguments are taken as Python ints and range-checked here (`int_arg`), so an
//! out-of-range value is a `ValueError` naming the argument and its valid range rather than a
//! bare `OverflowError`.
#![warn(missing_docs)]

mod policy;

use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard, TryLockError};

use mjskill::record::Recorder;
use mjskill::solvers::{make_policy, set_state_experts, state_expert, Policy, StateExpert};
use mjskill::VecEnv;
use mjskill::{Env, EnvConfig, EnvError, EnvState};
use numpy::ndarray::ArrayView2;
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, ToPyArray};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use mjskill::mujoco::Warnings;

mod args;
use args::{config, count_arg, env_kwargs_defaults, seed_arg, type_error, UNLIMITED_EPISODE_STEPS};

mod rollout;

/// A Rust env error as a Python `ValueError` with the same message.
fn value_err(e: EnvError) -> PyErr {
    match e {
        EnvError::Render(m) => PyRuntimeError::new_err(m.to_string()),
        e => PyValueError::new_err(e.to_string()),
    }
}

/// A poisoned lock (an earlier call panicked inside the env) as a Python `RuntimeError`.
fn poisoned<T>(_: T) -> PyErr {
    PyRuntimeError::new_err(
        "this env is unusable: an earlier call panicked inside it (see the earlier error)",
    )
}

/// Locks `m` without ever blocking while holding the GIL.
///
/// The thread that holds the lock may be inside `py.detach` (stepping without the GIL) and
/// needs the GIL back to build its results before it unlocks. A thread that blocked on the
/// lock while holding the GIL would wait for it forever, and the holder for the GIL: the
/// interpreter would hang. So the lock is only *tried* with the GIL; when it is busy, the
/// wait happens with the GIL released, and then the lock is tried again. Pending signals
/// (Ctrl-C) are checked between tries.
fn lock_without_gil<'a, T: Send>(py: Python<'_>, m: &'a Mutex<T>) -> PyResult<MutexGuard<'a, T>> {
    loop {
        match m.try_lock() {
            Ok(g) => return Ok(g),
            Err(TryLockError::Poisoned(e)) => return Err(poisoned(e)),
            Err(TryLockError::WouldBlock) => {
                // Wait until the holder is done (the guard is dropped at once, the lock is
                // re-taken with the GIL above).
                py.detach(|| drop(m.lock()));
                py.check_signals()?;
            }
        }
    }
}

/// `{"BadQacc": 1, ...}`: the MuJoCo warnings that fired (kind names as
/// [`mjskill::mujoco::Warning`]'s, with their counts); `None` when none did.
fn warnings_dict<'py>(py: Python<'py>, w: &Warnings) -> PyResult<Option<Bound<'py, PyDict>>> {
    let fired = w.fired();
    if fired.is_empty() {
        return Ok(None);
    }
    let d = PyDict::new(py);
    for k in fired {
        d.set_item(format!("{k:?}"), w.count(k))?;
    }
    Ok(Some(d))
}

/// The single-env info dict: `elapsed_steps`, the task keys (flags as `bool`) and, on
/// reset, `reconfigure`.
fn info_dict<'py>(py: Python<'py>, env: &Env) -> PyResult<Bound<'py, PyDict>> {
    let info = env.info();
    let d = PyDict::new(py);
    d.set_item("elapsed_steps", info.elapsed_steps)?;
    // A vector value is held as one scalar key per component, `name[0]`, `name[1]`, ...
    // (PegInsertionSide-v1's `peg_head_pos_at_hole`): here it is one array, as upstream.
    let mut vector: Option<(&str, Vec<f64>)> = None;
    for (k, v) in info.keys.iter().zip(&info.values) {
        let base = k
            .strip_suffix(']')
            .and_then(|s| s.rsplit_once('['))
            .map(|(b, _)| b);
        if let Some((name, values)) = vector.take_if(|(name, _)| Some(*name) != base) {
            d.set_item(name, PyArray1::from_vec(py, values))?;
        }
        if let Some(b) = base {
            vector.get_or_insert((b, Vec::new())).1.push(*v);
        } else if env.info_is_flag(k) {
            d.set_item(*k, *v != 0.0)?;
        } else {
            d.set_item(*k, *v)?;
        }
    }
    if let Some((name, values)) = vector {
        d.set_item(name, PyArray1::from_vec(py, values))?;
    }
    if let Some(r) = info.reconfigure {
        d.set_item("reconfigure", r)?;
    }
    if let Some(w) = warnings_dict(py, &info.warnings)? {
        d.set_item("warnings", w)?;
    }
    Ok(d)
}

/// The static description of an env (what the Python layer builds its spaces from).
fn spec_dict<'py>(py: Python<'py>, env: &Env) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let cfg = env.config();
    d.set_item("env_id", env.id())?;
    d.set_item("robot_uids", env.robot_id().uid())?;
    d.set_item("control_mode", env.control_mode())?;
    d.set_item("obs_mode", cfg.obs_mode.name())?;
    d.set_item("reward_mode", cfg.reward_mode.name())?;
    d.set_item("max_episode_steps", env.max_episode_steps())?;
    d.set_item("robot_init_qpos_noise", cfg.robot_init_qpos_noise)?;
    d.set_item("sim_freq", cfg.sim.sim_freq)?;
    let a = env.action_space();
    d.set_item("action_low", PyArray1::from_slice(py, &a.low))?;
    d.set_item("action_high", PyArray1::from_slice(py, &a.high))?;
    let o = env.observation_space();
    d.set_item("obs_low", PyArray1::from_slice(py, &o.low))?;
    d.set_item("obs_high", PyArray1::from_slice(py, &o.high))?;
    let layout = PyList::empty(py);
    for (name, r) in env.obs_layout() {
        layout.append((name.as_str(), r.start, r.end))?;
    }
    d.set_item("obs_layout", layout)?;
    d.set_item("gripper_joints", env.gripper_joints())?;
    let cams = PyList::empty(py);
    if cfg.obs_mode.is_visual() && !cfg.obs_mode.is_point_cloud() {
        for name in env.sensor_names() {
            if let Some(img) = env.image(name) {
                cams.append((
                    img.name,
                    img.width,
                    img.height,
                    img.rgb.is_some(),
                    img.depth.is_some(),
                    img.segmentation.is_some(),
                ))?;
            }
        }
    }
    d.set_item("cameras", cams)?;
    d.set_item("point_count", env.point_cloud().map(|p| p.len))?;
    d.set_item("segmentation_id_map", env.segmentation_id_map())?;
    let keys: Vec<(&str, bool)> = env
        .info()
        .keys
        .iter()
        .map(|k| (*k, env.info_is_flag(k)))
        .collect();
    d.set_item("info_keys", keys)?;
    d.set_item("render_size", env.render_size())?;
    d.set_item("reconfigures", env.reconfigures())?;
    Ok(d)
}

/// `{camera: {"rgb": H×W×3 uint8, "depth": H×W×1 float32 metres (int16 millimetres with
/// `depth_mm`), "segmentation": H×W×1 int16}}` of a single env (the textures its obs mode
/// renders).
fn images_dict<'py>(py: Python<'py>, env: &Env, depth_mm: bool) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for name in env.sensor_names() {
        let Some(img) = env.image(name) else { continue };
        let cam = PyDict::new(py);
        let (h, w) = (img.height, img.width);
        if let Some(rgb) = img.rgb {
            cam.set_item("rgb", PyArray1::from_slice(py, rgb).reshape([h, w, 3])?)?;
        }
        match (img.depth, img.depth_mm) {
            (Some(_), Some(mm)) if depth_mm => {
                cam.set_item("depth", PyArray1::from_slice(py, mm).reshape([h, w, 1])?)?
            }
            (Some(m), _) => {
                cam.set_item("depth", PyArray1::from_slice(py, m).reshape([h, w, 1])?)?
            }
            _ => {}
        }
        if let Some(seg) = img.segmentation {
            cam.set_item(
                "segmentation",
                PyArray1::from_slice(py, seg).reshape([h, w, 1])?,
            )?;
        }
        d.set_item(img.name, cam)?;
    }
    Ok(d)
}

/// ManiSkill's `pointcloud` dict of `n` stacked clouds: `xyzw` n×N×4 float32, `rgb` n×N×3
/// uint8, `segmentation` n×N×1 int16 (`single`: without the leading n).
fn point_cloud_dict<'py, 'a>(
    py: Python<'py>,
    clouds: impl Iterator<Item = mjskill::PointCloud<'a>>,
    single: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let (mut xyzw, mut rgb, mut seg) = (Vec::new(), Vec::new(), Vec::new());
    let (mut n, mut len) = (0usize, 0usize);
    for c in clouds {
        xyzw.extend_from_slice(c.xyzw);
        rgb.extend_from_slice(c.rgb);
        seg.extend_from_slice(c.segmentation);
        n += 1;
        len = c.len;
    }
    let d = PyDict::new(py);
    let shape = |k: usize| {
        if single {
            vec![len, k]
        } else {
            vec![n, len, k]
        }
    };
    d.set_item("xyzw", PyArray1::from_vec(py, xyzw).reshape(shape(4))?)?;
    d.set_item("rgb", PyArray1::from_vec(py, rgb).reshape(shape(3))?)?;
    d.set_item(
        "segmentation",
        PyArray1::from_vec(py, seg).reshape(shape(1))?,
    )?;
    Ok(d)
}

/// One mjskill env (`mjskill._native.Env`); the gymnasium class `mjskill.MjskillEnv` wraps it.
#[pyclass(module = "mjskill._native", name = "Env")]
struct PyEnv {
    env: Mutex<Env>,
    /// The state expert (`expert_action`), built on first use.
    expert: Mutex<Option<Box<dyn StateExpert>>>,
    /// The scripted solver (`solver_action`), built at the first call after each reset: it
    /// keeps the plan it makes over the episode, as `--policy solver` runs it.
    solver: Mutex<Option<Box<dyn Policy>>>,
}

impl PyEnv {
    fn lock(&self, py: Python<'_>) -> PyResult<MutexGuard<'_, Env>> {
        lock_without_gil(py, &self.env)
    }
}

#[pymethods]
impl PyEnv {
    /// Builds `env_id` with ManiSkill's keyword arguments (`ENV_KWARGS`).
    #[new]
    #[pyo3(signature = (env_id, **kwargs))]
    fn new(py: Python<'_>, env_id: &str, kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let cfg = config(kwargs, "Env")?;
        let env = py
            .detach(|| mjskill::make(env_id, cfg))
            .map_err(value_err)?;
        Ok(PyEnv {
            env: Mutex::new(env),
            expert: Mutex::new(None),
            solver: Mutex::new(None),
        })
    }

    /// The scripted solver's next action (`--policy solver`) for the current state, in this
    /// env's control mode. The solver is built at the first call after a reset and keeps the
    /// plan it makes over the episode; between calls the state may be set from elsewhere
    /// (`set_state_dict`), as when it runs closed loop on another simulator's states.
    fn solver_action<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f32>>> {
        let env = self.lock(py)?;
        let mut solver = lock_without_gil(py, &self.solver)?;
        let action = (|| {
            if solver.is_none() {
                let mut policy = make_policy("solver", &env, 0)?;
                policy.reset(&env);
                *solver = Some(policy);
            }
            let mut a = vec![0.0f32; env.action_space().shape[0]];
            if let Some(policy) = solver.as_mut() {
                policy.try_act(&env, &mut a)?;
            }
            Ok::<_, mjskill::solvers::SolverError>(a)
        })();
        let action = action.map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok(PyArray1::from_vec(py, action))
    }

    /// The state expert's action for the current state (`mjskill.solvers::state_expert`):
    /// a function of the state alone, for DAgger labels. A pair without an expert, or a mode
    /// its actions cannot be converted to, is a `ValueError` naming it.
    fn expert_action<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f32>>> {
        let env = self.lock(py)?;
        let mut expert = lock_without_gil(py, &self.expert)?;
        // One physics step at most (a converted mode's shadow env): the GIL stays held.
        let action = (|| {
            if expert.is_none() {
                *expert = Some(state_expert(&env)?);
            }
            let mut a = vec![0.0f32; env.action_space().shape[0]];
            expert.as_mut().map_or(Ok(()), |e| e.label(&env, &mut a))?;
            Ok::<_, mjskill::solvers::SolverError>(a)
        })();
        let action = action.map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok(PyArray1::from_vec(py, action))
    }

    /// The env's static description (ids, modes, space bounds, observation layout,
    /// cameras, info keys).
    fn spec<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        spec_dict(py, &*self.lock(py)?)
    }

    /// Resets (seeded: ManiSkill's exact initial state) and returns `(obs, info)`;
    /// `reconfigure`: ManiSkill's reset option (a task's per-episode shapes drawn anew).
    #[pyo3(signature = (seed=None, reconfigure=false))]
    fn reset<'py>(
        &self,
        py: Python<'py>,
        seed: Option<&Bound<'py, PyAny>>,
        reconfigure: bool,
    ) -> PyResult<(Bound<'py, PyArray1<f32>>, Bound<'py, PyDict>)> {
        let seed = seed_arg(seed, "seed")?;
        let mut g = self.lock(py)?;
        let env = &mut *g;
        py.detach(|| env.try_reset_with(seed, reconfigure).map(|_| ()))
            .map_err(value_err)?;
        // A new episode: the solver plans afresh at its next call.
        *lock_without_gil(py, &self.solver)? = None;
        Ok((PyArray1::from_slice(py, env.obs()), info_dict(py, env)?))
    }

    /// One step: `(obs, reward, terminated, truncated, info)`.
    #[allow(clippy::type_complexity)]
    fn step<'py>(
        &self,
        py: Python<'py>,
        action: PyReadonlyArray1<'py, f32>,
    ) -> PyResult<(
        Bound<'py, PyArray1<f32>>,
        f32,
        bool,
        bool,
        Bound<'py, PyDict>,
    )> {
        let mut g = self.lock(py)?;
        let env = &mut *g;
        let a = action.as_slice()?;
        // Copied so that the numpy buffer is not touched without the GIL.
        let mut buf = [0f32; 32];
        let a: &[f32] = if a.len() <= buf.len() {
            buf[..a.len()].copy_from_slice(a);
            &buf[..a.len()]
        } else {
            return Err(value_err(EnvError::ActionLength {
                got: a.len(),
                expected: env.action_space().shape[0],
                mode: env.control_mode().to_string(),
            }));
        };
        let (reward, terminated, truncated) = py
            .detach(|| env.step(a).map(|s| (s.reward, s.terminated, s.truncated)))
            .map_err(value_err)?;
        Ok((
            PyArray1::from_slice(py, env.obs()),
            reward,
            terminated,
            truncated,
            info_dict(py, env)?,
        ))
    }

    /// The current flat observation (empty for obs mode `none`).
    fn obs<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f32>>> {
        Ok(PyArray1::from_slice(py, self.lock(py)?.obs()))
    }

    /// The current info dict.
    fn info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        info_dict(py, &*self.lock(py)?)
    }

    /// The sensor images of the current state (visual obs modes; else empty); depth in
    /// ManiSkill's int16 millimetres with `depth_mm=True`, else float32 metres.
    #[pyo3(signature = (depth_mm=false))]
    fn images<'py>(&self, py: Python<'py>, depth_mm: bool) -> PyResult<Bound<'py, PyDict>> {
        images_dict(py, &*self.lock(py)?, depth_mm)
    }

    /// ManiSkill's fused point cloud of the current state (obs mode `pointcloud`; else
    /// `None`): `{"xyzw": N×4 float32, "rgb": N×3 uint8, "segmentation": N×1 int16}`.
    fn point_cloud<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let env = self.lock(py)?;
        env.point_cloud()
            .map(|c| point_cloud_dict(py, std::iter::once(c), true))
            .transpose()
    }

    /// The human camera's RGB frame (H×W×3 uint8).
    fn render<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let mut g = self.lock(py)?;
        let env = &mut *g;
        let (w, h) = env.render_size();
        let frame = py
            .detach(|| env.render().map(<[u8]>::to_vec))
            .map_err(value_err)?;
        Ok(PyArray1::from_vec(py, frame).reshape([h, w, 3])?.into_any())
    }

    /// [`Env::get_state`] as JSON (exact: floats round-trip).
    fn get_state(&self, py: Python<'_>) -> PyResult<String> {
        serde_json::to_string(&self.lock(py)?.get_state())
            .map_err(|e| PyRuntimeError::new_err(e.to_string()))
    }

    /// Restores a state from `get_state`; a bad state is a `ValueError` and changes nothing.
    fn set_state(&self, py: Python<'_>, state: &str) -> PyResult<()> {
        let s: EnvState = serde_json::from_str(state)
            .map_err(|e| PyValueError::new_err(format!("cannot set state: not a state: {e}")))?;
        self.lock(py)?.set_state(&s).map_err(value_err)
    }

    /// ManiSkill's `get_state_dict()` as nested JSON.
    fn get_state_dict(&self, py: Python<'_>) -> PyResult<String> {
        Ok(self.lock(py)?.get_state_dict().to_json().to_string())
    }

    /// ManiSkill's `set_state_dict()` from nested JSON.
    fn set_state_dict(&self, py: Python<'_>, state_dict: &str) -> PyResult<()> {
        let v: serde_json::Value = serde_json::from_str(state_dict)
            .map_err(|e| PyValueError::new_err(format!("cannot set state dict: not JSON: {e}")))?;
        let sd = mjskill::StateDict::from_json(&v)
            .map_err(|e| PyValueError::new_err(format!("cannot set state dict: {e}")))?;
        self.lock(py)?.set_state_dict(&sd).map_err(value_err)
    }

    /// Steps since the last reset.
    fn elapsed_steps(&self, py: Python<'_>) -> PyResult<u32> {
        Ok(self.lock(py)?.info().elapsed_steps)
    }
}

/// The VecEnv and its action buffer, behind one lock.
struct VecState {
    vec: VecEnv,
    actions: Vec<f32>,
}

/// N envs stepped on T threads (`mjskill._native.VecEnv`); `mjskill.MjskillVectorEnv`
/// wraps it. Autoreset is gymnasium's next-step mode.
#[pyclass(module = "mjskill._native", name = "VecEnv")]
struct PyVecEnv {
    inner: Mutex<VecState>,
    /// Info keys with their flag-ness.
    keys: Vec<(&'static str, bool)>,
    /// Read-only all-true `[N]` masks for gymnasium's `"_<key>"` info entries, made once.
    masks: Py<PyArray1<bool>>,
    num_envs: usize,
    obs_dim: usize,
}

impl PyVecEnv {
    fn lock(&self, py: Python<'_>) -> PyResult<MutexGuard<'_, VecState>> {
        lock_without_gil(py, &self.inner)
    }

    /// `{key: [N] array, "_key": mask}` of the last reset/step.
    fn info<'py>(&self, py: Python<'py>, vec: &VecEnv) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        let k = self.keys.len();
        let values = vec.info();
        let masks = self.masks.bind(py);
        for (j, (key, flag)) in self.keys.iter().enumerate() {
            let column = values.iter().skip(j).step_by(k.max(1));
            if *flag {
                let col: Vec<bool> = column.map(|v| *v != 0.0).collect();
                d.set_item(*key, PyArray1::from_vec(py, col))?;
            } else {
                let col: Vec<f64> = column.copied().collect();
                d.set_item(*key, PyArray1::from_vec(py, col))?;
            }
            d.set_item(format!("_{key}"), masks)?;
        }
        // Only when some env raised MuJoCo warnings: env i's `{kind: count}` dict (None for
        // the others) and gymnasium's mask of the envs that have one.
        let warnings = vec.warnings();
        if warnings.iter().any(|w| !w.fired().is_empty()) {
            let per_env = PyList::empty(py);
            let mut mask = Vec::with_capacity(warnings.len());
            for w in warnings {
                let entry = warnings_dict(py, w)?;
                mask.push(entry.is_some());
                per_env.append(entry)?;
            }
            let np = py.import("numpy")?;
            let kwargs = PyDict::new(py);
            kwargs.set_item("dtype", np.getattr("object_")?)?;
            let arr = np.call_method("empty", (warnings.len(),), Some(&kwargs))?;
            arr.call_method1("__setitem__", (pyo3::types::PySlice::full(py), per_env))?;
            d.set_item("warnings", arr)?;
            d.set_item("_warnings", PyArray1::from_vec(py, mask))?;
        }
        Ok(d)
    }

    fn obs<'py>(&self, py: Python<'py>, vec: &VecEnv) -> PyResult<Bound<'py, PyAny>> {
        let v = ArrayView2::from_shape((self.num_envs, self.obs_dim), vec.obs())
            .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
        Ok(v.to_pyarray(py).into_any())
    }
}

#[pymethods]
impl PyVecEnv {
    /// Builds `num_envs` envs of `env_id` on `num_threads` threads (default 1);
    /// `num_envs` and `num_threads` are in `1..=MAX_NUM_ENVS` (more threads than envs are
    /// clamped to `num_envs`).
    #[new]
    #[pyo3(signature = (env_id, num_envs, num_threads=None, autoreset=true, **kwargs))]
    fn new(
        py: Python<'_>,
        env_id: &str,
        num_envs: &Bound<'_, PyAny>,
        num_threads: Option<&Bound<'_, PyAny>>,
        autoreset: bool,
        kwargs: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let num_envs = count_arg(num_envs, "num_envs")?;
        let num_threads = match num_threads.filter(|t| !t.is_none()) {
            None => 1,
            Some(t) => count_arg(t, "num_threads")?,
        };
        let cfg = config(kwargs, "VecEnv")?;
        let mut vec = py
            .detach(|| VecEnv::new(env_id, cfg, num_envs, num_threads))
            .map_err(value_err)?;
        vec.set_autoreset(autoreset);
        let keys = vec
            .info_keys()
            .iter()
            .map(|k| (*k, vec.info_is_flag(k)))
            .collect();
        let masks = PyArray1::from_vec(py, vec![true; num_envs]);
        let kwargs = PyDict::new(py);
        kwargs.set_item("write", false)?;
        masks.call_method("setflags", (), Some(&kwargs))?;
        let obs_dim = vec.single_observation_space().shape.iter().product();
        let actions = Vec::with_capacity(num_envs * vec.single_action_space().shape[0]);
        Ok(PyVecEnv {
            inner: Mutex::new(VecState { vec, actions }),
            keys,
            masks: masks.unbind(),
            num_envs,
            obs_dim,
        })
    }

    /// Number of envs.
    #[getter]
    fn num_envs(&self) -> usize {
        self.num_envs
    }

    /// Threads stepping the envs (the caller's included).
    #[getter]
    fn num_threads(&self, py: Python<'_>) -> PyResult<usize> {
        Ok(self.lock(py)?.vec.num_threads())
    }

    /// Resets every env (env i with `seed + i`, or unseeded): `(obs [N × D], info)`;
    /// `reconfigure`: ManiSkill's reset option (every env's per-episode shapes drawn anew).
    #[pyo3(signature = (seed=None, reconfigure=false))]
    fn reset<'py>(
        &self,
        py: Python<'py>,
        seed: Option<&Bound<'py, PyAny>>,
        reconfigure: bool,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyDict>)> {
        let seed = seed_arg(seed, "seed")?;
        let mut g = self.lock(py)?;
        let st = &mut *g;
        py.detach(|| st.vec.try_reset_with(seed, reconfigure).map(|_| ()))
            .map_err(value_err)?;
        Ok((self.obs(py, &st.vec)?, self.info(py, &st.vec)?))
    }

    /// Resets the envs where `mask` (`[N]` bool) is set (env i with `seed + i`, or
    /// unseeded); the others keep their state: `(obs [N × D], info)` of every env.
    #[pyo3(signature = (mask, seed=None))]
    fn reset_envs<'py>(
        &self,
        py: Python<'py>,
        mask: PyReadonlyArray1<'py, bool>,
        seed: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyDict>)> {
        let seed = seed_arg(seed, "seed")?;
        let mask: Vec<bool> = mask.as_array().iter().copied().collect();
        let mut g = self.lock(py)?;
        let st = &mut *g;
        py.detach(|| st.vec.reset_envs(&mask, seed).map(|_| ()))
            .map_err(value_err)?;
        Ok((self.obs(py, &st.vec)?, self.info(py, &st.vec)?))
    }

    /// Whether an env whose episode ended resets on the next step (gymnasium's next-step
    /// autoreset; off for ManiSkill-style batched envs, which `reset_envs` resets).
    #[getter]
    fn get_autoreset_enabled(&self, py: Python<'_>) -> PyResult<bool> {
        Ok(self.lock(py)?.vec.autoreset_enabled())
    }

    /// Steps every env with its row of `actions` (`[N × A]` float32):
    /// `(obs, rewards, terminated, truncated, info)`.
    #[allow(clippy::type_complexity)]
    fn step<'py>(
        &self,
        py: Python<'py>,
        actions: PyReadonlyArray2<'py, f32>,
    ) -> PyResult<(
        Bound<'py, PyAny>,
        Bound<'py, PyArray1<f32>>,
        Bound<'py, PyArray1<bool>>,
        Bound<'py, PyArray1<bool>>,
        Bound<'py, PyDict>,
    )> {
        let mut g = self.lock(py)?;
        let st = &mut *g;
        let adim = st.vec.single_action_space().shape[0];
        let (rows, cols) = actions.as_array().dim();
        if (rows, cols) != (self.num_envs, adim) {
            return Err(PyValueError::new_err(format!(
                "actions have shape ({rows}, {cols}), expected (num_envs, action_dim) = ({}, {adim})",
                self.num_envs
            )));
        }
        // Copied into the env's own buffer: the numpy array is not read without the GIL.
        st.actions.clear();
        match actions.as_slice() {
            Ok(s) => st.actions.extend_from_slice(s),
            Err(_) => st.actions.extend(actions.as_array().iter().copied()),
        }
        let VecState { vec, actions } = st;
        py.detach(|| vec.step(actions)).map_err(value_err)?;
        Ok((
            self.obs(py, vec)?,
            PyArray1::from_slice(py, vec.rewards()),
            PyArray1::from_slice(py, vec.terminated()),
            PyArray1::from_slice(py, vec.truncated()),
            self.info(py, vec)?,
        ))
    }

    /// Envs that reset during the last step (their action was ignored).
    fn autoreset<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<bool>>> {
        Ok(PyArray1::from_slice(py, self.lock(py)?.vec.autoreset()))
    }

    /// Every env's state-expert action for its current state, `[N, act_dim]` float32, computed
    /// on the envs' threads (`solvers::set_state_experts`, installed on first use). A pair
    /// without a state expert, or a mode its actions cannot be converted to, is a
    /// `ValueError` naming it.
    fn expert_actions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let mut g = self.lock(py)?;
        let vec = &mut g.vec;
        let labels = py
            .detach(|| {
                if !vec.has_labellers() {
                    set_state_experts(vec).map_err(|e| e.to_string())?;
                }
                vec.expert_actions()
                    .map(<[f32]>::to_vec)
                    .map_err(|e| e.to_string())
            })
            .map_err(PyValueError::new_err)?;
        let ad = labels.len() / self.num_envs;
        PyArray1::from_vec(py, labels)
            .reshape([self.num_envs, ad])
            .map_err(|e| PyValueError::new_err(e.to_string()))
    }

    /// `{camera: {"rgb": N×H×W×3 uint8, "depth": N×H×W×1 float32 (int16 millimetres with
    /// `depth_mm`), "segmentation": N×H×W×1 int16}}` of the last reset/step.
    #[pyo3(signature = (depth_mm=false))]
    fn images<'py>(&self, py: Python<'py>, depth_mm: bool) -> PyResult<Bound<'py, PyDict>> {
        let g = self.lock(py)?;
        let vec = &g.vec;
        let n = self.num_envs;
        let d = PyDict::new(py);
        for name in vec.sensor_names() {
            let Some(first) = vec.image(0, name) else {
                continue;
            };
            let (w, h) = (first.width, first.height);
            let imgs = || (0..n).filter_map(|i| vec.image(i, name));
            let cam = PyDict::new(py);
            if first.rgb.is_some() {
                let all: Vec<u8> = imgs()
                    .flat_map(|c| c.rgb.unwrap_or_default())
                    .copied()
                    .collect();
                cam.set_item("rgb", PyArray1::from_vec(py, all).reshape([n, h, w, 3])?)?;
            }
            if first.depth.is_some() && depth_mm {
                let all: Vec<i16> = imgs()
                    .flat_map(|c| c.depth_mm.unwrap_or_default())
                    .copied()
                    .collect();
                cam.set_item("depth", PyArray1::from_vec(py, all).reshape([n, h, w, 1])?)?;
            } else if first.depth.is_some() {
                let all: Vec<f32> = imgs()
                    .flat_map(|c| c.depth.unwrap_or_default())
                    .copied()
                    .collect();
                cam.set_item("depth", PyArray1::from_vec(py, all).reshape([n, h, w, 1])?)?;
            }
            if first.segmentation.is_some() {
                let all: Vec<i16> = imgs()
                    .flat_map(|c| c.segmentation.unwrap_or_default())
                    .copied()
                    .collect();
                let a = PyArray1::from_vec(py, all).reshape([n, h, w, 1])?;
                cam.set_item("segmentation", a)?;
            }
            d.set_item(*name, cam)?;
        }
        Ok(d)
    }

    /// ManiSkill's fused point clouds of the last reset/step (obs mode `pointcloud`; else
    /// `None`): `{"xyzw": N×P×4 float32, "rgb": N×P×3 uint8, "segmentation": N×P×1 int16}`.
    fn point_cloud<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let g = self.lock(py)?;
        let vec = &g.vec;
        if vec.point_cloud(0).is_none() {
            return Ok(None);
        }
        let clouds = (0..self.num_envs).filter_map(|i| vec.point_cloud(i));
        point_cloud_dict(py, clouds, false).map(Some)
    }
}

/// Writes a recording of the given episodes to `path`, re-simulating each from its seed and
/// actions (`actions[k]` is episode k's `[steps × A]` array) in one env, the way `mjskill
/// rollout` records. Returns each episode's `(return, success)`. The file is written under a
/// temporary name and renamed into place only when complete, so a failure leaves nothing.
#[pyfunction]
#[pyo3(signature = (path, env_id, seeds, actions, **kwargs))]
fn record_episodes(
    py: Python<'_>,
    path: PathBuf,
    env_id: &str,
    seeds: Vec<Bound<'_, PyAny>>,
    actions: Vec<PyReadonlyArray2<'_, f32>>,
    kwargs: Option<&Bound<'_, PyDict>>,
) -> PyResult<Vec<(f64, bool)>> {
    let seeds = seeds
        .iter()
        .enumerate()
        .map(|(k, s)| {
            let name = format!("seeds[{k}]");
            seed_arg(Some(s), &name)?.ok_or_else(|| type_error(s, &name, "an int"))
        })
        .collect::<PyResult<Vec<u64>>>()?;
    if seeds.len() != actions.len() {
        return Err(PyValueError::new_err(format!(
            "{} seeds but {} action arrays: give one [steps × action_dim] array per seed",
            seeds.len(),
            actions.len()
        )));
    }
    let cfg = config(kwargs, "record_episodes")?;
    let episodes: Vec<Vec<f32>> = actions
        .iter()
        .map(|a| a.as_array().iter().copied().collect())
        .collect();
    let dims: Vec<usize> = actions.iter().map(|a| a.as_array().shape()[1]).collect();
    py.detach(|| write_recording(&path, env_id, cfg, &seeds, &episodes, &dims))
        .map_err(PyValueError::new_err)
}

/// [`record_episodes`] without the GIL: temp file, record, rename.
fn write_recording(
    path: &Path,
    env_id: &str,
    cfg: EnvConfig,
    seeds: &[u64],
    episodes: &[Vec<f32>],
    dims: &[usize],
) -> Result<Vec<(f64, bool)>, String> {
    let mut env = mjskill::make(env_id, cfg).map_err(|e| e.to_string())?;
    let adim = env.action_space().shape[0];
    if let Some(d) = dims.iter().find(|d| **d != adim) {
        return Err(format!(
            "action arrays have {d} columns, but {} expects {adim}",
            env.control_mode()
        ));
    }
    let name = path
        .file_name()
        .ok_or_else(|| format!("{}: not a file name", path.display()))?;
    let tmp = path.with_file_name(format!(".{}.tmp", name.to_string_lossy()));
    let mut rec = Recorder::create(&tmp, &env).map_err(|e| e.to_string())?;
    let result = (|| {
        let mut out = Vec::with_capacity(seeds.len());
        for (seed, acts) in seeds.iter().zip(episodes) {
            env.try_reset(Some(*seed)).map_err(|e| e.to_string())?;
            rec.begin_episode(&env, Some(*seed))
                .map_err(|e| e.to_string())?;
            let (mut ret, mut success) = (0.0f64, false);
            for a in acts.chunks_exact(adim) {
                let before = env.get_state();
                let (r, term, trunc) = {
                    let s = env.step(a).map_err(|e| e.to_string())?;
                    (s.reward, s.terminated, s.truncated)
                };
                rec.record_step(&env, a, r, term, trunc, &before)
                    .map_err(|e| e.to_string())?;
                ret += r as f64;
                success |= term;
            }
            rec.end_episode(success).map_err(|e| e.to_string())?;
            out.push((ret, success));
        }
        Ok::<_, String>(out)
    })();
    match result {
        Ok(out) => {
            rec.finish().map_err(|e| e.to_string())?;
            std::fs::rename(&tmp, path)
                .map_err(|e| format!("cannot move {} to {}: {e}", tmp.display(), path.display()))?;
            Ok(out)
        }
        Err(e) => {
            let _ = rec.abandon();
            let _ = std::fs::remove_file(&tmp);
            Err(e)
        }
    }
}

/// Every registered env: `[(env_id, [robot, ...], max_episode_steps)]`, default robot first.
#[pyfunction]
fn registry() -> Vec<(&'static str, Vec<&'static str>, u32)> {
    mjskill::registry()
        .into_iter()
        .map(|e| {
            (
                e.id,
                e.robots.iter().map(|(r, _)| *r).collect(),
                e.max_episode_steps,
            )
        })
        .collect()
}

/// Control modes of a robot (default first).
#[pyfunction]
fn control_modes(env_id: &str, robot_uids: &str) -> PyResult<Vec<&'static str>> {
    let info = mjskill::registry()
        .into_iter()
        .find(|e| e.id == env_id)
        .ok_or_else(|| {
            value_err(EnvError::UnknownEnv(
                env_id.into(),
                mjskill::registry()
                    .iter()
                    .map(|e| e.id)
                    .collect::<Vec<_>>()
                    .join(", "),
            ))
        })?;
    let valid = info
        .robots
        .iter()
        .map(|(r, _)| *r)
        .collect::<Vec<_>>()
        .join(", ");
    info.robots
        .into_iter()
        .find(|(r, _)| *r == robot_uids)
        .map(|(_, modes)| modes)
        .ok_or_else(|| {
            value_err(EnvError::UnsupportedRobot {
                env: env_id.into(),
                robot: robot_uids.into(),
                valid,
            })
        })
}

/// Checks a seed argument for the Python classes: `None` or an int in `0..=MAX_SEED`
/// (returned as a Python int), else the `ValueError` or `TypeError` the native classes raise.
#[pyfunction]
#[pyo3(signature = (seed, name="seed"))]
fn check_seed(seed: &Bound<'_, PyAny>, name: &str) -> PyResult<Option<u64>> {
    seed_arg(Some(seed), name)
}

/// Checks a count argument for the Python classes (`num_envs`, `num_threads`): an int in
/// `1..=MAX_NUM_ENVS`, else the `ValueError` or `TypeError` the native `VecEnv` raises.
#[pyfunction]
fn check_count(value: &Bound<'_, PyAny>, name: &str) -> PyResult<usize> {
    count_arg(value, name)
}

/// The `mjskill._native` module.
/// The pairs with a state expert (`Env.expert_action`): `[(env_id, robot, its own mode)]`.
#[pyfunction]
fn state_experts() -> Vec<(&'static str, &'static str, &'static str)> {
    mjskill::solvers::STATE_EXPERTS.to_vec()
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyEnv>()?;
    m.add_class::<PyVecEnv>()?;
    m.add_class::<rollout::PyGaussianMlp>()?;
    m.add_function(wrap_pyfunction!(rollout::rollout, m)?)?;
    m.add_function(wrap_pyfunction!(record_episodes, m)?)?;
    m.add_function(wrap_pyfunction!(registry, m)?)?;
    m.add_function(wrap_pyfunction!(control_modes, m)?)?;
    m.add_function(wrap_pyfunction!(state_experts, m)?)?;
    m.add_function(wrap_pyfunction!(check_seed, m)?)?;
    m.add_function(wrap_pyfunction!(check_count, m)?)?;
    m.add("ENV_KWARGS", env_kwargs_defaults(m.py())?)?;
    m.add("MAX_SEED", mjskill::MAX_SEED)?;
    m.add("CONTROL_FREQ", mjskill::CONTROL_FREQ)?;
    m.add("UNLIMITED_EPISODE_STEPS", UNLIMITED_EPISODE_STEPS)?;
    m.add_function(wrap_pyfunction!(policy::check_policy_file, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("MAX_NUM_ENVS", mjskill::MAX_NUM_ENVS)?;
    Ok(())
}
