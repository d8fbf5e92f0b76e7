//! Outcome agreement with ManiSkill: the same action sequences, replayed open loop in both
//! simulators, end the same way?
//!
//! An outcome file (`<source>__<env>__<robot>.json.gz`, format [`FORMAT`], written by
//! `examples/maniskill_outcomes.py` with a local ManiSkill 3) holds fixed action sequences
//! of one (env, robot) pair — mjskill's scripted-solver episodes exported with
//! `mjskill export --format maniskill`, or ManiSkill's own motion-planning demos — and what
//! ManiSkill did with them: every boolean of the task's `evaluate()` after every step, the
//! final `success` and the final object positions. [`measure`] replays the actions in
//! mjskill and counts the agreement (docs/outcome-agreement.md).
use std::path::Path;

use indexmap::IndexMap;
use serde::{Deserialize, Serialize};

use crate::env::{make, EnvConfig, EnvError, ObsMode, RewardMode, SimConfig};

/// The format tag of outcome files.
pub const FORMAT: &str = "mjskill-outcomes/1";

/// Errors of reading an outcome file; each names the file.
#[derive(Debug, thiserror::Error)]
pub enum OutcomeError {
    /// The file could not be read or decompressed (also: not a regular file, or beyond the
    /// size limit, [`crate::files`]).
    #[error(transparent)]
    File(#[from] crate::files::FileError),
    /// A directory of outcome files could not be listed.
    #[error("cannot read {path}: {source}")]
    Io {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// The JSON does not have the expected structure.
    #[error("{path} is not an mjskill outcome file ({FORMAT}): {msg}")]
    Format {
        /// File.
        path: String,
        /// What is wrong.
        msg: String,
    },
    /// mjskill cannot replay the file (unknown env, robot or mode, a bad action).
    #[error("{path}: {source}")]
    Env {
        /// File.
        path: String,
        /// Cause.
        source: EnvError,
    },
}

/// One episode of an outcome file.
#[derive(Debug, Clone, Deserialize)]
pub struct OutcomeEpisode {
    /// Reset seed.
    pub seed: u64,
    /// Number of actions.
    pub steps: usize,
    /// ManiSkill's `success` after the last action.
    pub final_success: bool,
    /// ManiSkill's boolean info entries after every step: one `0`/`1` per step.
    pub flags: IndexMap<String, String>,
    /// Final positions of the dynamic actors in ManiSkill (m, world frame): every one of the
    /// env's dynamic actors, or none (not recorded; no distance is measured).
    #[serde(default)]
    pub final_objects: IndexMap<String, [f64; 3]>,
    /// The actions, in the file's control mode.
    pub actions: Vec<Vec<f32>>,
}

/// An outcome file.
#[derive(Debug, Clone, Deserialize)]
pub struct OutcomeFile {
    /// [`FORMAT`].
    pub format: String,
    /// `solver` (mjskill's scripted solver) or `motionplanning` (ManiSkill's demos).
    pub source: String,
    /// Env id.
    pub env_id: String,
    /// Robot uid.
    pub robot: String,
    /// Control mode of the actions.
    pub control_mode: String,
    /// Episodes.
    pub episodes: Vec<OutcomeEpisode>,
}

impl OutcomeFile {
    /// Reads an outcome file (gzip-compressed or plain JSON; a regular file, it and its
    /// decompressed contents at most [`crate::files::max_bytes`]) and checks that every
    /// episode's actions and flags have `steps` entries.
    pub fn open(path: &Path) -> Result<OutcomeFile, OutcomeError> {
        let p = path.display().to_string();
        let text = crate::files::read_maybe_gzip(path, crate::files::max_bytes())?;
        let bad = |msg: String| OutcomeError::Format {
            path: p.clone(),
            msg,
        };
        let f: OutcomeFile = serde_json::from_slice(&text).map_err(|e| bad(e.to_string()))?;
        if f.format != FORMAT {
            return Err(bad(format!(
                "format is {:?}",
                crate::files::short(&f.format)
            )));
        }
        for (k, e) in f.episodes.iter().enumerate() {
            if e.actions.len() != e.steps {
                return Err(bad(format!(
                    "episode {k} (seed {}) has {} actions, steps {}",
                    e.seed,
                    e.actions.len(),
                    e.steps
                )));
            }
            if let Some((key, v)) = e
                .flags
                .iter()
                .find(|(_, v)| v.len() != e.steps || v.bytes().any(|c| c != b'0' && c != b'1'))
            {
                return Err(bad(format!(
                    "episode {k} (seed {}): flags.{} is not {} characters 0/1 ({:?})",
                    e.seed,
                    crate::files::short(key),
                    e.steps,
                    crate::files::short(v)
                )));
            }
        }
        Ok(f)
    }

    /// `<source> <env> <robot>`, the pair's label.
    pub fn label(&self) -> String {
        format!("{} {} {}", self.source, self.env_id, self.robot)
    }
}

/// Per-step agreement of one flag.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Default)]
pub struct FlagAgreement {
    /// Steps where mjskill's flag equals ManiSkill's.
    pub agree: usize,
    /// Steps compared.
    pub steps: usize,
    /// Steps where ManiSkill's flag is true.
    pub maniskill_true: usize,
    /// Steps where mjskill's flag is true.
    pub mjskill_true: usize,
}

/// One episode replayed in mjskill.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EpisodeOutcome {
    /// Reset seed.
    pub seed: u64,
    /// Steps.
    pub steps: usize,
    /// ManiSkill's final `success`.
    pub maniskill_success: bool,
    /// mjskill's final `success`.
    pub mjskill_success: bool,
    /// Steps on which some flag differs.
    pub steps_with_flag_mismatch: usize,
    /// Largest distance between ManiSkill's and mjskill's final object positions (m); None
    /// when the file records no final positions for the episode.
    pub final_object_distance_m: Option<f64>,
}

/// The agreement of one outcome file (one pair and source).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PairAgreement {
    /// `solver` or `motionplanning`.
    pub source: String,
    /// Env id.
    pub env_id: String,
    /// Robot uid.
    pub robot: String,
    /// Control mode of the actions.
    pub control_mode: String,
    /// Episodes replayed.
    pub episodes: usize,
    /// ManiSkill's successes (final step).
    pub maniskill_successes: usize,
    /// mjskill's successes (final step).
    pub mjskill_successes: usize,
    /// Episodes whose final `success` is the same in both.
    pub same_outcome: usize,
    /// Steps replayed.
    pub steps: usize,
    /// Steps on which every compared flag agrees.
    pub steps_all_flags_agree: usize,
    /// Per flag (ManiSkill's keys, in its order).
    pub flags: IndexMap<String, FlagAgreement>,
    /// Episodes whose final object positions are within 1 cm of ManiSkill's (of those with
    /// final positions recorded).
    pub final_objects_within_1cm: usize,
    /// Per episode.
    pub per_episode: Vec<EpisodeOutcome>,
}

