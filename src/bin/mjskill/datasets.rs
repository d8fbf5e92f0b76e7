//! `mjskill import-maniskill` and `mjskill export` (their flags always; running them needs
//! the `datasets` feature).
#[cfg(feature = "datasets")]
use std::path::{Path, PathBuf};

#[cfg(feature = "datasets")]
use mjskill::datasets::export::{self, Format};
#[cfg(feature = "datasets")]
use mjskill::datasets::import::{self, ImportArgs, ImportReport, ReplayBy};
#[cfg(feature = "datasets")]
use mjskill::datasets::DatasetError;
#[cfg(feature = "datasets")]
use mjskill::SimConfig;

/// Runs `import-maniskill`.
#[cfg(feature = "datasets")]
pub fn import_maniskill(
    h5: &Path,
    json: Option<&Path>,
    out: &Path,
    by: &str,
    sim_freq: u32,
) -> Result<ImportReport, DatasetError> {
    let sim = SimConfig {
        sim_freq,
        ..Default::default()
    };
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

/// `export --format lerobot`'s file size limits (None: LeRobot's default).
#[derive(Debug, clap::Args)]
pub struct LimitArgs {
    /// --format lerobot: files per chunk folder (LeRobot's chunks_size; default 1000;
    /// 1..=4294967295).
    #[arg(long, value_parser = crate::args::chunks_size, allow_hyphen_values = true)]
    pub chunks_size: Option<usize>,
    /// --format lerobot: size limit of data and meta/episodes parquet files in MB
    /// (default 100); an episode that would reach it starts the next file.
    #[arg(long, allow_hyphen_values = true)]
    pub data_files_size_in_mb: Option<f64>,
    /// --format lerobot: size limit of video files in MB (default 200).
    #[arg(long, allow_hyphen_values = true)]
    pub video_files_size_in_mb: Option<f64>,
}

/// Runs `export`.
#[cfg(feature = "datasets")]
pub fn export(
    file: &Path,
    format: &str,
    output: Option<PathBuf>,
    json: Option<&Path>,
    video: Option<bool>,
    control_mode: Option<&str>,
    limits: LimitArgs,
) -> Result<export::ExportSummary, DatasetError> {
    let any_limit = limits.chunks_size.is_some()
        || limits.data_files_size_in_mb.is_some()
        || limits.video_files_size_in_mb.is_some();
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
            if any_limit {
                return Err(DatasetError::Invalid {
                    msg: "--chunks-size, --data-files-size-in-mb and --video-files-size-in-mb \
                          apply to --format lerobot only"
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
            if std::fs::symlink_metadata(&output).is_ok_and(|m| m.file_type().is_symlink()) {
                let target = std::fs::canonicalize(&output)
                    .map_or_else(|_| "a missing target".into(), |t| t.display().to_string());
                return Err(DatasetError::Invalid {
                    msg: format!(
                        "-o {} is a symbolic link to {target}; the dataset is written to a \
                         temporary directory and renamed into place, which cannot go through \
                         a link: give the directory itself or a new name",
                        output.display()
                    ),
                });
            }
            let d = mjskill::datasets::lerobot::Limits::default();
            let limits = mjskill::datasets::lerobot::Limits {
                chunks_size: limits.chunks_size.unwrap_or(d.chunks_size),
                data_files_size_in_mb: limits
                    .data_files_size_in_mb
                    .unwrap_or(d.data_files_size_in_mb),
                video_files_size_in_mb: limits
                    .video_files_size_in_mb
                    .unwrap_or(d.video_files_size_in_mb),
            };
            mjskill::datasets::lerobot::write_with_limits(file, &output, video, &limits)
        }
    }
}
