//! Rollouts whose policy runs inside the vector env's threads ([`VecEnv::rollout`]).
//!
//! A training loop that steps a [`VecEnv`] from Python crosses into Rust once per step and
//! runs its policy on one thread between the steps. [`VecEnv::rollout`] instead runs `T`
//! steps in one call: before each step every worker thread evaluates the policy on its own
//! envs' observations, clips the actions to the action space and steps its envs, and the
//! caller's buffers receive each step's observations, raw actions, rewards and flags.

use std::sync::atomic::Ordering;
use std::sync::Arc;

use super::{VecEnv, CMD_STEP_POLICY};
use crate::env::EnvError;

/// Steps a [`VecPolicy`] is asked for are below this (2^48): [`VecEnv::rollout`] refuses a
/// `first_step` whose steps would reach it ([`EnvError::RolloutSteps`]), so that a policy
/// keying its noise by the step (as `GaussianMlp` does, in 48 bits) never repeats or wraps.
pub const MAX_POLICY_STEP: u64 = 1 << 48;

/// A policy that [`VecEnv::rollout`] evaluates on the worker threads, each thread on its own
/// contiguous share of the envs.
///
/// Its actions must depend only on the env's global index, the step and the observation (not
/// on how the envs are split over threads or calls), so that a rollout's results are the same
/// for any thread count.
pub trait VecPolicy: Send + Sync + std::fmt::Debug {
    /// Writes the raw actions `actions` (`[k × act_dim]`, row-major) of envs
    /// `first..first + k` for their observations `obs` (`[k × obs_dim]`) at rollout step
    /// `step` (the `first_step` of [`VecEnv::rollout`] plus the step's index, below
    /// [`MAX_POLICY_STEP`]). `scratch` belongs
    /// to the calling thread and is kept between calls, so that a policy allocates only on its
    /// first call.
    fn act(
        &self,
        first: usize,
        step: u64,
        obs: &[f32],
        actions: &mut [f32],
        scratch: &mut Vec<f32>,
    );
}

/// Where [`VecEnv::rollout`] writes `T` steps of `N` envs, step-major (`[T × N × …]`).
#[derive(Debug)]
pub struct RolloutBuffers<'a> {
    /// `[T × N × obs_dim]`: the observation each step's action was chosen from.
    pub obs: &'a mut [f32],
    /// `[T × N × act_dim]`: the policy's raw actions, before clipping to the action space
    /// (0 for an env that reset instead of stepping).
    pub actions: &'a mut [f32],
    /// `[T × N]` rewards.
    pub rewards: &'a mut [f32],
    /// `[T × N]` `terminated` flags.
    pub terminated: &'a mut [bool],
    /// `[T × N]` `truncated` flags.
    pub truncated: &'a mut [bool],
    /// `[T × N]`: the env reset at this step instead of stepping (its action was ignored;
    /// [`VecEnv::autoreset`]).
    pub autoreset: &'a mut [bool],
    /// `[T × N × act_dim]`, optional: the expert's action for the state each step's action
    /// was chosen from, by the labellers of [`VecEnv::set_labellers`] (0 for an env that reset
    /// instead of stepping).
    pub labels: Option<&'a mut [f32]>,
}

impl RolloutBuffers<'_> {
    /// The number of steps the buffers hold for `n` envs, or the first buffer whose length
    /// does not fit.
    fn steps(&self, n: usize, obs_dim: usize, act_dim: usize) -> Result<usize, EnvError> {
        let t = self.rewards.len() / n.max(1);
        if t == 0 || self.rewards.len() != t * n {
            return Err(EnvError::RolloutBuffer {
                buffer: "rewards",
                got: self.rewards.len(),
                expected: t.max(1) * n,
            });
        }
        let lens = [
            ("obs", self.obs.len(), t * n * obs_dim),
            ("actions", self.actions.len(), t * n * act_dim),
            ("terminated", self.terminated.len(), t * n),
            ("truncated", self.truncated.len(), t * n),
            ("autoreset", self.autoreset.len(), t * n),
            (
                "labels",
                self.labels.as_ref().map_or(t * n * act_dim, |l| l.len()),
                t * n * act_dim,
            ),
        ];
        for (buffer, got, expected) in lens {
            if got != expected {
                return Err(EnvError::RolloutBuffer {
                    buffer,
                    got,
                    expected,
                });
            }
        }
        Ok(t)
    }
}

