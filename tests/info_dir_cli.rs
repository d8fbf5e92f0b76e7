//! `mjskill info DIR`: a directory of recording shards read as one dataset.
#![cfg(feature = "cli")]

mod common;
use std::path::Path;
use std::process::Command;

fn mjskill() -> Command {
    Command::new(env!("CARGO_BIN_EXE_mjskill"))
}

fn json(out: &[u8]) -> serde_json::Value {
    serde_json::from_slice(out).unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(out)))
}

fn rollout(out: &Path, seed: u32, episodes: u32, extra: &[&str]) {
    let o = mjskill()
        .args(["rollout", "--no-frame", "--seed", &seed.to_string()])
        .args(["--episodes", &episodes.to_string()])
        .args(extra)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn shards_read_as_one_dataset_equal_one_recording_of_all_seeds() {
    let shards = common::scratch_dir("shards");
    rollout(&shards.join("shard-0.mcap"), 0, 2, &[]);
    rollout(&shards.join("shard-1.mcap"), 2, 2, &[]);
    std::fs::write(shards.join("notes.txt"), "not a shard").unwrap();
    let whole = common::scratch_dir("whole").join("all.mcap");
    rollout(&whole, 0, 4, &[]);
    let d = json(&mjskill().arg("info").arg(&shards).output().unwrap().stdout);
    let w = json(&mjskill().arg("info").arg(&whole).output().unwrap().stdout);
    assert_eq!(d["shards"].as_array().unwrap().len(), 2, "{d}");
    for key in [
        "env",
        "robot",
        "control_mode",
        "obs_mode",
        "episodes",
        "successes",
        "steps",
    ] {
        assert_eq!(d[key], w[key], "{key}: {d} vs {w}");
    }
    assert_eq!(d["complete"], true);
    let (a, b) = (
        d["mean_return"].as_f64().unwrap(),
        w["mean_return"].as_f64().unwrap(),
    );
    assert!((a - b).abs() <= 1e-9 * b.abs().max(1.0), "{a} vs {b}");
    assert!(
        d["successes"].as_u64().unwrap() >= 2,
        "the solver succeeds: {d}"
    );
}

#[test]
fn mixed_or_empty_directories_are_errors_naming_the_cause() {
    let empty = common::scratch_dir("empty");
    let o = mjskill().arg("info").arg(&empty).output().unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("holds no .mcap files"));
    let mixed = common::scratch_dir("mixed");
    rollout(&mixed.join("a.mcap"), 0, 1, &[]);
    rollout(&mixed.join("b.mcap"), 1, 1, &["--reward-mode", "sparse"]);
    let o = mjskill().arg("info").arg(&mixed).output().unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("not one dataset: reward mode \"normalized_dense\" vs \"sparse\""),
        "{err}"
    );
}
