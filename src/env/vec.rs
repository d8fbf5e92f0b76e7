//! `VecEnv`: N environments of one id and config, stepped in parallel on T threads.
//!
//! The calling thread steps the first share of the envs itself; T − 1 worker threads, created
//! once in [`VecEnv::new`], step the rest. A step hands work out by bumping an atomic epoch and
//! waking the workers (`Thread::unpark`); results come back through atomic cells (relaxed
//! stores of f32 bits, published by one release/acquire pair per worker), so the step path
//! takes no locks and allocates nothing. The caller sees contiguous `[N × obs_dim]`
//! observations and `[N]` rewards / terminated / truncated buffers.
//!
//! **Autoreset (gymnasium ≥ 1.0 "next-step" mode).** When env i reports terminated or
//! truncated at step t, the values returned at t are the finished episode's final observation,
//! reward and info. On the next [`VecEnv::step`] env i ignores its action, resets (unseeded:
//! its RNG streams continue, as ManiSkill does for an unseeded reset), and returns the new
//! episode's first observation with reward 0 and terminated = truncated = false;
//! [`VecEnv::autoreset`] marks those envs. So the final observation of an episode is simply
//! the observation returned with its terminated/truncated flag.
//!
//! **Seeds.** `reset(Some(s))` seeds env i with `s + i` (ManiSkill's per-env seeding); every
//! env owns its random streams, so results do not depend on the thread count.

use std::ops::Range;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, AtomicUsize, Ordering};
use std::sync::Arc;
use std::thread::{JoinHandle, Thread};

use super::{make, BoxSpace, Env, EnvConfig, EnvError};

const CMD_STEP: u64 = 0;
const CMD_RESET: u64 = 1;
const CMD_QUIT: u64 = 2;
/// Busy-wait iterations before a waiting thread parks or yields.
const SPINS: u32 = 20_000;

