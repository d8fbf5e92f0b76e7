//! `mjskill fidelity`: per-step deviations of mjskill from a ManiSkill reference trajectory,
//! or of a recording replayed with other physics settings.
use std::path::PathBuf;

use crate::CliError;
use mjskill::maniskill::fidelity::{replay_file, replay_recording, FidelityOptions, FileFidelity};
use mjskill::maniskill::reference::RefFile;
use mjskill::SimConfig;

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
pub fn run(args: &FidelityArgs) -> Result<(), CliError> {
    if args.resync == Some(0) {
        return Err("--resync must be at least 1 (re-import every K ≥ 1 steps)".into());
    }
    args.sim.validate()?;
    let opts = FidelityOptions {
        resync: args.resync,
        sim: args.sim,
    };
    let mut report = if is_mcap(&args.file)? {
        if args.control_mode.is_some() {
            return Err("--control-mode selects episodes of a reference file; a recording has one control mode".into());
        }
        let rec = mjskill::record::read(&args.file)?;
        replay_recording(&rec, opts)?
    } else {
        reference_report(args, opts)?
    };
    if let Some(p) = &args.plot {
        super::plot::error_curves(&report, p)?;
    }
    if args.summary {
        for e in &mut report.episodes {
            e.per_step.clear();
        }
    }
    super::emit(format_args!("{}", serde_json::to_string(&report)?))
}

/// Whether `path` is an MCAP file (its magic), as opposed to a reference trajectory file.
fn is_mcap(path: &std::path::Path) -> Result<bool, CliError> {
    use std::io::Read;
    let mut magic = [0u8; 8];
    let mut f = mjskill::files::open_regular(path)?;
    let n = f
        .read(&mut magic)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    Ok(n == 8 && magic == *mcap::MAGIC)
}

fn reference_report(args: &FidelityArgs, opts: FidelityOptions) -> Result<FileFidelity, CliError> {
    let mut file = RefFile::open(&args.file)?;
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
            )
            .into());
        }
        file.episodes.retain(|e| &e.control_mode == m);
    }
    Ok(replay_file(&file, opts)?)
}
