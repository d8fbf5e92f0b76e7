//! Policy files: a trained policy as an ONNX graph (observation in, mean action out), run with
//! the pure-Rust `tract` runtime. Each file describes itself in the ONNX `metadata_props`
//! ([`PolicyMeta`]): the env, robot, control mode and observation mode it was trained on, and
//! the command that trained it. docs/training.md documents the format.
//!
//! [`PolicyFile::load`] reads and checks a file; [`PolicyFile::configure`] takes the env id,
//! robot and modes from its metadata unless the caller chose them (and refuses a mismatch);
//! [`PolicyFile::policy`] checks the graph's input and output sizes against an env and builds
//! an [`OnnxPolicy`], whose every step writes the observation into one reused input tensor,
//! runs the graph and clips the action to the action space's bounds.
use std::path::{Path, PathBuf};
use std::sync::Arc;

use tract_onnx::pb::ModelProto;
use tract_onnx::prelude::*;
use tract_onnx::tract_hir::infer::Factoid;
use tract_onnx::tract_hir::internal::DimLike;

use crate::env::{Env, EnvConfig, ObsMode};
use crate::files::short;
use crate::solvers::onnx_guard::{check_declared, check_typed, guarded};
use crate::solvers::{Policy, SolverError};

pub use crate::solvers::onnx_guard::MAX_TENSOR_ELEMENTS;

/// The `metadata_props` keys every policy file carries.
pub const METADATA_KEYS: [&str; 5] = [
    "env_id",
    "robot_uids",
    "control_mode",
    "obs_mode",
    "training_command",
];

/// Why a policy file could not be loaded or run. Every message names the file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PolicyFileError {
    /// The file could not be read.
    #[error("cannot read policy file {path}: {reason}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        reason: String,
    },
    /// The file is not a usable ONNX model.
    #[error("policy file {path} is not a valid ONNX model: {reason}")]
    Malformed {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// `metadata_props` lacks keys a policy file needs.
    #[error(
        "policy file {path} lacks the metadata_props {missing} (a policy file carries {}; it has: {found})",
        METADATA_KEYS.join(", ")
    )]
    MissingMetadata {
        /// The file.
        path: PathBuf,
        /// The missing keys.
        missing: String,
        /// The keys it has.
        found: String,
    },
    /// The graph's inputs or outputs are not one observation in, one action out.
    #[error("policy file {path}: {reason}")]
    Interface {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The file was trained with another env, robot or mode than requested.
    #[error(
        "policy file {path} was trained with {key} {file:?}, but {requested:?} was requested; \
         leave the option out to use the file's"
    )]
    Mismatch {
        /// The file.
        path: PathBuf,
        /// The metadata key (env_id, robot_uids, control_mode, obs_mode).
        key: &'static str,
        /// The file's value.
        file: String,
        /// The requested value.
        requested: String,
    },
    /// The metadata names an observation mode a policy file cannot take as its one input.
    #[error(
        "policy file {path} has obs_mode {mode:?}; policy files take the flat state vector \
         (obs_mode state or state_dict)"
    )]
    ObsMode {
        /// The file.
        path: PathBuf,
        /// The file's obs mode.
        mode: String,
    },
    /// The graph's input size is not the env's observation size.
    #[error(
        "policy file {path} takes observations of {policy} values, but {env} gives {env_obs} \
         (obs_mode {obs_mode})"
    )]
    InputSize {
        /// The file.
        path: PathBuf,
        /// The graph's input size.
        policy: usize,
        /// The env id.
        env: String,
        /// The env's observation size.
        env_obs: usize,
        /// The env's obs mode.
        obs_mode: String,
    },
    /// The graph's output size is not the env's action size.
    #[error(
        "policy file {path} outputs actions of {policy} values, but {robot} in control mode \
         {control_mode} takes {env_act}"
    )]
    OutputSize {
        /// The file.
        path: PathBuf,
        /// The graph's output size.
        policy: usize,
        /// The robot.
        robot: String,
        /// The control mode.
        control_mode: String,
        /// The env's action size.
        env_act: usize,
    },
    /// The env, robot or mode the metadata names cannot be built.
    #[error("policy file {path}: {reason}")]
    Env {
        /// The file.
        path: PathBuf,
        /// The env's error.
        reason: String,
    },
    /// The runtime failed to run the graph.
    #[error("policy file {path} failed to run: {reason}")]
    Runtime {
        /// The file.
        path: PathBuf,
        /// The runtime's error.
        reason: String,
    },
}

/// What a policy file says about itself (ONNX `metadata_props`).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct PolicyMeta {
    /// The env id it was trained on (e.g. `PickCube-v1`).
    pub env_id: String,
    /// The robot uid (ManiSkill's `robot_uids`).
    pub robot_uids: String,
    /// The control mode.
    pub control_mode: String,
    /// The observation mode (`state`).
    pub obs_mode: String,
    /// The command that trained it.
    pub training_command: String,
    /// Every `metadata_props` entry, in file order (the keys above included).
    pub props: Vec<(String, String)>,
}

