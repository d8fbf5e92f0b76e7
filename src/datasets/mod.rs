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
//! when everything is written (all outputs or none), so a failure leaves no partial output
//! behind. Before anything is read or written, the outputs are checked: an output that is
//! one of the command's inputs (the same device and inode, through any link; or, for a file
//! yet to be created, the same canonical directory and name), two outputs at one path, and
//! an existing output that is not a regular file (a directory, `/dev/full`, a FIFO: a rename
//! would replace the node rather than write into it) are refused with an error naming both
//! paths.
use std::path::{Path, PathBuf};

use crate::env::EnvError;
use crate::record::RecordError;

pub mod export;
pub mod import;
pub mod lerobot;
pub mod maniskill_h5;
mod paths;

pub(crate) use paths::{check_outputs, Named};

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
/// `.<name>.tmp-<pid>`. Those of the same name left by killed runs (whose process is gone)
/// are removed first.
pub(crate) fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".into());
    remove_stale_temps(path, &name);
    path.with_file_name(format!(".{name}.tmp-{}", std::process::id()))
}

/// Removes `.<name>.tmp-<pid>` files and directories next to `path` whose process is gone
/// (Linux's /proc tells; elsewhere nothing is removed).
fn remove_stale_temps(path: &Path, name: &str) {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !Path::new("/proc/self").exists() {
        return;
    }
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let prefix = format!(".{name}.tmp-");
    for e in entries.flatten() {
        let file_name = e.file_name().to_string_lossy().to_string();
        let Some(pid) = file_name
            .strip_prefix(&prefix)
            .and_then(|p| p.parse::<u32>().ok())
        else {
            continue;
        };
        if pid == std::process::id() || Path::new("/proc").join(pid.to_string()).exists() {
            continue;
        }
        match std::fs::symlink_metadata(e.path()) {
            Ok(m) if m.is_dir() => std::fs::remove_dir_all(e.path()).ok(),
            Ok(m) if m.is_file() => std::fs::remove_file(e.path()).ok(),
            _ => None,
        };
    }
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

    /// Moves every temporary to its final name (replacing a file of that name). All or
    /// nothing: if a rename fails, the outputs already moved are taken back (the files they
    /// replaced restored) and the temporaries removed.
    pub(crate) fn commit(mut self) -> Result<(), DatasetError> {
        let entries = std::mem::take(&mut self.entries);
        // (final name, where the file it replaced was kept) of the outputs moved so far.
        let mut moved: Vec<(&Path, Option<PathBuf>)> = Vec::new();
        let mut failure = None;
        for (tmp, fin) in &entries {
            // With more than one output, keep the file being replaced (a hard link, so the
            // final name never goes missing) until every output is in place.
            let kept = (entries.len() > 1 && fin.symlink_metadata().is_ok()).then(|| {
                let k = fin.with_file_name(format!(
                    ".{}.old-{}",
                    fin.file_name()
                        .map_or_else(|| "output".into(), |n| n.to_string_lossy()),
                    std::process::id()
                ));
                remove_any(&k);
                // A copy where the file system has no hard links.
                std::fs::hard_link(fin, &k)
                    .or_else(|_| std::fs::copy(fin, &k).map(|_| ()))
                    .map(|()| k)
            });
            let kept = match kept.transpose() {
                Ok(k) => k,
                Err(source) => {
                    failure = Some(DatasetError::Io {
                        path: fin.clone(),
                        source,
                    });
                    break;
                }
            };
            if let Err(source) = std::fs::rename(tmp, fin) {
                if let Some(k) = kept {
                    remove_any(&k);
                }
                failure = Some(DatasetError::Io {
                    path: fin.clone(),
                    source,
                });
                break;
            }
            moved.push((fin, kept));
        }
        match failure {
            None => {
                for (_, kept) in moved {
                    if let Some(k) = kept {
                        remove_any(&k);
                    }
                }
                Ok(())
            }
            Some(e) => {
                for (fin, kept) in moved.into_iter().rev() {
                    match kept {
                        Some(k) => {
                            let _ = std::fs::rename(&k, fin);
                        }
                        None => remove_any(fin),
                    }
                }
                for (tmp, _) in &entries {
                    remove_any(tmp);
                }
                Err(e)
            }
        }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_commit_restores_the_outputs_already_moved() {
        let d = std::env::temp_dir().join(format!("mjskill-staged-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        let (old, new) = (d.join("old.h5"), d.join("new.h5"));
        std::fs::write(&old, b"old h5").unwrap();
        // The second output's name is a non-empty directory: its rename fails.
        let blocked = d.join("blocked.json");
        std::fs::create_dir_all(blocked.join("x")).unwrap();
        let mut staged = Staged::default();
        for p in [&old, &new, &blocked] {
            let tmp = staged.add(p);
            std::fs::write(tmp, b"new").unwrap();
        }
        let e = staged.commit().unwrap_err().to_string();
        assert!(e.contains("blocked.json"), "{e}");
        assert_eq!(std::fs::read(&old).unwrap(), b"old h5");
        assert!(!new.exists());
        let mut names: Vec<String> = std::fs::read_dir(&d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(names, ["blocked.json", "old.h5"]);
        // Committed in full, the outputs replace the old files and nothing else is left.
        std::fs::remove_dir_all(&blocked).unwrap();
        let mut staged = Staged::default();
        for p in [&old, &blocked] {
            let tmp = staged.add(p);
            std::fs::write(tmp, b"new").unwrap();
        }
        staged.commit().unwrap();
        assert_eq!(std::fs::read(&old).unwrap(), b"new");
        assert_eq!(std::fs::read(&blocked).unwrap(), b"new");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 2);
        std::fs::remove_dir_all(&d).unwrap();
    }
}
