//! `check_policy_file`: the policy-file checks of `mjskill eval --policy`, for Python's
//! `mjskill.policy.OnnxPolicy`, so that a file is accepted or refused by the same rules in
//! both languages (docs/training.md).
use std::path::PathBuf;
use std::sync::Arc;

use mjskill::solvers::{PolicyFile, PolicySpec};
use mjskill::EnvConfig;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// Checks the policy file `path` as `mjskill eval --policy` does (a regular file within the
/// size limit; a valid ONNX graph with one observation input and one action output; its
/// `metadata_props`, each key once, naming an env, robot, control mode and state obs mode
/// mjskill has; declared tensor sizes within the limit; the graph, fitted to that env's
/// observation size, giving f32 actions of the env's action size when run on zeros, with the
/// runtime's crashes caught) and returns its `metadata_props` as `[(key, value)]`. Errors are
/// `ValueError`s naming the file.
#[pyfunction]
pub fn check_policy_file(py: Python<'_>, path: PathBuf) -> PyResult<Vec<(String, String)>> {
    py.detach(|| {
        let file = Arc::new(PolicyFile::load(&path)?);
        let spec = PolicySpec::File(file.clone());
        let (env_id, config) = spec.target(None, EnvConfig::default(), false)?;
        let env = spec.make_env(&env_id, config)?;
        spec.make_policy(&env, 0)?;
        Ok(file.meta().props.clone())
    })
    .map_err(|e: mjskill::solvers::EvalError| PyValueError::new_err(e.to_string()))
}
