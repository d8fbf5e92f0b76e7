//! Buffers a test owns for `VecEnv::rollout`: every output of `T` steps of `N` envs.

use mjskill::RolloutBuffers;

/// All of a rollout's outputs, step-major.
#[derive(Debug, PartialEq)]
pub struct Out {
    pub obs: Vec<f32>,
    pub actions: Vec<f32>,
    pub rewards: Vec<f32>,
    pub terminated: Vec<bool>,
    pub truncated: Vec<bool>,
    pub autoreset: Vec<bool>,
    /// The expert labels (written only by [`Out::labelled`] rollouts).
    pub labels: Vec<f32>,
}

impl Out {
    /// Zeroed buffers for `t` steps of `n` envs.
    pub fn new(t: usize, n: usize, od: usize, ad: usize) -> Out {
        Out {
            obs: vec![0.0; t * n * od],
            actions: vec![0.0; t * n * ad],
            rewards: vec![0.0; t * n],
            terminated: vec![false; t * n],
            truncated: vec![false; t * n],
            autoreset: vec![false; t * n],
            labels: vec![0.0; t * n * ad],
        }
    }

    /// The buffers of a rollout without labels.
    pub fn buffers(&mut self) -> RolloutBuffers<'_> {
        self.with_labels(false)
    }

    /// The buffers of a rollout that also records the expert's labels.
    pub fn labelled(&mut self) -> RolloutBuffers<'_> {
        self.with_labels(true)
    }

    fn with_labels(&mut self, labels: bool) -> RolloutBuffers<'_> {
        RolloutBuffers {
            obs: &mut self.obs,
            actions: &mut self.actions,
            rewards: &mut self.rewards,
            terminated: &mut self.terminated,
            truncated: &mut self.truncated,
            autoreset: &mut self.autoreset,
            labels: labels.then_some(&mut self.labels[..]),
        }
    }
}
