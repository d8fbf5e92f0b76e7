//! `VecEnv::rollout`: a policy evaluated on the vector env's threads, T steps per call.

use std::sync::Arc;

use mjskill::solvers::{GaussianMlp, MlpError};
mod common;

use common::rollout::Out;
use mjskill::{EnvConfig, EnvError, VecEnv, VecPolicy};

/// A seeded 2-layer MLP (16 tanh units) for `obs_dim` → `act_dim`, with weights large enough
/// that some actions leave the action space's bounds.
fn mlp(obs_dim: usize, act_dim: usize, seed: u32) -> GaussianMlp {
    let w = |n: usize, k: u32| -> Vec<f32> {
        (0..n)
            .map(|i| (i as f32 * 0.37 + k as f32 * 1.3 + seed as f32).sin() * 0.6)
            .collect()
    };
    let layers = vec![
        (w(obs_dim * 16, 1), w(16, 2)),
        (
            w(16 * act_dim, 3).iter().map(|v| v * 4.0).collect(),
            w(act_dim, 4),
        ),
    ];
    let mean = (0..obs_dim).map(|i| (i as f64 * 0.1).cos() * 0.1).collect();
    let std = (0..obs_dim).map(|i| 0.5 + (i % 3) as f64).collect();
    GaussianMlp::new(layers, mean, std, Some(10.0)).unwrap()
}

fn short() -> EnvConfig {
    EnvConfig {
        max_episode_steps: Some(7),
        ..Default::default()
    }
}

fn dims(v: &VecEnv) -> (usize, usize) {
    (
        v.single_observation_space().shape[0],
        v.single_action_space().shape[0],
    )
}

/// `t` steps of `n` envs on `threads` threads, reset with seed 5, whose envs are envs
/// `offset..offset + n` of a larger whole.
fn run(n: usize, threads: usize, offset: u64, t: usize) -> (Out, Vec<f32>) {
    let mut v = VecEnv::new("PickCube-v1", short(), n, threads).unwrap();
    v.reset(Some(5 + offset));
    let (od, ad) = dims(&v);
    let policy = mlp(od, ad, 1)
        .with_noise(vec![0.3; ad], 11, offset)
        .unwrap();
    let mut out = Out::new(t, n, od, ad);
    let policy: Arc<dyn VecPolicy> = Arc::new(policy);
    assert_eq!(v.rollout(policy.clone(), 0, out.buffers()).unwrap(), t);
    // A second call continues where the first stopped (the policy's steps t..2t).
    let mut more = Out::new(t, n, od, ad);
    v.rollout(policy, t as u64, more.buffers()).unwrap();
    out.obs.extend(more.obs);
    out.actions.extend(more.actions);
    out.rewards.extend(more.rewards);
    out.terminated.extend(more.terminated);
    out.truncated.extend(more.truncated);
    out.autoreset.extend(more.autoreset);
    (out, v.obs().to_vec())
}

#[test]
fn a_rollout_is_stepping_with_the_policys_clipped_actions() {
    let (n, t) = (3, 10);
    let (out, last) = run(n, 2, 0, t);
    let mut v = VecEnv::new("PickCube-v1", short(), n, 1).unwrap();
    v.reset(Some(5));
    let (od, ad) = dims(&v);
    let (low, high) = (
        v.single_action_space().low.clone(),
        v.single_action_space().high.clone(),
    );
    let mean_policy = mlp(od, ad, 1);
    let mut scratch = Vec::new();
    let (mut clipped, mut some_clipped, mut noisy) = (vec![0.0; n * ad], false, false);
    for s in 0..2 * t {
        let rows = s * n..(s + 1) * n;
        assert_eq!(
            &out.obs[rows.start * od..rows.end * od],
            v.obs(),
            "step {s}: obs"
        );
        let raw = &out.actions[rows.start * ad..rows.end * ad];
        let mut mean = vec![0.0; n * ad];
        mean_policy.mean(v.obs(), &mut mean, &mut scratch);
        for (k, (&r, &m)) in raw.iter().zip(&mean).enumerate() {
            let (i, j) = (k / ad, k % ad);
            if out.autoreset[s * n + i] {
                assert_eq!(r, 0.0, "no action is taken at an autoreset");
                continue;
            }
            noisy |= (r - m).abs() > 1e-3;
            assert!(
                (r - m).abs() < 2.0,
                "sampled around the mean (std 0.3): {r} vs {m}"
            );
            clipped[k] = r.clamp(low[j], high[j]);
            some_clipped |= clipped[k] != r;
        }
        v.step(&clipped).unwrap();
        assert_eq!(&out.rewards[rows.clone()], v.rewards(), "step {s}: rewards");
        assert_eq!(&out.terminated[rows.clone()], v.terminated());
        assert_eq!(&out.truncated[rows.clone()], v.truncated());
        assert_eq!(&out.autoreset[rows], v.autoreset());
    }
    assert_eq!(last, v.obs());
    assert!(
        noisy && some_clipped,
        "the test exercises noise and clipping"
    );
    assert!(
        out.autoreset.iter().any(|&a| a),
        "episodes of 7 steps autoreset within 20"
    );
}