/// A loaded, checked policy file (not yet fitted to an env: [`PolicyFile::policy`]).
pub struct PolicyFile {
    path: PathBuf,
    meta: PolicyMeta,
    obs_mode: ObsMode,
    model: InferenceModel,
}

impl std::fmt::Debug for PolicyFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PolicyFile")
            .field("path", &self.path)
            .field("meta", &self.meta)
            .finish_non_exhaustive()
    }
}

/// Formats a runtime error with its causes.
fn chain(e: &TractError) -> String {
    format!("{e:#}")
}

/// The first `metadata_props` key that appears more than once (runtimes would take either
/// value: tract the first, onnxruntime the last).
fn duplicate_key(props: &[(String, String)]) -> Option<&str> {
    let mut seen = std::collections::HashSet::new();
    props
        .iter()
        .map(|(k, _)| k.as_str())
        .find(|k| !seen.insert(*k))
}

impl PolicyFile {
    /// Reads `path`: an ONNX model with one input (the observation) and one output (the
    /// action), and the [`METADATA_KEYS`] in its `metadata_props`.
    pub fn load(path: impl AsRef<Path>) -> Result<PolicyFile, PolicyFileError> {
        let path = path.as_ref().to_path_buf();
        let bytes = crate::files::read(&path).map_err(|e| PolicyFileError::Read {
            path: path.clone(),
            reason: e.reason(),
        })?;
        let malformed = |reason: String| PolicyFileError::Malformed {
            path: path.clone(),
            reason,
        };
        let onnx = tract_onnx::onnx();
        let proto: ModelProto =
            guarded(|| onnx.proto_model_for_read(&mut bytes.as_slice())).map_err(malformed)?;
        let Some(graph) = &proto.graph else {
            return Err(malformed("it has no graph".into()));
        };
        let props: Vec<(String, String)> = proto
            .metadata_props
            .iter()
            .map(|p| (p.key.clone(), p.value.clone()))
            .collect();
        if let Some(k) = duplicate_key(&props) {
            return Err(malformed(format!(
                "its metadata_props has the key {:?} more than once; each key may appear once",
                short(k)
            )));
        }
        check_declared(graph).map_err(malformed)?;
        let get = |k: &str| {
            props
                .iter()
                .find(|(key, _)| key == k)
                .map(|(_, v)| v.clone())
        };
        let missing: Vec<&str> = METADATA_KEYS
            .iter()
            .copied()
            .filter(|k| get(k).is_none())
            .collect();
        if !missing.is_empty() {
            let found: Vec<String> = props.iter().map(|(k, _)| short(k)).collect();
            return Err(PolicyFileError::MissingMetadata {
                path,
                missing: missing.join(", "),
                found: if found.is_empty() {
                    "none".into()
                } else {
                    found.join(", ")
                },
            });
        }
        let meta = PolicyMeta {
            env_id: get("env_id").unwrap_or_default(),
            robot_uids: get("robot_uids").unwrap_or_default(),
            control_mode: get("control_mode").unwrap_or_default(),
            obs_mode: get("obs_mode").unwrap_or_default(),
            training_command: get("training_command").unwrap_or_default(),
            props,
        };
        let obs_mode = match ObsMode::parse(&meta.obs_mode) {
            Ok(m @ (ObsMode::State | ObsMode::StateDict)) => m,
            _ => {
                return Err(PolicyFileError::ObsMode {
                    path,
                    mode: short(&meta.obs_mode),
                })
            }
        };
        let model = guarded(|| onnx.model_for_proto_model(&proto)).map_err(malformed)?;
        let (inputs, outputs) = (model.inputs.len(), model.outputs.len());
        if inputs != 1 || outputs != 1 {
            return Err(PolicyFileError::Interface {
                path,
                reason: format!(
                    "the graph has {inputs} inputs and {outputs} outputs; a policy file has one \
                     input (the observation) and one output (the action)"
                ),
            });
        }
        Ok(PolicyFile {
            path,
            meta,
            obs_mode,
            model,
        })
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Its metadata.
    pub fn meta(&self) -> &PolicyMeta {
        &self.meta
    }

    /// The env to run the policy in: the file's env id, robot, control mode and (unless
    /// `obs_mode_given`) obs mode fill what the caller left open (`env` None, `config.robot`
    /// and `config.control_mode` None); a value the caller chose must be the file's (obs modes
    /// `state` and `state_dict`, which give the same vector, are interchangeable). Returns
    /// the env id.
    pub fn configure(
        &self,
        env: Option<&str>,
        config: &mut EnvConfig,
        obs_mode_given: bool,
    ) -> Result<String, PolicyFileError> {
        let m = &self.meta;
        let check = |key: &'static str, file: &str, requested: Option<&str>| match requested {
            Some(r) if r != file => Err(self.mismatch(key, file, r)),
            _ => Ok(()),
        };
        check("env_id", &m.env_id, env)?;
        check("robot_uids", &m.robot_uids, config.robot.as_deref())?;
        check(
            "control_mode",
            &m.control_mode,
            config.control_mode.as_deref(),
        )?;
        if obs_mode_given {
            if !matches!(config.obs_mode, ObsMode::State | ObsMode::StateDict) {
                check("obs_mode", &m.obs_mode, Some(config.obs_mode.name()))?;
            }
        } else {
            config.obs_mode = self.obs_mode;
        }
        config.robot = Some(m.robot_uids.clone());
        config.control_mode = Some(m.control_mode.clone());
        Ok(m.env_id.clone())
    }

