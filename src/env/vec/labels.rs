//! Expert labels in the vector env's threads ([`VecEnv::expert_actions`], and
//! [`RolloutBuffers::labels`](super::RolloutBuffers::labels) in [`VecEnv::rollout`]).
//!
//! DAgger needs, for every state a learner visits, the action an expert would take there. The
//! experts (`mjskill::solvers::state_expert`) sit above this layer. The vector env therefore
//! takes them as [`EnvLabeller`]s, one per env, made by the caller from env 0, because every
//! env of a `VecEnv` has the same model. Each worker thread keeps the labellers of its own envs
//! and runs them next to its envs: a round of learner steps with the expert's label of every
//! visited state is one [`VecEnv::rollout`] call.

use std::sync::atomic::Ordering;

use super::{Shared, VecEnv, Worker, CMD_LABEL, CMD_SET_LABELLERS};
use crate::env::{Env, EnvError};

/// Labels an env's current state with an expert's action. The vector env calls it on the thread
/// that steps the env.
pub trait EnvLabeller: Send + std::fmt::Debug {
    /// Writes the expert's action for `env`'s current state into `action` (the env's action
    /// dimension). It must depend on the state alone, so that labels do not depend on the thread
    /// count. An error is a message naming what failed.
    fn label(&mut self, env: &Env, action: &mut [f32]) -> Result<(), String>;
}

impl Worker {
    /// Takes this worker's labellers out of the shared mailbox (`CMD_SET_LABELLERS`).
    pub(super) fn take_labellers(&mut self, sh: &Shared) {
        let mut mailbox = match sh.labeller_mailbox.lock() {
            Ok(m) => m,
            Err(m) => m.into_inner(),
        };
        if let Some(own) = mailbox.get_mut(self.index).and_then(Option::take) {
            self.labellers = own;
        }
    }

    /// Labels env `i` (of this worker) into the shared label cells: its labeller's action for
    /// its current state, or zeros where the env resets instead of stepping. The first failure
    /// of a call is kept in `sh.label_error`; its cells get NaN.
    pub(super) fn label_env(&mut self, sh: &Shared, i: usize, resets: bool) {
        let g = self.first + i;
        let cells = &sh.labels[g * self.act_dim..(g + 1) * self.act_dim];
        if resets {
            for cell in cells {
                cell.store(0, Ordering::Relaxed);
            }
            return;
        }
        let Some(labeller) = self.labellers.get_mut(i) else {
            return;
        };
        self.label.fill(0.0);
        if let Err(message) = labeller.label(&self.envs[i], &mut self.label) {
            self.label.fill(f32::NAN);
            if let Ok(mut slot) = sh.label_error.lock() {
                slot.get_or_insert((g, message));
            }
        }
        for (cell, v) in cells.iter().zip(&self.label) {
            cell.store(v.to_bits(), Ordering::Relaxed);
        }
    }
}

impl VecEnv {
    /// Gives every env a labeller: `make` is called `num_envs` times with env 0 (all envs share
    /// one model) and env i gets the i-th result. Replaces labellers set before. The first error
    /// of `make` is returned, with the labellers set before kept.
    pub fn set_labellers<E>(
        &mut self,
        mut make: impl FnMut(&Env) -> Result<Box<dyn EnvLabeller>, E>,
    ) -> Result<(), E> {
        let mut made = Vec::with_capacity(self.num_envs);
        for _ in 0..self.num_envs {
            made.push(make(&self.local.envs[0])?);
        }
        let mut shares = Vec::with_capacity(self.ranges.len());
        for r in self.ranges.iter().rev() {
            shares.push(Some(made.drain(r.clone()).collect::<Vec<_>>()));
        }
        shares.reverse();
        match self.shared.labeller_mailbox.lock() {
            Ok(mut m) => *m = shares,
            Err(m) => *m.into_inner() = shares,
        }
        self.dispatch(CMD_SET_LABELLERS);
        self.labels = vec![0.0; self.num_envs * self.act_dim];
        Ok(())
    }

    /// Whether the envs have labellers ([`VecEnv::set_labellers`]).
    pub fn has_labellers(&self) -> bool {
        !self.labels.is_empty()
    }

    /// Every env's expert action for its current state (`[N × act_dim]`, row-major), from the
    /// labellers of [`VecEnv::set_labellers`], computed on the envs' threads. Without labellers
    /// it is [`EnvError::NoLabellers`]; a labeller's failure is [`EnvError::Labeller`] naming
    /// the env. Nothing is stepped.
    pub fn expert_actions(&mut self) -> Result<&[f32], EnvError> {
        if !self.has_labellers() {
            return Err(EnvError::NoLabellers);
        }
        self.dispatch(CMD_LABEL);
        self.take_label_error()?;
        self.gather_labels(None);
        Ok(&self.labels)
    }

    /// The first labeller failure of the last command, as an error.
    pub(super) fn take_label_error(&mut self) -> Result<(), EnvError> {
        let failed = match self.shared.label_error.lock() {
            Ok(mut e) => e.take(),
            Err(e) => e.into_inner().take(),
        };
        match failed {
            Some((env, message)) => Err(EnvError::Labeller { env, message }),
            None => Ok(()),
        }
    }

    /// Copies the label cells into `out` (a rollout step's `[N × act_dim]` rows), or into the
    /// env's own labels with `None`.
    pub(super) fn gather_labels(&mut self, out: Option<&mut [f32]>) {
        let dst = match out {
            Some(o) => o,
            None => &mut self.labels[..],
        };
        for (d, cell) in dst.iter_mut().zip(&self.shared.labels) {
            *d = f32::from_bits(cell.load(Ordering::Relaxed));
        }
    }
}