#[test]
fn rollouts_do_not_depend_on_threads_or_on_how_the_envs_are_split() {
    let whole = run(4, 1, 0, 9);
    assert!(run(4, 3, 0, 9) == whole, "1 and 3 threads differ");
    let (whole, last) = whole;
    // Envs 0..4 as two vector envs of 3 and 1 envs (offsets 0 and 3), as Ray shares them.
    let (a, last_a) = run(3, 2, 0, 9);
    let (b, last_b) = run(1, 1, 3, 9);
    let (od, ad) = (last_b.len(), b.actions.len() / 18);
    fn merge<T: Copy>(x: &[T], y: &[T], w: usize) -> Vec<T> {
        x.chunks(3 * w)
            .zip(y.chunks(w))
            .flat_map(|(p, q)| p.iter().chain(q).copied())
            .collect()
    }
    assert_eq!(merge(&a.obs, &b.obs, od), whole.obs);
    assert_eq!(merge(&a.actions, &b.actions, ad), whole.actions);
    assert_eq!(merge(&a.rewards, &b.rewards, 1), whole.rewards);
    assert_eq!(merge(&a.terminated, &b.terminated, 1), whole.terminated);
    assert_eq!(merge(&a.truncated, &b.truncated, 1), whole.truncated);
    assert_eq!(merge(&a.autoreset, &b.autoreset, 1), whole.autoreset);
    assert_eq!([last_a, last_b].concat(), last);
}

#[test]
fn bad_buffers_and_non_finite_actions_are_errors() {
    let mut v = VecEnv::new("PickCube-v1", short(), 2, 1).unwrap();
    let (od, ad) = dims(&v);
    let policy: Arc<dyn VecPolicy> = Arc::new(mlp(od, ad, 2));
    let before = v.obs().to_vec();
    let mut out = Out::new(3, 2, od, ad);
    out.actions.pop();
    let err = v.rollout(policy.clone(), 0, out.buffers()).unwrap_err();
    assert!(
        matches!(err, EnvError::RolloutBuffer { buffer: "actions", got, expected }
            if got == 3 * 2 * ad - 1 && expected == 3 * 2 * ad),
        "{err}"
    );
    let mut empty = Out::new(0, 2, od, ad);
    let err = v.rollout(policy, 0, empty.buffers()).unwrap_err();
    assert!(
        matches!(
            err,
            EnvError::RolloutBuffer {
                buffer: "rewards",
                ..
            }
        ),
        "{err}"
    );
    assert_eq!(v.obs(), &before[..], "nothing stepped");

    // Weights whose products overflow f32: the action is infinite.
    let huge = GaussianMlp::new(
        vec![(vec![3e38; od * ad], vec![0.0; ad])],
        vec![0.0; od],
        vec![1.0; od],
        None,
    )
    .unwrap();
    let mut out = Out::new(3, 2, od, ad);
    let err = v.rollout(Arc::new(huge), 40, out.buffers()).unwrap_err();
    assert!(
        matches!(err, EnvError::PolicyActionNotFinite { step: 40, .. }),
        "{err}"
    );
    assert!(err.to_string().contains("not finite"), "{err}");
}

