//! What the two command lines (`mjskill`, `mjskill-meshes`) share: writing to standard output
//! and the range check of integer flags. Included by each binary with `#[path]`.

use std::io::Write;

/// Writes one line to standard output. A closed pipe (e.g. `mjskill envs | head`) is not an
/// error: the reader has what it wanted.
pub fn emit(line: std::fmt::Arguments) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    let mut out = std::io::stdout().lock();
    match writeln!(out, "{line}").and_then(|()| out.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            Err(format!("cannot write to stdout: {e}").into())
        }
        _ => Ok(()),
    }
}

/// `println!` through [`emit`], returning its error from the enclosing function.
macro_rules! out {
    ($($t:tt)*) => {
        emit(format_args!($($t)*))?
    };
}

/// Parses an integer in `lo..=hi`; any other input (negative, fractional, too large) is an
/// error naming the range.
pub fn ranged(s: &str, lo: u64, hi: u64) -> Result<u64, String> {
    let t = s.trim();
    let v: i128 = t
        .parse()
        .map_err(|_| format!("{t:?} is not an integer; valid: {lo}..={hi}"))?;
    if v < lo as i128 || v > hi as i128 {
        return Err(format!("{v} is not in {lo}..={hi}"));
    }
    Ok(v as u64)
}
