//! The memory a [`VecEnv`](super::VecEnv) of N envs needs, checked against the memory the
//! process may still take (the machine's available memory, `RLIMIT_AS`, the cgroup's limit)
//! before the envs are made (docs/python.md, "How many envs").

use super::{Env, EnvError};
use crate::mujoco::limits::{self, Headroom};

/// Memory of one env besides its MuJoCo model, data and images (bytes): the controller,
/// task, observation writer, the MuJoCo compiler's leftovers and the allocator's overhead.
/// Measured as the resident memory per env of a 200-env VecEnv minus what the model, data
/// and images account for: 0.3 to 0.5 MB over the envs and robots (docs/python.md).
pub const ENV_OVERHEAD_BYTES: u64 = 512 << 10;

/// Memory one env needs beyond its MuJoCo model, data and overhead when it renders (bytes):
/// the offscreen GL context and its framebuffers, measured per rendering env.
pub const RENDER_CONTEXT_BYTES: u64 = 18 << 20;

/// Estimated memory of one env like `env` (bytes): its MuJoCo model and data (buffer and
/// stack), a render context, the render model and its data if it renders, `image_bytes` of images and buffers, and
/// [`ENV_OVERHEAD_BYTES`].
pub(crate) fn env_bytes(env: &Env, image_bytes: u64) -> u64 {
    let (buffer, stack) = env.data().memory_bytes();
    // A rendering env also holds the render model (every geom) and its own state.
    let render = match env.render_model() {
        Some(m) => {
            let (b, s) = env.render_data_bytes();
            RENDER_CONTEXT_BYTES + m.memory_bytes() as u64 + b as u64 + s as u64
        }
        None if env.config().obs_mode.is_visual() => RENDER_CONTEXT_BYTES,
        None => 0,
    };
    env.model().memory_bytes() as u64
        + buffer as u64
        + stack as u64
        + render
        + image_bytes
        + ENV_OVERHEAD_BYTES
}

/// Address space one more rendering env takes beyond its resident memory (bytes): measured
/// 64 MB of new address space per `rgb` env made after the first (glibc's 64 MB malloc
/// heaps, reserved by Mesa's context), against 29 MB resident. Under `RLIMIT_AS` the estimate
/// of a rendering env grows by this.
pub const RENDER_ADDRESS_SPACE_BYTES: u64 = 64 << 20;

/// The memory this process may still take: the tightest of `MemAvailable` and the cgroup's
/// `memory.max` less its usage, and separately the address-space limit (`RLIMIT_AS`) less
/// the address space in use, which a rendering env uses more of than its resident memory.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Available {
    /// Resident memory left (None: unknown, e.g. not Linux).
    pub memory: Option<Headroom>,
    /// Address space left under `RLIMIT_AS` (None: no limit).
    pub address_space: Option<Headroom>,
}

/// The limits of this process now.
pub(crate) fn available() -> Available {
    Available {
        memory: [limits::mem_available(), limits::cgroup()]
            .into_iter()
            .flatten()
            .min_by_key(|h| h.bytes),
        address_space: limits::address_space(),
    }
}

/// Checks that `num_envs` envs like `env` of `per_env` bytes fit in both limits of
/// `available`.
pub(crate) fn check_all(
    env: &Env,
    num_envs: usize,
    per_env: u64,
    available: Available,
) -> Result<(), EnvError> {
    check_fits(num_envs, per_env, available.memory)?;
    let extra = if env.config().obs_mode.is_visual() {
        RENDER_ADDRESS_SPACE_BYTES
    } else {
        0
    };
    check_fits(num_envs, per_env + extra, available.address_space)
}

/// Checks that `num_envs` envs of `per_env` bytes fit in `available` (no check when
/// `available` is unknown).
pub(crate) fn check_fits(
    num_envs: usize,
    per_env: u64,
    available: Option<Headroom>,
) -> Result<(), EnvError> {
    let Some(available) = available else {
        return Ok(());
    };
    if (num_envs as u64).saturating_mul(per_env) > available.bytes {
        return Err(EnvError::EnvsExceedMemory {
            num_envs,
            per_env_bytes: per_env,
            available_bytes: available.bytes,
            limit: available.source,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn envs_that_do_not_fit_are_an_error_naming_the_sizes() {
        let mb = 1 << 20;
        let room = |bytes| {
            Some(Headroom {
                bytes,
                source: "MemAvailable in /proc/meminfo",
            })
        };
        assert!(check_fits(100, mb, room(100 * mb)).is_ok());
        assert!(check_fits(16_384, 5 * mb, None).is_ok());
        let e = check_fits(4096, 5 * mb, room(1024 * mb))
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
        assert!(check_fits(usize::MAX, u64::MAX, room(1)).is_err());
    }
}
