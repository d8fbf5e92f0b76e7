//! The output file of `mjskill rollout`: written under a temporary name in the same directory
//! and published under its final name once it holds a finished episode, with an exclusive
//! lock that makes two rollouts writing the same file a reported clash.
//!
//! * Before anything is simulated, the rollout takes the output's lock file `.<name>.lock`
//!   next to it (`flock` through [`File::try_lock`]) and holds it until it ends; if another
//!   rollout holds it, that is the clash, refused at once, so two rollouts never write one
//!   `--out` at the same time and a finished recording is never replaced by a run that
//!   started while it was being written. The lock file is removed when the rollout ends (a
//!   killed rollout's is reused). An existing file at the final name is locked too (for
//!   rollouts of versions without the lock file), and the temporary file
//!   `.<name>.<pid>.part` is created and locked.
//! * After the first finished episode, the temporary file becomes the final name: a hard link
//!   when no file is there (atomic, never replacing a file another rollout published
//!   meanwhile), else a rename over the old file (whose lock this rollout holds). Recording
//!   then continues into the same open file, so a rollout killed later leaves every finished
//!   episode under the final name.
//! * A run that fails or is killed before its first episode is finished never touches the
//!   final name (a failed run removes its temporary file; the temporary files of killed runs,
//!   which no process holds locked any more, are removed by the next rollout to the same
//!   name).
//! * The final name must be a regular file or not exist: a device, FIFO, socket or symbolic
//!   link there (even a dangling one), or a name ending in `/`, is refused before anything is
//!   simulated.
//! * The lock file is never opened through a symbolic link (`O_NOFOLLOW`): a link at its path
//!   is an error naming it, and the file it points to is left as it is.

use std::fs::{File, OpenOptions, TryLockError};
use std::io::ErrorKind;
use std::path::{Path, PathBuf};

/// The rollout's output file (see the module documentation).
#[derive(Debug)]
pub struct Output {
    out: PathBuf,
    temp: PathBuf,
    /// The output's lock file, held (locked) until the end.
    _lock: LockFile,
    /// The lock on the file found at the final name at start, held until the end.
    _held: Option<File>,
    published: bool,
}

/// Whether `f` is locked by someone else; Ok(false) after taking the lock (or where the file
/// system has no locks).
fn locked_elsewhere(f: &File) -> std::io::Result<bool> {
    match f.try_lock() {
        Ok(()) => Ok(false),
        Err(TryLockError::WouldBlock) => Ok(true),
        Err(TryLockError::Error(e)) if e.kind() == ErrorKind::Unsupported => Ok(false),
        Err(TryLockError::Error(e)) => Err(e),
    }
}

/// Whether two open files are the same file (the lock this rollout already holds).
fn same_file(a: &File, b: &File) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        match (a.metadata(), b.metadata()) {
            (Ok(x), Ok(y)) => x.dev() == y.dev() && x.ino() == y.ino(),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        let _ = (a, b);
        false
    }
}

/// Removes the temporary files `.<name>.<pid>.part` in `dir` that rollouts killed before
/// their first episode left: those no process holds locked, whose process is gone.
fn remove_stale(dir: &Path, name: &str) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let prefix = format!(".{name}.");
    for e in entries.flatten() {
        let file_name = e.file_name().to_string_lossy().to_string();
        let Some(pid) = file_name
            .strip_prefix(&prefix)
            .and_then(|r| r.strip_suffix(".part"))
            .and_then(|p| p.parse::<u32>().ok())
        else {
            continue;
        };
        if pid == std::process::id() || process_alive(pid) {
            continue;
        }
        let path = e.path();
        if !std::fs::symlink_metadata(&path).is_ok_and(|m| m.is_file()) {
            continue;
        }
        if let Ok(f) = OpenOptions::new().write(true).open(&path) {
            if matches!(locked_elsewhere(&f), Ok(false)) {
                std::fs::remove_file(&path).ok();
            }
        }
    }
}

