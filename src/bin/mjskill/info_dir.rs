//! `mjskill info DIR`: a directory of recordings (e.g. the per-worker shards written by the
//! Python package's Ray sharding) summarised as one dataset.
use std::path::Path;

use serde::Serialize;

use super::rollout::{info, InfoSummary};
use crate::CliError;

/// The summary of a directory of `.mcap` shards: the fields of [`InfoSummary`] over all
/// shards, plus each shard's own summary.
#[derive(Debug, Clone, Serialize)]
pub struct DirSummary {
    /// The dataset as one recording: `file` is the directory; env, robot, modes are the
    /// shards' (the same in every shard), `version` the first shard's; counts, steps and
    /// unfinished steps are summed, the mean return is over all finished episodes,
    /// `complete` holds if every shard was closed properly, and with `--salvage` `damage`
    /// names each damaged shard's damage.
    #[serde(flatten)]
    pub total: InfoSummary,
    /// Each shard's summary, in file-name order.
    pub shards: Vec<InfoSummary>,
}

/// Summarises every `*.mcap` file directly inside `dir` (in file-name order) as one dataset.
/// Errors: no shard, an unreadable shard (named), or shards of different envs, robots or
/// modes (both files and values named).
pub fn info_dir(dir: &Path, salvage: bool) -> Result<DirSummary, CliError> {
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .map_err(|e| format!("cannot read the directory {}: {e}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && p.extension().is_some_and(|x| x == "mcap"))
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(format!(
            "{} holds no .mcap files; give a recording or a directory of .mcap shards",
            dir.display()
        )
        .into());
    }
    let shards = files
        .iter()
        .map(|f| info(f, salvage))
        .collect::<Result<Vec<_>, _>>()?;
    let first = &shards[0];
    for s in &shards[1..] {
        let pairs = [
            ("env", &first.env, &s.env),
            ("robot", &first.robot, &s.robot),
            ("control mode", &first.control_mode, &s.control_mode),
            ("obs mode", &first.obs_mode, &s.obs_mode),
            ("reward mode", &first.reward_mode, &s.reward_mode),
        ];
        if let Some((what, a, b)) = pairs.iter().find(|(_, a, b)| a != b) {
            return Err(format!(
                "{} and {} are not one dataset: {what} {a:?} vs {b:?}",
                first.file, s.file
            )
            .into());
        }
    }
    let episodes: usize = shards.iter().map(|s| s.episodes).sum();
    let returns: f64 = shards
        .iter()
        .map(|s| s.mean_return * s.episodes as f64)
        .sum();
    let unfinished: Vec<usize> = shards.iter().filter_map(|s| s.unfinished_steps).collect();
    let damage: Vec<String> = shards
        .iter()
        .filter_map(|s| s.damage.as_ref().map(|d| format!("{}: {d}", s.file)))
        .collect();
    let total = InfoSummary {
        file: dir.display().to_string(),
        env: first.env.clone(),
        robot: first.robot.clone(),
        control_mode: first.control_mode.clone(),
        obs_mode: first.obs_mode.clone(),
        reward_mode: first.reward_mode.clone(),
        version: first.version.clone(),
        episodes,
        successes: shards.iter().map(|s| s.successes).sum(),
        steps: shards.iter().map(|s| s.steps).sum(),
        mean_return: if episodes == 0 {
            0.0
        } else {
            returns / episodes as f64
        },
        complete: shards.iter().all(|s| s.complete),
        unfinished_steps: (!unfinished.is_empty()).then(|| unfinished.iter().sum()),
        damage: (!damage.is_empty()).then(|| damage.join("; ")),
    };
    Ok(DirSummary { total, shards })
}
