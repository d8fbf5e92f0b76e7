//! `VecEnv`: N environments of one id and config, stepped in parallel on T threads.
//!
//! The calling thread steps the first share of the envs itself; T − 1 worker threads, created
//! once in [`VecEnv::new`], step the rest. A step hands work out by bumping an atomic epoch and
//! waking the workers (`Thread::unpark`); results come back through atomic cells (relaxed
//! stores of f32 bits, published by one release/acquire pair per worker), and the last worker
//! to finish wakes the caller. So the step path allocates nothing and takes one lock, which no
//! other thread wants in the steady state: that worker's read of the caller's handle (the
//! caller writes it only when it is another thread than last time). A waiting thread spins for
//! at most 50 µs, then sleeps (`wait`), so idle env threads leave the cores to whatever runs
//! between steps. The caller sees contiguous `[N × obs_dim]` observations and `[N]` rewards /
//! terminated / truncated buffers.
//!
//! **Autoreset (gymnasium ≥ 1.0 "next-step" mode).** When env i reports terminated or
//! truncated at step t, the values returned at t are the finished episode's final observation,
//! reward and info. On the next [`VecEnv::step`] env i ignores its action, resets (unseeded:
//! its RNG streams continue, as ManiSkill does for an unseeded reset), and returns the new
//! episode's first observation with reward 0 and terminated = truncated = false;
//! [`VecEnv::autoreset`] marks those envs. So the final observation of an episode is simply
//! the observation returned with its terminated/truncated flag.
//!
//! **Manual resets (ManiSkill's batched env).** With [`VecEnv::set_autoreset`]`(false)` no env
//! resets by itself: an env whose episode ended keeps stepping, as a single [`Env`] (and
//! ManiSkill's batched env) does — `elapsed_steps` keeps counting and `truncated` stays true —
//! until the caller resets it. [`VecEnv::reset_envs`] resets a chosen subset (ManiSkill's
//! `reset(options={"env_idx": ...})`) and leaves every other env's state and buffers as they
//! were.
//!
//! **Camera images.** In the visual obs modes (`rgb`, `depth`, `segmentation`, their `+`
//! combinations, `rgbd`, `pointcloud`) every env renders its
//! sensor cameras (the task's sensor camera, then the robot's mounted ones, e.g. Fetch's
//! `fetch_head` and `fetch_hand`) on the thread that steps it. The pixels cross threads through
//! atomic cells made in [`VecEnv::new`] (colour bytes packed four per `AtomicU32`,
//! segmentation ids two per cell, each env's block padded to whole cells; depth and point
//! coordinates as f32 bits) and are unpacked into the VecEnv's own buffers
//! once every thread is done. [`VecEnv::image`]`(i, name)` returns env i's images of the last
//! `reset`/`step` (after an autoreset: the new episode's first frame, like `obs()`);
//! [`VecEnv::sensor_names`] lists the cameras. A state-only VecEnv has no image cells.
//!
//! **Seeds.** `reset(Some(s))` seeds env i with `s + i` (ManiSkill's per-env seeding; seeds
//! are 32-bit, so as for [`Env::reset`] the seeds act mod 2³², and [`VecEnv::try_reset`]
//! rejects a range that leaves them); every
//! env owns its random streams, so results do not depend on the thread count.
//!
//! **Panics.** A panic inside an env on a worker thread is caught there and re-raised on the
//! caller's thread by the `step`/`reset` that ran it (the same panic a single env would
//! raise), instead of leaving the caller waiting; the VecEnv is unusable afterwards.

