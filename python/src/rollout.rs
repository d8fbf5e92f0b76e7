//! Rollouts with the policy evaluated in the vector env's threads: `GaussianMlp` (PPO's
//! actor, [`mjskill::solvers::GaussianMlp`]) and `rollout`, which runs T steps of a `VecEnv`
//! with it in one call and writes into the caller's numpy buffers.
//!
//! Every array is checked before anything is copied or stepped (docs/limits.md, "Arrays given
//! to native rollouts"): its type and dtype (`TypeError`), its exact shape, C order, size
//! limit, writability and, for the rollout buffers, that no two of them share memory
//! (`ValueError`s naming the array and what fits). Two overlapping buffers would be two
//! overlapping `&mut` slices in Rust, which is undefined behaviour; numpy's own borrow
//! tracking misses views of one Python buffer (`np.frombuffer` of one `bytearray`), so the
//! memory ranges are compared here.

use std::sync::Arc;

use mjskill::solvers::{set_state_experts, GaussianMlp, MAX_LAYER_ELEMENTS};
use mjskill::{RolloutBuffers, MAX_POLICY_STEP};
use numpy::{
    BorrowError, Element, PyArrayDescrMethods, PyArrayDyn, PyArrayMethods, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;

use super::args::int_arg;
use super::{value_err, PyVecEnv, VecState};

/// Most values `GaussianMlp.mean` takes or returns in one call (2^26 float32s, 256 MiB):
/// observations `rows × obs_dim` and actions `rows × act_dim` must each stay within it.
pub(crate) const MAX_MEAN_VALUES: usize = 1 << 26;

/// PPO's actor for [`rollout`]: dense layers (`(weights [in × out] float32, bias [out]
/// float32)`, tanh between them) on observations normalised as `clip((obs − obs_mean) /
/// obs_std, ±obs_clip)`; with `std`, actions are sampled as `mean + std · ε`, ε from a
/// random stream keyed by `seed`, the env's global index (`env_offset` + its index) and the
/// step.
#[pyclass(module = "mjskill._native", name = "GaussianMlp", frozen)]
pub(crate) struct PyGaussianMlp {
    policy: Arc<GaussianMlp>,
}

/// `a` as a numpy array of element type `T` and `ndim` dimensions, or a `TypeError` naming
/// `what`, the type or dtype it has and the one it needs.
fn typed<'py, T: Element>(
    a: &Bound<'py, PyAny>,
    what: &str,
    ndim: usize,
    dtype: &str,
) -> PyResult<Bound<'py, PyArrayDyn<T>>> {
    let Ok(u) = a.cast::<PyUntypedArray>() else {
        let ty = a
            .get_type()
            .name()
            .map(|n| n.to_string())
            .unwrap_or_else(|_| "object".into());
        return Err(PyTypeError::new_err(format!(
            "{what} must be a numpy array of {dtype}, not {ty}"
        )));
    };
    if !u.dtype().is_equiv_to(&numpy::dtype::<T>(a.py())) {
        return Err(PyTypeError::new_err(format!(
            "{what} has dtype {}, expected {dtype} (convert it with .astype(np.{dtype}))",
            u.dtype()
        )));
    }
    if u.ndim() != ndim {
        return Err(PyValueError::new_err(format!(
            "{what} has shape {:?}, expected {ndim} dimensions",
            u.shape()
        )));
    }
    Ok(a.cast::<PyArrayDyn<T>>()?.clone())
}

/// The product of `shape`, or None beyond `usize`.
fn elements(shape: &[usize]) -> Option<usize> {
    shape.iter().try_fold(1usize, |n, &d| n.checked_mul(d))
}

/// `a`'s values, copied (after the shape and size checks, so a huge broadcast view is
/// refused before anything is allocated).
fn values<T: Element + Copy>(a: &Bound<'_, PyArrayDyn<T>>, what: &str) -> PyResult<Vec<T>> {
    let r = a
        .try_readonly()
        .map_err(|e| PyValueError::new_err(format!("{what}: {e}")))?;
    Ok(match r.as_slice() {
        Ok(s) if a.is_c_contiguous() => s.to_vec(),
        _ => r.as_array().iter().copied().collect(),
    })
}