impl VecEnv {
    /// Runs `T` steps (the buffers' length) with `policy` evaluated on the worker threads:
    /// before each step, every env's raw action is `policy`'s for its current observation,
    /// and the env steps with it clipped to the action space (or, with autoreset on, resets
    /// instead when its episode ended on the previous step, as [`VecEnv::step`] does). Step
    /// `t` of the rollout is the policy's step `first_step + t`. Returns `T`; the observations
    /// after the last step are [`VecEnv::obs`].
    ///
    /// With [`RolloutBuffers::labels`], every env's labeller labels its state before each step
    /// on the env's thread (DAgger's expert labels of the states the policy visits).
    ///
    /// Buffers of the wrong length are [`EnvError::RolloutBuffer`], labels without labellers
    /// [`EnvError::NoLabellers`] and steps that reach [`MAX_POLICY_STEP`] are
    /// [`EnvError::RolloutSteps`], with nothing stepped; a non-finite action is
    /// [`EnvError::PolicyActionNotFinite`] and a labeller's failure [`EnvError::Labeller`],
    /// after the step that produced it (the env with a non-finite action did not step, and
    /// reports `truncated`).
    pub fn rollout(
        &mut self,
        policy: Arc<dyn VecPolicy>,
        first_step: u64,
        out: RolloutBuffers<'_>,
    ) -> Result<usize, EnvError> {
        let (n, od, ad) = (self.num_envs, self.obs_dim, self.act_dim);
        let steps = out.steps(n, od, ad)?;
        if (first_step as u128) + (steps as u128) > MAX_POLICY_STEP as u128 {
            return Err(EnvError::RolloutSteps { first_step, steps });
        }
        let mut labels = out.labels;
        if labels.is_some() && !self.has_labellers() {
            return Err(EnvError::NoLabellers);
        }
        self.shared
            .want_labels
            .store(labels.is_some(), Ordering::Relaxed);
        self.set_policy(Some(policy));
        let mut result = Ok(steps);
        for t in 0..steps {
            out.obs[t * n * od..(t + 1) * n * od].copy_from_slice(&self.obs);
            self.shared
                .policy_step
                .store(first_step + t as u64, Ordering::Relaxed);
            self.dispatch(CMD_STEP_POLICY);
            let actions = &mut out.actions[t * n * ad..(t + 1) * n * ad];
            for (dst, cell) in actions.iter_mut().zip(&self.shared.actions) {
                *dst = f32::from_bits(cell.load(Ordering::Relaxed));
            }
            let row = t * n..(t + 1) * n;
            out.rewards[row.clone()].copy_from_slice(&self.rewards);
            out.terminated[row.clone()].copy_from_slice(&self.terminated);
            out.truncated[row.clone()].copy_from_slice(&self.truncated);
            out.autoreset[row].copy_from_slice(&self.autoreset);
            if let Some(l) = labels.as_deref_mut() {
                self.gather_labels(Some(&mut l[t * n * ad..(t + 1) * n * ad]));
                if let Err(e) = self.take_label_error() {
                    result = Err(e);
                    break;
                }
            }
            if let Some(index) = actions.iter().position(|a| !a.is_finite()) {
                result = Err(EnvError::PolicyActionNotFinite {
                    env: index / ad,
                    step: first_step + t as u64,
                    value: actions[index],
                });
                break;
            }
        }
        self.set_policy(None);
        self.shared.want_labels.store(false, Ordering::Relaxed);
        result
    }

    fn set_policy(&mut self, policy: Option<Arc<dyn VecPolicy>>) {
        match self.shared.policy.lock() {
            Ok(mut p) => *p = policy,
            Err(p) => *p.into_inner() = policy,
        }
    }
}