use std::any::Any;
use std::ops::Range;
use std::panic::{catch_unwind, resume_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::{JoinHandle, Thread, ThreadId};
use std::time::Instant;

use super::memory;
use super::{depth_to_mm, make, BoxSpace, CameraImage, Env, EnvConfig, EnvError, PointCloud};
use crate::mujoco::Warnings;

mod images;
mod labels;
mod rollout;
mod wait;
use images::{pack_bytes, pack_i16, store_f32, unpack_bytes, unpack_i16, ImageLayout};
pub use labels::EnvLabeller;
pub use rollout::{RolloutBuffers, VecPolicy, MAX_POLICY_STEP};
use wait::{wait_until, Busy};

/// Largest `num_envs` of a [`VecEnv`] (and the most threads the Python binding accepts).
///
/// Every env owns its MuJoCo model and data: measured 2.9 MB resident per PickCube-v1/panda
/// env (about 20 MB when it renders; docs/python.md, "How many envs"), so 16384 envs need
/// about 48 GB, and 10⁶ would need 3 TB. 16384 is 4× the largest batch ManiSkill's GPU
/// simulation is usually run with (4096). A larger request is far more likely a mistake (e.g.
/// `2**62`) than a workload, and is refused up front with [`EnvError::TooManyEnvs`]; a
/// smaller one that would not fit in the memory available is refused with
/// [`EnvError::EnvsExceedMemory`] before the envs are made.
pub const MAX_NUM_ENVS: usize = 16_384;

const CMD_STEP: u64 = 0;
const CMD_RESET: u64 = 1;
const CMD_QUIT: u64 = 2;
/// Reset the envs whose `reset_mask` cell is set; the others are untouched.
const CMD_RESET_SOME: u64 = 4;
/// Step every env with the action of the policy in `Shared::policy` ([`VecEnv::rollout`]).
const CMD_STEP_POLICY: u64 = 5;
/// One thread's labellers, in its envs' order.
type Labellers = Vec<Box<dyn EnvLabeller>>;
/// Label every env's current state ([`VecEnv::expert_actions`]).
const CMD_LABEL: u64 = 6;
/// Take the labellers of [`VecEnv::set_labellers`] out of the mailbox.
const CMD_SET_LABELLERS: u64 = 7;
/// Test-only: workers other than the caller's panic.
#[cfg(test)]
const CMD_TEST_PANIC: u64 = 3;
/// Test-only: workers other than the caller's sleep 20 ms, long past the caller's spin.
#[cfg(test)]
const CMD_TEST_SLEEP: u64 = 8;

impl Worker {
    /// One worker per range of `envs`, in order; `dims` = (obs_dim, act_dim, info keys).
    fn split(
        mut envs: Vec<Env>,
        ranges: &[Range<usize>],
        dims: (usize, usize, usize),
    ) -> Vec<Worker> {
        let (obs_dim, act_dim, nkeys) = dims;
        let mut workers: Vec<Worker> = Vec::with_capacity(ranges.len());
        for (index, r) in ranges.iter().enumerate().rev() {
            let part: Vec<Env> = envs.drain(r.clone()).collect();
            let n = part.len();
            let space = part[0].action_space();
            let (low, high) = (space.low.clone(), space.high.clone());
            workers.push(Worker {
                needs_reset: vec![false; n],
                envs: part,
                first: r.start,
                obs_dim,
                act_dim,
                nkeys,
                action: vec![0.0; act_dim],
                low,
                high,
                policy_obs: vec![0.0; n * obs_dim],
                policy_actions: vec![0.0; n * act_dim],
                policy_scratch: Vec::new(),
                index,
                labellers: Vec::new(),
                label: vec![0.0; act_dim],
            });
        }
        workers.reverse();
        workers
    }
}

/// Even split of `num_envs` over `threads`: the first `num_envs % threads` shares get one
/// extra env.
fn shares(num_envs: usize, threads: usize) -> Vec<Range<usize>> {
    (0..threads)
        .map(|t| {
            let (q, r) = (num_envs / threads, num_envs % threads);
            let start = t * q + t.min(r);
            start..start + q + usize::from(t < r)
        })
        .collect()
}

/// State shared between the caller and the workers.
#[derive(Debug)]
struct Shared {
    /// Bumped once per command; workers act when it changes.
    epoch: AtomicU64,
    command: AtomicU64,
    /// Reset seed (valid when `has_seed`).
    seed: AtomicU64,
    has_seed: AtomicBool,
    /// Whether a full reset rebuilds the envs' per-episode shapes (ManiSkill's reset option
    /// `reconfigure`, see [`Env::reset_with`]).
    reconfigure: AtomicBool,
    /// Workers that finished the current command.
    done: AtomicUsize,
    /// Worker threads (the caller's not counted): the last to finish wakes the caller.
    workers: usize,
    /// The thread that dispatched the current command (the caller may change between calls).
    caller: Mutex<Option<Thread>>,
    /// Each thread's time running commands (index: its share; 0 is the caller's).
    busy: Vec<Busy>,
    /// Whether an ended env resets on the next step ([`VecEnv::set_autoreset`]).
    autoreset_on: AtomicBool,
    /// The envs a `CMD_RESET_SOME` resets.
    reset_mask: Vec<AtomicBool>,
    actions: Vec<AtomicU32>,
    obs: Vec<AtomicU32>,
    rewards: Vec<AtomicU32>,
    terminated: Vec<AtomicBool>,
    truncated: Vec<AtomicBool>,
    autoreset: Vec<AtomicBool>,
    info: Vec<AtomicU64>,
    /// `[N × 8]` MuJoCo warning counts ([`Warnings::counts`]) of each env's last reset/step.
    warnings: Vec<AtomicU32>,
    images: ImageLayout,
    /// `[N × images.rgb_cells]` packed colour bytes (empty unless the mode renders rgb).
    rgb: Vec<AtomicU32>,
    /// `[N × images.depth_len]` depth values as f32 bits (empty unless the mode renders depth).
    depth: Vec<AtomicU32>,
    /// `[N × images.seg_cells]` packed segmentation ids (empty unless the mode renders them).
    seg: Vec<AtomicU32>,
    /// `[N × images.xyzw_len]` point coordinates as f32 bits (`pointcloud` mode only).
    xyzw: Vec<AtomicU32>,
    /// The policy a `CMD_STEP_POLICY` runs (set for the length of a [`VecEnv::rollout`]).
    policy: Mutex<Option<Arc<dyn VecPolicy>>>,
    /// The rollout step a `CMD_STEP_POLICY` runs ([`VecPolicy::act`]'s `step`).
    policy_step: AtomicU64,
    /// `[N × act_dim]` expert labels (f32 bits) of the last labelling.
    labels: Vec<AtomicU32>,
    /// A rollout also labels each env's state before its step.
    want_labels: AtomicBool,
    /// Each thread's labellers on their way to it (`CMD_SET_LABELLERS`).
    labeller_mailbox: Mutex<Vec<Option<Labellers>>>,
    /// The first labeller failure of a command: (global env index, message).
    label_error: Mutex<Option<(usize, String)>>,
    /// Set by a worker whose envs panicked; the payload waits in `panic_payload`.
    panicked: AtomicBool,
    /// The first worker panic, re-raised on the caller's thread (locked only after a panic).
    panic_payload: Mutex<Option<Box<dyn Any + Send>>>,
}

/// The envs one thread steps.
#[derive(Debug)]
struct Worker {
    envs: Vec<Env>,
    /// Global index of `envs[0]`.
    first: usize,
    needs_reset: Vec<bool>,
    obs_dim: usize,
    act_dim: usize,
    nkeys: usize,
    action: Vec<f32>,
    /// The action space's bounds, which a policy's actions are clipped to.
    low: Vec<f32>,
    high: Vec<f32>,
    /// `[envs × obs_dim]` and `[envs × act_dim]`: a policy's inputs and raw actions
    /// (`CMD_STEP_POLICY`), and the policy's own scratch space.
    policy_obs: Vec<f32>,
    policy_actions: Vec<f32>,
    policy_scratch: Vec<f32>,
    /// This worker's share (0: the calling thread's).
    index: usize,
    /// Its envs' labellers (empty until [`VecEnv::set_labellers`]).
    labellers: Vec<Box<dyn EnvLabeller>>,
    /// A label's scratch (`act_dim`).
    label: Vec<f32>,
}

impl Worker {
    fn write(&self, sh: &Shared, i: usize, env: &Env, reward: f32, term: bool, trunc: bool) {
        let g = self.first + i;
        for (cell, v) in sh.obs[g * self.obs_dim..(g + 1) * self.obs_dim]
            .iter()
            .zip(env.obs())
        {
            cell.store(v.to_bits(), Ordering::Relaxed);
        }
        sh.rewards[g].store(reward.to_bits(), Ordering::Relaxed);
        sh.terminated[g].store(term, Ordering::Relaxed);
        sh.truncated[g].store(trunc, Ordering::Relaxed);
        for (cell, v) in sh.info[g * self.nkeys..(g + 1) * self.nkeys]
            .iter()
            .zip(&env.info().values)
        {
            cell.store(v.to_bits(), Ordering::Relaxed);
        }
        let nw = Warnings::default().counts.len();
        for (cell, c) in sh.warnings[g * nw..(g + 1) * nw]
            .iter()
            .zip(env.info().warnings.counts)
        {
            cell.store(c as u32, Ordering::Relaxed);
        }
        let l = &sh.images;
        if let Some(v) = env.vision.as_ref().filter(|_| !l.cams.is_empty()) {
            let (rgb, depth, seg, xyzw) = v.buffers();
            pack_bytes(&sh.rgb[g * l.rgb_cells..(g + 1) * l.rgb_cells], rgb);
            store_f32(&sh.depth[g * l.depth_len..(g + 1) * l.depth_len], depth);
            pack_i16(&sh.seg[g * l.seg_cells..(g + 1) * l.seg_cells], seg);
            store_f32(&sh.xyzw[g * l.xyzw_len..(g + 1) * l.xyzw_len], xyzw);
        }
    }

    /// Runs the rollout's policy on every env's observation (`policy_actions`).
    fn act(&mut self, sh: &Shared) {
        let policy = match sh.policy.lock() {
            Ok(p) => p.clone(),
            Err(p) => p.into_inner().clone(),
        };
        let Some(policy) = policy else {
            return;
        };
        // An obs mode without observations (`none`) has obs_dim 0: nothing to copy.
        if self.obs_dim > 0 {
            for (dst, env) in self
                .policy_obs
                .chunks_exact_mut(self.obs_dim)
                .zip(&self.envs)
            {
                dst.copy_from_slice(env.obs());
            }
        }
        policy.act(
            self.first,
            sh.policy_step.load(Ordering::Relaxed),
            &self.policy_obs,
            &mut self.policy_actions,
            &mut self.policy_scratch,
        );
    }

    fn run(&mut self, sh: &Shared, command: u64) {
        #[cfg(test)]
        if command == CMD_TEST_PANIC {
            assert!(self.first == 0, "test panic in env {}", self.first);
            return;
        }
        #[cfg(test)]
        if command == CMD_TEST_SLEEP {
            if self.first != 0 {
                std::thread::sleep(std::time::Duration::from_millis(20));
            }
            return;
        }
        if command == CMD_SET_LABELLERS {
            self.take_labellers(sh);
            return;
        }
        if command == CMD_LABEL {
            for i in 0..self.envs.len() {
                self.label_env(sh, i, false);
            }
            return;
        }
        if command == CMD_STEP_POLICY {
            self.act(sh);
        }
        let labels = command == CMD_STEP_POLICY && sh.want_labels.load(Ordering::Relaxed);
        for i in 0..self.envs.len() {
            let g = self.first + i;
            let reset_this = command == CMD_RESET
                || (command == CMD_RESET_SOME && sh.reset_mask[g].load(Ordering::Relaxed));
            if command == CMD_RESET_SOME && !reset_this {
                continue;
            }
            if reset_this {
                let seed = sh
                    .has_seed
                    .load(Ordering::Relaxed)
                    .then(|| sh.seed.load(Ordering::Relaxed).wrapping_add(g as u64));
                let reconfigure = command == CMD_RESET && sh.reconfigure.load(Ordering::Relaxed);
                self.envs[i].reset_with(seed, reconfigure);
                self.needs_reset[i] = false;
                sh.autoreset[g].store(false, Ordering::Relaxed);
                self.write(sh, i, &self.envs[i], 0.0, false, false);
                continue;
            }
            if self.needs_reset[i] && sh.autoreset_on.load(Ordering::Relaxed) {
                if command == CMD_STEP_POLICY {
                    // No action is taken: the raw action reported for this step is zero.
                    for cell in &sh.actions[g * self.act_dim..(g + 1) * self.act_dim] {
                        cell.store(0, Ordering::Relaxed);
                    }
                }
                if labels {
                    self.label_env(sh, i, true);
                }
                self.envs[i].reset(None);
                self.needs_reset[i] = false;
                sh.autoreset[g].store(true, Ordering::Relaxed);
                self.write(sh, i, &self.envs[i], 0.0, false, false);
                continue;
            }
            sh.autoreset[g].store(false, Ordering::Relaxed);
            let cells = &sh.actions[g * self.act_dim..(g + 1) * self.act_dim];
            if labels {
                self.label_env(sh, i, false);
            }
            if command == CMD_STEP_POLICY {
                // The policy's raw action goes back to the caller; the env gets it clipped.
                let raw = &self.policy_actions[i * self.act_dim..(i + 1) * self.act_dim];
                for (((a, cell), &r), (&lo, &hi)) in self
                    .action
                    .iter_mut()
                    .zip(cells)
                    .zip(raw)
                    .zip(self.low.iter().zip(&self.high))
                {
                    cell.store(r.to_bits(), Ordering::Relaxed);
                    *a = r.clamp(lo, hi);
                }
            } else {
                for (a, cell) in self.action.iter_mut().zip(cells) {
                    *a = f32::from_bits(cell.load(Ordering::Relaxed));
                }
            }
            // Lengths and finiteness were validated by the caller, so stepping cannot fail.
            let (reward, term, trunc) = match self.envs[i].step(&self.action) {
                Ok(s) => (s.reward, s.terminated, s.truncated),
                Err(_) => (f32::NAN, false, true),
            };
            self.needs_reset[i] = (term || trunc) && sh.autoreset_on.load(Ordering::Relaxed);
            self.write(sh, i, &self.envs[i], reward, term, trunc);
        }
    }
}

/// N environments stepped in parallel; see the module documentation.
#[derive(Debug)]
pub struct VecEnv {
    num_envs: usize,
    obs_dim: usize,
    act_dim: usize,
    keys: &'static [&'static str],
    /// Whether each of `keys` is a flag ([`Env::info_is_flag`]).
    key_is_flag: Vec<bool>,
    shared: Arc<Shared>,
    /// The envs stepped by the calling thread.
    local: Worker,
    threads: Vec<Thread>,
    /// The thread the workers wake when they finish (`Shared::caller`), by id.
    caller: Option<ThreadId>,
    handles: Vec<JoinHandle<()>>,
    ranges: Vec<Range<usize>>,
    single_action_space: BoxSpace,
    single_observation_space: BoxSpace,
    obs: Vec<f32>,
    rewards: Vec<f32>,
    terminated: Vec<bool>,
    truncated: Vec<bool>,
    autoreset: Vec<bool>,
    info: Vec<f64>,
    warnings: Vec<Warnings>,
    sensor_names: Vec<&'static str>,
    /// Unpacked colour bytes, `[N × 4·rgb_cells]` (camera k of env i at
    /// `4·(i·rgb_cells + rgb_cell)`).
    rgb: Vec<u8>,
    /// Depth values, `[N × depth_len]`.
    depth: Vec<f32>,
    /// ManiSkill's millimetre depth of `depth`.
    depth_mm: Vec<i16>,
    /// Segmentation ids, `[N × px]`.
    seg: Vec<i16>,
    /// Point clouds, `[N × 4·px]`.
    xyzw: Vec<f32>,
    /// The expert labels of [`VecEnv::expert_actions`], `[N × act_dim]` (empty without
    /// labellers).
    labels: Vec<f32>,
}

