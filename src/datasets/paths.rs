//! The output rule of the dataset commands (`import-maniskill`, `export`): before anything is
//! written, every output is checked against every input and every other output, and each
//! output must be a regular file or not exist yet.
//!
//! * Two paths are the same file when they resolve to the same (device, inode) (symbolic and
//!   hard links included); a path that does not exist yet is compared by its canonical parent
//!   directory and its file name.
//! * An output that is an input is refused (the command would destroy what it reads); two
//!   outputs at one path are refused (the second would replace the first).
//! * An existing output that is not a regular file (a directory, a device such as
//!   `/dev/full`, a FIFO, a socket) is refused: the outputs are written to temporary files
//!   next to their final names and renamed into place only when everything is written, so a
//!   failure leaves nothing behind; a rename over a device or FIFO would replace the node
//!   itself rather than write into it, and writing into it directly would forfeit that
//!   guarantee.
use std::path::{Path, PathBuf};

use super::DatasetError;

/// A file a command reads or writes, with how the user named it (a flag, or a description
/// of a default such as "the json next to -o").
#[derive(Debug, Clone, Copy)]
pub(crate) struct Named<'a> {
    /// How the user named it: `-o`, `--json`, `the recording`, ...
    pub what: &'a str,
    /// The path.
    pub path: &'a Path,
}

impl<'a> Named<'a> {
    pub(crate) fn new(what: &'a str, path: &'a Path) -> Named<'a> {
        Named { what, path }
    }

    fn describe(&self) -> String {
        format!("{} {}", self.what, self.path.display())
    }
}

/// What identifies a file: its (device, inode) when it exists, else the canonical path it
/// would be created at.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Identity {
    Inode(u64, u64),
    Path(PathBuf),
}

fn identity(p: &Path) -> Identity {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let Ok(m) = std::fs::metadata(p) {
            return Identity::Inode(m.dev(), m.ino());
        }
    }
    #[cfg(not(unix))]
    {
        if let Ok(c) = std::fs::canonicalize(p) {
            return Identity::Path(c);
        }
    }
    Identity::Path(would_be(p))
}

/// The canonical path a file that does not exist yet would get: its canonical parent
/// directory joined with its file name (the lexical absolute path when the parent does not
/// exist either).
fn would_be(p: &Path) -> PathBuf {
    let parent = match p.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    match (std::fs::canonicalize(&parent), p.file_name()) {
        (Ok(dir), Some(name)) => dir.join(name),
        _ => std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf()),
    }
}

/// What kind of non-regular file `m` is.
fn kind(m: &std::fs::Metadata) -> &'static str {
    let t = m.file_type();
    if t.is_dir() {
        return "a directory";
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    "not a regular file"
}

/// Checks the outputs of a command against its inputs and each other (see the module
/// documentation); nothing is written. Errors name both paths and how they were given.
pub(crate) fn check_outputs(inputs: &[Named], outputs: &[Named]) -> Result<(), DatasetError> {
    let invalid = |msg: String| Err(DatasetError::Invalid { msg });
    for o in outputs {
        if o.path.file_name().is_none() {
            return invalid(format!("{} names no file", o.describe()));
        }
        if let Ok(m) = std::fs::metadata(o.path) {
            if !m.is_file() {
                return invalid(format!(
                    "{} is {}, not a regular file; the output is written to a temporary file \
                     and renamed into place when complete, which would replace it rather \
                     than write into it: name a regular file",
                    o.describe(),
                    kind(&m)
                ));
            }
        }
        let parent = match o.path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        if !parent.is_dir() {
            return invalid(format!(
                "{}: the directory {} does not exist",
                o.describe(),
                parent.display()
            ));
        }
    }
    for (k, o) in outputs.iter().enumerate() {
        let id = identity(o.path);
        if let Some(i) = inputs.iter().find(|i| identity(i.path) == id) {
            return invalid(format!(
                "{} is {}, an input of this command: writing it would destroy the input \
                 (nothing was written); choose another output",
                o.describe(),
                i.describe()
            ));
        }
        if let Some(p) = outputs[..k].iter().find(|p| identity(p.path) == id) {
            return invalid(format!(
                "{} and {} are the same file, but they are two outputs: the second would \
                 replace the first (nothing was written); give them different names",
                p.describe(),
                o.describe()
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn same_file(a: &Path, b: &Path) -> bool {
        identity(a) == identity(b)
    }

    #[test]
    fn same_file_sees_links_and_files_yet_to_be_created() {
        let d = std::env::temp_dir().join(format!("mjskill-paths-{}", std::process::id()));
        std::fs::create_dir_all(d.join("sub")).unwrap();
        let a = d.join("a.h5");
        std::fs::write(&a, b"x").unwrap();
        std::fs::hard_link(&a, d.join("hard.h5")).unwrap();
        #[cfg(unix)]
        std::os::unix::fs::symlink(&a, d.join("soft.h5")).unwrap();
        assert!(same_file(&a, &d.join("hard.h5")));
        #[cfg(unix)]
        assert!(same_file(&a, &d.join("soft.h5")));
        assert!(same_file(&a, &d.join("sub/../a.h5")));
        assert!(!same_file(&a, &d.join("b.h5")));
        // Neither exists: compared through the canonical parent.
        assert!(same_file(&d.join("new.json"), &d.join("sub/../new.json")));
        assert!(!same_file(&d.join("new.json"), &d.join("sub/new.json")));
        let e = check_outputs(
            &[Named::new("the recording", &a)],
            &[Named::new("-o", &d.join("sub/../hard.h5"))],
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("-o") && e.contains("the recording"), "{e}");
        let e = check_outputs(&[], &[Named::new("--json", &d.join("sub"))])
            .unwrap_err()
            .to_string();
        assert!(e.contains("a directory") && e.contains("--json"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }
}
