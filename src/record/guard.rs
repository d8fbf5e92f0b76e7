//! The recording's file behind a guard that writes nothing while its thread panics: the MCAP
//! writer's `Drop` writes the summary, which would make the file of a run that crashed claim
//! to be complete. With the guard, such a file reads as cut short (`complete == false`), like
//! that of a killed run, keeping every finished (already synced) episode.
use std::fs::File;
use std::io::{Seek, SeekFrom, Write};

/// A file that refuses writes while the thread panics.
#[derive(Debug)]
pub(crate) struct UnwindGuard(pub(crate) File);

fn refused() -> std::io::Error {
    std::io::Error::other("not written: the recording thread panicked")
}

impl Write for UnwindGuard {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if std::thread::panicking() {
            return Err(refused());
        }
        self.0.write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        if std::thread::panicking() {
            return Err(refused());
        }
        self.0.flush()
    }
}

impl Seek for UnwindGuard {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        self.0.seek(pos)
    }
}