/// Replays the first `max_episodes` episodes (all with `None`) of `file` in mjskill with
/// the physics settings `sim` and counts the agreement with ManiSkill. Errors name the file
/// and, for a flag ManiSkill reports that mjskill's task lacks, the flag.
pub fn measure(
    file: &OutcomeFile,
    path: &Path,
    max_episodes: Option<usize>,
    sim: SimConfig,
) -> Result<PairAgreement, OutcomeError> {
    let p = path.display().to_string();
    let env_err = |source| OutcomeError::Env {
        path: p.clone(),
        source,
    };
    let mut env = make(
        &file.env_id,
        EnvConfig {
            robot: Some(file.robot.clone()),
            control_mode: Some(file.control_mode.clone()),
            obs_mode: ObsMode::None,
            reward_mode: RewardMode::None,
            sim,
            ..EnvConfig::default()
        },
    )
    .map_err(env_err)?;
    let episodes = &file.episodes[..max_episodes
        .unwrap_or(file.episodes.len())
        .min(file.episodes.len())];
    // ManiSkill's flag keys, each with its position in mjskill's info.
    let mut flags: IndexMap<String, FlagAgreement> = IndexMap::new();
    let mut index: Vec<usize> = Vec::new();
    if let Some(first) = episodes.first() {
        for key in first.flags.keys() {
            let i = env
                .info()
                .keys
                .iter()
                .position(|k| *k == key.as_str() && env.info_is_flag(k))
                .ok_or_else(|| OutcomeError::Format {
                    path: p.clone(),
                    msg: format!(
                        "flag {:?} is not one of {}'s info flags ({})",
                        crate::files::short(key),
                        file.env_id,
                        env.info()
                            .keys
                            .iter()
                            .filter(|k| env.info_is_flag(k))
                            .copied()
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                })?;
            flags.insert(key.clone(), FlagAgreement::default());
            index.push(i);
        }
    }
    let mut out = PairAgreement {
        source: file.source.clone(),
        env_id: file.env_id.clone(),
        robot: file.robot.clone(),
        control_mode: file.control_mode.clone(),
        episodes: episodes.len(),
        maniskill_successes: 0,
        mjskill_successes: 0,
        same_outcome: 0,
        steps: 0,
        steps_all_flags_agree: 0,
        flags,
        final_objects_within_1cm: 0,
        per_episode: Vec::with_capacity(episodes.len()),
    };
    let keys: Vec<String> = out.flags.keys().cloned().collect();
    let objects = env.dynamic_actor_names();
    for ep in episodes {
        // ManiSkill's scene names of the objects, as mjskill names them.
        let merged = ep.final_objects.iter().map(|(name, p)| {
            let known = |n: &str| objects.contains(&n);
            (super::merged_actor_name(name, known).to_string(), *p)
        });
        let ep = &OutcomeEpisode {
            final_objects: merged.collect(),
            ..ep.clone()
        };
        if ep.flags.keys().ne(keys.iter()) {
            return Err(OutcomeError::Format {
                path: p.clone(),
                msg: format!("episode seed {} has other flags than the first", ep.seed),
            });
        }
        check_objects(ep, &objects, &file.env_id).map_err(|msg| OutcomeError::Format {
            path: p.clone(),
            msg,
        })?;
        env.try_reset(Some(ep.seed)).map_err(env_err)?;
        let columns: Vec<&[u8]> = ep.flags.values().map(|v| v.as_bytes()).collect();
        let mut mismatch_steps = 0;
        for (t, a) in ep.actions.iter().enumerate() {
            env.step(a).map_err(env_err)?;
            let values = &env.info().values;
            let mut all = true;
            for ((col, &i), fa) in columns.iter().zip(&index).zip(out.flags.values_mut()) {
                let ms = col[t] == b'1';
                let mj = values[i] != 0.0;
                fa.steps += 1;
                fa.agree += (ms == mj) as usize;
                fa.maniskill_true += ms as usize;
                fa.mjskill_true += mj as usize;
                all &= ms == mj;
            }
            out.steps += 1;
            out.steps_all_flags_agree += all as usize;
            mismatch_steps += (!all) as usize;
        }
        let mj_success = env.info().success();
        // Every name is one of the env's objects (checked above).
        let distance = (!ep.final_objects.is_empty()).then(|| {
            ep.final_objects
                .iter()
                .filter_map(|(name, p)| {
                    let q = env.actor_pose(name)?;
                    Some(
                        ((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) + (q[2] - p[2]).powi(2))
                            .sqrt(),
                    )
                })
                .fold(0.0, f64::max)
        });
        out.maniskill_successes += ep.final_success as usize;
        out.mjskill_successes += mj_success as usize;
        out.same_outcome += (ep.final_success == mj_success) as usize;
        out.final_objects_within_1cm += distance.is_some_and(|d| d <= 0.01) as usize;
        out.per_episode.push(EpisodeOutcome {
            seed: ep.seed,
            steps: ep.steps,
            maniskill_success: ep.final_success,
            mjskill_success: mj_success,
            steps_with_flag_mismatch: mismatch_steps,
            final_object_distance_m: distance,
        });
    }
    Ok(out)
}

/// Checks that an episode's `final_objects` (if any: a file may record none) name exactly the
/// env's dynamic objects: an unknown (misspelt) or missing one would otherwise count as no
/// distance at all.
fn check_objects(ep: &OutcomeEpisode, objects: &[&str], env_id: &str) -> Result<(), String> {
    if ep.final_objects.is_empty() {
        return Ok(());
    }
    let valid = objects.join(", ");
    if let Some(name) = ep
        .final_objects
        .keys()
        .find(|n| !objects.contains(&n.as_str()))
    {
        return Err(format!(
            "episode seed {}: final_objects names {:?}, which is not one of {env_id}'s objects \
             ({valid})",
            ep.seed,
            crate::files::short(name)
        ));
    }
    if let Some(name) = objects.iter().find(|o| !ep.final_objects.contains_key(**o)) {
        return Err(format!(
            "episode seed {}: final_objects lacks {name:?}; it holds the final position of \
             each of {env_id}'s objects ({valid})",
            ep.seed
        ));
    }
    Ok(())
}

/// The outcome files of a directory (`*.json.gz` / `*.json` with the [`FORMAT`] layout), in
/// name order; a single file is returned as is.
pub fn files(path: &Path) -> Result<Vec<std::path::PathBuf>, OutcomeError> {
    if !path.is_dir() {
        return Ok(vec![path.to_path_buf()]);
    }
    let io = |source| OutcomeError::Io {
        path: path.display().to_string(),
        source,
    };
    let mut out: Vec<_> = std::fs::read_dir(path)
        .map_err(io)?
        .map(|e| e.map(|e| e.path()))
        .collect::<Result<_, _>>()
        .map_err(io)?;
    out.retain(|p| {
        let n = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
        n.ends_with(".json.gz") || n.ends_with(".json")
    });
    out.sort();
    Ok(out)
}