/// Starts worker thread `k` (named `mjskill-vecenv-k`): it waits for each new epoch of
/// `sh` (spinning briefly, then asleep: [`wait`]), runs the epoch's command on its envs,
/// counts itself done (the last one wakes the caller), until the command is [`CMD_QUIT`].
fn spawn_worker(k: usize, mut w: Worker, sh: Arc<Shared>) -> Result<JoinHandle<()>, EnvError> {
    std::thread::Builder::new()
        .name(format!("mjskill-vecenv-{k}"))
        .spawn(move || {
            let mut seen = 0u64;
            loop {
                wait_until(|| sh.epoch.load(Ordering::Acquire) != seen);
                seen = sh.epoch.load(Ordering::Acquire);
                let command = sh.command.load(Ordering::Relaxed);
                if command == CMD_QUIT {
                    break;
                }
                let start = Instant::now();
                // A panic in an env (a bug, or a GL driver failing mid-run) must not
                // leave the caller waiting for `done` forever: it is caught here and
                // re-raised on the caller's thread, as a single env's panic would be.
                if let Err(payload) = catch_unwind(AssertUnwindSafe(|| w.run(&sh, command))) {
                    if let Ok(mut slot) = sh.panic_payload.lock() {
                        slot.get_or_insert(payload);
                    }
                    sh.panicked.store(true, Ordering::Release);
                }
                sh.busy[k].add_since(start);
                if sh.done.fetch_add(1, Ordering::AcqRel) + 1 == sh.workers {
                    // The last worker wakes the caller, in case it stopped spinning.
                    let caller = match sh.caller.lock() {
                        Ok(c) => c.clone(),
                        Err(c) => c.into_inner().clone(),
                    };
                    if let Some(t) = caller {
                        t.unpark();
                    }
                }
            }
        })
        .map_err(|e| EnvError::WorkerThread(e.to_string()))
}

