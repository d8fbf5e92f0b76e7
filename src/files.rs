//! The one rule for every input file mjskill reads whole (policy files, outcome files, numpy
//! archives, meshes; docs/limits.md):
//!
//! * regular files only: a directory, FIFO, socket or device (also behind a symlink, such as
//!   one to `/dev/zero`) is refused before anything is read, and a FIFO is opened without
//!   blocking, so it never hangs;
//! * at most a limit of bytes, on the file and on what it decompresses to (gzip, zip members,
//!   all members of an archive together): [`max_bytes`], [`DEFAULT_MAX_BYTES`] unless the
//!   environment variable [`MAX_BYTES_VAR`] sets a lower one;
//! * every error names the file, and the limit when it is the limit.
//!
//! [`short`] cuts long values (a 20 MB metadata string) for error messages.
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

/// The default limit of bytes read from one input file, and of the bytes a compressed input
/// expands to: 256 MiB.
pub const DEFAULT_MAX_BYTES: u64 = 256 << 20;

/// The environment variable that sets a lower limit than [`DEFAULT_MAX_BYTES`] (bytes; for
/// tests and small machines). A value above the default, or not a number, is ignored.
pub const MAX_BYTES_VAR: &str = "MJSKILL_MAX_FILE_BYTES";

/// The limit of bytes read from one input file or decompressed from it: [`DEFAULT_MAX_BYTES`],
/// or the lower value of [`MAX_BYTES_VAR`]. A value of the variable that is not a decimal
/// number of bytes, or is above [`DEFAULT_MAX_BYTES`], is ignored, and the first call says so
/// on stderr (once per process).
pub fn max_bytes() -> u64 {
    let (limit, warning) = max_bytes_of(std::env::var(MAX_BYTES_VAR).ok().as_deref());
    if let Some(w) = warning {
        static WARNED: std::sync::Once = std::sync::Once::new();
        WARNED.call_once(|| eprintln!("warning: {w}"));
    }
    limit
}

/// The limit [`max_bytes`] takes from the variable's value `value`, and the warning for a
/// value it ignores.
pub fn max_bytes_of(value: Option<&str>) -> (u64, Option<String>) {
    let Some(v) = value else {
        return (DEFAULT_MAX_BYTES, None);
    };
    let t = v.trim();
    let ignored = |why: &str| {
        Some(format!(
            "{MAX_BYTES_VAR}={v:?} is ignored: {why}; the limit stays {DEFAULT_MAX_BYTES} bytes \
             (256 MiB)",
            v = short(v)
        ))
    };
    if t.is_empty() || !t.bytes().all(|b| b.is_ascii_digit()) {
        return (
            DEFAULT_MAX_BYTES,
            ignored("it must be a plain decimal number of bytes, e.g. 1000000"),
        );
    }
    match t.parse::<u64>() {
        Ok(n) if n <= DEFAULT_MAX_BYTES => (n, None),
        _ => (
            DEFAULT_MAX_BYTES,
            ignored("it may only lower the limit, which it exceeds"),
        ),
    }
}

/// Why an input file could not be read. Displayed as `cannot read FILE: REASON`
/// ([`FileError::reason`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FileError {
    /// The operating system's error.
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        reason: String,
    },
    /// Not a regular file.
    NotRegular {
        /// The file.
        path: PathBuf,
        /// What it is: "a directory", "a FIFO", "a character device", ...
        kind: &'static str,
    },
    /// Larger than the limit.
    TooLarge {
        /// The file.
        path: PathBuf,
        /// What is too large: "the file", "its decompressed contents", "member x.npy", ...
        what: String,
        /// The limit.
        limit: u64,
    },
}

impl std::fmt::Display for FileError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "cannot read {}: {}",
            self.path().display(),
            self.reason()
        )
    }
}

impl std::error::Error for FileError {}

impl FileError {
    /// The file.
    pub fn path(&self) -> &Path {
        match self {
            FileError::Io { path, .. }
            | FileError::NotRegular { path, .. }
            | FileError::TooLarge { path, .. } => path,
        }
    }