/// State shared between the caller and the workers.
#[derive(Debug)]
struct Shared {
    /// Bumped once per command; workers act when it changes.
    epoch: AtomicU64,
    command: AtomicU64,
    /// Reset seed (valid when `has_seed`).
    seed: AtomicU64,
    has_seed: AtomicBool,
    /// Workers that finished the current command.
    done: AtomicUsize,
    actions: Vec<AtomicU32>,
    obs: Vec<AtomicU32>,
    rewards: Vec<AtomicU32>,
    terminated: Vec<AtomicBool>,
    truncated: Vec<AtomicBool>,
    autoreset: Vec<AtomicBool>,
    info: Vec<AtomicU64>,
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
    }

    fn run(&mut self, sh: &Shared, command: u64) {
        for i in 0..self.envs.len() {
            let g = self.first + i;
            if command == CMD_RESET {
                let seed = sh
                    .has_seed
                    .load(Ordering::Relaxed)
                    .then(|| sh.seed.load(Ordering::Relaxed) + g as u64);
                self.envs[i].reset(seed);
                self.needs_reset[i] = false;
                sh.autoreset[g].store(false, Ordering::Relaxed);
                self.write(sh, i, &self.envs[i], 0.0, false, false);
                continue;
            }
            if self.needs_reset[i] {
                self.envs[i].reset(None);
                self.needs_reset[i] = false;
                sh.autoreset[g].store(true, Ordering::Relaxed);
                self.write(sh, i, &self.envs[i], 0.0, false, false);
                continue;
            }
            sh.autoreset[g].store(false, Ordering::Relaxed);
            for (a, cell) in self
                .action
                .iter_mut()
                .zip(&sh.actions[g * self.act_dim..(g + 1) * self.act_dim])
            {
                *a = f32::from_bits(cell.load(Ordering::Relaxed));
            }
            // Lengths and finiteness were validated by the caller, so stepping cannot fail.
            let (reward, term, trunc) = match self.envs[i].step(&self.action) {
                Ok(s) => (s.reward, s.terminated, s.truncated),
                Err(_) => (f32::NAN, false, true),
            };
            self.needs_reset[i] = term || trunc;
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
    shared: Arc<Shared>,
    /// The envs stepped by the calling thread.
    local: Worker,
    threads: Vec<Thread>,
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
}

impl VecEnv {
    /// Builds `num_envs` envs of `env_id` with `config`, spread over `threads` threads (the
    /// calling thread counts as one). Like [`make`], every env starts reset (env i with seed
    /// 2022 + i).
    pub fn new(
        env_id: &str,
        config: EnvConfig,
        num_envs: usize,
        threads: usize,
    ) -> Result<VecEnv, EnvError> {
        if num_envs == 0 {
            return Err(EnvError::Build("a VecEnv needs at least one env".into()));
        }
        let threads = threads.clamp(1, num_envs);
        let mut envs = Vec::with_capacity(num_envs);
        for _ in 0..num_envs {
            envs.push(make(env_id, config.clone())?);
        }
        let first = &envs[0];
        let obs_dim = first.obs().len();
        let act_dim = first.action_space().shape[0];
        let keys = first.info().keys;
        let nkeys = keys.len();
        let single_action_space = first.action_space().clone();
        let single_observation_space = first.observation_space().clone();
        let cells32 = |n: usize| (0..n).map(|_| AtomicU32::new(0)).collect::<Vec<_>>();
        let flags = |n: usize| (0..n).map(|_| AtomicBool::new(false)).collect::<Vec<_>>();
        let shared = Arc::new(Shared {
            epoch: AtomicU64::new(0),
            command: AtomicU64::new(CMD_STEP),
            seed: AtomicU64::new(0),
            has_seed: AtomicBool::new(false),
            done: AtomicUsize::new(0),
            actions: cells32(num_envs * act_dim),
            obs: cells32(num_envs * obs_dim),
            rewards: cells32(num_envs),
            terminated: flags(num_envs),
            truncated: flags(num_envs),
            autoreset: flags(num_envs),
            info: (0..num_envs * nkeys).map(|_| AtomicU64::new(0)).collect(),
        });
        // Even split: the first `num_envs % threads` shares get one extra env.
        let ranges: Vec<Range<usize>> = (0..threads)
            .map(|t| {
                let (q, r) = (num_envs / threads, num_envs % threads);
                let start = t * q + t.min(r);
                start..start + q + usize::from(t < r)
            })
            .collect();
        let mut workers: Vec<Worker> = Vec::with_capacity(threads);
        for r in ranges.iter().rev() {
            let part: Vec<Env> = envs.drain(r.clone()).collect();
            workers.push(Worker {
                needs_reset: vec![false; part.len()],
                envs: part,
                first: r.start,
                obs_dim,
                act_dim,
                nkeys,
                action: vec![0.0; act_dim],
            });
        }
        workers.reverse();
        let mut workers = workers.into_iter();
        let local = workers.next().expect("at least one share");
        let mut handles = Vec::new();
        let mut thread_handles = Vec::new();
        for (k, mut w) in workers.enumerate() {
            let sh = shared.clone();
            let h = std::thread::Builder::new()
                .name(format!("mjskill-vecenv-{}", k + 1))
                .spawn(move || {
                    let mut seen = 0u64;
                    loop {
                        let mut spins = 0u32;
                        let epoch = loop {
                            let e = sh.epoch.load(Ordering::Acquire);
                            if e != seen {
                                break e;
                            }
                            if spins < SPINS {
                                spins += 1;
                                std::hint::spin_loop();
                            } else {
                                std::thread::park();
                            }
                        };
                        seen = epoch;
                        let command = sh.command.load(Ordering::Relaxed);
                        if command == CMD_QUIT {
                            break;
                        }
                        w.run(&sh, command);
                        sh.done.fetch_add(1, Ordering::Release);
                    }
                })
                .map_err(|e| {
                    EnvError::Build(format!("cannot start a VecEnv worker thread: {e}"))
                })?;
            thread_handles.push(h.thread().clone());
            handles.push(h);
        }
        let mut v = VecEnv {
            num_envs,
            obs_dim,
            act_dim,
            keys,
            shared,
            local,
            threads: thread_handles,
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
        };
        v.shared.has_seed.store(true, Ordering::Relaxed);
        v.shared
            .seed
            .store(super::CONSTRUCTION_SEED, Ordering::Relaxed);
        v.dispatch(CMD_RESET);
        Ok(v)
    }

    /// Runs one command on every thread and gathers the results.
    fn dispatch(&mut self, command: u64) {
        let sh = &*self.shared;
        sh.command.store(command, Ordering::Relaxed);
        sh.done.store(0, Ordering::Relaxed);
        sh.epoch.fetch_add(1, Ordering::Release);
        for t in &self.threads {
            t.unpark();
        }
        self.local.run(sh, command);
        let mut spins = 0u32;
        while sh.done.load(Ordering::Acquire) < self.threads.len() {
            if spins < SPINS {
                spins += 1;
                std::hint::spin_loop();
            } else {
                std::thread::yield_now();
            }
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
    }

    /// Resets every env (env i with seed `s + i`, or unseeded) and returns the observations.
    pub fn reset(&mut self, seed: Option<u64>) -> &[f32] {
        self.shared
            .has_seed
            .store(seed.is_some(), Ordering::Relaxed);
        self.shared.seed.store(seed.unwrap_or(0), Ordering::Relaxed);
        self.dispatch(CMD_RESET);
        &self.obs
    }

    /// Steps every env with its row of `actions` (`[N × action_dim]`, row-major); envs whose
    /// episode ended on the previous step reset instead (see the module documentation).
    pub fn step(&mut self, actions: &[f32]) -> Result<(), EnvError> {
        if actions.len() != self.num_envs * self.act_dim {
            return Err(EnvError::Build(format!(
                "VecEnv actions have {} values, expected {} envs × {} = {}",
                actions.len(),
                self.num_envs,
                self.act_dim,
                self.num_envs * self.act_dim
            )));
        }
        if let Some((index, &value)) = actions.iter().enumerate().find(|(_, a)| !a.is_finite()) {
            return Err(EnvError::ActionNotFinite { index, value });
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
    /// Observation of env `i`.
    pub fn obs_of(&self, i: usize) -> &[f32] {
        &self.obs[i * self.obs_dim..(i + 1) * self.obs_dim]
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
    /// Task info values, `[N × keys]` row-major (booleans as 0/1).
    pub fn info(&self) -> &[f64] {
        &self.info
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