/// Whether process `pid` is running (Linux's /proc; elsewhere every process counts as alive,
/// so nothing is removed).
fn process_alive(pid: u32) -> bool {
    !Path::new("/proc/self").exists() || Path::new("/proc").join(pid.to_string()).exists()
}

/// The lock file `.<name>.lock` of an output, locked by this process; removed on drop.
#[derive(Debug)]
struct LockFile {
    path: PathBuf,
    file: File,
}

impl LockFile {
    /// Takes the lock of `out` (whose file name is `name`, in `dir`): Ok(None) when another
    /// rollout holds it.
    fn take(dir: &Path, name: &str) -> std::io::Result<Option<LockFile>> {
        let path = dir.join(format!(".{name}.lock"));
        // A lock file removed by its holder between our open and our lock would leave us
        // locking a file no one else can find: lock, then check that the name still leads
        // to the file locked, else try again.
        for _ in 0..10 {
            refuse_link(&path)?;
            let mut opts = OpenOptions::new();
            opts.read(true).write(true).create(true).truncate(false);
            // Never through a symlink (one swapped in after the check fails to open).
            #[cfg(unix)]
            {
                use std::os::unix::fs::OpenOptionsExt;
                opts.custom_flags(libc::O_NOFOLLOW);
            }
            let file = match opts.open(&path) {
                Ok(f) => f,
                Err(e) if e.raw_os_error() == Some(libc::ELOOP) => {
                    refuse_link(&path)?;
                    return Err(e);
                }
                Err(e) => return Err(e),
            };
            match file.try_lock() {
                Ok(()) => {}
                Err(TryLockError::WouldBlock) => return Ok(None),
                Err(TryLockError::Error(e)) if e.kind() == ErrorKind::Unsupported => {
                    return Self::take_unlocked(path, file);
                }
                Err(TryLockError::Error(e)) => return Err(e),
            }
            match File::open(&path) {
                Ok(now) if same_file(&now, &file) => {
                    write_pid(&file);
                    return Ok(Some(LockFile { path, file }));
                }
                Ok(_) => continue,
                Err(e) if e.kind() == ErrorKind::NotFound => continue,
                Err(e) => return Err(e),
            }
        }
        Ok(None)
    }

    /// Where the file system has no `flock`: the lock file names its holder's pid, and a
    /// running holder other than this process is a clash.
    fn take_unlocked(path: PathBuf, file: File) -> std::io::Result<Option<LockFile>> {
        let holder = std::fs::read_to_string(&path)
            .ok()
            .and_then(|s| s.trim().parse::<u32>().ok());
        if holder.is_some_and(|p| p != std::process::id() && process_alive(p)) {
            return Ok(None);
        }
        write_pid(&file);
        Ok(Some(LockFile { path, file }))
    }
}

/// An error when `path` is a symbolic link: the lock file is written (its holder's pid), and
/// a link there would have that written into whatever file it points to.
fn refuse_link(path: &Path) -> std::io::Result<()> {
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.file_type().is_symlink() => {
            let to = std::fs::read_link(path)
                .map(|t| t.display().to_string())
                .unwrap_or_else(|_| "?".into());
            Err(std::io::Error::other(format!(
                "its lock file {} is a symbolic link (to {to}), which mjskill never writes \
                 through; remove the link",
                path.display()
            )))
        }
        _ => Ok(()),
    }
}

/// Writes this process's id into the lock file (who holds it, for people and for file
/// systems without locks).
fn write_pid(file: &File) {
    use std::io::{Seek, Write};
    let mut f = file;
    file.set_len(0).ok();
    f.seek(std::io::SeekFrom::Start(0)).ok();
    f.write_all(format!("{}\n", std::process::id()).as_bytes())
        .ok();
}

impl Drop for LockFile {
    fn drop(&mut self) {
        // Removed while still locked, so a rollout that opened it meanwhile finds, after
        // locking, that the name no longer leads to it and tries again.
        std::fs::remove_file(&self.path).ok();
        self.file.unlock().ok();
    }
}

