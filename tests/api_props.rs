//! The library API under bad input: 32-bit seeds, `VecEnv::obs_of` out of range, `set_state`
//! with non-finite or out-of-range values, the initial-noise bound, and a property test
//! (fixed seed, bounded cases) of random bad actions, states and configs: every call is an
//! `Err` or gives finite output, and the env stays usable.

use mjskill::VecEnv;
use mjskill::MAX_SEED;
use mjskill::{make, Env, EnvConfig, EnvError, EnvState, ObsMode, RewardMode};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};

fn env() -> Env {
    make("PickCube-v1", EnvConfig::default()).unwrap()
}

fn finite(v: &[f32]) -> bool {
    v.iter().all(|x| x.is_finite())
}

#[test]
fn seeds_are_32_bit_reduced_as_documented_or_rejected() {
    let mut a = env();
    let mut b = env();
    // reset reduces mod 2^32 (documented): the same episode, never a silent wrap elsewhere.
    let s = 7u64;
    let obs = a.reset(Some(s)).0.to_vec();
    assert_eq!(b.reset(Some(s + (1 << 32))).0, obs.as_slice());
    // try_reset rejects it, names the range and leaves the env as it was.
    let before = a.get_state();
    let e = a.try_reset(Some(MAX_SEED + 1)).unwrap_err();
    assert_eq!(e, EnvError::BadSeed(MAX_SEED + 1));
    assert!(e.to_string().contains("0..=4294967295"), "{e}");
    assert_eq!(a.get_state(), before);
    assert_eq!(a.try_reset(Some(MAX_SEED)).unwrap().0.len(), obs.len());
    // VecEnv: seeds s + i; try_reset rejects a range that leaves 32 bits, reset never panics.
    let mut v = VecEnv::new("PickCube-v1", EnvConfig::default(), 2, 1).unwrap();
    // The error names the seed given, not env 1's derived seed (issue 42).
    let e = v.try_reset(Some(MAX_SEED)).unwrap_err();
    assert_eq!(
        e,
        EnvError::VecSeedRange {
            seed: MAX_SEED,
            last_env: 1
        }
    );
    let msg = e.to_string();
    assert!(
        msg.starts_with("seed 4294967295 is out of range") && msg.contains("at most 4294967294"),
        "{msg}"
    );
    v.reset(Some(u64::MAX)); // env 1 gets (2^64 - 1 + 1) mod 2^32 = 0
    let zero = a.reset(Some(0)).0.to_vec();
    assert_eq!(v.obs_of(1).unwrap(), zero.as_slice());
    assert!(v.try_reset(Some(MAX_SEED - 1)).is_ok());
}

#[test]
fn obs_of_is_none_out_of_range() {
    let v = VecEnv::new("PickCube-v1", EnvConfig::default(), 3, 1).unwrap();
    assert_eq!(v.obs_of(2).map(<[f32]>::len), Some(v.obs().len() / 3));
    assert!(v.obs_of(3).is_none());
    assert!(v.obs_of(usize::MAX).is_none());
}

/// `set_state(bad)` is an error naming `field`, and the env is left unchanged and usable.
fn rejected(env: &mut Env, bad: &EnvState, field: &str) {
    let before = env.get_state();
    let obs = env.obs().to_vec();
    let e = env.set_state(bad).unwrap_err();
    assert!(matches!(e, EnvError::BadState(_)), "{e}");
    assert!(e.to_string().contains(field), "{field}: {e}");
    assert_eq!(env.get_state(), before, "{field}: the env is unchanged");
    assert_eq!(env.obs(), obs.as_slice());
    let dim = env.action_space().shape[0];
    let s = env.step(&vec![0.0; dim]).unwrap();
    assert!(finite(s.obs) && s.reward.is_finite(), "{field}");
    env.set_state(&before).unwrap();
}

