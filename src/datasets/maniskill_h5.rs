//! ManiSkill's native trajectory format, as its `RecordEpisode` wrapper writes it:
//! `trajectory.h5` with one group `traj_<k>` per episode, and `trajectory.json` describing
//! the env (`env_info`) and the episodes (`episodes`: seed, control mode, reset kwargs,
//! success).
//!
//! Per episode of T steps:
//!
//! | dataset | shape | type |
//! |---|---|---|
//! | `actions` | (T, A) | float32 |
//! | `terminated`, `truncated`, `success` (and `fail` when the task has it) | (T,) | bool |
//! | `rewards` (optional) | (T,) | float32 |
//! | `obs` (optional; empty group with `obs_mode="none"`) | (T+1, D) | float32 |
//! | `env_states/actors/<actor>` | (T+1, 13) | float32 |
//! | `env_states/articulations/<robot>` | (T+1, 13 + 2n) | float32 |
//! | `env_states/controller/<part>/<key>` (target modes only) | (T+1, k) | float32 |
//!
//! Row 0 of `obs` / `env_states` is the state after reset, row t the state after action t.
//! Booleans are HDF5 enums of int8 (`FALSE` = 0, `TRUE` = 1), as h5py writes numpy bools.
use std::path::Path;

use hdf5_metno as h5;
use indexmap::IndexMap;
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

use super::DatasetError;
use crate::env::StateDict;

/// `env_info` of the json.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EnvInfo {
    /// Env id (`PickCube-v1`, ...).
    pub env_id: String,
    /// `gym.make` kwargs (`obs_mode`, `control_mode`, `render_mode`, `sim_backend`, ...).
    #[serde(default)]
    pub env_kwargs: Map<String, Value>,
    /// `max_episode_steps` of the env (the time limit; episodes may run longer).
    #[serde(default)]
    pub max_episode_steps: Option<u32>,
}

/// One entry of the json's `episodes`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeInfo {
    /// Index k of the group `traj_<k>`.
    pub episode_id: usize,
    /// Seed of the episode's reset.
    #[serde(default)]
    pub episode_seed: Option<u64>,
    /// Control mode of the actions.
    pub control_mode: String,
    /// Steps of the episode.
    pub elapsed_steps: u32,
    /// `env.reset` kwargs (`{"seed": ..., "options": ...}`).
    #[serde(default)]
    pub reset_kwargs: Value,
    /// Final success, when recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub success: Option<bool>,
}

impl EpisodeInfo {
    /// The reset seed: `reset_kwargs.seed`, else `episode_seed`.
    pub fn seed(&self) -> Option<u64> {
        self.reset_kwargs
            .get("seed")
            .and_then(Value::as_u64)
            .or(self.episode_seed)
    }

    /// The reset seed a replay must use, checked: `episode_seed` and `reset_kwargs.seed`
    /// (a null counts as absent) must be integers in `0..=`[`crate::env::checks::MAX_SEED`]
    /// (ManiSkill's seeds are 32-bit), must agree when both are given, and at least one must
    /// be given.
    /// The error names the episode, the field and the value.
    pub fn checked_seed(&self) -> Result<u64, SeedError> {
        let id = self.episode_id;
        let max = crate::env::checks::MAX_SEED;
        let kw =
            match self.reset_kwargs.get("seed") {
                None | Some(Value::Null) => None,
                Some(v) => Some(v.as_u64().filter(|s| *s <= max).ok_or_else(|| {
                    SeedError::BadResetSeed {
                        episode: id,
                        value: v.to_string(),
                    }
                })?),
            };
        if let Some(s) = self.episode_seed.filter(|s| *s > max) {
            return Err(SeedError::BadEpisodeSeed {
                episode: id,
                seed: s,
            });
        }
        match (kw, self.episode_seed) {
            (Some(a), Some(b)) if a != b => Err(SeedError::Differ {
                episode: id,
                reset: a,
                episode_seed: b,
            }),
            (Some(s), _) | (None, Some(s)) => Ok(s),
            (None, None) => Err(SeedError::Missing { episode: id }),
        }
    }
}