    /// What went wrong, without the file's name.
    pub fn reason(&self) -> String {
        match self {
            FileError::Io { reason, .. } => reason.clone(),
            FileError::NotRegular { kind, .. } => {
                format!("it is {kind}, not a regular file (mjskill reads regular files only)")
            }
            FileError::TooLarge { what, limit, .. } => format!(
                "{what} is larger than the limit of {limit} bytes (docs/limits.md; \
                 {MAX_BYTES_VAR} sets a lower one)"
            ),
        }
    }

    /// An I/O error on `path`.
    pub fn io(path: &Path, e: std::io::Error) -> FileError {
        FileError::Io {
            path: path.to_path_buf(),
            reason: e.to_string(),
        }
    }
}

/// What a file type is, for messages.
fn kind_of(t: std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if t.is_dir() {
        "a directory"
    } else {
        "not a regular file"
    }
}

/// Refuses a path that exists and is not a regular file (symlinks followed); Ok for a regular
/// file or a path that does not exist. For output paths, checked before anything is written.
pub fn check_not_special(path: &Path) -> Result<(), FileError> {
    match std::fs::metadata(path) {
        Ok(m) if !m.is_file() => Err(FileError::NotRegular {
            path: path.to_path_buf(),
            kind: kind_of(m.file_type()),
        }),
        Ok(_) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(FileError::io(path, e)),
    }
}

/// Opens `path` for reading if it is a regular file (checked on the open file, so a FIFO
/// swapped in meanwhile is refused too; opened non-blocking, so a FIFO never hangs).
pub fn open_regular(path: &Path) -> Result<File, FileError> {
    let mut opts = std::fs::OpenOptions::new();
    opts.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        opts.custom_flags(libc::O_NONBLOCK);
    }
    let f = opts.open(path).map_err(|e| FileError::io(path, e))?;
    let m = f.metadata().map_err(|e| FileError::io(path, e))?;
    if !m.is_file() {
        return Err(FileError::NotRegular {
            path: path.to_path_buf(),
            kind: kind_of(m.file_type()),
        });
    }
    Ok(f)
}

/// Reads all of `reader` (the contents of `path`, or a stream decompressed from it) into
/// memory, at most `limit` bytes; more is [`FileError::TooLarge`] naming `what`.
pub fn read_bounded(
    reader: impl Read,
    path: &Path,
    what: &str,
    limit: u64,
) -> Result<Vec<u8>, FileError> {
    let mut out = Vec::new();
    reader
        .take(limit.saturating_add(1))
        .read_to_end(&mut out)
        .map_err(|e| FileError::io(path, e))?;
    if out.len() as u64 > limit {
        return Err(FileError::TooLarge {
            path: path.to_path_buf(),
            what: what.to_string(),
            limit,
        });
    }
    Ok(out)
}

/// The bytes of the regular file `path`, at most `limit` of them.
pub fn read_limited(path: &Path, limit: u64) -> Result<Vec<u8>, FileError> {
    let f = open_regular(path)?;
    let len = f.metadata().map_err(|e| FileError::io(path, e))?.len();
    let too_large = || FileError::TooLarge {
        path: path.to_path_buf(),
        what: "the file".into(),
        limit,
    };
    if len > limit {
        return Err(too_large());
    }
    read_bounded(f, path, "the file", limit)
}

/// The bytes of the regular file `path`, at most [`max_bytes`] of them.
pub fn read(path: &Path) -> Result<Vec<u8>, FileError> {
    read_limited(path, max_bytes())
}

/// The bytes of `path`, gunzipped when it starts with gzip's magic number; the file and its
/// decompressed contents each at most `limit` bytes.
pub fn read_maybe_gzip(path: &Path, limit: u64) -> Result<Vec<u8>, FileError> {
    let raw = read_limited(path, limit)?;
    if !raw.starts_with(&[0x1f, 0x8b]) {
        return Ok(raw);
    }
    read_bounded(
        flate2::read::MultiGzDecoder::new(raw.as_slice()),
        path,
        "its decompressed contents",
        limit,
    )
}