fn clash(out: &Path) -> String {
    format!(
        "{} is being written by another mjskill rollout (it holds the file's lock); choose \
         another --out or wait for that rollout to finish",
        out.display()
    )
}

impl Output {
    /// Checks the final name and creates the locked temporary file next to it; returns it
    /// with the file to write. Errors name `out`: a directory, a clash with a running
    /// rollout, an unwritable directory.
    pub fn start(out: &Path) -> Result<(Output, File), String> {
        let cannot = |e: std::io::Error| format!("cannot write {}: {e}", out.display());
        let name = out
            .file_name()
            .ok_or_else(|| format!("--out {} names no file", out.display()))?;
        if out.is_dir() {
            return Err(format!("--out {} is a directory", out.display()));
        }
        if out.as_os_str().as_encoded_bytes().ends_with(b"/") {
            return Err(format!(
                "--out {} ends with a slash, which names a directory; name the recording's \
                 file (e.g. {}.mcap)",
                out.display(),
                out.display().to_string().trim_end_matches('/')
            ));
        }
        mjskill::files::check_not_special(out).map_err(|e| {
            format!(
                "--out {}: {}; the recording is written to a temporary file and renamed into \
                 place, which would replace it: name a regular file",
                out.display(),
                e.reason()
            )
        })?;
        if std::fs::symlink_metadata(out).is_ok_and(|m| m.file_type().is_symlink()) {
            let to = std::fs::read_link(out)
                .map(|t| t.display().to_string())
                .unwrap_or_else(|_| "?".into());
            return Err(format!(
                "--out {} is a symbolic link (to {to}); the recording is renamed into place, \
                 which would replace the link rather than write its target: name the file \
                 itself",
                out.display()
            ));
        }
        let dir = match out.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let lock = match LockFile::take(&dir, &name.to_string_lossy()) {
            Ok(Some(l)) => l,
            Ok(None) => return Err(clash(out)),
            Err(e) => return Err(cannot(e)),
        };
        let old = match File::open(out) {
            Ok(f) => {
                if locked_elsewhere(&f).map_err(cannot)? {
                    return Err(clash(out));
                }
                Some(f)
            }
            Err(e) if e.kind() == ErrorKind::NotFound => None,
            Err(e) => return Err(cannot(e)),
        };
        remove_stale(&dir, &name.to_string_lossy());
        let temp = dir.join(format!(
            ".{}.{}.part",
            name.to_string_lossy(),
            std::process::id()
        ));
        let file = OpenOptions::new()
            .write(true)
            .read(true)
            .create_new(true)
            .open(&temp)
            .map_err(cannot)?;
        if let Err(e) = locked_elsewhere(&file) {
            std::fs::remove_file(&temp).ok();
            return Err(cannot(e));
        }
        Ok((
            Output {
                out: out.to_path_buf(),
                temp,
                _lock: lock,
                _held: old,
                published: false,
            },
            file,
        ))
    }

    /// The name the file has now (temporary until [`Output::publish`]).
    pub fn current(&self) -> &Path {
        if self.published {
            &self.out
        } else {
            &self.temp
        }
    }

    /// Whether the file is under its final name.
    pub fn published(&self) -> bool {
        self.published
    }

