//! The recording command line: rollout, info, replay and durability under kill (reference
//! trajectories: tests/reference.rs).
#![cfg(feature = "cli")]

mod common;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn mjskill() -> Command {
    Command::new(env!("CARGO_BIN_EXE_mjskill"))
}

fn json(out: &[u8]) -> serde_json::Value {
    serde_json::from_slice(out).unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(out)))
}

#[test]
fn rollout_info_and_replay_round_trip() {
    let out = common::scratch("three.mcap");
    let o = mjskill()
        .args(["rollout", "--episodes", "3", "--seed", "5", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = json(&o.stdout);
    assert_eq!(s["episodes"], 3);
    assert_eq!(s["steps"], 150);
    assert_eq!(s["policy"], "solver");
    assert!(s["successes"].as_u64().unwrap() >= 2);
    let i = json(&mjskill().arg("info").arg(&out).output().unwrap().stdout);
    assert_eq!(i["episodes"], 3);
    assert_eq!(i["complete"], true);
    assert_eq!(i["successes"], s["successes"]);
    let r = mjskill()
        .args(["replay", "--tolerance", "0"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let r = json(&r.stdout);
    assert_eq!(r["steps"], 150);
    assert_eq!(r["max_obs_dev"], 0.0, "same machine: bitwise");
}

#[test]
fn no_frame_skips_the_png_next_to_the_recording() {
    let out = common::scratch("noframe.mcap");
    // The frame goes next to the recording: `noframe.mcap` → `noframe.png`.
    let png = out.with_extension("png");
    let o = mjskill()
        .args(["rollout", "--episodes", "1", "--no-frame", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(json(&o.stdout)["frame"].is_null());
    assert!(out.exists() && !png.exists());
}

#[test]
fn bad_files_and_unwritable_outputs_are_clear_errors() {
    let garbage = common::scratch("garbage.mcap");
    std::fs::write(&garbage, b"definitely not mcap").unwrap();
    for cmd in ["info", "replay"] {
        let o = mjskill().arg(cmd).arg(&garbage).output().unwrap();
        assert_eq!(o.status.code(), Some(2));
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(e.contains("garbage.mcap") && !e.contains("panicked"), "{e}");
        let o = mjskill()
            .arg(cmd)
            .arg(common::scratch("missing.mcap"))
            .output()
            .unwrap();
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(
            o.status.code() == Some(2) && e.contains("missing.mcap"),
            "{e}"
        );
    }
    let o = mjskill()
        .args(["rollout", "--out", "/nonexistent-dir/x.mcap"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("/nonexistent-dir/x.mcap"));
    assert!(o.stdout.is_empty(), "no summary: nothing was simulated");
    let o = mjskill()
        .args(["rollout", "--policy", "telepathy", "--out"])
        .arg(common::scratch("p.mcap"))
        .output()
        .unwrap();
    assert!(String::from_utf8_lossy(&o.stderr).contains("telepathy"));
}

/// Starts a long rollout, waits until `finished` episodes are on disk, then kills it with
/// `signal` and checks what survives.
fn kill_mid_run(signal: &str, name: &str) {
    let out = common::scratch(name);
    // A process started in the background by a script inherits SIGINT ignored, and a command
    // line program rightly keeps it so (the shell asked for it); the test runs the rollout
    // with the default disposition, as from a terminal (`env` then execs it, same pid).
    let mut cmd = Command::new("env");
    cmd.arg("--default-signal=INT")
        .arg(env!("CARGO_BIN_EXE_mjskill"));
    let mut child = cmd
        .args(["rollout", "--episodes", "500", "--out"])
        .arg(&out)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let t = Instant::now();
    loop {
        std::thread::sleep(Duration::from_millis(100));
        let o = mjskill().arg("info").arg(&out).output().unwrap();
        if o.status.success() && json(&o.stdout)["episodes"].as_u64().unwrap() >= 2 {
            break;
        }
        assert!(
            t.elapsed() < Duration::from_secs(120),
            "rollout made no progress"
        );
    }
    let st = Command::new("kill")
        .args([signal, &child.id().to_string()])
        .status()
        .unwrap();
    assert!(st.success());
    let status = child.wait().unwrap();
    assert!(!status.success(), "the rollout was killed");
    let i = json(&mjskill().arg("info").arg(&out).output().unwrap().stdout);
    assert!(i["episodes"].as_u64().unwrap() >= 2, "{i}");
    assert_eq!(i["complete"], false, "{i}");
    // Every finished episode replays exactly.
    let r = mjskill()
        .args(["replay", "--tolerance", "0"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert_eq!(json(&r.stdout)["episodes"], i["episodes"]);
}

#[test]
fn a_rollout_killed_with_sigkill_keeps_every_finished_episode() {
    kill_mid_run("-KILL", "killed.mcap");
}

#[test]
fn a_rollout_interrupted_with_sigint_keeps_every_finished_episode() {
    kill_mid_run("-INT", "interrupted.mcap");
}

#[test]
fn a_closed_stdout_is_not_a_crash() {
    // `mjskill envs | head -c 1`: the reader goes away before the listing is written.
    let mut child = mjskill()
        .arg("envs")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn bench_replays_the_envs_trajectory_bitwise_with_cloned_drives() {
    // `bench` times raw physics on a clone of the env's `Data` and `Drives`; the clone must
    // step exactly as the env did. 400 random steps make the Panda's fingers touch things
    // (a clone that lost the drives' contact buffers diverged here).
    for robot in ["panda", "fetch"] {
        let o = mjskill()
            .args([
                "bench",
                "--env",
                "PickCube-v1",
                "--robot",
                robot,
                "--steps",
                "400",
            ])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert_eq!(json(&o.stdout)["replay_identical"], true, "{robot}");
    }
}

/// A build without a feature (the quick start's: `--no-default-features --features cli`) still
/// parses every command and flag, and what needs a left-out feature stops at once with an
/// error naming the feature, writing nothing.
#[test]
fn left_out_features_are_named_errors() {
    let out = common::scratch("feature.mcap");
    let mut cases: Vec<(Vec<String>, &str)> = Vec::new();
    if !cfg!(feature = "datasets") {
        for args in [
            vec!["export", "x.mcap", "--format", "lerobot", "-o", "ds"],
            vec!["import-maniskill", "trajectory.h5", "--out", "demos.mcap"],
        ] {
            cases.push((args.into_iter().map(String::from).collect(), "datasets"));
        }
    }
    if !cfg!(feature = "onnx") {
        let args = ["eval", "--policy", "policy.onnx", "--episodes", "1"];
        cases.push((args.into_iter().map(String::from).collect(), "onnx"));
    }
    if !cfg!(feature = "video") {
        let mut args: Vec<String> = ["rollout", "--episodes", "1", "--video", "--out"]
            .into_iter()
            .map(String::from)
            .collect();
        args.push(out.display().to_string());
        cases.push((args, "video"));
    }
    for (args, feature) in &cases {
        let o = mjskill().args(args).output().unwrap();
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        assert!(e.contains(&format!("`{feature}` feature")), "{args:?}: {e}");
        assert!(!out.exists(), "{args:?} left {}", out.display());
    }
}
