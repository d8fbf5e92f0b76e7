//! Moving episodes between mjskill recordings (MCAP) and the robot-learning dataset formats:
//!
//! * [`maniskill_h5`]: ManiSkill's native trajectory format (`trajectory.h5` + `.json`),
//!   read and written through HDF5;
//! * [`import`]: `mjskill import-maniskill`, which replays ManiSkill demos in mjskill (by
//!   actions or by states), records them and reports per-episode success and divergence;
//! * [`export`]: `mjskill export --format maniskill|lerobot`, from a recording;
//! * [`lerobot`]: the LeRobotDataset v3 writer (parquet + H.264 mp4).
//!
//! Every writer works on temporary files next to the output and moves them into place only
//! when everything is written, so a failure leaves no partial output behind.
use std::path::{Path, PathBuf};

use crate::env::EnvError;
use crate::record::RecordError;

pub mod export;
pub mod import;
pub mod lerobot;
pub mod maniskill_h5;

/// Errors of the dataset importers and exporters; each names the file concerned.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// Creating, writing, renaming or reading a file failed.
    #[error("{}: {source}", .path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The HDF5 library failed (e.g. a truncated or non-HDF5 file).
    #[error("{}: HDF5 error: {source}", .path.display())]
    Hdf5 {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: hdf5_metno::Error,
    },
    /// The file's content does not have the expected layout.
    #[error("{}: {msg}", .path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        msg: String,
    },
    /// The env could not be made or rejected a state or an action.
    #[error("{}: {source}", .path.display())]
    Env {
        /// The file whose content the env rejected.
        path: PathBuf,
        /// The cause.
        source: EnvError,
    },
    /// Reading or writing a recording failed.
    #[error(transparent)]
    Record(#[from] RecordError),
    /// Writing parquet failed.
    #[error("{}: parquet error: {source}", .path.display())]
    Parquet {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: parquet::errors::ParquetError,
    },
    /// Building the arrow columns failed.
    #[error("{}: arrow error: {source}", .path.display())]
    Arrow {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: arrow_schema::ArrowError,
    },
    /// Encoding or muxing video failed.
    #[error("{}: video error: {msg}", .path.display())]
    Video {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        msg: String,
    },
    /// The request cannot be satisfied (e.g. video requested from a recording without frames).
    #[error("{msg}")]
    Invalid {
        /// What is wrong, with the valid choices.
        msg: String,
    },
}

impl DatasetError {
    pub(crate) fn format(path: &Path, msg: impl Into<String>) -> DatasetError {
        DatasetError::Format {
            path: path.to_path_buf(),
            msg: msg.into(),
        }
    }
    pub(crate) fn io(path: &Path) -> impl Fn(std::io::Error) -> DatasetError + '_ {
        move |source| DatasetError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
    pub(crate) fn hdf5(path: &Path) -> impl Fn(hdf5_metno::Error) -> DatasetError + '_ {
        move |source| DatasetError::Hdf5 {
            path: path.to_path_buf(),
            source,
        }
    }
    pub(crate) fn env(path: &Path) -> impl Fn(EnvError) -> DatasetError + '_ {
        move |source| DatasetError::Env {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// A temporary path next to `path` (same directory, so the final rename is atomic):
/// `.<name>.tmp-<pid>`.
pub(crate) fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".into());
    path.with_file_name(format!(".{name}.tmp-{}", std::process::id()))
}

/// Files or directories written under temporary names and moved to their final names by
/// [`Staged::commit`]; dropped uncommitted, it removes them all.
#[derive(Debug, Default)]
pub(crate) struct Staged {
    entries: Vec<(PathBuf, PathBuf)>,
}

impl Staged {
    /// Registers `final_path`; returns the temporary path to write instead.
    pub(crate) fn add(&mut self, final_path: &Path) -> PathBuf {
        let tmp = temp_path(final_path);
        remove_any(&tmp);
        self.entries.push((tmp.clone(), final_path.to_path_buf()));
        tmp
    }

    /// Moves every temporary to its final name (replacing a file of that name).
    pub(crate) fn commit(mut self) -> Result<(), DatasetError> {
        let entries = std::mem::take(&mut self.entries);
        for (i, (tmp, fin)) in entries.iter().enumerate() {
            if let Err(e) = std::fs::rename(tmp, fin) {
                for (t, _) in &entries[i..] {
                    remove_any(t);
                }
                return Err(DatasetError::Io {
                    path: fin.clone(),
                    source: e,
                });
            }
        }
        Ok(())
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        for (tmp, _) in &self.entries {
            remove_any(tmp);
        }
    }
}

fn remove_any(p: &Path) {
    if p.is_dir() {
        let _ = std::fs::remove_dir_all(p);
    } else {
        let _ = std::fs::remove_file(p);
    }
}