    /// Fits the graph to `env` (checked to be the file's env, robot, control mode and a state
    /// obs mode): its input must take the env's observation size and its output give the
    /// action size. The graph is optimised for one observation and run once on zeros, so a
    /// graph the runtime cannot run fails here, not in the middle of an episode.
    pub fn policy(&self, env: &Env) -> Result<OnnxPolicy, PolicyFileError> {
        let mut config = env.config().clone();
        self.configure(Some(env.id()), &mut config, true)?;
        let robot = env.robot_id().uid();
        if robot != self.meta.robot_uids {
            return Err(self.mismatch("robot_uids", &self.meta.robot_uids, robot));
        }
        if env.control_mode() != self.meta.control_mode {
            return Err(self.mismatch("control_mode", &self.meta.control_mode, env.control_mode()));
        }
        let obs_dim = env.obs().len();
        let act_space = env.action_space();
        let act_dim = act_space.shape.iter().product::<usize>();
        let runtime = |e: TractError| PolicyFileError::Runtime {
            path: self.path.clone(),
            reason: chain(&e),
        };
        let interface = |reason: String| PolicyFileError::Interface {
            path: self.path.clone(),
            reason,
        };
        // The input: [batch, obs] (batch 1 here) or [obs], of f32.
        let fact = self.model.input_fact(0).map_err(runtime)?;
        let dims: Vec<Option<usize>> = fact
            .shape
            .dims()
            .map(|d| d.concretize().and_then(|d| d.to_usize().ok()))
            .collect();
        let rank = if fact.shape.is_open() && dims.is_empty() {
            2
        } else {
            dims.len()
        };
        if !(rank == 1 || rank == 2) {
            return Err(interface(format!(
                "its input has rank {rank}; a policy file takes [batch, observation] or \
                 [observation]"
            )));
        }
        if let Some(Some(n)) = dims.get(rank - 1) {
            if *n != obs_dim {
                return Err(PolicyFileError::InputSize {
                    path: self.path.clone(),
                    policy: *n,
                    env: env.id().to_string(),
                    env_obs: obs_dim,
                    obs_mode: env.config().obs_mode.name().to_string(),
                });
            }
        }
        if let Some(dt) = fact.datum_type.concretize() {
            if dt != f32::datum_type() {
                return Err(interface(format!(
                    "its input is of type {dt:?}; a policy file takes f32 observations"
                )));
            }
        }
        let shape: TVec<usize> = if rank == 2 {
            tvec![1, obs_dim]
        } else {
            tvec![obs_dim]
        };
        let mut model = self.model.clone();
        model
            .set_input_fact(0, InferenceFact::dt_shape(f32::datum_type(), shape.clone()))
            .map_err(runtime)?;
        let cannot = |e: String| {
            interface(format!(
                "its graph cannot take one observation of {obs_dim} values ({e})"
            ))
        };
        let typed = guarded(|| model.into_typed()).map_err(cannot)?;
        check_typed(&typed).map_err(interface)?;
        let typed = guarded(|| typed.into_optimized()).map_err(cannot)?;
        check_typed(&typed).map_err(interface)?;
        let out = typed.output_fact(0).map_err(runtime)?;
        let out_shape: Option<Vec<usize>> = out.shape.as_concrete().map(|s| s.to_vec());
        let out_dim = match out_shape.as_deref() {
            Some([n]) | Some([1, n]) => *n,
            other => {
                return Err(interface(format!(
                    "its output has shape {other:?} for one observation; a policy file outputs \
                     [1, action] or [action]"
                )))
            }
        };
        if out.datum_type != f32::datum_type() {
            return Err(interface(format!(
                "its output is of type {:?}; a policy file outputs f32 actions",
                out.datum_type
            )));
        }
        if out_dim != act_dim {
            return Err(PolicyFileError::OutputSize {
                path: self.path.clone(),
                policy: out_dim,
                robot: robot.to_string(),
                control_mode: env.control_mode().to_string(),
                env_act: act_dim,
            });
        }
        let failed = |reason: String| PolicyFileError::Runtime {
            path: self.path.clone(),
            reason,
        };
        let plan = guarded(|| typed.into_runnable()).map_err(failed)?;
        let state = guarded(|| TypedSimpleState::new(&plan)).map_err(failed)?;
        let input = Arc::new(Tensor::zero::<f32>(&shape).map_err(runtime)?);
        let mut policy = OnnxPolicy {
            path: self.path.clone(),
            state,
            input,
            low: act_space.low.clone(),
            high: act_space.high.clone(),
            failure: None,
        };
        let mut action = vec![0.0f32; act_dim];
        policy.run(&vec![0.0; obs_dim], &mut action)?;
        Ok(policy)
    }