impl VecEnv {
    /// Builds `num_envs` envs of `env_id` with `config`, spread over `threads` threads (the
    /// calling thread counts as one; more threads than envs are clamped to `num_envs`). Like
    /// [`make`], every env starts reset (env i with seed 2022 + i). `num_envs` must be in
    /// `1..=`[`MAX_NUM_ENVS`] ([`EnvError::NoEnvs`], [`EnvError::TooManyEnvs`]), and
    /// `num_envs` envs like the first must fit in the memory available (the tightest of
    /// `MemAvailable` of `/proc/meminfo`, `RLIMIT_AS` less the address space in use and the
    /// cgroup's `memory.max` less its usage; [`EnvError::EnvsExceedMemory`], checked before
    /// the others are made); an env that still cannot be made is
    /// [`EnvError::VecEnvMake`], naming it and `num_envs`.
    pub fn new(
        env_id: &str,
        config: EnvConfig,
        num_envs: usize,
        threads: usize,
    ) -> Result<VecEnv, EnvError> {
        Self::new_within(env_id, config, num_envs, threads, memory::available())
    }

    /// [`VecEnv::new`] given the memory available (None: unknown, not checked).
    fn new_within(
        env_id: &str,
        config: EnvConfig,
        num_envs: usize,
        threads: usize,
        available: memory::Available,
    ) -> Result<VecEnv, EnvError> {
        if num_envs == 0 {
            return Err(EnvError::NoEnvs);
        }
        if num_envs > MAX_NUM_ENVS {
            return Err(EnvError::TooManyEnvs(num_envs));
        }
        let threads = threads.clamp(1, num_envs);
        // ManiSkill's default: a batch of envs keeps the shapes of its construction seeds.
        let config = EnvConfig {
            reconfiguration_freq: Some(config.reconfiguration_freq.unwrap_or(if num_envs == 1 {
                1
            } else {
                0
            })),
            ..config
        };
        let first = make(env_id, config.clone())?;
        let obs_dim = first.obs().len();
        let act_dim = first.action_space().shape[0];
        let images = ImageLayout::of(&first);
        // The first env's size (with its share of the buffers below) times num_envs must fit
        // before the others are made.
        let per_env = memory::env_bytes(&first, images.buffer_bytes(obs_dim + act_dim));
        memory::check_all(&first, num_envs, per_env, available)?;
        let mut envs = Vec::with_capacity(num_envs);
        envs.push(first);
        for index in 1..num_envs {
            let env = make(env_id, config.clone()).map_err(|e| EnvError::VecEnvMake {
                index,
                num_envs,
                source: Box::new(e),
            })?;
            envs.push(env);
        }
        let first = &envs[0];
        let keys = first.info().keys;
        let nkeys = keys.len();
        let key_is_flag = keys.iter().map(|k| first.info_is_flag(k)).collect();
        let single_action_space = first.action_space().clone();
        let single_observation_space = first.observation_space().clone();
        let sensor_names: Vec<&'static str> = images.cams.iter().map(|c| c.name).collect();
        let (rgb_cells, depth_len) = (images.rgb_cells, images.depth_len);
        let (seg_cells, xyzw_len, px) = (images.seg_cells, images.xyzw_len, images.px);
        let cells32 = |n: usize| (0..n).map(|_| AtomicU32::new(0)).collect::<Vec<_>>();
        let flags = |n: usize| (0..n).map(|_| AtomicBool::new(false)).collect::<Vec<_>>();
        let ranges = shares(num_envs, threads);
        let shared = Arc::new(Shared {
            epoch: AtomicU64::new(0),
            command: AtomicU64::new(CMD_STEP),
            seed: AtomicU64::new(0),
            has_seed: AtomicBool::new(false),
            reconfigure: AtomicBool::new(false),
            done: AtomicUsize::new(0),
            workers: ranges.len() - 1,
            caller: Mutex::new(None),
            busy: (0..ranges.len()).map(|_| Busy::default()).collect(),
            autoreset_on: AtomicBool::new(true),
            reset_mask: flags(num_envs),
            actions: cells32(num_envs * act_dim),
            obs: cells32(num_envs * obs_dim),
            rewards: cells32(num_envs),
            terminated: flags(num_envs),
            truncated: flags(num_envs),
            autoreset: flags(num_envs),
            info: (0..num_envs * nkeys).map(|_| AtomicU64::new(0)).collect(),
            warnings: cells32(num_envs * Warnings::default().counts.len()),
            images,
            rgb: cells32(num_envs * rgb_cells),
            depth: cells32(num_envs * depth_len),
            seg: cells32(num_envs * seg_cells),
            xyzw: cells32(num_envs * xyzw_len),
            policy: Mutex::new(None),
            policy_step: AtomicU64::new(0),
            labels: cells32(num_envs * act_dim),
            want_labels: AtomicBool::new(false),
            labeller_mailbox: Mutex::new(Vec::new()),
            label_error: Mutex::new(None),
            panicked: AtomicBool::new(false),
            panic_payload: Mutex::new(None),
        });
        let dims = (obs_dim, act_dim, nkeys);
        let mut workers = Worker::split(envs, &ranges, dims).into_iter();
        let local = workers.next().expect("at least one share");
        let mut handles = Vec::new();
        let mut thread_handles = Vec::new();
        for (k, w) in workers.enumerate() {
            let h = spawn_worker(k + 1, w, shared.clone())?;
            thread_handles.push(h.thread().clone());
            handles.push(h);
        }
        let mut v = VecEnv {
            num_envs,
            obs_dim,
            act_dim,
            keys,
            key_is_flag,
            shared,
            local,
            threads: thread_handles,
            caller: None,
            handles,
            ranges,
            single_action_space,
            single_observation_space,
            obs: vec![0.0; num_envs * obs_dim],
            rewards: vec![0.0; num_envs],
            terminated: vec![false; num_envs],
            truncated: vec![false; num_envs],
            autoreset: vec![false; num_envs],
            info: vec![0.0; num_envs * nkeys],
            warnings: vec![Warnings::default(); num_envs],
            sensor_names,
            rgb: vec![0; num_envs * rgb_cells * 4],
            depth: vec![0.0; num_envs * depth_len],
            depth_mm: vec![0; num_envs * depth_len],
            seg: vec![0; if seg_cells > 0 { num_envs * px } else { 0 }],
            xyzw: vec![0.0; num_envs * xyzw_len],
            labels: Vec::new(),
        };
        v.shared.has_seed.store(true, Ordering::Relaxed);
        v.shared
            .seed
            .store(super::CONSTRUCTION_SEED, Ordering::Relaxed);
        // ManiSkill's construction: a reconfiguring reset, env i with seed 2022 + i.
        v.shared.reconfigure.store(true, Ordering::Relaxed);
        v.dispatch(CMD_RESET);
        v.shared.reconfigure.store(false, Ordering::Relaxed);
        Ok(v)
    }

