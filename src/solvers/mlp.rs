//! A Gaussian MLP policy for rollouts inside the vector env's threads
//! ([`VecEnv::rollout`](crate::env::VecEnv::rollout)): PPO's actor as `examples/ppo.py` builds
//! it (observation normalisation and clip, dense layers with tanh between them, a
//! state-independent standard deviation), evaluated in f32 with a fixed summation order and a
//! rational tanh, and sampled with a counter-based random stream, so that an env's action
//! depends only on the weights, the env's global index, the step and its observation: the
//! same for any thread count, vector env split or x86-64 machine.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::env::{VecPolicy, MAX_POLICY_STEP};

/// Words of the random stream reserved for one env step (2^20, far more than any action
/// needs). ChaCha8's word position has 68 bits, so steps below 2^48 ([`MAX_POLICY_STEP`],
/// which `VecEnv::rollout` enforces) each get their own words; 2^48 would repeat step 0.
const WORDS_PER_STEP: u32 = 20;
const _: () = assert!(MAX_POLICY_STEP == 1 << (68 - WORDS_PER_STEP));

/// Most values one layer's weights (and the observation size, the biases, the standard
/// deviations) may have: 2^24, as for one tensor of a policy file (docs/limits.md). PPO's
/// actors have about 2^16.
pub const MAX_LAYER_ELEMENTS: usize = 1 << 24;

/// Why a [`GaussianMlp`] could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MlpError {
    /// No layers.
    #[error("an MLP policy needs at least one layer")]
    NoLayers,
    /// A layer's weights or bias do not fit the sizes around it.
    #[error(
        "layer {layer} has {weights} weights and {bias} biases, but takes {inputs} inputs \
         (weights are inputs × outputs, row-major, one bias per output, at most {max} weights)",
        max = MAX_LAYER_ELEMENTS
    )]
    LayerShape {
        /// The layer's index.
        layer: usize,
        /// Its weight count.
        weights: usize,
        /// Its bias count.
        bias: usize,
        /// The inputs it takes (the observation size or the previous layer's outputs).
        inputs: usize,
    },
    /// Normalisation statistics or standard deviations of the wrong length.
    #[error("{what} has {got} values, expected {expected}")]
    Length {
        /// Which vector.
        what: &'static str,
        /// Its length.
        got: usize,
        /// The length that fits.
        expected: usize,
    },
    /// A NaN or infinite parameter, or a non-positive standard deviation.
    #[error("{what}[{index}] = {value} is not allowed (finite values; standard deviations > 0)")]
    BadValue {
        /// Which parameter.
        what: &'static str,
        /// Its index.
        index: usize,
        /// Its value.
        value: f64,
    },
}

/// One dense layer, `y = b + x·W` with `W` stored inputs × outputs.
#[derive(Debug, Clone)]
struct Dense {
    w: Vec<f32>,
    b: Vec<f32>,
    inputs: usize,
    outputs: usize,
}

/// Sampling noise: `action = mean + std · ε`, with ε from the env's own random stream.
#[derive(Debug, Clone)]
struct Noise {
    std: Vec<f32>,
    seed: u64,
    env_offset: u64,
}

/// PPO's actor: `mean = MLP(clip((obs − μ)/σ, ±clip))`, optionally sampled around.
#[derive(Debug, Clone)]
pub struct GaussianMlp {
    layers: Vec<Dense>,
    obs_mean: Vec<f64>,
    obs_std: Vec<f64>,
    obs_clip: Option<f64>,
    noise: Option<Noise>,
    width: usize,
}

fn check_finite(what: &'static str, values: impl Iterator<Item = f64>) -> Result<(), MlpError> {
    for (index, value) in values.enumerate() {
        if !value.is_finite() {
            return Err(MlpError::BadValue { what, index, value });
        }
    }
    Ok(())
}