fn vector<T: Element + Copy>(a: &Bound<'_, PyAny>, what: &str, dtype: &str) -> PyResult<Vec<T>> {
    let a = typed::<T>(a, what, 1, dtype)?;
    let n = a.shape()[0];
    if n > MAX_LAYER_ELEMENTS {
        return Err(PyValueError::new_err(format!(
            "{what} has {n} values, more than the {MAX_LAYER_ELEMENTS} a policy vector may have"
        )));
    }
    values(&a, what)
}

#[pymethods]
impl PyGaussianMlp {
    #[new]
    #[pyo3(signature = (layers, obs_mean, obs_std, obs_clip=None, std=None, seed=0, env_offset=0))]
    fn new(
        layers: Vec<(Bound<'_, PyAny>, Bound<'_, PyAny>)>,
        obs_mean: &Bound<'_, PyAny>,
        obs_std: &Bound<'_, PyAny>,
        obs_clip: Option<f64>,
        std: Option<&Bound<'_, PyAny>>,
        seed: u64,
        env_offset: u64,
    ) -> PyResult<Self> {
        let obs_mean: Vec<f64> = vector(obs_mean, "obs_mean", "float64")?;
        let obs_std: Vec<f64> = vector(obs_std, "obs_std", "float64")?;
        let mut inputs = obs_mean.len();
        let mut dense = Vec::with_capacity(layers.len());
        for (k, (w, b)) in layers.iter().enumerate() {
            let b: Vec<f32> = vector(b, &format!("layers[{k}] bias"), "float32")?;
            let what = format!("layers[{k}] weights");
            let w = typed::<f32>(w, &what, 2, "float32")?;
            let shape = w.shape().to_vec();
            if shape != [inputs, b.len()] {
                let torch = if shape == [b.len(), inputs] {
                    " (this is torch's (out, in) layout: pass weight.T)"
                } else {
                    ""
                };
                return Err(PyValueError::new_err(format!(
                    "{what} have shape ({}, {}), expected (inputs, outputs) = ({inputs}, {}): \
                     the layer takes {inputs} inputs (the observation size or the previous \
                     layer's outputs) and has {} biases{torch}",
                    shape[0],
                    shape[1],
                    b.len(),
                    b.len()
                )));
            }
            if elements(&shape).is_none_or(|n| n > MAX_LAYER_ELEMENTS) {
                return Err(PyValueError::new_err(format!(
                    "{what} have shape ({}, {}), more than the {MAX_LAYER_ELEMENTS} values a \
                     layer may have",
                    shape[0], shape[1]
                )));
            }
            dense.push((values(&w, &what)?, b));
            inputs = shape[1];
        }
        let mlp = GaussianMlp::new(dense, obs_mean, obs_std, obs_clip);
        let mlp = match std {
            None => mlp,
            Some(s) => {
                let s = vector(s, "std", "float32")?;
                mlp.and_then(|m| m.with_noise(s, seed, env_offset))
            }
        }
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok(PyGaussianMlp {
            policy: Arc::new(mlp),
        })
    }

    /// Mean actions `[k × act_dim]` of observations `[k × obs_dim]` (float32; at most
    /// `MAX_MEAN_VALUES` values in and out).
    fn mean<'py>(
        &self,
        py: Python<'py>,
        obs: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, numpy::PyArray2<f32>>> {
        let obs = typed::<f32>(obs, "observations", 2, "float32")?;
        let (rows, cols) = (obs.shape()[0], obs.shape()[1]);
        let (od, ad) = (self.policy.obs_dim(), self.policy.act_dim());
        if cols != od {
            return Err(PyValueError::new_err(format!(
                "observations have {cols} columns, the policy takes {od}"
            )));
        }
        if rows.saturating_mul(od.max(ad)) > MAX_MEAN_VALUES {
            return Err(PyValueError::new_err(format!(
                "observations have {rows} rows: with {od} observations and {ad} actions per row \
                 that is more than the {MAX_MEAN_VALUES} values one call takes; split them"
            )));
        }
        let x = values(&obs, "observations")?;
        let mut out = vec![0.0; rows * ad];
        let mut scratch = Vec::new();
        py.detach(|| self.policy.mean(&x, &mut out, &mut scratch));
        numpy::PyArray1::from_vec(py, out).reshape([rows, ad])
    }
}