#[test]
fn set_state_rejects_non_finite_and_out_of_range_values_naming_the_field() {
    for mode in ["pd_joint_delta_pos", "pd_ee_target_delta_pose"] {
        let mut env = make(
            "PickCube-v1",
            EnvConfig {
                control_mode: Some(mode.into()),
                ..Default::default()
            },
        )
        .unwrap();
        let good = env.get_state();
        let nq = env.model().nq();
        for (i, field) in [(1, "qpos[0]"), (1 + nq, "qvel[0]"), (0, "time")] {
            for v in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e300, -1e11] {
                let mut s = good.clone();
                s.physics[i] = v;
                rejected(&mut env, &s, field);
            }
        }
        let mut s = good.clone();
        s.physics[0] = -1.0;
        rejected(&mut env, &s, "time");
        for v in [f64::NAN, f64::INFINITY, 1e300] {
            let mut s = good.clone();
            let last = s.controller.len() - 1;
            s.controller[last] = v;
            rejected(&mut env, &s, &format!("controller[{last}]"));
            let mut s = good.clone();
            s.finger_forces[1][2] = v;
            rejected(&mut env, &s, "finger_forces[5]");
        }
        let mut s = good.clone();
        s.elapsed_steps = u32::MAX;
        rejected(&mut env, &s, "elapsed_steps");
        // An all-zero RNG state (it would output zeros forever): rejected when read.
        let mut j = serde_json::to_value(&good).unwrap();
        j["numpy"]["mt"]["state"] = serde_json::json!(vec![0u32; 624]);
        let e = serde_json::from_value::<EnvState>(j).unwrap_err();
        assert!(e.to_string().contains("all zero"), "{e}");
        // A good state still restores exactly.
        env.set_state(&good).unwrap();
        assert_eq!(env.get_state(), good);
    }
    // Every state a live env reaches restores, even after the largest actions (absolute
    // targets are unclipped, as upstream: ctrl = kp × 3.4e38).
    for mode in ["pd_joint_pos", "pd_joint_pos_vel", "pd_joint_vel"] {
        let mut env = make(
            "PickCube-v1",
            EnvConfig {
                control_mode: Some(mode.into()),
                ..Default::default()
            },
        )
        .unwrap();
        let dim = env.action_space().shape[0];
        for a in [f32::MAX, f32::MIN, 1e30] {
            env.step(&vec![a; dim]).unwrap();
            let s = env.get_state();
            env.set_state(&s)
                .unwrap_or_else(|e| panic!("{mode} after {a}: {e}"));
            assert_eq!(env.get_state(), s);
        }
    }
}

#[test]
fn initial_noise_is_bounded() {
    for sigma in [f64::MAX, 1e300, 1.0001, -0.1, f64::NAN, f64::INFINITY] {
        let e = make(
            "PickCube-v1",
            EnvConfig {
                robot_init_qpos_noise: sigma,
                ..Default::default()
            },
        )
        .unwrap_err();
        assert!(e.to_string().contains("[0, 1]"), "{sigma}: {e}");
    }
    for robot in ["panda", "so100", "xarm6_robotiq"] {
        let mut env = make(
            "PickCube-v1",
            EnvConfig {
                robot: Some(robot.into()),
                robot_init_qpos_noise: 1.0,
                ..Default::default()
            },
        )
        .unwrap();
        for seed in 0..5 {
            assert!(finite(env.reset(Some(seed)).0), "{robot} seed {seed}");
        }
    }
}

/// A float that is often bad: NaN, ±inf, huge, tiny, or ordinary.
fn wild_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(f64::NEG_INFINITY),
        Just(f64::MAX),
        Just(1e300),
        Just(-1e11),
        Just(f64::MIN_POSITIVE / 2.0),
        -1.0f64..1.0,
    ]
}

fn config() -> Config {
    Config {
        cases: 64,
        rng_seed: RngSeed::Fixed(18),
        failure_persistence: None,
        ..Config::default()
    }
}