impl GaussianMlp {
    /// The deterministic policy (the mean action) of `layers` (`(weights, bias)`, weights
    /// inputs × outputs row-major; tanh between layers, none after the last) on observations
    /// normalised as `clip((obs − obs_mean)/obs_std, ±obs_clip)` in f64 and rounded to f32.
    pub fn new(
        layers: Vec<(Vec<f32>, Vec<f32>)>,
        obs_mean: Vec<f64>,
        obs_std: Vec<f64>,
        obs_clip: Option<f64>,
    ) -> Result<GaussianMlp, MlpError> {
        if layers.is_empty() {
            return Err(MlpError::NoLayers);
        }
        let obs_dim = obs_mean.len();
        if obs_dim > MAX_LAYER_ELEMENTS {
            return Err(MlpError::Length {
                what: "obs_mean (the observation size)",
                got: obs_dim,
                expected: MAX_LAYER_ELEMENTS,
            });
        }
        if obs_std.len() != obs_dim {
            return Err(MlpError::Length {
                what: "obs_std",
                got: obs_std.len(),
                expected: obs_dim,
            });
        }
        check_finite("obs_mean", obs_mean.iter().copied())?;
        check_finite("obs_std", obs_std.iter().copied())?;
        if let Some((index, &value)) = obs_std.iter().enumerate().find(|(_, s)| **s <= 0.0) {
            return Err(MlpError::BadValue {
                what: "obs_std",
                index,
                value,
            });
        }
        if let Some(c) = obs_clip.filter(|c| !c.is_finite() || *c <= 0.0) {
            return Err(MlpError::BadValue {
                what: "obs_clip",
                index: 0,
                value: c,
            });
        }
        let mut dense = Vec::with_capacity(layers.len());
        let mut inputs = obs_dim;
        for (layer, (w, b)) in layers.into_iter().enumerate() {
            let outputs = b.len();
            if outputs == 0
                || outputs > MAX_LAYER_ELEMENTS
                || Some(w.len()) != inputs.checked_mul(outputs)
                || w.len() > MAX_LAYER_ELEMENTS
            {
                return Err(MlpError::LayerShape {
                    layer,
                    weights: w.len(),
                    bias: b.len(),
                    inputs,
                });
            }
            check_finite("weights", w.iter().map(|&v| v as f64))?;
            check_finite("bias", b.iter().map(|&v| v as f64))?;
            dense.push(Dense {
                w,
                b,
                inputs,
                outputs,
            });
            inputs = outputs;
        }
        let width = dense
            .iter()
            .map(|d| d.outputs)
            .max()
            .unwrap_or(0)
            .max(obs_dim);
        Ok(GaussianMlp {
            layers: dense,
            obs_mean,
            obs_std,
            obs_clip,
            noise: None,
            width,
        })
    }

    /// Samples actions `mean + std · ε` (PPO's exploration), with ε standard normal from a
    /// ChaCha8 stream keyed by `seed`, the env's global index (its index in the vector env
    /// plus `env_offset`, for envs split over several vector envs) and the step.
    pub fn with_noise(
        mut self,
        std: Vec<f32>,
        seed: u64,
        env_offset: u64,
    ) -> Result<Self, MlpError> {
        if std.len() != self.act_dim() {
            return Err(MlpError::Length {
                what: "std",
                got: std.len(),
                expected: self.act_dim(),
            });
        }
        if let Some((index, &s)) = std
            .iter()
            .enumerate()
            .find(|(_, s)| !(s.is_finite() && **s > 0.0))
        {
            return Err(MlpError::BadValue {
                what: "std",
                index,
                value: s as f64,
            });
        }
        self.noise = Some(Noise {
            std,
            seed,
            env_offset,
        });
        Ok(self)
    }

    /// Observation size.
    pub fn obs_dim(&self) -> usize {
        self.obs_mean.len()
    }

    /// Action size.
    pub fn act_dim(&self) -> usize {
        self.layers.last().map_or(0, |l| l.outputs)
    }

