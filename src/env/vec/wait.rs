//! How the vector env's threads wait for each other, and how long each one works.
//!
//! A waiting thread spins for at most [`SPIN_TIME`] and then sleeps (`std::thread::park`)
//! until the thread it waits for wakes it. Back-to-back steps (a Rust loop, `mjskill bench`)
//! hand over within the spin; between the steps of a training loop, where Python and torch
//! run for a millisecond or more, the env threads sleep and leave the cores to torch. The
//! spin is bounded by time, not by a count of `pause` instructions, whose length differs
//! tenfold between CPU generations (about 10 ns here, 20,000 of them 212 µs).
//!
//! Each thread adds the time it spends running commands to its own counter, on a cache line
//! of its own ([`Busy`]): [`super::VecEnv::thread_busy_seconds`] tells a slow machine (every
//! thread busy all the time) from threads that wait for each other.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// Longest a waiting thread spins before it sleeps: several times a wake-up's cost on this
/// project's 2-core virtual machine (from `unpark` to running: 1–2 µs median, 8–12 µs at the
/// 99th percentile), and about a tenth of one step of a thread's share (8 Panda envs on 2
/// threads: about 400 µs).
pub(super) const SPIN_TIME: Duration = Duration::from_micros(50);

/// Waits until `ready()` holds: spins for at most [`SPIN_TIME`], then parks, rechecking after
/// every wake-up (`park` may return spuriously, and a stale wake-up returns it at once).
pub(super) fn wait_until(ready: impl Fn() -> bool) {
    if ready() {
        return;
    }
    let start = Instant::now();
    while !ready() {
        if start.elapsed() < SPIN_TIME {
            std::hint::spin_loop();
        } else {
            std::thread::park();
        }
    }
}

/// One thread's running time in nanoseconds, alone on its cache line (two adjacent lines:
/// the prefetcher pairs them), so that counting it never slows the other threads.
#[derive(Debug, Default)]
#[repr(align(128))]
pub(super) struct Busy(AtomicU64);

impl Busy {
    /// Adds the time since `since`.
    pub(super) fn add_since(&self, since: Instant) {
        let ns = since.elapsed().as_nanos().min(u64::MAX as u128) as u64;
        // Only this counter's thread writes it: a load and a store, no read-modify-write.
        let total = self.0.load(Ordering::Relaxed).saturating_add(ns);
        self.0.store(total, Ordering::Relaxed);
    }

    /// The total, in seconds.
    pub(super) fn seconds(&self) -> f64 {
        self.0.load(Ordering::Relaxed) as f64 * 1e-9
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicBool;
    use std::sync::Arc;

    #[test]
    fn a_sleeping_waiter_wakes_when_unparked() {
        let flag = Arc::new(AtomicBool::new(false));
        let waiter = {
            let flag = flag.clone();
            std::thread::spawn(move || wait_until(|| flag.load(Ordering::Acquire)))
        };
        // Long past the spin: the waiter is asleep by now.
        std::thread::sleep(SPIN_TIME * 20);
        flag.store(true, Ordering::Release);
        waiter.thread().unpark();
        waiter.join().expect("the waiter returns");
    }

    #[test]
    fn busy_time_accumulates() {
        let b = Busy::default();
        let t = Instant::now();
        std::thread::sleep(Duration::from_millis(2));
        b.add_since(t);
        let first = b.seconds();
        assert!(first >= 0.002, "{first}");
        b.add_since(Instant::now());
        assert!(b.seconds() >= first);
        assert_eq!(std::mem::align_of::<Busy>(), 128);
    }
}
