//! Expert labels in the vector env (issue 55): `VecEnv::expert_actions` and labelled
//! rollouts give every env the single env's state-expert label, on the envs' threads, for any
//! thread count, and refuse clearly when there are no labellers or no expert.

use std::sync::Arc;

use mjskill::solvers::{set_state_experts, state_expert, GaussianMlp, SolverError};
mod common;

use common::rollout::Out;
use mjskill::{make, EnvConfig, EnvError, VecEnv, VecPolicy};

/// Short episodes, so that rollouts cross autoresets.
const MAX_STEPS: u32 = 6;

fn config(mode: Option<&str>) -> EnvConfig {
    EnvConfig {
        control_mode: mode.map(str::to_string),
        max_episode_steps: Some(MAX_STEPS),
        ..Default::default()
    }
}

/// A seeded 2-layer MLP (16 tanh units) whose actions move the arm about.
fn mlp(obs_dim: usize, act_dim: usize) -> GaussianMlp {
    let w = |n: usize, k: u32| -> Vec<f32> {
        (0..n)
            .map(|i| (i as f32 * 0.37 + k as f32 * 1.3).sin() * 0.6)
            .collect()
    };
    let layers = vec![
        (w(obs_dim * 16, 1), w(16, 2)),
        (w(16 * act_dim, 3), w(act_dim, 4)),
    ];
    let mean = vec![0.0; obs_dim];
    let std = vec![1.0; obs_dim];
    GaussianMlp::new(layers, mean, std, Some(10.0)).unwrap()
}

/// A labelled rollout of `t` steps of `n` envs on `threads` threads (reset with seed 40).
fn labelled_rollout(mode: Option<&str>, n: usize, threads: usize, t: usize) -> Out {
    let mut v = VecEnv::new("PickCube-v1", config(mode), n, threads).unwrap();
    v.reset(Some(40));
    set_state_experts(&mut v).unwrap();
    let (od, ad) = (
        v.single_observation_space().shape[0],
        v.single_action_space().shape[0],
    );
    let policy: Arc<dyn VecPolicy> = Arc::new(mlp(od, ad).with_noise(vec![0.3; ad], 3, 0).unwrap());
    let mut out = Out::new(t, n, od, ad);
    assert_eq!(v.rollout(policy, 0, out.labelled()).unwrap(), t);
    out
}

#[test]
fn vector_labels_are_the_single_envs_expert_labels() {
    for mode in [None, Some("pd_joint_pos")] {
        let n = 5;
        let mut v = VecEnv::new("PickCube-v1", config(mode), n, 2).unwrap();
        v.reset(Some(100));
        set_state_experts(&mut v).unwrap();
        assert!(v.has_labellers());
        let labels = v.expert_actions().unwrap().to_vec();
        let ad = v.single_action_space().shape[0];
        for i in 0..n {
            let mut env = make("PickCube-v1", config(mode)).unwrap();
            env.reset(Some(100 + i as u64));
            let mut expected = vec![0.0f32; ad];
            state_expert(&env)
                .unwrap()
                .label(&env, &mut expected)
                .unwrap();
            assert_eq!(
                &labels[i * ad..(i + 1) * ad],
                &expected[..],
                "env {i}, mode {mode:?}"
            );
        }
        // The reset state's label moves the arm (not an untouched buffer).
        assert!(labels.iter().any(|&a| a != 0.0));
    }
}

#[test]
fn a_labelled_rollout_labels_the_state_each_action_was_chosen_from() {
    let (n, t) = (3, 14);
    let out = labelled_rollout(None, n, 2, t);
    // Replayed step by step in a vector env of its own: before each step its labels are the
    // rollout's, and 0 where the env reset instead of stepping.
    let mut v = VecEnv::new("PickCube-v1", config(None), n, 1).unwrap();
    v.reset(Some(40));
    set_state_experts(&mut v).unwrap();
    let space = v.single_action_space().clone();
    let (od, ad) = (v.single_observation_space().shape[0], space.shape[0]);
    let mut resets = 0;
    for s in 0..t {
        let rows = s * n..(s + 1) * n;
        assert_eq!(
            &out.obs[rows.start * od..rows.end * od],
            v.obs(),
            "step {s}"
        );
        let expected = v.expert_actions().unwrap().to_vec();
        let got = &out.labels[rows.start * ad..rows.end * ad];
        let mut clipped = vec![0.0; n * ad];
        for i in 0..n {
            let k = i * ad..(i + 1) * ad;
            if out.autoreset[s * n + i] {
                resets += 1;
                assert!(got[k].iter().all(|&x| x == 0.0), "step {s}, env {i}");
                continue;
            }
            assert_eq!(&got[k.clone()], &expected[k.clone()], "step {s}, env {i}");
            for (j, c) in k.clone().enumerate() {
                clipped[c] = out.actions[s * n * ad + c].clamp(space.low[j], space.high[j]);
            }
        }
        v.step(&clipped).unwrap();
        assert_eq!(&out.rewards[rows], v.rewards(), "step {s}");
    }
    assert_eq!(
        resets,
        2 * n,
        "two autoresets per env in {t} steps of {MAX_STEPS}"
    );
}

#[test]
fn labels_do_not_depend_on_the_thread_count() {
    let (n, t) = (5, 8);
    for mode in [None, Some("pd_joint_pos")] {
        let one = labelled_rollout(mode, n, 1, t);
        let three = labelled_rollout(mode, n, 3, t);
        assert_eq!(one.labels, three.labels, "mode {mode:?}");
        assert_eq!(one.actions, three.actions, "mode {mode:?}");
        assert!(one.labels.iter().all(|x| x.is_finite()));
    }
}

#[test]
fn labels_without_labellers_are_refused_with_nothing_stepped() {
    let mut v = VecEnv::new("PickCube-v1", config(None), 2, 2).unwrap();
    let before = v.reset(Some(7)).to_vec();
    assert!(!v.has_labellers());
    assert!(matches!(v.expert_actions(), Err(EnvError::NoLabellers)));
    let (od, ad) = (
        v.single_observation_space().shape[0],
        v.single_action_space().shape[0],
    );
    let mut out = Out::new(3, 2, od, ad);
    let policy: Arc<dyn VecPolicy> = Arc::new(mlp(od, ad));
    let err = v.rollout(policy.clone(), 0, out.labelled()).unwrap_err();
    assert!(matches!(err, EnvError::NoLabellers), "{err}");
    assert!(err.to_string().contains("set_state_experts"), "{err}");
    assert_eq!(v.obs(), &before[..]);
    // A labels buffer of the wrong length is named.
    set_state_experts(&mut v).unwrap();
    let mut short = Out::new(3, 2, od, ad);
    short.labels.pop();
    let err = v.rollout(policy, 0, short.labelled()).unwrap_err();
    assert!(err.to_string().contains("labels"), "{err}");
    assert_eq!(v.obs(), &before[..]);
}

#[test]
fn a_pair_without_an_expert_sets_no_labellers_and_names_the_pairs() {
    let mut v = VecEnv::new("StackCube-v1", EnvConfig::default(), 2, 1).unwrap();
    let err = set_state_experts(&mut v).unwrap_err();
    assert!(matches!(err, SolverError::NoStateExpert { .. }), "{err}");
    let msg = err.to_string();
    assert!(
        msg.contains("StackCube-v1 with panda")
            && msg.contains("PickCube-v1 with panda")
            && msg.contains("PickCubeSO100-v1 with so100"),
        "{msg}"
    );
    assert!(!v.has_labellers());
}
