//! `mjskill import-maniskill` and `mjskill export`.
use std::path::{Path, PathBuf};

use mjskill::datasets::export::{self, Format};
use mjskill::datasets::import::{self, ImportArgs, ImportReport, ReplayBy};
use mjskill::datasets::DatasetError;
use mjskill::SimConfig;

/// Runs `import-maniskill`.
pub fn import_maniskill(
    h5: &Path,
    json: Option<&Path>,
    out: &Path,
    by: &str,
    sim_freq: u32,
) -> Result<ImportReport, DatasetError> {
    let sim = SimConfig { sim_freq };
    sim.validate().map_err(|source| DatasetError::Invalid {
        msg: source.to_string(),
    })?;
    import::run(&ImportArgs {
        h5: h5.to_path_buf(),
        json: json.map(Path::to_path_buf),
        out: out.to_path_buf(),
        by: ReplayBy::parse(by)?,
        sim,
    })
}

/// Runs `export`.
pub fn export(
    file: &Path,
    format: &str,
    output: Option<PathBuf>,
    json: Option<&Path>,
    video: Option<bool>,
    control_mode: Option<&str>,
) -> Result<export::ExportSummary, DatasetError> {
    let format = Format::parse(format)?;
    let output = output.unwrap_or_else(|| export::default_output(file, format));
    match format {
        Format::ManiSkill => {
            if video == Some(true) {
                return Err(DatasetError::Invalid {
                    msg: "--video yes applies to --format lerobot only (ManiSkill's trajectory \
                          format holds no video)"
                        .into(),
                });
            }
            export::to_maniskill_in_mode(file, &output, json, control_mode)
        }
        Format::LeRobot => {
            if json.is_some() {
                return Err(DatasetError::Invalid {
                    msg: "--json applies to --format maniskill only".into(),
                });
            }
            if control_mode.is_some() {
                return Err(DatasetError::Invalid {
                    msg: "--control-mode applies to --format maniskill only".into(),
                });
            }
            mjskill::datasets::lerobot::write(file, &output, video)
        }
    }
}