    /// Mean actions of `k` observations (`obs`: `[k × obs_dim]`, `out`: `[k × act_dim]`;
    /// `k` is `out`'s row count, and a policy of `obs_dim` 0 reads nothing from `obs`, so its
    /// actions are the last layer's bias). Each row's result depends only on that row (not on
    /// `k` or the blocking). Rows that `obs` lacks are left as they are.
    pub fn mean(&self, obs: &[f32], out: &mut [f32], scratch: &mut Vec<f32>) {
        let (od, ad) = (self.obs_dim(), self.act_dim());
        let rows = match obs.len().checked_div(od) {
            Some(r) => r.min(out.len() / ad),
            None => out.len() / ad,
        };
        scratch.resize(2 * BLOCK * self.width, 0.0);
        let (a, b) = scratch.split_at_mut(BLOCK * self.width);
        for start in (0..rows).step_by(BLOCK) {
            let k = BLOCK.min(rows - start);
            if od > 0 {
                for (r, x) in a[..k * od].chunks_exact_mut(od).enumerate() {
                    let o = &obs[(start + r) * od..(start + r + 1) * od];
                    for (i, x) in x.iter_mut().enumerate() {
                        let z = (o[i] as f64 - self.obs_mean[i]) / self.obs_std[i];
                        *x = match self.obs_clip {
                            Some(c) => z.clamp(-c, c),
                            None => z,
                        } as f32;
                    }
                }
            }
            let (mut cur, mut next) = (&mut *a, &mut *b);
            for (l, d) in self.layers.iter().enumerate() {
                dense_block(d, k, cur, next);
                if l + 1 < self.layers.len() {
                    next[..k * d.outputs].iter_mut().for_each(|v| *v = tanh(*v));
                }
                std::mem::swap(&mut cur, &mut next);
            }
            out[start * ad..(start + k) * ad].copy_from_slice(&cur[..k * ad]);
        }
    }
}

/// Rows (envs) evaluated together, so that each weight row is read once per block.
const BLOCK: usize = 8;

/// `y[r] = b + Σᵢ x[r][i]·W[i]` for `k` rows, summing over the inputs in order (the same
/// result for a row whatever block it is in).
fn dense_block(d: &Dense, k: usize, x: &[f32], y: &mut [f32]) {
    let (n_in, n_out) = (d.inputs, d.outputs);
    for row in y[..k * n_out].chunks_exact_mut(n_out) {
        row.copy_from_slice(&d.b);
    }
    for (i, w) in d.w.chunks_exact(n_out).enumerate() {
        for (r, row) in y[..k * n_out].chunks_exact_mut(n_out).enumerate() {
            let xi = x[r * n_in + i];
            for (yj, wj) in row.iter_mut().zip(w) {
                *yj += xi * wj;
            }
        }
    }
}

/// `tanh` in f32 by the rational approximation of Eigen's `generic_fast_tanh_float` (a
/// 13/6-degree minimax fit on [−7.9, 7.9], saturating beyond): within 5e-7 of the exact
/// value, and branch-free so that the compiler vectorises the loops that call it.
#[inline]
pub fn tanh(x: f32) -> f32 {
    const CLAMP: f32 = 7.905_311;
    const TINY: f32 = 0.0004;
    const ALPHA: [f32; 7] = [
        -2.760_768_5e-16,
        2.000_188e-13,
        -8.604_672e-11,
        5.122_297e-8,
        1.485_722_4e-5,
        6.372_619_3e-4,
        4.893_524_6e-3,
    ];
    const BETA: [f32; 4] = [1.198_258_4e-6, 1.185_347e-4, 2.268_434_7e-3, 4.893_525e-3];
    let c = x.clamp(-CLAMP, CLAMP);
    let x2 = c * c;
    let p = ALPHA.iter().skip(1).fold(ALPHA[0], |p, a| p * x2 + a) * c;
    let q = BETA.iter().skip(1).fold(BETA[0], |q, b| q * x2 + b);
    if x.abs() < TINY {
        x
    } else {
        p / q
    }
}

impl VecPolicy for GaussianMlp {
    fn act(
        &self,
        first: usize,
        step: u64,
        obs: &[f32],
        actions: &mut [f32],
        scratch: &mut Vec<f32>,
    ) {
        self.mean(obs, actions, scratch);
        let Some(noise) = &self.noise else {
            return;
        };
        let ad = self.act_dim();
        for (r, row) in actions.chunks_exact_mut(ad).enumerate() {
            let mut rng = ChaCha8Rng::seed_from_u64(noise.seed);
            // An offset near 2^64 wraps the stream number (never a panic).
            rng.set_stream(noise.env_offset.wrapping_add((first + r) as u64));
            rng.set_word_pos(u128::from(step) << WORDS_PER_STEP);
            for (a, s) in row.iter_mut().zip(&noise.std) {
                let eps: f32 = StandardNormal.sample(&mut rng);
                *a += s * eps;
            }
        }
    }
}