/// After whatever happened, a seeded reset gives the fresh env's first observation.
fn still_usable(env: &mut Env) {
    let fresh = make(env.id(), env.config().clone()).unwrap();
    let mut fresh = fresh;
    let want = fresh.reset(Some(3)).0.to_vec();
    assert_eq!(env.reset(Some(3)).0, want.as_slice());
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn random_actions_are_errors_or_finite_steps(
        mode in prop::sample::select(vec!["pd_joint_delta_pos", "pd_joint_pos",
            "pd_ee_delta_pose", "pd_ee_target_delta_pose", "pd_joint_vel"]),
        actions in prop::collection::vec(
            prop::collection::vec(
                prop_oneof![
                    Just(f32::NAN), Just(f32::INFINITY), Just(f32::MAX), Just(-1e30f32),
                    -2.0f32..2.0, -2.0f32..2.0, -2.0f32..2.0,
                ],
                0..12,
            ),
            1..6,
        ),
    ) {
        let mut env = make("PickCube-v1", EnvConfig {
            control_mode: Some(mode.into()),
            ..Default::default()
        }).unwrap();
        let dim = env.action_space().shape[0];
        for a in &actions {
            let before = env.get_state();
            let bad = a.len() != dim || a.iter().any(|x| !x.is_finite());
            match env.step(a) {
                Ok(s) => {
                    prop_assert!(!bad, "accepted {a:?}");
                    prop_assert!(finite(s.obs) && s.reward.is_finite(), "{mode}: {a:?}");
                }
                Err(e) => {
                    prop_assert!(bad, "{mode}: rejected a good action {a:?}: {e}");
                    prop_assert_eq!(env.get_state(), before);
                }
            }
        }
        still_usable(&mut env);
    }

    #[test]
    fn random_states_are_errors_or_finite_steps(
        edits in prop::collection::vec((0usize..3, any::<prop::sample::Index>(), wild_f64()),
                                       1..4),
        steps in prop_oneof![Just(u32::MAX), Just(u32::MAX - 1), 0u32..100],
    ) {
        let mut env = env();
        env.reset(Some(1));
        let good = env.get_state();
        let mut s = good.clone();
        for (part, ix, v) in &edits {
            match part {
                0 => { let i = ix.index(s.physics.len()); s.physics[i] += v; }
                1 => { let i = ix.index(s.controller.len()); s.controller[i] += v; }
                _ => { let i = ix.index(6); s.finger_forces[i / 3][i % 3] = *v; }
            }
        }
        s.elapsed_steps = steps;
        // The documented bounds: physics within 1e10 but ctrl and qfrc_applied (finite),
        // targets within f32.
        let m = env.model();
        let c0 = 1 + m.nq() + m.nv() + m.na();
        let ctrl = c0..c0 + m.nu();
        let applied = ctrl.end + m.nv()..ctrl.end + 2 * m.nv();
        let valid = s.physics.iter().enumerate()
                .all(|(i, x)| x.is_finite()
                    && (x.abs() <= 1e10 || ctrl.contains(&i) || applied.contains(&i)))
            && s.controller.iter().all(|x| x.is_finite() && x.abs() <= f32::MAX as f64)
            && s.finger_forces.as_flattened().iter().all(|x| x.is_finite() && x.abs() <= 1e10)
            && s.physics[0] >= 0.0 && steps != u32::MAX;
        match env.set_state(&s) {
            Ok(()) => {
                prop_assert!(valid, "accepted a bad state");
                let dim = env.action_space().shape[0];
                let st = env.step(&vec![0.0; dim]).unwrap();
                prop_assert!(finite(st.obs) && st.reward.is_finite());
            }
            Err(e) => {
                prop_assert!(!valid, "rejected a good state: {e}");
                prop_assert_eq!(env.get_state(), good);
            }
        }
        still_usable(&mut env);
    }

    #[test]
    fn random_configs_are_errors_or_finite_envs(
        id in prop::sample::select(vec!["PickCube-v1", "PokeCube-v1", "PlaceSphere-v1",
                                        "PushCube-v1", "PullCube-v1", "StackCube-v1",
                                        "LiftPegUpright-v1", "PushT-v1",
                                        "PickCubeSO100-v1",
                                        "Bogus-v9"]),
        robot in prop::option::of(prop::sample::select(vec!["panda", "fetch", "so100",
                                                            "widowxai", "panda_stick",
                                                            "r2d2"])),
        mode in prop::option::of(prop::sample::select(vec!["pd_joint_delta_pos",
                                                           "pd_ee_delta_pos", "pd_nope"])),
        obs in prop::sample::select(vec![ObsMode::State, ObsMode::StateDict, ObsMode::None]),
        reward in prop::sample::select(vec![RewardMode::Dense, RewardMode::Sparse,
                                            RewardMode::NormalizedDense, RewardMode::None]),
        noise in prop_oneof![wild_f64(), 0.0f64..1.0],
        max_steps in prop::option::of(prop_oneof![Just(0u32), Just(u32::MAX), 1u32..80]),
        seed in any::<u64>(),
    ) {
        let config = EnvConfig {
            robot: robot.map(String::from),
            obs_mode: obs,
            reward_mode: reward,
            control_mode: mode.map(String::from),
            robot_init_qpos_noise: noise,
            max_episode_steps: max_steps,
            ..Default::default()
        };
        match make(id, config) {
            Err(e) => prop_assert!(!e.to_string().is_empty()),
            Ok(mut env) => {
                prop_assert!((0.0..=1.0).contains(&noise), "accepted noise {noise}");
                match env.try_reset(Some(seed)) {
                    Ok((o, _)) => {
                        prop_assert!(seed <= MAX_SEED);
                        prop_assert!(finite(o));
                    }
                    Err(e) => prop_assert!(seed > MAX_SEED, "{e}"),
                }
                let dim = env.action_space().shape[0];
                for t in 0..3 {
                    let a: Vec<f32> = (0..dim).map(|i| ((i + t) as f32).sin()).collect();
                    let s = env.step(&a).unwrap();
                    prop_assert!(finite(s.obs) && s.reward.is_finite());
                }
                still_usable(&mut env);
            }
        }
    }
}
