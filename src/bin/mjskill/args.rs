//! Value parsers of the command line's numeric flags: each checks the valid range, so that a
//! bad value (negative numbers included, which clap would otherwise take for flags) is an
//! error naming the flag and the range, before anything runs.

use mjskill::MAX_SEED;

use crate::cli::ranged;

/// A seed: 0..=4294967295 (ManiSkill's seeds are 32-bit).
pub fn seed(s: &str) -> Result<u64, String> {
    ranged(s, 0, MAX_SEED)
}

/// A number of episodes: 1..=4294967296 (one per 32-bit seed).
pub fn episodes(s: &str) -> Result<usize, String> {
    ranged(s, 1, MAX_SEED + 1).map(|v| v as usize)
}

/// `export --chunks-size`: 1..=4294967295.
pub fn chunks_size(s: &str) -> Result<usize, String> {
    ranged(s, 1, u32::MAX as u64).map(|v| v as usize)
}

/// `bench --steps`: 1..=[`super::bench::MAX_STEPS`].
pub fn bench_steps(s: &str) -> Result<usize, String> {
    ranged(s, 1, super::bench::MAX_STEPS as u64).map(|v| v as usize)
}

/// `bench --envs`: 1..=[`super::bench::MAX_ENVS`].
pub fn envs(s: &str) -> Result<usize, String> {
    ranged(s, 1, super::bench::MAX_ENVS as u64).map(|v| v as usize)
}

/// `bench --threads`: 1..=[`super::bench::MAX_THREADS`].
pub fn threads(s: &str) -> Result<usize, String> {
    ranged(s, 1, super::bench::MAX_THREADS as u64).map(|v| v as usize)
}

/// `bench --render`: 1..=[`super::bench::MAX_RENDER`].
pub fn render_frames(s: &str) -> Result<usize, String> {
    ranged(s, 1, super::bench::MAX_RENDER as u64).map(|v| v as usize)
}

/// A finite float ≥ 0 (`replay --tolerance`).
pub fn tolerance(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a number; valid: a finite number ≥ 0"))?;
    if !(v.is_finite() && v >= 0.0) {
        return Err(format!("{v} is not a finite number ≥ 0"));
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_name_the_valid_values() {
        assert_eq!(seed("4294967295"), Ok(4294967295));
        assert_eq!(seed("-1").unwrap_err(), "-1 is not in 0..=4294967295");
        assert_eq!(
            seed("18446744073709551615").unwrap_err(),
            "18446744073709551615 is not in 0..=4294967295"
        );
        assert!(seed("1e12").unwrap_err().contains("not an integer"));
        assert_eq!(episodes("0").unwrap_err(), "0 is not in 1..=4294967296");
        assert_eq!(episodes("4294967296"), Ok(4294967296));
        assert!(bench_steps("1000000000000")
            .unwrap_err()
            .contains("1..=1000000"));
        assert!(tolerance("nan").unwrap_err().contains("finite"));
        assert!(tolerance("-1").is_err() && tolerance("inf").is_err());
        assert_eq!(tolerance("0"), Ok(0.0));
        assert_eq!(
            chunks_size("-1").unwrap_err(),
            "-1 is not in 1..=4294967295"
        );
    }
}
