//! Unit tests of the thread pool: panics, memory refusal, sleeping waits.
use super::*;
use crate::mujoco::limits::Headroom;

#[test]
fn a_worker_panic_reaches_the_caller_instead_of_hanging() {
    let mut v = VecEnv::new("PickCube-v1", EnvConfig::default(), 2, 2).unwrap();
    let r = catch_unwind(AssertUnwindSafe(|| v.dispatch(CMD_TEST_PANIC)));
    let msg = r.expect_err("the worker's panic is re-raised here");
    assert_eq!(
        msg.downcast_ref::<String>().map(String::as_str),
        Some("test panic in env 1")
    );
    drop(v); // the workers survived the panic and join
}

#[test]
fn envs_that_would_not_fit_in_memory_are_refused_before_they_are_made() {
    // 16384 envs against 64 MB: refused after the first env is made (making them all
    // would take minutes and about 48 GB).
    let cfg = EnvConfig::default();
    let room = |bytes| memory::Available {
        memory: Some(Headroom {
            bytes,
            source: "MemAvailable in /proc/meminfo",
        }),
        address_space: None,
    };
    let e = VecEnv::new_within("PickCube-v1", cfg.clone(), MAX_NUM_ENVS, 4, room(64 << 20))
        .unwrap_err();
    let EnvError::EnvsExceedMemory {
        num_envs,
        per_env_bytes,
        available_bytes,
        ..
    } = e
    else {
        panic!("{e}");
    };
    assert_eq!((num_envs, available_bytes), (MAX_NUM_ENVS, 64 << 20));
    // The estimate covers the measured 2.1 MB per PickCube-v1 env (docs/python.md).
    assert!(
        (2_100_000..4 << 20).contains(&per_env_bytes),
        "{per_env_bytes}"
    );
    let msg = e.to_string();
    assert!(
        msg.contains("num_envs 16384") && msg.contains("64 MB of memory available"),
        "{msg}"
    );
    // Rendering envs cost more: 100 of them do not fit in 1 GB, as 100 state envs do.
    let rgb = EnvConfig {
        obs_mode: crate::env::ObsMode::Rgb,
        ..cfg.clone()
    };
    assert!(VecEnv::new_within("PickCube-v1", rgb, 100, 1, room(1 << 30)).is_err());
    let v = VecEnv::new_within("PickCube-v1", cfg, 2, 1, room(1 << 30)).unwrap();
    assert_eq!(v.num_envs(), 2);
}

#[test]
fn a_caller_that_stopped_spinning_is_woken_by_the_last_worker() {
    let mut v = VecEnv::new("PickCube-v1", EnvConfig::default(), 3, 3).unwrap();
    let busy0 = v.thread_busy_seconds();
    v.dispatch(CMD_TEST_SLEEP);
    let busy: Vec<f64> = v
        .thread_busy_seconds()
        .iter()
        .zip(&busy0)
        .map(|(b, b0)| b - b0)
        .collect();
    // The workers slept 20 ms inside the command; the caller had nothing to do.
    assert!(busy[1] >= 0.02 && busy[2] >= 0.02, "{busy:?}");
    assert!(busy[0] < 0.02, "{busy:?}");
    // Moved to another thread, the VecEnv wakes that thread, not the one it left.
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for _ in 0..3 {
            v.dispatch(CMD_TEST_SLEEP);
        }
        v.step(&vec![0.0; 3 * v.single_action_space().shape[0]])
            .unwrap();
        tx.send(()).unwrap();
    });
    rx.recv_timeout(std::time::Duration::from_secs(30))
        .expect("the new caller was woken");
}
