//! VecEnv: thread-count independence, autoreset semantics, errors.

use mjskill::VecEnv;
use mjskill::{make, Env, EnvConfig, ObsMode};

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
    assert_eq!(v.obs_of(2).unwrap(), single.obs());
    let acts = actions(3, 8, 1);
    v.step(&acts).unwrap();
    let s = single.step(&acts[16..24]).unwrap();
    assert_eq!(v.obs_of(2).unwrap(), s.obs);
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
        assert_eq!(v.obs_of(1).unwrap(), s.obs, "step {k}");
        final_obs = s.obs.to_vec();
    }
    // The final observation is what the truncating step returned.
    assert_eq!(v.obs_of(1).unwrap(), final_obs.as_slice());
    // Next step: the action is ignored, the env resets unseeded (its streams continue).
    v.step(&actions(2, 8, 99)).unwrap();
    assert!(v.autoreset()[0] && v.autoreset()[1]);
    assert!(!v.truncated()[1] && !v.terminated()[1]);
    assert_eq!(v.rewards()[1], 0.0);
    single.reset(None);
    assert_eq!(
        v.obs_of(1).unwrap(),
        single.obs(),
        "new episode's first observation"
    );
    assert_ne!(v.obs_of(1).unwrap(), final_obs.as_slice());
    // And the following step is an ordinary step of the new episode.
    v.step(&actions(2, 8, 3)).unwrap();
    assert!(!v.autoreset()[1]);
    let s = single.step(&actions(2, 8, 3)[8..]).unwrap();
    assert_eq!(v.obs_of(1).unwrap(), s.obs);
}

#[test]
fn without_autoreset_ended_envs_keep_stepping_as_single_envs_do() {
    let mut v = VecEnv::new("PickCube-v1", short(), 2, 2).unwrap();
    assert!(v.autoreset_enabled());
    v.set_autoreset(false);
    assert!(!v.autoreset_enabled());
    v.reset(Some(7));
    let mut single = make("PickCube-v1", short()).unwrap();
    single.reset(Some(8)); // mirrors env 1
                           // Past the 6-step limit: truncated stays set, nothing resets, the actions are applied.
    for k in 0..9 {
        let a = actions(2, 8, k);
        v.step(&a).unwrap();
        let s = single.step(&a[8..]).unwrap();
        assert_eq!(v.truncated()[1], k >= 5, "step {k}");
        assert!(!v.autoreset()[0] && !v.autoreset()[1], "step {k}");
        assert_eq!(v.obs_of(1).unwrap(), s.obs, "step {k}");
        assert_eq!(v.rewards()[1], s.reward, "step {k}");
    }
    // Turned back on, the ended envs reset on the next step as usual.
    v.set_autoreset(true);
    v.step(&actions(2, 8, 20)).unwrap();
    v.step(&actions(2, 8, 21)).unwrap();
    assert!(v.autoreset()[0] && v.autoreset()[1]);
    single.reset(None);
    assert_eq!(v.obs_of(1).unwrap(), single.obs());
}

#[test]
fn reset_envs_resets_the_masked_envs_and_leaves_the_others_untouched() {
    let mut v = VecEnv::new("PickCube-v1", short(), 3, 2).unwrap();
    let mut twin = VecEnv::new("PickCube-v1", short(), 3, 1).unwrap();
    v.set_autoreset(false);
    twin.set_autoreset(false);
    v.reset(Some(30));
    twin.reset(Some(30));
    for k in 0..3 {
        v.step(&actions(3, 8, k)).unwrap();
        twin.step(&actions(3, 8, k)).unwrap();
    }
    let info_len = v.info().len() / 3;
    // Env 1 restarts with seed 500 + 1, as a full reset(Some(500)) would seed it.
    v.reset_envs(&[false, true, false], Some(500)).unwrap();
    let mut single = make("PickCube-v1", short()).unwrap();
    single.reset(Some(501));
    assert_eq!(v.obs_of(1).unwrap(), single.obs());
    assert_eq!(v.rewards()[1], 0.0);
    assert!(!v.truncated()[1] && !v.terminated()[1]);
    for i in [0, 2] {
        assert_eq!(v.obs_of(i).unwrap(), twin.obs_of(i).unwrap(), "env {i}");
        assert_eq!(v.rewards()[i], twin.rewards()[i], "env {i}");
        assert_eq!(
            &v.info()[i * info_len..(i + 1) * info_len],
            &twin.info()[i * info_len..(i + 1) * info_len],
            "env {i}"
        );
    }
    // The untouched envs go on with their episodes; the reset one with its new episode.
    for k in 3..5 {
        let a = actions(3, 8, k);
        v.step(&a).unwrap();
        twin.step(&a).unwrap();
        let s = single.step(&a[8..16]).unwrap();
        assert_eq!(v.obs_of(1).unwrap(), s.obs, "step {k}");
        for i in [0, 2] {
            assert_eq!(
                v.obs_of(i).unwrap(),
                twin.obs_of(i).unwrap(),
                "env {i} step {k}"
            );
        }
    }
    // An unseeded partial reset continues env 0's own random streams, like a single env's.
    let mut single0 = make("PickCube-v1", short()).unwrap();
    single0.reset(Some(30));
    single0.reset(None);
    v.reset_envs(&[true, false, false], None).unwrap();
    assert_eq!(v.obs_of(0).unwrap(), single0.obs());
}