    /// Gives the file its final name (idempotent). A file at the final name that another
    /// rollout has locked is a clash (only a rollout without the lock file can cause one):
    /// the error says that this run's temporary file is removed, which the caller does.
    pub fn publish(&mut self) -> Result<(), String> {
        if self.published {
            return Ok(());
        }
        let fail = |e: std::io::Error| {
            format!(
                "cannot move the recording to {}: {e}; this run's recording ({}) is removed",
                self.out.display(),
                self.temp.display()
            )
        };
        for _ in 0..3 {
            match File::open(&self.out) {
                Ok(f) => {
                    // The file found at start is locked by this rollout already (a lock is
                    // per open file: opening it again does not share it).
                    let mine = self._held.as_ref().is_some_and(|h| same_file(h, &f));
                    if !mine && locked_elsewhere(&f).map_err(fail)? {
                        return Err(format!(
                            "{}; this run's recording ({}) is removed",
                            clash(&self.out),
                            self.temp.display()
                        ));
                    }
                    std::fs::rename(&self.temp, &self.out).map_err(fail)?;
                    if !mine {
                        self._held = Some(f);
                    }
                }
                Err(e) if e.kind() == ErrorKind::NotFound => {
                    match std::fs::hard_link(&self.temp, &self.out) {
                        Ok(()) => {
                            std::fs::remove_file(&self.temp).map_err(fail)?;
                        }
                        // Another rollout published meanwhile: look again.
                        Err(e) if e.kind() == ErrorKind::AlreadyExists => continue,
                        // No hard links here (some file systems): a plain rename.
                        Err(_) => std::fs::rename(&self.temp, &self.out).map_err(fail)?,
                    }
                }
                Err(e) => return Err(fail(e)),
            }
            self.published = true;
            // Make the new name durable too.
            if let Some(dir) = self.out.parent().filter(|d| !d.as_os_str().is_empty()) {
                if let Ok(d) = File::open(dir) {
                    d.sync_all().ok();
                }
            }
            return Ok(());
        }
        Err(format!(
            "{}; this run's recording ({}) is removed",
            clash(&self.out),
            self.temp.display()
        ))
    }

    /// Removes the temporary file of a run that ends before publishing, and releases the
    /// lock on the old file.
    pub fn discard(self) {
        if !self.published {
            std::fs::remove_file(&self.temp).ok();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hidden files (temporaries) left in `d`.
    fn leftovers(d: &Path) -> Vec<String> {
        std::fs::read_dir(d)
            .unwrap()
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().to_string())
            .filter(|n| n.starts_with('.'))
            .collect()
    }

    #[test]
    fn a_failed_run_before_its_first_episode_leaves_the_old_file() {
        // What a rollout killed or failing in its first episode leaves: the old file as it was.
        let d =
            std::env::temp_dir().join(format!("mjskill-output-{}-unpublished", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let out = d.join("run.mcap");
        std::fs::write(&out, b"old recording").unwrap();
        let (o, mut f) = Output::start(&out).unwrap();
        std::io::Write::write_all(&mut f, b"half an episode").unwrap();
        assert!(o.current() != out && o.current().starts_with(&d));
        o.discard();
        assert_eq!(std::fs::read(&out).unwrap(), b"old recording");
        assert!(leftovers(&d).is_empty());
        // Publishing moves the new file into place; what is written after lands there too.
        let (mut o, mut f) = Output::start(&out).unwrap();
        std::io::Write::write_all(&mut f, b"episode 1").unwrap();
        o.publish().unwrap();
        std::io::Write::write_all(&mut f, b", episode 2").unwrap();
        drop(f);
        assert_eq!(std::fs::read(&out).unwrap(), b"episode 1, episode 2");
        // The lock file goes with the run.
        assert_eq!(leftovers(&d), [".run.mcap.lock"]);
        drop(o);
        assert!(leftovers(&d).is_empty());
    }

    #[test]
    fn a_second_writer_is_refused_while_the_first_holds_the_lock() {
        let d = std::env::temp_dir().join(format!("mjskill-output-{}-lock", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let out = d.join("run.mcap");
        // Before the first has published anything (no file at the final name yet).
        let (a, _fa) = Output::start(&out).unwrap();
        let e = Output::start(&out).unwrap_err();
        assert!(e.contains("another mjskill rollout"), "{e}");
        assert!(d.join(".run.mcap.lock").exists());
        a.discard();
        assert!(leftovers(&d).is_empty(), "{:?}", leftovers(&d));
        let (b, _fb) = Output::start(&out).unwrap();
        b.discard();
        std::fs::remove_dir_all(&d).ok();
    }
}
