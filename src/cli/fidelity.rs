//! `mjskill fidelity`: per-step deviations of mjskill from a ManiSkill reference trajectory.
use std::path::PathBuf;

use crate::env::SimConfig;
use crate::maniskill::fidelity::{replay_file, FidelityOptions};
use crate::maniskill::reference::RefFile;

/// Arguments of `mjskill fidelity`.
#[derive(Debug, Clone)]
pub struct FidelityArgs {
    /// Reference file.
    pub file: PathBuf,
    /// Resync interval.
    pub resync: Option<u32>,
    /// Physics settings.
    pub sim: SimConfig,
    /// Only this control mode's episodes.
    pub control_mode: Option<String>,
    /// Omit per-step arrays.
    pub summary: bool,
    /// PNG of the error curves.
    pub plot: Option<PathBuf>,
}

/// Runs the command: prints the report as one JSON line.
pub fn run(args: &FidelityArgs) -> Result<(), String> {
    if args.resync == Some(0) {
        return Err("--resync must be at least 1 (re-import every K ≥ 1 steps)".into());
    }
    args.sim.validate().map_err(|e| e.to_string())?;
    let mut file = RefFile::open(&args.file).map_err(|e| e.to_string())?;
    if let Some(m) = &args.control_mode {
        if !file.control_modes.contains_key(m) {
            return Err(format!(
                "{} has no episodes in control mode {m:?}; recorded modes: {}",
                args.file.display(),
                file.control_modes
                    .keys()
                    .cloned()
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        file.episodes.retain(|e| &e.control_mode == m);
    }
    let mut report = replay_file(
        &file,
        FidelityOptions {
            resync: args.resync,
            sim: args.sim,
        },
    )
    .map_err(|e| e.to_string())?;
    if let Some(p) = &args.plot {
        super::plot::error_curves(&report, p)?;
    }
    if args.summary {
        for e in &mut report.episodes {
            e.per_step.clear();
        }
    }
    super::emit(format_args!(
        "{}",
        serde_json::to_string(&report).map_err(|e| e.to_string())?
    ))
}
