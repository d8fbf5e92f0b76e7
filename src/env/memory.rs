//! The memory a [`VecEnv`](super::VecEnv) of N envs needs, checked against the memory the
//! machine has available before the envs are made (docs/python.md, "How many envs").

use super::{Env, EnvError};

/// Memory of one env besides its MuJoCo model, data and images (bytes): the controller,
/// task, observation writer, the MuJoCo compiler's leftovers and the allocator's overhead.
/// Measured as the resident memory per env of a 200-env VecEnv minus what the model, data
/// and images account for: 0.3 to 0.5 MB over the envs and robots (docs/python.md).
pub const ENV_OVERHEAD_BYTES: u64 = 512 << 10;

/// Memory one env needs beyond its MuJoCo model, data and overhead when it renders (bytes):
/// the offscreen GL context and its framebuffers, measured per rendering env.
pub const RENDER_CONTEXT_BYTES: u64 = 18 << 20;

/// Estimated memory of one env like `env` (bytes): its MuJoCo model and data (buffer and
/// stack), a render context if it renders, `image_bytes` of images and buffers, and
/// [`ENV_OVERHEAD_BYTES`].
pub(crate) fn env_bytes(env: &Env, image_bytes: u64) -> u64 {
    let (buffer, stack) = env.data().memory_bytes();
    let render = if env.config().obs_mode.is_visual() {
        RENDER_CONTEXT_BYTES
    } else {
        0
    };
    env.model().memory_bytes() as u64
        + buffer as u64
        + stack as u64
        + render
        + image_bytes
        + ENV_OVERHEAD_BYTES
}

/// `MemAvailable` of a `/proc/meminfo` text, in bytes.
pub(crate) fn parse_mem_available(meminfo: &str) -> Option<u64> {
    let line = meminfo.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let mut it = line["MemAvailable:".len()..].split_whitespace();
    let kb: u64 = it.next()?.parse().ok()?;
    match it.next() {
        Some("kB") => kb.checked_mul(1024),
        _ => None,
    }
}

/// The memory available for new allocations (`MemAvailable` of `/proc/meminfo`, bytes);
/// None where there is no such file (not Linux), and then nothing is checked.
pub(crate) fn available_bytes() -> Option<u64> {
    parse_mem_available(&std::fs::read_to_string("/proc/meminfo").ok()?)
}

/// Checks that `num_envs` envs of `per_env` bytes fit in `available` bytes (no check when
/// `available` is unknown).
pub(crate) fn check_fits(
    num_envs: usize,
    per_env: u64,
    available: Option<u64>,
) -> Result<(), EnvError> {
    let Some(available) = available else {
        return Ok(());
    };
    if (num_envs as u64).saturating_mul(per_env) > available {
        return Err(EnvError::EnvsExceedMemory {
            num_envs,
            per_env_bytes: per_env,
            available_bytes: available,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mem_available_is_read_in_bytes() {
        let text = "MemTotal:       24684032 kB\nMemFree:        16349184 kB\n\
                    MemAvailable:   22212608 kB\nBuffers:          123 kB\n";
        assert_eq!(parse_mem_available(text), Some(22_212_608 * 1024));
        assert_eq!(parse_mem_available("MemTotal: 5 kB\n"), None);
        assert_eq!(parse_mem_available("MemAvailable: lots\n"), None);
        assert_eq!(parse_mem_available("MemAvailable: 5 MB\n"), None);
    }

    #[test]
    fn envs_that_do_not_fit_are_an_error_naming_the_sizes() {
        let mb = 1 << 20;
        assert!(check_fits(100, mb, Some(100 * mb)).is_ok());
        assert!(check_fits(16_384, 5 * mb, None).is_ok());
        let e = check_fits(4096, 5 * mb, Some(1024 * mb))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("num_envs 4096")
                && e.contains("5120 KB per env")
                && e.contains("20480 MB")
                && e.contains("1024 MB of memory available"),
            "{e}"
        );
        // No overflow on absurd sizes.
        assert!(check_fits(usize::MAX, u64::MAX, Some(1)).is_err());
    }
}
