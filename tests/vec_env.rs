//! VecEnv: thread-count independence, autoreset semantics, errors.

use mjskill::env::VecEnv;
use mjskill::{make, EnvConfig};

fn actions(n: usize, dim: usize, k: usize) -> Vec<f32> {
    (0..n * dim)
        .map(|i| ((i * 13 + k * 7) as f32 * 0.37).sin())
        .collect()
}

fn short() -> EnvConfig {
    EnvConfig {
        max_episode_steps: Some(6),
        ..Default::default()
    }
}

#[test]
fn one_and_two_threads_give_bitwise_identical_buffers() {
    let run = |threads: usize| {
        let mut v = VecEnv::new("PickCube-v1", short(), 5, threads).unwrap();
        assert_eq!(v.num_threads(), threads);
        v.reset(Some(42));
        let mut out: Vec<u32> = v.obs().iter().map(|x| x.to_bits()).collect();
        for k in 0..15 {
            v.step(&actions(5, 8, k)).unwrap();
            out.extend(v.obs().iter().map(|x| x.to_bits()));
            out.extend(v.rewards().iter().map(|x| x.to_bits()));
            out.extend(
                v.terminated()
                    .iter()
                    .chain(v.truncated())
                    .chain(v.autoreset())
                    .map(|&b| b as u32),
            );
            out.extend(v.info().iter().map(|x| x.to_bits() as u32));
        }
        out
    };
    let (a, b) = (run(1), run(2));
    assert_eq!(a.len(), b.len());
    assert!(a == b, "T=1 and T=2 differ");
}

#[test]
fn vec_env_i_matches_a_single_env_seeded_s_plus_i() {
    let mut v = VecEnv::new("PickCube-v1", short(), 3, 2).unwrap();
    v.reset(Some(100));
    let mut single = make("PickCube-v1", short()).unwrap();
    single.reset(Some(102));
    assert_eq!(v.obs_of(2), single.obs());
    let acts = actions(3, 8, 1);
    v.step(&acts).unwrap();
    let s = single.step(&acts[16..24]).unwrap();
    assert_eq!(v.obs_of(2), s.obs);
    assert_eq!(v.rewards()[2], s.reward);
}

#[test]
fn autoreset_happens_on_the_step_after_truncation() {
    let mut v = VecEnv::new("PickCube-v1", short(), 2, 2).unwrap();
    v.reset(Some(7));
    let mut single = make("PickCube-v1", short()).unwrap();
    single.reset(Some(8)); // mirrors env 1
    let mut final_obs = Vec::new();
    for k in 0..6 {
        let a = actions(2, 8, k);
        v.step(&a).unwrap();
        let s = single.step(&a[8..]).unwrap();
        assert_eq!(v.truncated()[1], k == 5);
        assert_eq!(v.obs_of(1), s.obs, "step {k}");
        final_obs = s.obs.to_vec();
    }
    // The final observation is what the truncating step returned.
    assert_eq!(v.obs_of(1), final_obs.as_slice());
    // Next step: the action is ignored, the env resets unseeded (its streams continue).
    v.step(&actions(2, 8, 99)).unwrap();
    assert!(v.autoreset()[0] && v.autoreset()[1]);
    assert!(!v.truncated()[1] && !v.terminated()[1]);
    assert_eq!(v.rewards()[1], 0.0);
    single.reset(None);
    assert_eq!(v.obs_of(1), single.obs(), "new episode's first observation");
    assert_ne!(v.obs_of(1), final_obs.as_slice());
    // And the following step is an ordinary step of the new episode.
    v.step(&actions(2, 8, 3)).unwrap();
    assert!(!v.autoreset()[1]);
    let s = single.step(&actions(2, 8, 3)[8..]).unwrap();
    assert_eq!(v.obs_of(1), s.obs);
}

#[test]
fn bad_actions_are_errors_and_the_vec_env_stays_usable() {
    let mut v = VecEnv::new("PickCube-v1", EnvConfig::default(), 2, 2).unwrap();
    let e = v.step(&[0.0; 15]).unwrap_err().to_string();
    assert!(e.contains("15") && e.contains("16"), "{e}");
    let mut a = vec![0.0f32; 16];
    a[9] = f32::NAN;
    let e = v.step(&a).unwrap_err().to_string();
    assert!(e.contains("action[9]"), "{e}");
    assert!(v.step(&[0.0; 16]).is_ok());
    assert!(VecEnv::new("PickCube-v1", EnvConfig::default(), 0, 1).is_err());
}