#[test]
fn reset_envs_rejects_a_bad_mask_or_seed_and_resets_nothing() {
    let mut v = VecEnv::new("PickCube-v1", short(), 2, 1).unwrap();
    v.reset(Some(3));
    v.step(&actions(2, 8, 0)).unwrap();
    let before = v.obs().to_vec();
    let e = v.reset_envs(&[true], None).unwrap_err().to_string();
    assert!(e.contains("1 values") && e.contains("(2)"), "{e}");
    let e = v
        .reset_envs(&[false, true], Some(u32::MAX as u64))
        .unwrap_err()
        .to_string();
    assert!(e.contains("4294967296"), "{e}");
    assert_eq!(v.obs(), before.as_slice());
    // The last env's seed must fit: s + 1 for env 1, s alone when only env 0 resets.
    assert!(v.reset_envs(&[true, false], Some(u32::MAX as u64)).is_ok());
    // An empty mask resets nothing.
    let now = v.obs().to_vec();
    v.reset_envs(&[false, false], Some(9)).unwrap();
    assert_eq!(v.obs(), now.as_slice());
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

#[test]
fn a_non_finite_action_names_its_env_and_component() {
    let mut v = VecEnv::new("PickCube-v1", EnvConfig::default(), 4, 1).unwrap();
    let mut a = vec![0.0f32; 32];
    a[3 * 8 + 5] = f32::NAN;
    let e = v.step(&a).unwrap_err().to_string();
    assert!(
        e.contains("action[29] = NaN (env 3, action component 5) is not finite"),
        "{e}"
    );
}

#[test]
fn mujoco_warnings_of_each_env_are_reported_and_cleared_by_reset() {
    // Absolute joint targets 100× beyond the action space at one 0.05 s substep diverge.
    let cfg = EnvConfig {
        control_mode: Some("pd_joint_pos".into()),
        sim: mjskill::SimConfig {
            sim_freq: 20,
            ..Default::default()
        },
        max_episode_steps: Some(1000),
        ..Default::default()
    };
    let mut v = VecEnv::new("PickCube-v1", cfg, 2, 2).unwrap();
    v.reset(Some(0));
    assert!(v.warnings().iter().all(|w| w.fired().is_empty()));
    let (lo, hi) = (
        v.single_action_space().low.clone(),
        v.single_action_space().high.clone(),
    );
    let mut fired = false;
    for k in 0..100 {
        let a: Vec<f32> = (0..16)
            .map(|i| {
                let j = i % 8;
                100.0
                    * if (i * 7 + k * 3) % 5 < 2 {
                        lo[j]
                    } else {
                        hi[j]
                    }
            })
            .collect();
        v.step(&a).unwrap();
        if v.warnings().iter().any(|w| !w.fired().is_empty()) {
            fired = true;
            break;
        }
    }
    assert!(fired, "no MuJoCo warning in 100 diverging steps");
    v.reset(Some(0));
    assert!(
        v.warnings().iter().all(|w| w.fired().is_empty()),
        "a reset clears the warnings"
    );
}

#[test]
fn num_envs_beyond_the_bound_is_an_error_not_a_huge_allocation() {
    assert_eq!(mjskill::MAX_NUM_ENVS, 16_384);
    for n in [mjskill::MAX_NUM_ENVS + 1, 1 << 62, usize::MAX] {
        let e = VecEnv::new("PickCube-v1", EnvConfig::default(), n, 1)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(&format!("num_envs {n} is out of range: 1..=16384")),
            "{e}"
        );
    }
}

// ---- camera images (rendering: CI installs EGL/Mesa, see tests/render.rs) ----------------