/// Why an episode of a trajectory has no usable reset seed ([`EpisodeInfo::checked_seed`]);
/// each names the episode, the field and the value.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SeedError {
    /// `reset_kwargs.seed` is no integer in `0..=MAX_SEED`.
    #[error(
        "episode {episode}: reset_kwargs.seed {value} is not an integer in 0..={max} \
         (ManiSkill's seeds are 32-bit)",
        max = crate::env::checks::MAX_SEED
    )]
    BadResetSeed {
        /// The episode id.
        episode: usize,
        /// The value as JSON.
        value: String,
    },
    /// `episode_seed` beyond `MAX_SEED`.
    #[error(
        "episode {episode}: episode_seed {seed} is not in 0..={max} (ManiSkill's seeds are \
         32-bit)",
        max = crate::env::checks::MAX_SEED
    )]
    BadEpisodeSeed {
        /// The episode id.
        episode: usize,
        /// The seed.
        seed: u64,
    },
    /// Both seeds are given and differ.
    #[error(
        "episode {episode}: reset_kwargs.seed {reset} and episode_seed {episode_seed} differ; \
         an episode has one reset seed"
    )]
    Differ {
        /// The episode id.
        episode: usize,
        /// `reset_kwargs.seed`.
        reset: u64,
        /// `episode_seed`.
        episode_seed: u64,
    },
    /// Neither seed is given.
    #[error(
        "episode {episode}: no seed (episode_seed and reset_kwargs.seed are null or \
         missing); the episode cannot be replayed from its reset"
    )]
    Missing {
        /// The episode id.
        episode: usize,
    },
}

/// The whole `trajectory.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrajectoryJson {
    /// The env.
    pub env_info: EnvInfo,
    /// Git info of ManiSkill (null when unknown).
    #[serde(default)]
    pub commit_info: Value,
    /// The episodes, in `traj_<k>` order.
    pub episodes: Vec<EpisodeInfo>,
    /// Other top-level keys (`source_type`, `source_desc`), kept as they are.
    #[serde(flatten)]
    pub extra: Map<String, Value>,
}

/// The datasets of one `traj_<k>` group.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct EpisodeData {
    /// Actions, row-major (T × `action_dim`).
    pub actions: Vec<f32>,
    /// Entries per action.
    pub action_dim: usize,
    /// `env_states`, T+1 entries (values widened from float32).
    pub env_states: Vec<StateDict>,
    /// `terminated` after each step.
    pub terminated: Vec<bool>,
    /// `truncated` after each step.
    pub truncated: Vec<bool>,
    /// `success` after each step, when recorded.
    pub success: Option<Vec<bool>>,
    /// `fail` after each step, when recorded.
    pub fail: Option<Vec<bool>>,
    /// Rewards, when recorded.
    pub rewards: Option<Vec<f32>>,
    /// Flat observations ((T+1) × `obs_dim`), when recorded as one dataset.
    pub obs: Option<(Vec<f32>, usize)>,
}

impl EpisodeData {
    /// Number of steps T.
    pub fn steps(&self) -> usize {
        self.actions.len() / self.action_dim.max(1)
    }

    /// Action t.
    pub fn action(&self, t: usize) -> &[f32] {
        &self.actions[t * self.action_dim..(t + 1) * self.action_dim]
    }
}

/// A ManiSkill trajectory file pair.
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    /// The json.
    pub json: TrajectoryJson,
    /// One entry per `traj_<k>`, in order.
    pub episodes: Vec<EpisodeData>,
}

/// The json next to an h5: `trajectory.h5` → `trajectory.json`.
pub fn json_path_for(h5: &Path) -> std::path::PathBuf {
    h5.with_extension("json")
}

/// Longest episode the reader accepts (steps). An episode's `elapsed_steps` must not exceed
/// it, and every dataset's declared row count must match `elapsed_steps` before the dataset
/// is read.
pub const MAX_EPISODE_STEPS: u32 = 100_000;
/// Most columns a dataset may declare (entries per action, observation or state row).
pub const MAX_COLUMNS: usize = 4096;
/// Most values the reader loads from one h5 file (2²⁸ float32 values, 1 GiB), summed over
/// the declared shapes of everything it reads, checked before each dataset is read.
pub const MAX_VALUES: u64 = 1 << 28;