    /// Runs one command on every thread and gathers the results.
    fn dispatch(&mut self, command: u64) {
        let sh = &*self.shared;
        sh.command.store(command, Ordering::Relaxed);
        sh.done.store(0, Ordering::Relaxed);
        // Only workers wake the caller: a one-thread VecEnv needs no handle.
        if let Some(me) = (!self.threads.is_empty()).then(std::thread::current) {
            if self.caller != Some(me.id()) {
                // A new calling thread (the VecEnv moved): the workers wake this one from now on.
                self.caller = Some(me.id());
                match sh.caller.lock() {
                    Ok(mut c) => *c = Some(me),
                    Err(c) => *c.into_inner() = Some(me),
                }
            }
        }
        sh.epoch.fetch_add(1, Ordering::Release);
        for t in &self.threads {
            t.unpark();
        }
        let start = Instant::now();
        self.local.run(sh, command);
        sh.busy[0].add_since(start);
        let workers = self.threads.len();
        wait_until(|| sh.done.load(Ordering::Acquire) >= workers);
        if sh.panicked.load(Ordering::Acquire) {
            let payload = sh.panic_payload.lock().ok().and_then(|mut p| p.take());
            resume_unwind(payload.unwrap_or_else(|| Box::new("a VecEnv worker panicked")));
        }
        for (dst, cell) in self.obs.iter_mut().zip(&sh.obs) {
            *dst = f32::from_bits(cell.load(Ordering::Relaxed));
        }
        for (dst, cell) in self.rewards.iter_mut().zip(&sh.rewards) {
            *dst = f32::from_bits(cell.load(Ordering::Relaxed));
        }
        for (dst, cell) in self.terminated.iter_mut().zip(&sh.terminated) {
            *dst = cell.load(Ordering::Relaxed);
        }
        for (dst, cell) in self.truncated.iter_mut().zip(&sh.truncated) {
            *dst = cell.load(Ordering::Relaxed);
        }
        for (dst, cell) in self.autoreset.iter_mut().zip(&sh.autoreset) {
            *dst = cell.load(Ordering::Relaxed);
        }
        for (dst, cell) in self.info.iter_mut().zip(&sh.info) {
            *dst = f64::from_bits(cell.load(Ordering::Relaxed));
        }
        let nw = Warnings::default().counts.len();
        for (dst, cells) in self.warnings.iter_mut().zip(sh.warnings.chunks_exact(nw)) {
            for (d, cell) in dst.counts.iter_mut().zip(cells) {
                *d = cell.load(Ordering::Relaxed) as i32;
            }
        }
        unpack_bytes(&mut self.rgb, &sh.rgb);
        let far = sh.images.far;
        for ((dst, mm), cell) in self.depth.iter_mut().zip(&mut self.depth_mm).zip(&sh.depth) {
            *dst = f32::from_bits(cell.load(Ordering::Relaxed));
            *mm = depth_to_mm(*dst, far);
        }
        let px = sh.images.px;
        for (dst, cells) in self
            .seg
            .chunks_exact_mut(px.max(1))
            .zip(sh.seg.chunks_exact(sh.images.seg_cells.max(1)))
        {
            unpack_i16(dst, cells);
        }
        for (dst, cell) in self.xyzw.iter_mut().zip(&sh.xyzw) {
            *dst = f32::from_bits(cell.load(Ordering::Relaxed));
        }
    }