/// One rollout buffer, checked: its name, the array and its byte range.
struct Checked<'py, T: Element> {
    name: &'static str,
    array: Bound<'py, PyArrayDyn<T>>,
}

impl<'py, T: Element> Checked<'py, T> {
    /// `a` as rollout buffer `name` of exactly `shape`, C-contiguous and writable.
    fn new(
        a: &Bound<'py, PyAny>,
        name: &'static str,
        shape: &[usize],
        dtype: &str,
    ) -> PyResult<Self> {
        let what = format!("rollout buffer {name}");
        let array = typed::<T>(a, &what, shape.len(), dtype)?;
        if array.shape() != shape {
            return Err(PyValueError::new_err(format!(
                "{what} has shape {:?}, expected {shape:?} ([T steps, num_envs{}]; \
                 rollout_buffers(T) makes them)",
                array.shape(),
                match name {
                    "obs" => ", obs_dim",
                    "actions" => ", act_dim",
                    _ => "",
                }
            )));
        }
        if !array.is_c_contiguous() {
            return Err(PyValueError::new_err(format!(
                "{what} must be C-contiguous (row-major, as rollout_buffers(T) makes them); a \
                 Fortran-ordered array or a strided view is refused: use \
                 np.ascontiguousarray"
            )));
        }
        if !array
            .getattr("flags")?
            .getattr("writeable")?
            .extract::<bool>()?
        {
            return Err(PyValueError::new_err(format!(
                "{what} is read-only: the rollout writes into it (use a writable array, e.g. \
                 from rollout_buffers(T))"
            )));
        }
        Ok(Checked { name, array })
    }

    /// The bytes the buffer occupies (empty for no elements).
    fn range(&self) -> std::ops::Range<usize> {
        let start = self.array.data() as usize;
        start..start + self.array.len() * std::mem::size_of::<T>()
    }

    /// Borrows it for writing; numpy's borrow tracking may still see a conflict.
    fn borrow(&self) -> PyResult<numpy::PyReadwriteArrayDyn<'py, T>> {
        self.array.try_readwrite().map_err(|e| {
            PyValueError::new_err(match e {
                BorrowError::NotWriteable => format!("rollout buffer {} is read-only", self.name),
                _ => format!(
                    "rollout buffer {} shares memory with another buffer in use (another \
                     rollout buffer, or an array borrowed elsewhere): each buffer needs its \
                     own memory",
                    self.name
                ),
            })
        })
    }
}