    fn mismatch(&self, key: &'static str, file: &str, requested: &str) -> PolicyFileError {
        PolicyFileError::Mismatch {
            path: self.path.clone(),
            key,
            file: short(file),
            requested: short(requested),
        }
    }
}

/// A policy file fitted to an env ([`PolicyFile::policy`]): the observation in, the graph's
/// output (the mean action) clipped to the action space's bounds out. Deterministic: the same
/// observation gives the same action. The input tensor is allocated once and reused; the
/// runtime allocates its intermediate values.
pub struct OnnxPolicy {
    path: PathBuf,
    state: TypedSimpleState,
    input: Arc<Tensor>,
    low: Vec<f32>,
    high: Vec<f32>,
    /// The first runtime failure of [`Policy::act`] (which cannot return it).
    failure: Option<PolicyFileError>,
}

impl std::fmt::Debug for OnnxPolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OnnxPolicy")
            .field("path", &self.path)
            .finish_non_exhaustive()
    }
}

impl OnnxPolicy {
    /// Runs the graph on `obs` and writes the clipped action into `action`.
    pub fn run(&mut self, obs: &[f32], action: &mut [f32]) -> Result<(), PolicyFileError> {
        let runtime = |e: TractError| PolicyFileError::Runtime {
            path: self.path.clone(),
            reason: chain(&e),
        };
        // Reuse the input tensor: the state drops its reference at the end of every run, so
        // it is unique again here (a fresh one is made should it not be).
        if Arc::get_mut(&mut self.input).is_none() {
            let shape: TVec<usize> = self.input.shape().into();
            self.input = Arc::new(Tensor::zero::<f32>(&shape).map_err(runtime)?);
        }
        {
            let input = Arc::get_mut(&mut self.input).ok_or_else(|| PolicyFileError::Runtime {
                path: self.path.clone(),
                reason: "the input tensor is still in use".into(),
            })?;
            let mut view = input.try_as_plain_ram_mut().map_err(runtime)?;
            let buf = view.as_slice_mut::<f32>().map_err(runtime)?;
            if buf.len() != obs.len() {
                return Err(PolicyFileError::InputSize {
                    path: self.path.clone(),
                    policy: buf.len(),
                    env: "the env".into(),
                    env_obs: obs.len(),
                    obs_mode: "state".into(),
                });
            }
            buf.copy_from_slice(obs);
        }
        let input = self.input.clone().into_tvalue();
        let state = &mut self.state;
        let outputs =
            guarded(|| state.run(tvec![input])).map_err(|reason| PolicyFileError::Runtime {
                path: self.path.clone(),
                reason,
            })?;
        let view = outputs[0].try_as_plain_ram().map_err(runtime)?;
        let out = view.as_slice::<f32>().map_err(runtime)?;
        if out.len() != action.len() {
            return Err(PolicyFileError::OutputSize {
                path: self.path.clone(),
                policy: out.len(),
                robot: "the robot".into(),
                control_mode: "its control mode".into(),
                env_act: action.len(),
            });
        }
        for (((a, &o), &lo), &hi) in action.iter_mut().zip(out).zip(&self.low).zip(&self.high) {
            // max/min rather than clamp: a NaN output stays NaN and the env rejects it.
            *a = if o.is_nan() { o } else { o.max(lo).min(hi) };
        }
        Ok(())
    }
}

impl Policy for OnnxPolicy {
    fn reset(&mut self, _env: &Env) {}

    fn act(&mut self, env: &Env, action: &mut [f32]) {
        if let Err(e) = self.run(env.obs(), action) {
            action.fill(0.0);
            self.failure.get_or_insert(e);
        }
    }

    fn try_act(&mut self, env: &Env, action: &mut [f32]) -> Result<(), SolverError> {
        if let Some(e) = self.failure.take() {
            return Err(e.into());
        }
        self.run(env.obs(), action).map_err(SolverError::from)
    }
}