    /// Like [`VecEnv::reset`], but seeds `s..s + N` that leave ManiSkill's 32-bit range
    /// ([`super::checks::MAX_SEED`]) are an error ([`EnvError::BadSeed`] for a seed beyond it,
    /// [`EnvError::VecSeedRange`] naming the seed given when only `s + i` is) and nothing is
    /// reset.
    pub fn try_reset(&mut self, seed: Option<u64>) -> Result<&[f32], EnvError> {
        self.try_reset_with(seed, false)
    }

    /// [`VecEnv::try_reset`] with ManiSkill's reset option `reconfigure`
    /// ([`VecEnv::reset_with`]).
    pub fn try_reset_with(
        &mut self,
        seed: Option<u64>,
        reconfigure: bool,
    ) -> Result<&[f32], EnvError> {
        if let Some(s) = seed {
            let last = s as u128 + self.num_envs as u128 - 1;
            if s > super::checks::MAX_SEED {
                return Err(EnvError::BadSeed(s));
            }
            if last > super::checks::MAX_SEED as u128 {
                return Err(EnvError::VecSeedRange {
                    seed: s,
                    last_env: self.num_envs - 1,
                });
            }
        }
        Ok(self.reset_with(seed, reconfigure))
    }

    /// Resets every env (env i with seed `s + i`, or unseeded) and returns the observations.
    /// Seeds act mod 2³² as for [`Env::reset`] (env i gets `(s + i) mod 2³²`).
    pub fn reset(&mut self, seed: Option<u64>) -> &[f32] {
        self.reset_with(seed, false)
    }