fn visual(mode: ObsMode, robot: Option<&str>, episode: u32) -> EnvConfig {
    EnvConfig {
        robot: robot.map(str::to_string),
        obs_mode: mode,
        max_episode_steps: Some(episode),
        ..Default::default()
    }
}

const NEEDS_RENDER: &str = "rendering must be available (bash .ci/setup installs EGL/Mesa)";

/// Every image of every env of `v`, in sensor-name order, as raw bits.
fn all_images(v: &VecEnv) -> Vec<u32> {
    let mut out = Vec::new();
    for i in 0..v.num_envs() {
        for cam in v.sensor_names() {
            let img = v.image(i, cam).unwrap();
            out.extend(img.rgb.unwrap_or(&[]).iter().map(|&b| b as u32));
            out.extend(img.depth.unwrap_or(&[]).iter().map(|d| d.to_bits()));
        }
    }
    out
}

/// Asserts that env `i` of `v` shows exactly the images of `single`.
fn assert_same_images(v: &VecEnv, i: usize, single: &Env, what: &str) {
    assert_eq!(v.sensor_names(), single.sensor_names().as_slice());
    for cam in v.sensor_names() {
        let (a, b) = (v.image(i, cam).unwrap(), single.image(cam).unwrap());
        assert_eq!((a.name, a.width, a.height), (b.name, b.width, b.height));
        assert!(a.rgb == b.rgb, "{what}: env {i} {cam} rgb differs");
        let bits = |d: Option<&[f32]>| d.map(|d| d.iter().map(|x| x.to_bits()).collect::<Vec<_>>());
        assert!(
            bits(a.depth) == bits(b.depth),
            "{what}: env {i} {cam} depth differs"
        );
    }
}

#[test]
fn vec_env_images_equal_single_envs_across_autoresets() {
    let (n, episode, seed) = (3, 4, 300);
    let config = visual(ObsMode::Rgbd, None, episode);
    let mut v = VecEnv::new("PickCube-v1", config.clone(), n, 2).expect(NEEDS_RENDER);
    assert_eq!(v.sensor_names(), ["base_camera"]);
    v.reset(Some(seed));
    let mut singles: Vec<Env> = (0..n)
        .map(|i| {
            let mut e = make("PickCube-v1", config.clone()).unwrap();
            e.reset(Some(seed + i as u64));
            e
        })
        .collect();
    for (i, s) in singles.iter().enumerate() {
        assert_same_images(&v, i, s, "after reset");
    }
    let dim = v.single_action_space().shape[0];
    let mut ended = vec![false; n];
    let mut autoresets = 0;
    let mut previous = all_images(&v);
    for k in 0..2 * episode as usize + 2 {
        let a = actions(n, dim, k);
        v.step(&a).unwrap();
        for (i, s) in singles.iter_mut().enumerate() {
            assert_eq!(v.autoreset()[i], ended[i], "step {k}");
            if ended[i] {
                s.reset(None);
                ended[i] = false;
                autoresets += 1;
            } else {
                let st = s.step(&a[i * dim..(i + 1) * dim]).unwrap();
                ended[i] = st.terminated || st.truncated;
            }
            assert_eq!(v.obs_of(i).unwrap(), s.obs(), "step {k}");
            assert_same_images(&v, i, s, &format!("step {k}"));
        }
        // The images follow the state: every step changes them.
        let now = all_images(&v);
        assert_ne!(now, previous, "step {k}: images did not change");
        previous = now;
    }
    assert_eq!(autoresets, 2 * n, "two autoresets per env");
}

#[test]
fn fetch_mounted_camera_images_are_identical_for_one_and_two_threads() {
    let run = |threads: usize| {
        let config = visual(ObsMode::Rgb, Some("fetch"), 3);
        let mut v = VecEnv::new("PickCube-v1", config, 3, threads).expect(NEEDS_RENDER);
        assert_eq!(
            v.sensor_names(),
            ["base_camera", "fetch_head", "fetch_hand"]
        );
        v.reset(Some(5));
        let dim = v.single_action_space().shape[0];
        let mut out = all_images(&v);
        for k in 0..5 {
            v.step(&actions(3, dim, k)).unwrap();
            out.extend(all_images(&v));
        }
        // rgb mode: colour only; the three cameras see different things.
        let img = |cam| v.image(2, cam).unwrap();
        assert!(img("fetch_hand").depth.is_none());
        assert_ne!(img("fetch_head").rgb, img("fetch_hand").rgb);
        assert_ne!(img("base_camera").rgb, img("fetch_head").rgb);
        out
    };
    let (a, b) = (run(1), run(2));
    assert_eq!(a.len(), 6 * 3 * 3 * 128 * 128 * 3);
    assert!(a == b, "T=1 and T=2 images differ");
}