/// The longest value [`short`] keeps whole, in characters.
pub const SHORT_CHARS: usize = 200;

/// `value` for an error message: whole up to [`SHORT_CHARS`] characters, else its start,
/// `…` and the full length, so a huge value never makes a huge message.
pub fn short(value: &str) -> String {
    match value.char_indices().nth(SHORT_CHARS) {
        None => value.to_string(),
        Some((cut, _)) => format!("{}… ({} bytes)", &value[..cut], value.len()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("mjskill-files-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn bad_limit_values_are_ignored_and_said_so() {
        assert_eq!(max_bytes_of(None), (DEFAULT_MAX_BYTES, None));
        assert_eq!(max_bytes_of(Some(" 1000 ")), (1000, None));
        for bad in [
            "1e3",
            "0x10",
            "1_000",
            "abc",
            "-1",
            "",
            "99999999999999999999999",
        ] {
            let (limit, w) = max_bytes_of(Some(bad));
            assert_eq!(limit, DEFAULT_MAX_BYTES, "{bad}");
            let w = w.unwrap_or_else(|| panic!("{bad} ignored silently"));
            assert!(
                w.contains(&format!("MJSKILL_MAX_FILE_BYTES={bad:?} is ignored")),
                "{w}"
            );
        }
        let (limit, w) = max_bytes_of(Some("300000000"));
        assert_eq!(limit, DEFAULT_MAX_BYTES);
        assert!(w.unwrap().contains("only lower the limit"));
    }

    #[test]
    fn only_regular_files_are_read() {
        let d = dir("regular");
        let e = read(&d).unwrap_err();
        assert!(
            matches!(
                e,
                FileError::NotRegular {
                    kind: "a directory",
                    ..
                }
            ),
            "{e}"
        );
        let e = read(Path::new("/dev/zero")).unwrap_err();
        assert!(e.to_string().contains("a character device"), "{e}");
        // A symlink to a device is the device.
        let link = d.join("zero.onnx");
        std::fs::remove_file(&link).ok();
        std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
        let e = read(&link).unwrap_err();
        assert!(e.to_string().contains(&link.display().to_string()), "{e}");
        assert!(check_not_special(&link).is_err());
        assert!(check_not_special(&d.join("absent")).is_ok());
        // A FIFO without a writer: refused at once, not a hang.
        let fifo = d.join("fifo");
        std::fs::remove_file(&fifo).ok();
        assert!(std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success());
        let e = read(&fifo).unwrap_err();
        assert!(e.to_string().contains("a FIFO"), "{e}");
    }

    #[test]
    fn files_and_decompressed_contents_are_bounded() {
        let d = dir("bounded");
        let f = d.join("big.json");
        std::fs::write(&f, vec![b' '; 1000]).unwrap();
        assert_eq!(read_limited(&f, 1000).unwrap().len(), 1000);
        let e = read_limited(&f, 999).unwrap_err();
        assert_eq!(
            e,
            FileError::TooLarge {
                path: f.clone(),
                what: "the file".into(),
                limit: 999
            }
        );
        assert!(e.to_string().contains("999 bytes"), "{e}");
        // 100 bytes of gzip that expand to 100 kB.
        let gz = d.join("bomb.json.gz");
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
        enc.write_all(&vec![b' '; 100_000]).unwrap();
        std::fs::write(&gz, enc.finish().unwrap()).unwrap();
        assert_eq!(read_maybe_gzip(&gz, 100_000).unwrap().len(), 100_000);
        let e = read_maybe_gzip(&gz, 10_000).unwrap_err();
        assert!(
            matches!(&e, FileError::TooLarge { what, limit: 10_000, .. } if what == "its decompressed contents"),
            "{e}"
        );
    }

    #[test]
    fn long_values_are_cut_in_messages() {
        assert_eq!(short("PickCube-v1"), "PickCube-v1");
        let huge = "é".repeat(10_000_000);
        let s = short(&huge);
        assert!(
            s.len() < 1000 && s.ends_with("… (20000000 bytes)"),
            "{}",
            s.len()
        );
    }
}
