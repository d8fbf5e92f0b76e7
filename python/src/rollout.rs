//! Rollouts with the policy evaluated in the vector env's threads: `GaussianMlp` (PPO's
//! actor, [`mjskill::solvers::GaussianMlp`]) and `rollout`, which runs T steps of a `VecEnv`
//! with it in one call and writes into the caller's numpy buffers.

use std::sync::Arc;

use mjskill::solvers::GaussianMlp;
use mjskill::RolloutBuffers;
use numpy::{PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadwriteArrayDyn};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use super::{value_err, PyVecEnv, VecState};

/// PPO's actor for [`rollout`]: dense layers (`(weights [in × out] float32, bias [out]
/// float32)`, tanh between them) on observations normalised as `clip((obs − obs_mean) /
/// obs_std, ±obs_clip)`; with `std`, actions are sampled as `mean + std · ε`, ε from a
/// random stream keyed by `seed`, the env's global index (`env_offset` + its index) and the
/// step.
#[pyclass(module = "mjskill._native", name = "GaussianMlp", frozen)]
pub(crate) struct PyGaussianMlp {
    policy: Arc<GaussianMlp>,
}

fn vector(a: &PyReadonlyArray1<'_, f64>) -> Vec<f64> {
    a.as_array().iter().copied().collect()
}

#[pymethods]
impl PyGaussianMlp {
    #[new]
    #[pyo3(signature = (layers, obs_mean, obs_std, obs_clip=None, std=None, seed=0, env_offset=0))]
    fn new(
        layers: Vec<(PyReadonlyArray2<'_, f32>, PyReadonlyArray1<'_, f32>)>,
        obs_mean: PyReadonlyArray1<'_, f64>,
        obs_std: PyReadonlyArray1<'_, f64>,
        obs_clip: Option<f64>,
        std: Option<PyReadonlyArray1<'_, f32>>,
        seed: u64,
        env_offset: u64,
    ) -> PyResult<Self> {
        let layers = layers
            .iter()
            .map(|(w, b)| {
                let w: Vec<f32> = w.as_array().iter().copied().collect();
                (w, b.as_array().to_vec())
            })
            .collect();
        let mlp = GaussianMlp::new(layers, vector(&obs_mean), vector(&obs_std), obs_clip);
        let mlp = match std {
            None => mlp,
            Some(s) => mlp.and_then(|m| m.with_noise(s.as_array().to_vec(), seed, env_offset)),
        }
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok(PyGaussianMlp {
            policy: Arc::new(mlp),
        })
    }

    /// Mean actions `[k × act_dim]` of observations `[k × obs_dim]`.
    fn mean<'py>(
        &self,
        py: Python<'py>,
        obs: PyReadonlyArray2<'py, f32>,
    ) -> PyResult<Bound<'py, numpy::PyArray2<f32>>> {
        let (rows, cols) = obs.as_array().dim();
        if cols != self.policy.obs_dim() {
            return Err(PyValueError::new_err(format!(
                "observations have {cols} columns, the policy takes {}",
                self.policy.obs_dim()
            )));
        }
        let x: Vec<f32> = obs.as_array().iter().copied().collect();
        let mut out = vec![0.0; rows * self.policy.act_dim()];
        let mut scratch = Vec::new();
        py.detach(|| self.policy.mean(&x, &mut out, &mut scratch));
        numpy::PyArray1::from_vec(py, out).reshape([rows, self.policy.act_dim()])
    }
}

/// Runs T steps of `vec_env` with `policy` evaluated on its threads (`VecEnv::rollout`): the
/// buffers (`obs` `[T, N, obs_dim]` float32, `actions` `[T, N, act_dim]` float32, `rewards`
/// `[T, N]` float32, `terminated`, `truncated`, `autoreset` `[T, N]` bool, all C-contiguous
/// and writable) receive each step's observation before the step, raw action, reward and
/// flags; step t is the policy's step `first_step + t`. Returns `(T, obs [N, obs_dim])`, the
/// observations after the last step.
#[pyfunction]
#[pyo3(signature = (vec_env, policy, first_step, obs, actions, rewards, terminated, truncated, autoreset))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn rollout<'py>(
    py: Python<'py>,
    vec_env: &PyVecEnv,
    policy: &PyGaussianMlp,
    first_step: u64,
    mut obs: PyReadwriteArrayDyn<'_, f32>,
    mut actions: PyReadwriteArrayDyn<'_, f32>,
    mut rewards: PyReadwriteArrayDyn<'_, f32>,
    mut terminated: PyReadwriteArrayDyn<'_, bool>,
    mut truncated: PyReadwriteArrayDyn<'_, bool>,
    mut autoreset: PyReadwriteArrayDyn<'_, bool>,
) -> PyResult<(usize, Bound<'py, PyAny>)> {
    fn slice<'a, T: numpy::Element>(
        a: &'a mut PyReadwriteArrayDyn<'_, T>,
        name: &str,
    ) -> PyResult<&'a mut [T]> {
        a.as_slice_mut().map_err(|_| {
            PyValueError::new_err(format!("rollout buffer {name} must be C-contiguous"))
        })
    }
    let (od, ad) = (policy.policy.obs_dim(), policy.policy.act_dim());
    let mut g = vec_env.lock(py)?;
    let VecState { vec, .. } = &mut *g;
    let (vd, va) = (
        vec.single_observation_space()
            .shape
            .iter()
            .product::<usize>(),
        vec.single_action_space().shape[0],
    );
    if (od, ad) != (vd, va) {
        return Err(PyValueError::new_err(format!(
            "the policy maps {od} observations to {ad} actions, but the envs have {vd} and {va}"
        )));
    }
    let out = RolloutBuffers {
        obs: slice(&mut obs, "obs")?,
        actions: slice(&mut actions, "actions")?,
        rewards: slice(&mut rewards, "rewards")?,
        terminated: slice(&mut terminated, "terminated")?,
        truncated: slice(&mut truncated, "truncated")?,
        autoreset: slice(&mut autoreset, "autoreset")?,
    };
    let p = policy.policy.clone();
    let steps = py
        .detach(|| vec.rollout(p, first_step, out))
        .map_err(value_err)?;
    Ok((steps, vec_env.obs(py, vec)?))
}