/// Reads and checks `trajectory.json` (see [`TrajectoryJson::check`]).
pub fn read_json(path: &Path) -> Result<TrajectoryJson, DatasetError> {
    let text = std::fs::read_to_string(path).map_err(DatasetError::io(path))?;
    let json: TrajectoryJson = serde_json::from_str(&text).map_err(|e| {
        DatasetError::format(
            path,
            format!("not a ManiSkill trajectory json (env_info, episodes): {e}"),
        )
    })?;
    json.check(path)?;
    Ok(json)
}

impl TrajectoryJson {
    /// Checks what the h5 reader relies on: every `episode_id` is listed once (it names the
    /// group `traj_<id>`, so a repeated id would read one group twice and another never),
    /// and no episode is longer than [`MAX_EPISODE_STEPS`]. `path` is the json, for errors.
    pub fn check(&self, path: &Path) -> Result<(), DatasetError> {
        let mut seen = std::collections::HashMap::new();
        for (i, e) in self.episodes.iter().enumerate() {
            if let Some(j) = seen.insert(e.episode_id, i) {
                return Err(DatasetError::format(
                    path,
                    format!(
                        "episodes[{j}] and episodes[{i}] both have episode_id {}; each \
                         episode_id names one h5 group traj_<id>, so one episode would be \
                         read twice and another never",
                        e.episode_id
                    ),
                ));
            }
            if e.elapsed_steps > MAX_EPISODE_STEPS {
                return Err(DatasetError::format(
                    path,
                    format!(
                        "episode {}: elapsed_steps {} exceeds the limit of {MAX_EPISODE_STEPS} \
                         steps per episode",
                        e.episode_id, e.elapsed_steps
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// Reads an h5 file and its json (default: the h5 path with extension `.json`) and checks
/// that they describe the same episodes with consistent shapes.
pub fn read(h5_path: &Path, json_path: Option<&Path>) -> Result<Trajectory, DatasetError> {
    let jp = json_path.map_or_else(|| json_path_for(h5_path), Path::to_path_buf);
    let json = read_json(&jp)?;
    read_h5(h5_path, &jp, json)
}

/// Reads the h5 file of an already read and checked json (`json_path` names it in errors).
/// Every dataset's declared shape is checked against the json's `elapsed_steps`,
/// [`MAX_COLUMNS`] and [`MAX_VALUES`] before it is read.
pub fn read_h5(
    h5_path: &Path,
    json_path: &Path,
    json: TrajectoryJson,
) -> Result<Trajectory, DatasetError> {
    let jp = json_path;
    json.check(jp)?;
    let file = h5::File::open(h5_path).map_err(DatasetError::hdf5(h5_path))?;
    let names = file.member_names().map_err(DatasetError::hdf5(h5_path))?;
    let trajs = names.iter().filter(|n| n.starts_with("traj_")).count();
    if trajs != json.episodes.len() {
        return Err(DatasetError::format(
            h5_path,
            format!(
                "has {trajs} traj_<k> groups but {} lists {} episodes",
                jp.display(),
                json.episodes.len()
            ),
        ));
    }
    let mut reader = Reader {
        path: h5_path,
        json: jp,
        left: MAX_VALUES,
    };
    let mut episodes = Vec::with_capacity(trajs);
    for info in &json.episodes {
        let name = format!("traj_{}", info.episode_id);
        let g = file.group(&name).map_err(|_| {
            DatasetError::format(
                h5_path,
                format!(
                    "{} lists episode_id {} but the h5 has no group {name}",
                    jp.display(),
                    info.episode_id
                ),
            )
        })?;
        let ep = reader.episode(&name, &g, info)?;
        episodes.push(ep);
    }
    Ok(Trajectory { json, episodes })
}

/// Reads datasets after checking their declared shapes (see [`read_h5`]).
struct Reader<'a> {
    path: &'a Path,
    json: &'a Path,
    /// Values still allowed by [`MAX_VALUES`].
    left: u64,
}

impl Reader<'_> {
    fn err(&self, msg: String) -> DatasetError {
        DatasetError::format(self.path, msg)
    }

    /// Takes `rows × cols` values from the budget.
    fn charge(&mut self, what: &str, rows: usize, cols: usize) -> Result<(), DatasetError> {
        let n = rows as u128 * cols as u128;
        if n > self.left as u128 {
            return Err(self.err(format!(
                "{what} declares {rows}×{cols} values, beyond the limit of {MAX_VALUES} values \
                 read from one file; refusing to read it"
            )));
        }
        self.left -= n as u64;
        Ok(())
    }

    /// A 1- or 2-dimensional float dataset of `rows` rows (`why` says where that count comes
    /// from); returns (values, columns). The shape is checked before anything is read.
    fn matrix(
        &mut self,
        g: &h5::Group,
        what: &str,
        name: &str,
        rows: usize,
        why: &str,
    ) -> Result<(Vec<f32>, usize), DatasetError> {
        let ds = g
            .dataset(name)
            .map_err(|_| self.err(format!("{what}: missing dataset {name}")))?;
        let shape = ds.shape();
        let (r, cols) = match shape.as_slice() {
            [r] => (*r, 1),
            [r, c] => (*r, *c),
            s => {
                return Err(self.err(format!(
                    "{what}/{name} has shape {s:?}, expected 1 or 2 dimensions"
                )))
            }
        };
        if r != rows {
            return Err(self.err(format!(
                "{what}/{name} declares {r} rows, expected {rows} ({why})"
            )));
        }
        if cols > MAX_COLUMNS {
            return Err(self.err(format!(
                "{what}/{name} declares {cols} columns, beyond the limit of {MAX_COLUMNS}"
            )));
        }
        self.charge(&format!("{what}/{name}"), rows, cols)?;
        let v = ds
            .read_raw::<f32>()
            .map_err(DatasetError::hdf5(self.path))?;
        if v.len() != rows * cols {
            return Err(self.err(format!(
                "{what}/{name} holds {} values, expected {rows}×{cols}",
                v.len()
            )));
        }
        Ok((v, cols))
    }

    /// A boolean dataset of shape (`steps`,), or None when absent and not `required`.
    fn bools(
        &mut self,
        g: &h5::Group,
        what: &str,
        name: &str,
        steps: usize,
        required: bool,
    ) -> Result<Option<Vec<bool>>, DatasetError> {
        if !g.link_exists(name) {
            return if required {
                Err(self.err(format!("{what}: missing dataset {name}")))
            } else {
                Ok(None)
            };
        }
        let ds = g.dataset(name).map_err(DatasetError::hdf5(self.path))?;
        let shape = ds.shape();
        if shape != [steps] {
            return Err(self.err(format!(
                "{what}/{name} has shape {shape:?}, expected [{steps}] (one flag per action)"
            )));
        }
        self.charge(&format!("{what}/{name}"), steps, 1)?;
        let v = ds
            .read_raw::<bool>()
            .map_err(DatasetError::hdf5(self.path))?;
        if v.len() != steps {
            return Err(self.err(format!(
                "{what}/{name} has {} entries, expected {steps}",
                v.len()
            )));
        }
        Ok(Some(v))
    }

    fn episode(
        &mut self,
        name: &str,
        g: &h5::Group,
        info: &EpisodeInfo,
    ) -> Result<EpisodeData, DatasetError> {
        let path = self.path;
        let steps = info.elapsed_steps as usize;
        let why = format!(
            "episode {}'s elapsed_steps in {}: one action per step",
            info.episode_id,
            self.json.display()
        );
        let (actions, action_dim) = self.matrix(g, name, "actions", steps, &why)?;
        if action_dim == 0 {
            return Err(self.err(format!("{name}/actions has 0 columns")));
        }
        let terminated = self
            .bools(g, name, "terminated", steps, true)?
            .unwrap_or_default();
        let truncated = self
            .bools(g, name, "truncated", steps, true)?
            .unwrap_or_default();
        let success = self.bools(g, name, "success", steps, false)?;
        let fail = self.bools(g, name, "fail", steps, false)?;
        let rewards = if g.link_exists("rewards") {
            Some(self.matrix(g, name, "rewards", steps, "one per action")?.0)
        } else {
            None
        };
        let states_why = format!("one more than the {steps} actions");
        let obs = match g.dataset("obs") {
            Ok(_) => Some(self.matrix(g, name, "obs", steps + 1, &states_why)?),
            Err(_) => None,
        };
        let es = g
            .group("env_states")
            .map_err(|_| self.err(format!("{name}: missing group env_states")))?;
        let mut states = vec![StateDict::default(); steps + 1];
        let mut leaf = |r: &mut Self,
                        kind: &str,
                        key: String,
                        g: &h5::Group,
                        ds_name: &str|
         -> Result<(), DatasetError> {
            let what = format!("{name}/env_states/{kind}");
            if kind == "actors" {
                // The column count is known: check it before reading.
                if let Ok(ds) = g.dataset(ds_name) {
                    if let [_, c] = ds.shape().as_slice() {
                        if *c != 13 {
                            return Err(
                                r.err(format!("{what}/{ds_name} has {c} columns, expected 13"))
                            );
                        }
                    }
                }
            }
            let (v, cols) = r.matrix(g, &what, ds_name, steps + 1, &states_why)?;
            for (t, s) in states.iter_mut().enumerate() {
                let row: Vec<f64> = v[t * cols..(t + 1) * cols]
                    .iter()
                    .map(|&x| x as f64)
                    .collect();
                match kind {
                    "actors" => {
                        let arr: [f64; 13] = row.as_slice().try_into().map_err(|_| {
                            DatasetError::format(
                                path,
                                format!("{what}/{ds_name} has {cols} columns, expected 13"),
                            )
                        })?;
                        s.actors.insert(key.clone(), arr);
                    }
                    "articulations" => {
                        s.articulations.insert(key.clone(), row);
                    }
                    _ => {
                        s.controller.insert(key.clone(), row);
                    }
                }
            }
            Ok(())
        };
        for kind in ["actors", "articulations"] {
            let sub = es.group(kind).map_err(|_| {
                DatasetError::format(path, format!("{name}: missing group env_states/{kind}"))
            })?;
            for m in members(path, &sub)? {
                leaf(self, kind, m.clone(), &sub, &m)?;
            }
        }
        if let Ok(ctrl) = es.group("controller") {
            for m in members(path, &ctrl)? {
                if let Ok(part) = ctrl.group(&m) {
                    for k in members(path, &part)? {
                        leaf(self, "controller", format!("{m}.{k}"), &part, &k)?;
                    }
                } else {
                    leaf(self, "controller", m.clone(), &ctrl, &m)?;
                }
            }
        }
        Ok(EpisodeData {
            actions,
            action_dim,
            env_states: states,
            terminated,
            truncated,
            success,
            fail,
            rewards,
            obs,
        })
    }
}

/// A group's member names in creation order when the file tracks it (h5py's
/// `track_order=True`, and mjskill's exports), else in name order.
fn members(path: &Path, g: &h5::Group) -> Result<Vec<String>, DatasetError> {
    use h5::{IndexType, IterationOrder};
    match g.member_names_by(IndexType::CreationOrder, IterationOrder::Increasing) {
        Ok(v) => Ok(v),
        Err(_) => g.member_names().map_err(DatasetError::hdf5(path)),
    }
}

fn h5_group(parent: &h5::Group, name: &str) -> h5::Result<h5::Group> {
    // Track and index link creation order, as h5py's `track_order=True`: readers list the
    // actors in ManiSkill's scene order rather than alphabetically.
    use h5::plist::group_create::LinkCreationOrder;
    parent
        .create_group_builder()
        .with_gcpl(|p| p.link_creation_order(LinkCreationOrder::Indexed))
        .create(name)
}

fn write_matrix(g: &h5::Group, name: &str, v: &[f32], cols: Option<usize>) -> h5::Result<()> {
    let ds = match cols {
        Some(c) => g
            .new_dataset::<f32>()
            .shape((v.len() / c.max(1), c))
            .create(name)?,
        None => g.new_dataset::<f32>().shape(v.len()).create(name)?,
    };
    ds.write_raw(v)
}

fn write_bools(g: &h5::Group, name: &str, v: &[bool]) -> h5::Result<()> {
    g.new_dataset::<bool>()
        .shape(v.len())
        .create(name)?
        .write_raw(v)
}

fn write_episode(g: &h5::Group, ep: &EpisodeData) -> h5::Result<()> {
    write_matrix(g, "actions", &ep.actions, Some(ep.action_dim))?;
    write_bools(g, "terminated", &ep.terminated)?;
    write_bools(g, "truncated", &ep.truncated)?;
    if let Some(s) = &ep.success {
        write_bools(g, "success", s)?;
    }
    if let Some(f) = &ep.fail {
        write_bools(g, "fail", f)?;
    }
    if let Some(r) = &ep.rewards {
        write_matrix(g, "rewards", r, None)?;
    }
    match &ep.obs {
        Some((o, d)) => write_matrix(g, "obs", o, Some(*d))?,
        None => {
            h5_group(g, "obs")?;
        }
    }
    let es = h5_group(g, "env_states")?;
    let Some(first) = ep.env_states.first() else {
        return Ok(());
    };
    let column = |f: &dyn Fn(&StateDict) -> &[f64]| -> Vec<f32> {
        ep.env_states
            .iter()
            .flat_map(|s| f(s).iter().map(|&x| x as f32))
            .collect()
    };
    let actors = h5_group(&es, "actors")?;
    for (name, a) in &first.actors {
        let v = column(&|s| s.actors.get(name).map_or(&[][..], |x| &x[..]));
        write_matrix(&actors, name, &v, Some(a.len()))?;
    }
    let arts = h5_group(&es, "articulations")?;
    for (name, a) in &first.articulations {
        let v = column(&|s| s.articulations.get(name).map_or(&[][..], |x| &x[..]));
        write_matrix(&arts, name, &v, Some(a.len()))?;
    }
    if !first.controller.is_empty() {
        let ctrl = h5_group(&es, "controller")?;
        let mut parts: IndexMap<&str, h5::Group> = IndexMap::new();
        for (key, c) in &first.controller {
            let v = column(&|s| s.controller.get(key).map_or(&[][..], |x| &x[..]));
            match key.split_once('.') {
                Some((part, leaf)) => {
                    if !parts.contains_key(part) {
                        parts.insert(part, h5_group(&ctrl, part)?);
                    }
                    write_matrix(&parts[part], leaf, &v, Some(c.len()))?;
                }
                None => write_matrix(&ctrl, key, &v, Some(c.len()))?,
            }
        }
    }
    Ok(())
}

/// Writes `traj` to `h5_path` and its json to `json_path`, each under a temporary name that
/// takes the final name only once both are complete. Every episode's `env_states` must hold
/// the same entries in every row.
pub fn write(traj: &Trajectory, h5_path: &Path, json_path: &Path) -> Result<(), DatasetError> {
    for (k, ep) in traj.episodes.iter().enumerate() {
        let steps = ep.steps();
        let first = ep.env_states.first();
        let same_keys = ep.env_states.iter().all(|s| {
            first.is_some_and(|f| {
                s.actors.keys().eq(f.actors.keys())
                    && s.articulations.keys().eq(f.articulations.keys())
                    && s.controller.keys().eq(f.controller.keys())
            })
        });
        if ep.env_states.len() != steps + 1 || !same_keys || ep.terminated.len() != steps {
            return Err(DatasetError::format(
                h5_path,
                format!(
                    "episode {k}: inconsistent data to write ({steps} actions, {} states)",
                    ep.env_states.len()
                ),
            ));
        }
    }
    super::check_outputs(
        &[],
        &[
            super::Named::new("the h5", h5_path),
            super::Named::new("the json", json_path),
        ],
    )?;
    let mut staged = super::Staged::default();
    let tmp_h5 = staged.add(h5_path);
    let tmp_json = staged.add(json_path);
    {
        use h5::plist::file_create::LinkCreationOrder;
        // No HDF5 file lock: the file has a private temporary name until it is complete, and
        // HDF5 opens it without O_CLOEXEC, so a child process another thread starts meanwhile
        // would keep an exclusive lock alive after `close` and make the finished file
        // unreadable ("unable to lock file, errno = 11").
        let file = h5::File::with_options()
            .with_fapl(|p| p.file_locking(false))
            .with_fcpl(|p| p.link_creation_order(LinkCreationOrder::Indexed))
            .create(&tmp_h5)
            .map_err(DatasetError::hdf5(h5_path))?;
        for (info, ep) in traj.json.episodes.iter().zip(&traj.episodes) {
            let g = h5_group(&file, &format!("traj_{}", info.episode_id))
                .map_err(DatasetError::hdf5(h5_path))?;
            write_episode(&g, ep).map_err(DatasetError::hdf5(h5_path))?;
        }
        file.close().map_err(DatasetError::hdf5(h5_path))?;
    }
    let text = serde_json::to_string_pretty(&traj.json).map_err(|e| DatasetError::Format {
        path: json_path.to_path_buf(),
        msg: e.to_string(),
    })?;
    std::fs::write(&tmp_json, text).map_err(DatasetError::io(json_path))?;
    staged.commit()
}