#[test]
fn policy_parameters_are_checked() {
    let ok = || (vec![0.5f32; 6], vec![0.0f32; 3]);
    let e = GaussianMlp::new(vec![ok()], vec![0.0; 2], vec![1.0; 3], None).unwrap_err();
    assert_eq!(
        e,
        MlpError::Length {
            what: "obs_std",
            got: 3,
            expected: 2
        }
    );
    let e = GaussianMlp::new(vec![ok()], vec![0.0; 3], vec![1.0; 3], None).unwrap_err();
    assert!(
        matches!(
            e,
            MlpError::LayerShape {
                layer: 0,
                weights: 6,
                bias: 3,
                inputs: 3
            }
        ),
        "{e}"
    );
    let e = GaussianMlp::new(vec![ok()], vec![f64::NAN, 0.0], vec![1.0; 2], None).unwrap_err();
    assert!(
        matches!(
            e,
            MlpError::BadValue {
                what: "obs_mean",
                index: 0,
                ..
            }
        ),
        "{e}"
    );
    let e = GaussianMlp::new(vec![ok()], vec![0.0; 2], vec![1.0, 0.0], None).unwrap_err();
    assert!(
        matches!(
            e,
            MlpError::BadValue {
                what: "obs_std",
                index: 1,
                ..
            }
        ),
        "{e}"
    );
    let m = GaussianMlp::new(vec![ok()], vec![0.0; 2], vec![1.0; 2], None).unwrap();
    let e = m.clone().with_noise(vec![0.1; 2], 0, 0).unwrap_err();
    assert!(
        matches!(
            e,
            MlpError::Length {
                what: "std",
                got: 2,
                expected: 3
            }
        ),
        "{e}"
    );
    let e = m.with_noise(vec![0.1, -1.0, 0.1], 0, 0).unwrap_err();
    assert!(
        matches!(
            e,
            MlpError::BadValue {
                what: "std",
                index: 1,
                ..
            }
        ),
        "{e}"
    );
    assert!(GaussianMlp::new(vec![], vec![], vec![], None).is_err());
}

#[test]
fn the_mean_is_the_mlp_computed_in_f64_within_f32_rounding() {
    let (od, ad) = (5, 2);
    let m = mlp(od, ad, 3);
    let obs: Vec<f32> = (0..3 * od).map(|i| (i as f32 * 0.9).cos() * 3.0).collect();
    let mut out = vec![0.0; 3 * ad];
    m.mean(&obs, &mut out, &mut Vec::new());
    // The same weights, recomputed here in f64.
    let w = |n: usize, k: u32| -> Vec<f64> {
        (0..n)
            .map(|i| ((i as f32 * 0.37 + k as f32 * 1.3 + 3.0).sin() * 0.6) as f64)
            .collect()
    };
    let (w1, b1, b2) = (w(od * 16, 1), w(16, 2), w(ad, 4));
    let w2: Vec<f64> = w(16 * ad, 3)
        .iter()
        .map(|v| (*v as f32 * 4.0) as f64)
        .collect();
    for r in 0..3 {
        let x: Vec<f64> = (0..od)
            .map(|i| {
                let z = (obs[r * od + i] as f64 - (i as f64 * 0.1).cos() * 0.1)
                    / (0.5 + (i % 3) as f64);
                z.clamp(-10.0, 10.0) as f32 as f64
            })
            .collect();
        let h: Vec<f64> = (0..16)
            .map(|j| (b1[j] + (0..od).map(|i| x[i] * w1[i * 16 + j]).sum::<f64>()).tanh())
            .collect();
        for j in 0..ad {
            let y = b2[j] + (0..16).map(|i| h[i] * w2[i * ad + j]).sum::<f64>();
            assert!(
                (y - out[r * ad + j] as f64).abs() < 1e-5,
                "{y} vs {}",
                out[r * ad + j]
            );
        }
    }
}

#[test]
fn the_rational_tanh_is_within_5e7_of_the_exact_one() {
    let mut worst = 0.0f64;
    for i in -200_000..=200_000 {
        let x = i as f32 * 1e-4; // -20..20, through the saturated tails
        let err = (mjskill::solvers::mlp::tanh(x) as f64 - (x as f64).tanh()).abs();
        worst = worst.max(err);
    }
    assert!(worst < 5e-7, "largest error {worst:e}");
    assert_eq!(mjskill::solvers::mlp::tanh(f32::INFINITY), 1.0);
    assert_eq!(mjskill::solvers::mlp::tanh(-1e-5), -1e-5);
}

