//! `mjskill compare-images`: mjskill's sensor images against ManiSkill's, state by state
//! (segmentation IoU, depth error, colour difference; side-by-side panels).
use std::collections::BTreeMap;
use std::path::PathBuf;

use mjskill::maniskill::images::{list_states, Comparer, RefImageState, StateScore, Summary};
use serde::Serialize;

use crate::{args, CliError};

/// What `compare-images` does (its command-line arguments).
#[derive(Debug, clap::Args)]
pub struct CompareArgs {
    /// Reference directory with `<env>__<robot>/` directories of ManiSkill's `.npz`
    /// renders (per camera `<cam>_rgb`, `<cam>_depth`, `<cam>_segmentation`;
    /// `state_json`, `control_mode`).
    pub reference: PathBuf,
    /// Only this `<env>__<robot>` directory (repeatable).
    #[arg(long = "pair")]
    pub pairs: Vec<String>,
    /// Write one side-by-side PNG per state here (mjskill | ManiSkill | difference; colour
    /// above, segmentation below).
    #[arg(long)]
    pub panels: Option<PathBuf>,
    /// At most this many states per pair (1..=1000000).
    #[arg(long, value_parser = args::bench_steps, allow_hyphen_values = true)]
    pub limit: Option<usize>,
    /// Include every state's per-camera scores (and per-id IoU).
    #[arg(long)]
    pub per_state: bool,
}

/// The report printed (one JSON line).
#[derive(Debug, Serialize)]
pub struct CompareReport {
    reference: String,
    overall: Summary,
    pairs: BTreeMap<String, Summary>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    states: Vec<StateScore>,
}

/// Runs the comparison.
pub fn run(a: &CompareArgs) -> Result<CompareReport, CliError> {
    if let Some(dir) = &a.panels {
        std::fs::create_dir_all(dir)
            .map_err(|e| format!("cannot create --panels {}: {e}", dir.display()))?;
    }
    let files = list_states(&a.reference, &a.pairs)?;
    if files.is_empty() {
        return Err(format!(
            "no reference states (<env>__<robot>/*.npz) under {}",
            a.reference.display()
        )
        .into());
    }
    let mut cmp = Comparer::new(a.panels.clone());
    let mut scores: Vec<StateScore> = Vec::new();
    let mut per_pair: BTreeMap<String, usize> = BTreeMap::new();
    for f in &files {
        let s = RefImageState::open(f)?;
        let pair = format!("{}__{}", s.env_id, s.robot);
        let n = per_pair.entry(pair).or_default();
        if a.limit.is_some_and(|l| *n >= l) {
            continue;
        }
        *n += 1;
        scores.push(cmp.compare(&s)?);
    }
    let mut pairs = BTreeMap::new();
    for p in per_pair.keys() {
        pairs.insert(
            p.clone(),
            Summary::of(scores.iter().filter(|s| &s.pair == p)),
        );
    }
    Ok(CompareReport {
        reference: a.reference.display().to_string(),
        overall: Summary::of(&scores),
        pairs,
        states: if a.per_state { scores } else { Vec::new() },
    })
}