#[test]
fn image_is_none_for_bad_index_name_and_state_mode() {
    let config = visual(ObsMode::Depth, None, 50);
    let mut v = VecEnv::new("PickCube-v1", config.clone(), 2, 2).expect(NEEDS_RENDER);
    v.reset(Some(9));
    let img = v.image(1, "base_camera").unwrap();
    assert!(img.rgb.is_none());
    let mut single = make("PickCube-v1", config).unwrap();
    single.reset(Some(10));
    assert_same_images(&v, 1, &single, "depth mode");
    assert!(v.image(2, "base_camera").is_none());
    assert!(v.image(0, "fetch_head").is_none());
    assert!(v.image(0, "render_camera").is_none());
    let state = VecEnv::new("PickCube-v1", EnvConfig::default(), 2, 2).unwrap();
    assert!(state.sensor_names().is_empty());
    assert!(state.image(0, "base_camera").is_none());
}

/// VecEnv builds its envs on the calling thread and moves them to worker threads. An EGL
/// context still current on its creator cannot be made current elsewhere (EGL_BAD_ACCESS,
/// which Mesa enforces), so the renderer must leave it current nowhere: an env made here and
/// stepped on another thread renders the same frames as its twin stepped here.
#[test]
fn an_env_made_on_one_thread_renders_on_another() {
    let config = visual(ObsMode::Rgb, None, 50);
    let mut here = make("PickCube-v1", config.clone()).expect(NEEDS_RENDER);
    // Made last, so the last context used on this thread is its own.
    let moved = make("PickCube-v1", config).unwrap();
    let a = actions(1, 8, 4);
    let frames = std::thread::spawn(move || {
        let mut e = moved;
        e.step(&a).unwrap();
        let first = e.sensor_rgb().unwrap().to_vec();
        e.step(&a).unwrap();
        (first, e.sensor_rgb().unwrap().to_vec())
    })
    .join()
    .expect("stepping on another thread failed");
    here.step(&actions(1, 8, 4)).unwrap();
    assert!(frames.0 == here.sensor_rgb().unwrap(), "first step differs");
    here.step(&actions(1, 8, 4)).unwrap();
    assert!(
        frames.1 == here.sensor_rgb().unwrap(),
        "second step differs"
    );
}

/// Issue 42: 30 `rgb` envs under `prlimit --as=2000000000` crashed the process (SIGSEGV in
/// Mesa's `driCreateContextAttribs`). They are refused with an error naming `num_envs` and
/// the address-space limit, and a single rendering env past the limit gets a render error.
#[test]
fn rendering_envs_beyond_an_address_space_limit_are_an_error_not_a_crash() {
    if std::env::var_os("MJSKILL_AS_CHILD").is_some() {
        let cfg = EnvConfig {
            obs_mode: ObsMode::Rgb,
            ..Default::default()
        };
        let e = VecEnv::new("PickCube-v1", cfg.clone(), 30, 1).unwrap_err();
        println!("vec: {e}");
        // Envs made one by one until the limit: an error, never a crash.
        let mut envs = Vec::new();
        let e = loop {
            match make("PickCube-v1", cfg.clone()) {
                Ok(env) => envs.push(env),
                Err(e) => break e,
            }
            assert!(envs.len() < 200, "no limit reached");
        };
        println!("single after {}: {e}", envs.len());
        return;
    }
    if make(
        "PickCube-v1",
        EnvConfig {
            obs_mode: ObsMode::Rgb,
            ..Default::default()
        },
    )
    .is_err()
    {
        eprintln!("skipped: no headless rendering here");
        return;
    }
    let Ok(o) = std::process::Command::new("prlimit")
        .arg("--as=2000000000")
        .arg(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "rendering_envs_beyond_an_address_space_limit_are_an_error_not_a_crash",
            "--nocapture",
            "--test-threads=1",
        ])
        .env("MJSKILL_AS_CHILD", "1")
        .output()
    else {
        eprintln!("skipped: no prlimit");
        return;
    };
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{:?}\n{out}\n{}",
        o.status,
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        out.contains("vec: num_envs 30 would need")
            && out.contains("RLIMIT_AS")
            && out.contains("cannot create a GL context"),
        "{out}"
    );
}