/// Issue 42, item 5: a bias-only policy (obs_dim 0) gives its bias, and a rollout of envs
/// with obs_mode `none` (no observations) runs instead of panicking in a worker thread
/// (`chunk size must be non-zero`) and leaving the env unusable.
#[test]
fn a_bias_only_policy_acts_on_envs_without_observations() {
    let cfg = EnvConfig {
        obs_mode: mjskill::ObsMode::None,
        ..short()
    };
    let mut v = VecEnv::new("PickCube-v1", cfg, 3, 2).unwrap();
    let (od, ad) = dims(&v);
    assert_eq!(od, 0);
    let bias: Vec<f32> = (0..ad).map(|i| 0.1 * i as f32 - 0.3).collect();
    let p = GaussianMlp::new(vec![(vec![], bias.clone())], vec![], vec![], None).unwrap();
    let mut mean = vec![0.0; 2 * ad];
    p.mean(&[], &mut mean, &mut Vec::new());
    assert_eq!(mean, [bias.clone(), bias.clone()].concat());
    let mut out = Out::new(4, 3, od, ad);
    assert_eq!(v.rollout(Arc::new(p), 0, out.buffers()).unwrap(), 4);
    assert_eq!(&out.actions[..ad], &bias[..]);
    // Still usable.
    v.step(&vec![0.0; 3 * ad]).unwrap();
}

/// Issue 42, minor: the noise is keyed by the step in 48 bits, so steps from 2^48 on would
/// repeat step 0's noise and `2^64 - 1` would wrap: such rollouts are refused, nothing
/// stepped.
#[test]
fn rollout_steps_beyond_the_noise_key_are_refused() {
    let mut v = VecEnv::new("PickCube-v1", short(), 2, 1).unwrap();
    let (od, ad) = dims(&v);
    let policy: Arc<dyn VecPolicy> =
        Arc::new(mlp(od, ad, 2).with_noise(vec![0.5; ad], 3, 0).unwrap());
    let before = v.obs().to_vec();
    let max = mjskill::MAX_POLICY_STEP;
    assert_eq!(max, 1 << 48);
    for first in [max - 2, max, u64::MAX] {
        let mut out = Out::new(3, 2, od, ad);
        let err = v.rollout(policy.clone(), first, out.buffers()).unwrap_err();
        assert_eq!(
            err,
            EnvError::RolloutSteps {
                first_step: first,
                steps: 3
            }
        );
        assert!(err.to_string().contains("at most 281474976710653"), "{err}");
    }
    assert_eq!(v.obs(), &before[..], "nothing stepped");
    let mut out = Out::new(3, 2, od, ad);
    assert_eq!(v.rollout(policy, max - 3, out.buffers()).unwrap(), 3);
}

/// Issue 42, item 1: layers beyond the size limit are refused (Python checks the shapes
/// before copying anything, so a huge broadcast view costs nothing).
#[test]
fn layers_beyond_the_size_limit_are_refused() {
    let max = mjskill::solvers::MAX_LAYER_ELEMENTS;
    let e = GaussianMlp::new(
        vec![(vec![], vec![0.0])],
        vec![0.0; max + 1],
        vec![1.0; max + 1],
        None,
    )
    .unwrap_err();
    assert!(
        matches!(e, MlpError::Length { got, .. } if got == max + 1),
        "{e}"
    );
}

/// Timing of `GaussianMlp::mean` for PPO's 3×256 actor (not a check; `--ignored`).
#[test]
#[ignore]
fn time_the_3x256_actor() {
    let (od, h, ad) = (42, 256, 8);
    let w = |n: usize, k: u32| -> Vec<f32> {
        (0..n)
            .map(|i| ((i as f32) * 0.37 + k as f32).sin() * 0.1)
            .collect()
    };
    let p = GaussianMlp::new(
        vec![
            (w(od * h, 1), w(h, 2)),
            (w(h * h, 3), w(h, 4)),
            (w(h * ad, 5), w(ad, 6)),
        ],
        vec![0.0; od],
        vec![1.0; od],
        Some(10.0),
    )
    .unwrap();
    for rows in [8usize, 128] {
        let obs: Vec<f32> = (0..rows * od).map(|i| (i as f32 * 0.01).cos()).collect();
        let mut out = vec![0.0; rows * ad];
        let mut scratch = Vec::new();
        let reps = 20_000 / rows;
        p.mean(&obs, &mut out, &mut scratch);
        let t = std::time::Instant::now();
        for _ in 0..reps {
            p.mean(&obs, &mut out, &mut scratch);
        }
        let us = t.elapsed().as_secs_f64() * 1e6 / (reps * rows) as f64;
        println!(
            "rows {rows}: {us:.2} us per row (checksum {})",
            out.iter().sum::<f32>()
        );
    }
}