    /// [`VecEnv::reset`] with ManiSkill's reset option `reconfigure`: every env redraws a
    /// task's per-episode shapes (PegInsertionSide-v1) from its seed, as
    /// [`Env::reset_with`]; without it, each env follows its
    /// [`EnvConfig::reconfiguration_freq`] (for a batch of envs by default 0: the shapes of
    /// construction, env i's from seed 2022 + i, as in ManiSkill).
    pub fn reset_with(&mut self, seed: Option<u64>, reconfigure: bool) -> &[f32] {
        self.shared
            .reconfigure
            .store(reconfigure, Ordering::Relaxed);
        self.shared
            .has_seed
            .store(seed.is_some(), Ordering::Relaxed);
        self.shared.seed.store(seed.unwrap_or(0), Ordering::Relaxed);
        self.dispatch(CMD_RESET);
        &self.obs
    }

    /// Resets the envs `i` with `mask[i]` (env i with seed `s + i`, as [`VecEnv::reset`] seeds
    /// it, or unseeded) and returns every env's observations; the other envs keep their state,
    /// observations, rewards, flags and info. A mask of the wrong length is
    /// [`EnvError::VecMaskLength`] and seeds that leave the 32-bit range are
    /// [`EnvError::BadSeed`] or [`EnvError::VecSeedRange`], with nothing reset.
    pub fn reset_envs(&mut self, mask: &[bool], seed: Option<u64>) -> Result<&[f32], EnvError> {
        if mask.len() != self.num_envs {
            return Err(EnvError::VecMaskLength {
                got: mask.len(),
                num_envs: self.num_envs,
            });
        }
        if let (Some(s), Some(last)) = (seed, mask.iter().rposition(|&m| m)) {
            let top = s as u128 + last as u128;
            if s > super::checks::MAX_SEED {
                return Err(EnvError::BadSeed(s));
            }
            if top > super::checks::MAX_SEED as u128 {
                return Err(EnvError::VecSeedRange {
                    seed: s,
                    last_env: last,
                });
            }
        }
        for (cell, &m) in self.shared.reset_mask.iter().zip(mask) {
            cell.store(m, Ordering::Relaxed);
        }
        self.shared
            .has_seed
            .store(seed.is_some(), Ordering::Relaxed);
        self.shared.seed.store(seed.unwrap_or(0), Ordering::Relaxed);
        self.dispatch(CMD_RESET_SOME);
        Ok(&self.obs)
    }

    /// Turns the next-step autoreset on (the default, gymnasium's mode) or off (ManiSkill's
    /// batched env: ended envs keep stepping until [`VecEnv::reset_envs`] or
    /// [`VecEnv::reset`] resets them). Turning it off drops resets still pending from the
    /// last step.
    pub fn set_autoreset(&mut self, on: bool) {
        self.shared.autoreset_on.store(on, Ordering::Relaxed);
    }

    /// Whether ended envs reset on the next step ([`VecEnv::set_autoreset`]).
    pub fn autoreset_enabled(&self) -> bool {
        self.shared.autoreset_on.load(Ordering::Relaxed)
    }

    /// Steps every env with its row of `actions` (`[N × action_dim]`, row-major); with
    /// autoreset on (the default), envs whose episode ended on the previous step reset instead
    /// (see the module documentation).
    pub fn step(&mut self, actions: &[f32]) -> Result<(), EnvError> {
        if actions.len() != self.num_envs * self.act_dim {
            return Err(EnvError::VecActionLength {
                got: actions.len(),
                num_envs: self.num_envs,
                act_dim: self.act_dim,
            });
        }
        if let Some((index, &value)) = actions.iter().enumerate().find(|(_, a)| !a.is_finite()) {
            return Err(EnvError::VecActionNotFinite {
                index,
                env: index / self.act_dim,
                component: index % self.act_dim,
                value,
            });
        }
        for (cell, a) in self.shared.actions.iter().zip(actions) {
            cell.store(a.to_bits(), Ordering::Relaxed);
        }
        self.dispatch(CMD_STEP);
        Ok(())
    }