/// Runs T steps of `vec_env` with `policy` evaluated on its threads (`VecEnv::rollout`): the
/// buffers (`obs` `[T, N, obs_dim]` float32, `actions` `[T, N, act_dim]` float32, `rewards`
/// `[T, N]` float32, `terminated`, `truncated`, `autoreset` `[T, N]` bool; exactly these
/// shapes, C-contiguous, writable and each in its own memory) receive each step's observation
/// before the step, raw action, reward and flags; step t is the policy's step `first_step +
/// t`, and `first_step + T` is at most 2^48. Returns `(T, obs [N, obs_dim])`, the
/// observations after the last step. With `labels` (`[T, N, act_dim]` float32, as the others),
/// every env's state expert labels the state each action was chosen from
/// (`solvers::set_state_experts`, installed on first use; a pair without one is a
/// `ValueError` naming it).
#[pyfunction]
#[pyo3(signature = (vec_env, policy, first_step, obs, actions, rewards, terminated, truncated, autoreset, labels=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn rollout<'py>(
    py: Python<'py>,
    vec_env: &PyVecEnv,
    policy: &PyGaussianMlp,
    first_step: &Bound<'py, PyAny>,
    obs: &Bound<'py, PyAny>,
    actions: &Bound<'py, PyAny>,
    rewards: &Bound<'py, PyAny>,
    terminated: &Bound<'py, PyAny>,
    truncated: &Bound<'py, PyAny>,
    autoreset: &Bound<'py, PyAny>,
    labels: Option<&Bound<'py, PyAny>>,
) -> PyResult<(usize, Bound<'py, PyAny>)> {
    let valid = format!(
        "0..{MAX_POLICY_STEP} (2^48: the step keys the policy's sampling noise, which must not \
         repeat)"
    );
    let first_step = int_arg(
        first_step,
        "first_step",
        0,
        MAX_POLICY_STEP as i128 - 1,
        &valid,
    )? as u64;
    let (od, ad) = (policy.policy.obs_dim(), policy.policy.act_dim());
    let n = vec_env.num_envs;
    let vd = vec_env.obs_dim;
    let va = {
        let g = vec_env.lock(py)?;
        g.vec.single_action_space().shape[0]
    };
    if (od, ad) != (vd, va) {
        return Err(PyValueError::new_err(format!(
            "the policy maps {od} observations to {ad} actions, but the envs have {vd} and {va}"
        )));
    }
    // T comes from the rewards; every other buffer must have exactly its shape.
    let r = typed::<f32>(rewards, "rollout buffer rewards", 2, "float32")?;
    let t = r.shape()[0];
    if t == 0 || r.shape()[1] != n {
        return Err(PyValueError::new_err(format!(
            "rollout buffer rewards has shape {:?}, expected [T, {n}] with T ≥ 1 steps \
             (num_envs {n}; rollout_buffers(T) makes them)",
            r.shape()
        )));
    }
    let obs = Checked::<f32>::new(obs, "obs", &[t, n, od], "float32")?;
    let actions = Checked::<f32>::new(actions, "actions", &[t, n, ad], "float32")?;
    let rewards = Checked::<f32>::new(rewards, "rewards", &[t, n], "float32")?;
    let terminated = Checked::<bool>::new(terminated, "terminated", &[t, n], "bool")?;
    let truncated = Checked::<bool>::new(truncated, "truncated", &[t, n], "bool")?;
    let autoreset = Checked::<bool>::new(autoreset, "autoreset", &[t, n], "bool")?;
    let labels = labels
        .filter(|l| !l.is_none())
        .map(|l| Checked::<f32>::new(l, "labels", &[t, n, ad], "float32"))
        .transpose()?;
    let mut ranges = vec![
        (obs.name, obs.range()),
        (actions.name, actions.range()),
        (rewards.name, rewards.range()),
        (terminated.name, terminated.range()),
        (truncated.name, truncated.range()),
        (autoreset.name, autoreset.range()),
    ];
    if let Some(l) = &labels {
        ranges.push((l.name, l.range()));
    }
    for (i, (a, ra)) in ranges.iter().enumerate() {
        for (b, rb) in &ranges[i + 1..] {
            if ra.start < rb.end && rb.start < ra.end {
                return Err(PyValueError::new_err(format!(
                    "rollout buffers {a} and {b} overlap in memory: each buffer needs its own \
                     memory (rollout_buffers(T) makes them)"
                )));
            }
        }
    }
    let (mut o, mut a, mut re) = (obs.borrow()?, actions.borrow()?, rewards.borrow()?);
    let (mut te, mut tr, mut au) = (
        terminated.borrow()?,
        truncated.borrow()?,
        autoreset.borrow()?,
    );
    let mut la = labels.as_ref().map(|l| l.borrow()).transpose()?;
    // C-contiguous and writable, checked above: the slices cannot fail.
    let slice_err = |_| PyValueError::new_err("a rollout buffer is not contiguous");
    let out = RolloutBuffers {
        obs: o.as_slice_mut().map_err(slice_err)?,
        actions: a.as_slice_mut().map_err(slice_err)?,
        rewards: re.as_slice_mut().map_err(slice_err)?,
        terminated: te.as_slice_mut().map_err(slice_err)?,
        truncated: tr.as_slice_mut().map_err(slice_err)?,
        autoreset: au.as_slice_mut().map_err(slice_err)?,
        labels: la
            .as_mut()
            .map(|l| l.as_slice_mut())
            .transpose()
            .map_err(slice_err)?,
    };
    let mut g = vec_env.lock(py)?;
    let VecState { vec, .. } = &mut *g;
    if out.labels.is_some() && !vec.has_labellers() {
        py.detach(|| set_state_experts(vec))
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
    }
    let p = policy.policy.clone();
    let steps = py
        .detach(|| vec.rollout(p, first_step, out))
        .map_err(value_err)?;
    Ok((steps, vec_env.obs(py, vec)?))
}
