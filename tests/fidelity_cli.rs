//! `mjskill fidelity`: per-step deviations from a ManiSkill reference file or from a recording
//! replayed with other physics settings; `--resync`, `--control-mode`, `--plot` and bad input.
#![cfg(feature = "cli")]
mod common;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

fn mjskill(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mjskill"))
        .args(args)
        .output()
        .unwrap()
}

fn json(o: &Output) -> Value {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

fn reference(name: &str) -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/maniskill")
        .join(name)
        .display()
        .to_string()
}

/// Mean of a metric over a bucket of the file summary.
fn bucket_mean(v: &Value, from: u64, key: &str) -> f64 {
    v["buckets"]
        .as_array()
        .unwrap()
        .iter()
        .find(|b| b["from"] == from)
        .unwrap()["mean"][key]
        .as_f64()
        .unwrap()
}

#[test]
fn a_reference_file_reports_per_step_and_per_bucket_deviations() {
    let f = reference("PickCube-v1__so100.json.gz");
    let open = json(&mjskill(&["fidelity", &f]));
    let eps = open["episodes"].as_array().unwrap();
    assert_eq!(eps.len(), 10);
    for e in eps {
        let steps = e["per_step"].as_array().unwrap();
        assert_eq!(steps.len() as u64, e["steps"].as_u64().unwrap());
        for k in [
            "joint", "tcp_pos", "tcp_rot", "obj_pos", "obj_rot", "reward",
        ] {
            assert!(steps[0][k].as_f64().unwrap() >= 0.0, "{k}");
        }
        assert!(
            e["initial"]["joint"].as_f64().unwrap() < 1e-6,
            "seeded start"
        );
    }
    // Re-importing ManiSkill's state every step leaves only the one-step error: far smaller
    // late in the episodes than the open-loop drift. (The Panda's: the SO100 tracks
    // ManiSkill so closely that its drift is hardly larger than one step's error.)
    let panda = reference("PickCube-v1__panda.json.gz");
    let open_panda = json(&mjskill(&["fidelity", &panda, "--summary"]));
    let resync = json(&mjskill(&[
        "fidelity",
        &panda,
        "--resync",
        "1",
        "--summary",
    ]));
    assert!(resync["episodes"][0]["per_step"]
        .as_array()
        .unwrap()
        .is_empty());
    let (o, r) = (
        bucket_mean(&open_panda, 26, "joint"),
        bucket_mean(&resync, 26, "joint"),
    );
    assert!(r < 0.5 * o, "one-step {r} vs open loop {o}");
    // The held / free split covers every step; the motion-planning grasps are held, and
    // their one-step object error (in-hand dynamics) exceeds that of free objects.
    let split = &resync["grasp_split"];
    let total: u64 = resync["episodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["steps"].as_u64().unwrap())
        .sum();
    let (held, free) = (
        split["held_steps"].as_u64().unwrap(),
        split["free_steps"].as_u64().unwrap(),
    );
    assert_eq!(held + free, total);
    assert!(held > 0 && free > held, "held {held}, free {free}");
    let (held_err, free_err) = (
        split["held"]["obj_pos"].as_f64().unwrap(),
        split["free"]["obj_pos"].as_f64().unwrap(),
    );
    assert!(
        held_err > 10.0 * free_err,
        "held {held_err} vs free {free_err}"
    );
    // Only one control mode's episodes.
    let one = json(&mjskill(&[
        "fidelity",
        &f,
        "--control-mode",
        "pd_joint_pos",
        "--summary",
    ]));
    let eps = one["episodes"].as_array().unwrap();
    assert_eq!(eps.len(), 2);
    assert!(eps.iter().all(|e| e["control_mode"] == "pd_joint_pos"));
}

#[test]
fn plot_draws_the_error_curves_to_a_png() {
    let png = common::scratch("curves.png");
    let f = reference("PickCube-v1__widowxai.json.gz");
    json(&mjskill(&[
        "fidelity",
        &f,
        "--summary",
        "--plot",
        png.to_str().unwrap(),
    ]));
    let bytes = std::fs::read(&png).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    let reader = decoder.read_info().unwrap();
    assert_eq!((reader.info().width, reader.info().height), (900, 900));
}

#[test]
fn a_recording_replays_exactly_at_its_own_rate_and_drifts_at_another() {
    let out = common::scratch("r500.mcap");
    let o = mjskill(&[
        "rollout",
        "--episodes",
        "2",
        "--sim-freq",
        "500",
        "--no-frame",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let same = json(&mjskill(&[
        "fidelity",
        out.to_str().unwrap(),
        "--sim-freq",
        "500",
        "--summary",
    ]));
    for b in same["buckets"].as_array().unwrap() {
        for k in ["joint", "tcp_pos", "obj_pos", "reward"] {
            assert_eq!(
                b["max"][k].as_f64().unwrap(),
                0.0,
                "{k} at the recorded rate"
            );
        }
    }
    let other = json(&mjskill(&[
        "fidelity",
        out.to_str().unwrap(),
        "--sim-freq",
        "100",
        "--summary",
    ]));
    assert_eq!(other["sim"]["sim_freq"], 100);
    assert!(bucket_mean(&other, 26, "joint") > 1e-5);
    // The solver's episodes still succeed at the other rate.
    for e in other["episodes"].as_array().unwrap() {
        assert_eq!(e["reference_success"], true);
        assert_eq!(e["mjskill_success"], true);
    }
}

fn fails_with(args: &[&str], want: &str) {
    let o = mjskill(args);
    assert_eq!(o.status.code(), Some(2), "{args:?}");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains(want), "{args:?}: {err}");
}

#[test]
fn bad_input_is_an_error_naming_it() {
    let f = reference("PickCube-v1__panda.json.gz");
    fails_with(
        &["fidelity", "/nonexistent.json.gz"],
        "/nonexistent.json.gz",
    );
    let junk = common::scratch("junk.json");
    std::fs::write(&junk, "{\"format\": 3}").unwrap();
    fails_with(
        &["fidelity", junk.to_str().unwrap()],
        "is not a ManiSkill reference trajectory file",
    );
    let other = common::scratch("other.json");
    let text = std::fs::read(Path::new(&f)).unwrap();
    let mut s = String::new();
    std::io::Read::read_to_string(&mut flate2::read::GzDecoder::new(&text[..]), &mut s).unwrap();
    std::fs::write(
        &other,
        s.replace("mjskill-ref-traj/1", "mjskill-ref-traj/9"),
    )
    .unwrap();
    fails_with(
        &["fidelity", other.to_str().unwrap()],
        "format is \"mjskill-ref-traj/9\", expected \"mjskill-ref-traj/1\"",
    );
    fails_with(
        &["fidelity", &f, "--resync", "0"],
        "--resync must be at least 1",
    );
    fails_with(&["fidelity", &f, "--sim-freq", "30"], "sim_freq 30");
    fails_with(
        &["fidelity", &f, "--control-mode", "pd_ee_pose"],
        "recorded modes: pd_joint_delta_pos",
    );
}

#[test]
fn the_grasp_split_counts_the_release_step_as_held() {
    use mjskill::maniskill::fidelity::{GraspSplit, StepError};
    let step = |grasped: bool, obj_pos: f64| StepError {
        obj_pos,
        reference_grasped: grasped,
        ..StepError::default()
    };
    // Episode 1: free, grasped, grasped, released (held: it starts grasped), free.
    let a = [
        step(false, 1.0),
        step(true, 2.0),
        step(true, 2.0),
        step(false, 2.0),
        step(false, 1.0),
    ];
    // Episode 2 starts grasped: its first step is held.
    let b = [step(false, 4.0)];
    let s = GraspSplit::of(&[(false, &a[..]), (true, &b[..])]);
    assert_eq!((s.held_steps, s.free_steps), (4, 2));
    assert_eq!(s.held.unwrap().obj_pos, 2.5);
    assert_eq!(s.free.unwrap().obj_pos, 1.0);
    let none = GraspSplit::of(&[(false, &a[..1])]);
    assert_eq!((none.held_steps, none.held), (0, None));
}

#[test]
fn a_reference_file_with_short_joint_rows_or_a_64_bit_seed_is_refused() {
    let f = reference("PickCube-v1__so100.json.gz");
    let gz = std::fs::read(Path::new(&f)).unwrap();
    let mut s = String::new();
    std::io::Read::read_to_string(&mut flate2::read::GzDecoder::new(&gz[..]), &mut s).unwrap();
    let base: Value = serde_json::from_str(&s).unwrap();
    let edited = |name: &str, edit: &dyn Fn(&mut Value)| {
        let mut v = base.clone();
        edit(&mut v);
        let p = common::scratch(name);
        std::fs::write(&p, v.to_string()).unwrap();
        p.display().to_string()
    };
    let short = edited("short_qpos.json", &|v| {
        v["episodes"][1]["steps"][2]["robot_qpos"]
            .as_array_mut()
            .unwrap()
            .pop();
    });
    fails_with(
        &["fidelity", &short],
        "episode 1: step 3: robot_qpos has 5 values but joint_names lists 6 joints",
    );
    let long = edited("long_qvel.json", &|v| {
        v["episodes"][0]["initial"]["robot_qvel"]
            .as_array_mut()
            .unwrap()
            .push(0.0.into());
    });
    fails_with(
        &["fidelity", &long],
        "episode 0: the initial state: robot_qvel has 7 values but joint_names lists 6 joints",
    );
    let seed = edited("seed.json", &|v| {
        v["episodes"][0]["seed"] = (1u64 << 32).into();
    });
    fails_with(
        &["fidelity", &seed],
        "episode 0: seed 4294967296 is not in 0..=4294967295",
    );
}