    /// Number of envs.
    pub fn num_envs(&self) -> usize {
        self.num_envs
    }
    /// Worker threads including the caller.
    pub fn num_threads(&self) -> usize {
        self.ranges.len()
    }
    /// Seconds each thread has spent running commands (resets, steps, rollout steps, labels)
    /// since the VecEnv was built, in [`VecEnv::thread_ranges`]' order. Against the wall time
    /// of the same calls it tells threads that wait for each other (a share idle while another
    /// works) from a machine that runs every thread slower.
    pub fn thread_busy_seconds(&self) -> Vec<f64> {
        self.shared.busy.iter().map(Busy::seconds).collect()
    }
    /// The env index ranges handled by each thread (thread 0 is the caller).
    pub fn thread_ranges(&self) -> &[Range<usize>] {
        &self.ranges
    }
    /// One env's action space.
    pub fn single_action_space(&self) -> &BoxSpace {
        &self.single_action_space
    }
    /// One env's observation space.
    pub fn single_observation_space(&self) -> &BoxSpace {
        &self.single_observation_space
    }
    /// Observations, `[N × obs_dim]` row-major.
    pub fn obs(&self) -> &[f32] {
        &self.obs
    }
    /// Observation of env `i`; `None` for `i ≥ N` (like [`VecEnv::image`]).
    pub fn obs_of(&self, i: usize) -> Option<&[f32]> {
        if i >= self.num_envs {
            return None;
        }
        self.obs.get(i * self.obs_dim..(i + 1) * self.obs_dim)
    }
    /// Rewards of the last step.
    pub fn rewards(&self) -> &[f32] {
        &self.rewards
    }
    /// `terminated` (success) flags of the last step.
    pub fn terminated(&self) -> &[bool] {
        &self.terminated
    }
    /// `truncated` (time limit) flags of the last step.
    pub fn truncated(&self) -> &[bool] {
        &self.truncated
    }
    /// Envs that reset during the last step (their action was ignored).
    pub fn autoreset(&self) -> &[bool] {
        &self.autoreset
    }
    /// Task info keys (columns of [`VecEnv::info`]).
    pub fn info_keys(&self) -> &'static [&'static str] {
        self.keys
    }
    /// Whether info key `key` is a boolean flag (0 or 1), as [`Env::info_is_flag`].
    pub fn info_is_flag(&self, key: &str) -> bool {
        self.keys
            .iter()
            .position(|k| *k == key)
            .is_some_and(|i| self.key_is_flag[i])
    }
    /// Task info values, `[N × keys]` row-major (booleans as 0/1).
    pub fn info(&self) -> &[f64] {
        &self.info
    }
    /// MuJoCo instability warnings of each env's last reset/step (`[N]`, as
    /// [`Env::info`]'s `warnings`: e.g. BADQACC when env i's simulation diverged and MuJoCo
    /// reset it; all zero after a reset or an autoreset).
    pub fn warnings(&self) -> &[Warnings] {
        &self.warnings
    }
    /// Names of the sensor cameras [`VecEnv::image`] serves, as [`Env::sensor_names`] lists
    /// them (the task's sensor camera, then the robot's mounted cameras); empty unless the obs
    /// mode is visual.
    pub fn sensor_names(&self) -> &[&'static str] {
        &self.sensor_names
    }
    /// Env `i`'s images from sensor camera `camera` after the last `reset`/`step` (after an
    /// autoreset: the new episode's first frame), as [`Env::image`] gives them; `None` for an
    /// env index ≥ N, an unknown camera or a non-visual obs mode.
    pub fn image(&self, i: usize, camera: &str) -> Option<CameraImage<'_>> {
        if i >= self.num_envs {
            return None;
        }
        let l = &self.shared.images;
        let slot = l.cams.iter().find(|c| c.name == camera)?;
        let (w, h) = slot.size;
        let px = i * l.px + slot.at..i * l.px + slot.at + w * h;
        let rgb_at = 4 * i * l.rgb_cells + 3 * slot.at;
        let t = l.tex;
        Some(CameraImage {
            name: slot.name,
            width: w,
            height: h,
            rgb: t.rgb.then(|| &self.rgb[rgb_at..rgb_at + w * h * 3]),
            depth: t.depth.then(|| &self.depth[px.clone()]),
            depth_mm: t.depth.then(|| &self.depth_mm[px.clone()]),
            segmentation: t.segmentation.then(|| &self.seg[px]),
        })
    }

    /// Env `i`'s fused point cloud after the last `reset`/`step` (obs mode `pointcloud`), as
    /// [`Env::point_cloud`] gives it; `None` for `i ≥ N` or another obs mode.
    pub fn point_cloud(&self, i: usize) -> Option<PointCloud<'_>> {
        let l = &self.shared.images;
        if i >= self.num_envs || !l.point_cloud {
            return None;
        }
        let rgb_at = 4 * i * l.rgb_cells;
        Some(PointCloud {
            len: l.px,
            xyzw: &self.xyzw[i * l.xyzw_len..(i + 1) * l.xyzw_len],
            rgb: &self.rgb[rgb_at..rgb_at + 3 * l.px],
            segmentation: &self.seg[i * l.px..(i + 1) * l.px],
        })
    }
}

impl Drop for VecEnv {
    fn drop(&mut self) {
        self.shared.command.store(CMD_QUIT, Ordering::Relaxed);
        self.shared.epoch.fetch_add(1, Ordering::Release);
        for t in &self.threads {
            t.unpark();
        }
        for h in self.handles.drain(..) {
            let _ = h.join();
        }
    }
}

#[cfg(test)]
mod tests;
