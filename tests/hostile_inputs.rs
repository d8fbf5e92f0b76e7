//! The rule for every file mjskill reads or writes (docs/limits.md), tried with hostile and
//! faulty inputs made here: devices, FIFOs and symlinks to `/dev/zero` are refused without a
//! hang; gzip and zip bombs stop at the size limit (set low with `MJSKILL_MAX_FILE_BYTES`);
//! policy files that crash the ONNX runtime, declare huge tensors, carry a key twice or give
//! NaN actions are errors naming the file, and a rollout they stop keeps its finished
//! episodes in a file marked incomplete; outcome files name every object they compare.
//!
//! The policy files are made by `tests/make_hostile_policy.py` (numpy and `onnx`) in the venv
//! `.ci/setup` creates; without it those tests print a note and pass, unless
//! `MJSKILL_REQUIRE_PYTHON` is set.
// Policy files, exports and rollouts with policies: the default features (the quick start
// builds without onnx and datasets; its own left-out-feature errors are in rollout_cli.rs).
#![cfg(all(feature = "cli", feature = "onnx", feature = "datasets"))]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

mod common;
use common::run_within;

fn mjskill() -> Command {
    Command::new(env!("CARGO_BIN_EXE_mjskill"))
}

fn json(o: &Output) -> serde_json::Value {
    serde_json::from_slice(&o.stdout).unwrap_or_else(|e| {
        panic!(
            "{e}: {} {}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        )
    })
}

/// Hidden files (temporaries) in `d`.
fn leftovers(d: &Path) -> Vec<String> {
    std::fs::read_dir(d)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().to_string())
        .filter(|n| n.starts_with('.'))
        .collect()
}

fn mkfifo(p: &Path) {
    std::fs::remove_file(p).ok();
    assert!(Command::new("mkfifo").arg(p).status().unwrap().success());
}

fn symlink_to_zero(p: &Path) {
    std::fs::remove_file(p).ok();
    std::os::unix::fs::symlink("/dev/zero", p).unwrap();
}

fn python() -> Option<PathBuf> {
    common::venv_python("hostile policy test")
}

/// The observation and action sizes of PickCube-v1 with the Panda in pd_ee_delta_pos (the
/// defaults of tests/make_hostile_policy.py).
fn dims() -> (usize, usize) {
    let env = mjskill::make(
        "PickCube-v1",
        mjskill::EnvConfig {
            control_mode: Some("pd_ee_delta_pos".into()),
            ..Default::default()
        },
    )
    .unwrap();
    (env.obs().len(), env.action_space().shape[0])
}

/// Makes a policy file of `kind` with tests/make_hostile_policy.py (named after `kind` and
/// `extra`, so that files of one kind with other options do not replace each other).
fn hostile(py: &Path, d: &Path, kind: &str, extra: &[&str]) -> PathBuf {
    let (obs, act) = dims();
    let tag: String = extra
        .concat()
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    let out = d.join(format!("{kind}{tag}.onnx"));
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/make_hostile_policy.py");
    let o = Command::new(py)
        .arg(script)
        .arg(kind)
        .args(["--obs-dim", &obs.to_string(), "--act-dim", &act.to_string()])
        .arg("--out")
        .arg(&out)
        .args(extra)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    out
}

#[test]
fn rollout_out_must_be_a_regular_file() {
    let d = common::scratch_dir("out");
    // A device behind a symlink (as root, `--out /dev/null` would have replaced /dev/null).
    let null = d.join("null.mcap");
    std::fs::remove_file(&null).ok();
    std::os::unix::fs::symlink("/dev/null", &null).unwrap();
    let fifo = d.join("fifo.mcap");
    mkfifo(&fifo);
    for (out, kind) in [(&null, "a character device"), (&fifo, "a FIFO")] {
        let mut cmd = mjskill();
        cmd.args(["rollout", "--episodes", "1", "--no-frame", "--out"])
            .arg(out);
        let err = common::fails(&run_within(cmd, 60));
        assert!(
            err.contains(&out.display().to_string()) && err.contains(kind),
            "{err}"
        );
    }
    assert_eq!(std::fs::read_link(&null).unwrap(), Path::new("/dev/null"));
    use std::os::unix::fs::FileTypeExt;
    assert!(std::fs::symlink_metadata(&fifo)
        .unwrap()
        .file_type()
        .is_fifo());
    assert!(leftovers(&d).is_empty(), "{:?}", leftovers(&d));
}

#[test]
fn stale_temporaries_of_killed_runs_are_removed() {
    let d = common::scratch_dir("stale");
    // A pid no process has (above Linux's largest pid_max).
    let dead = 4_194_400u32;
    let part = d.join(format!(".run.mcap.{dead}.part"));
    std::fs::write(&part, b"half an episode").unwrap();
    let o = mjskill()
        .args(["rollout", "--episodes", "1", "--no-frame", "--out"])
        .arg(d.join("run.mcap"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(leftovers(&d).is_empty(), "{:?}", leftovers(&d));
    // An interrupted export's hidden directory.
    let tmp = d.join(format!(".ds.tmp-{dead}"));
    std::fs::create_dir_all(tmp.join("data")).unwrap();
    let o = mjskill()
        .arg("export")
        .arg(d.join("run.mcap"))
        .args(["--format", "lerobot", "-o"])
        .arg(d.join("ds"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(leftovers(&d).is_empty(), "{:?}", leftovers(&d));
}

#[test]
fn export_flags_and_links_get_clear_messages() {
    let d = common::scratch_dir("export");
    let rec = d.join("run.mcap");
    let o = mjskill()
        .args(["rollout", "--episodes", "1", "--no-frame", "--out"])
        .arg(&rec)
        .output()
        .unwrap();
    assert!(o.status.success());
    let err = common::fails(
        &mjskill()
            .arg("export")
            .arg(&rec)
            .args(["--format", "lerobot", "--chunks-size", "-1"])
            .output()
            .unwrap(),
    );
    assert!(err.contains("-1 is not in 1..=4294967295"), "{err}");
    let target = d.join("real");
    std::fs::create_dir_all(&target).unwrap();
    let link = d.join("link");
    std::fs::remove_file(&link).ok();
    std::os::unix::fs::symlink(&target, &link).unwrap();
    let err = common::fails(
        &mjskill()
            .arg("export")
            .arg(&rec)
            .args(["--format", "lerobot", "-o"])
            .arg(&link)
            .output()
            .unwrap(),
    );
    assert!(
        err.contains("is a symbolic link") && err.contains(&target.display().to_string()),
        "{err}"
    );
}

/// A small outcome file of PickCube-v1 (Panda) with the given final objects.
fn outcome_json(objects: serde_json::Value) -> serde_json::Value {
    serde_json::json!({
        "format": "mjskill-outcomes/1", "source": "solver", "env_id": "PickCube-v1",
        "robot": "panda", "control_mode": "pd_ee_delta_pos",
        "episodes": [{"seed": 0, "steps": 1, "final_success": false,
                      "flags": {"success": "0"}, "final_objects": objects,
                      "actions": [[0.0, 0.0, 0.0, 1.0]]}]
    })
}

#[test]
fn outcome_objects_must_be_the_envs() {
    let d = common::scratch_dir("objects");
    for (name, objects, want) in [
        (
            "misspelt.json",
            serde_json::json!({"cub": [0.0, 0.0, 0.02]}),
            "\"cub\"",
        ),
        (
            "missing.json",
            serde_json::json!({"goal_site": [0.0, 0.0, 0.02]}),
            "\"goal_site\"",
        ),
    ] {
        let p = d.join(name);
        std::fs::write(&p, outcome_json(objects).to_string()).unwrap();
        let err = common::fails(&mjskill().arg("outcomes").arg(&p).output().unwrap());
        assert!(
            err.contains(name) && err.contains(want) && err.contains("(cube)"),
            "{err}"
        );
    }
    let p = d.join("lacking.json");
    let mut v = outcome_json(serde_json::json!({"cube": [0.0, 0.0, 0.02]}));
    v["env_id"] = "PokeCube-v1".into();
    std::fs::write(&p, v.to_string()).unwrap();
    let err = common::fails(&mjskill().arg("outcomes").arg(&p).output().unwrap());
    assert!(
        err.contains("lacks \"peg\"") && err.contains("cube, peg"),
        "{err}"
    );
    // The right object is measured.
    let p = d.join("good.json");
    std::fs::write(
        &p,
        outcome_json(serde_json::json!({"cube": [5.0, 0.0, 0.02]})).to_string(),
    )
    .unwrap();
    let o = mjskill()
        .args(["outcomes", "--per-episode"])
        .arg(&p)
        .output()
        .unwrap();
    let r = json(&o);
    assert_eq!(r["final_objects_within_1cm"], 0, "{r}");
    assert!(
        r["per_episode"][0]["final_object_distance_m"]
            .as_f64()
            .unwrap()
            > 4.0
    );
}

#[test]
fn compressed_inputs_stop_at_the_size_limit() {
    use std::io::Write;
    let d = common::scratch_dir("bombs");
    // 1 MB of JSON whitespace in a gzip file of about 1 kB.
    let gz = d.join("bomb.json.gz");
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
    enc.write_all(&vec![b' '; 1 << 20]).unwrap();
    std::fs::write(&gz, enc.finish().unwrap()).unwrap();
    let o = run_within(
        {
            let mut c = mjskill();
            c.env("MJSKILL_MAX_FILE_BYTES", "100000")
                .arg("outcomes")
                .arg(&gz);
            c
        },
        60,
    );
    let err = common::fails(&o);
    assert!(
        err.contains("bomb.json.gz")
            && err.contains("decompressed contents")
            && err.contains("limit of 100000 bytes"),
        "{err}"
    );
    // A ManiSkill render archive whose deflated member expands beyond the limit.
    let root = d.join("images");
    let pair = root.join("PickCube-v1__panda");
    std::fs::create_dir_all(&pair).unwrap();
    let npz = pair.join("state0.npz");
    let py =
        "import numpy as np, sys; np.savez_compressed(sys.argv[1], a=np.zeros(1 << 20, np.uint8))";
    let Some(python) = python() else { return };
    let made = Command::new(python).args(["-c", py]).arg(&npz).status();
    assert!(made.unwrap().success());
    let o = run_within(
        {
            let mut c = mjskill();
            c.env("MJSKILL_MAX_FILE_BYTES", "100000")
                .arg("compare-images")
                .arg(&root);
            c
        },
        120,
    );
    let err = common::fails(&o);
    assert!(
        err.contains("state0.npz") && err.contains("member a.npy") && err.contains("100000"),
        "{err}"
    );
}

#[test]
fn devices_fifos_and_links_to_dev_zero_are_refused_as_inputs() {
    let d = common::scratch_dir("inputs");
    let zero = d.join("zero.onnx");
    symlink_to_zero(&zero);
    let fifo = d.join("fifo.onnx");
    mkfifo(&fifo);
    for p in [&zero, &fifo] {
        let mut c = mjskill();
        c.args(["eval", "--policy"]).arg(p);
        let err = common::fails(&run_within(c, 30));
        assert!(
            err.contains(&p.display().to_string()) && err.contains("not a regular file"),
            "{err}"
        );
    }
    // In an outcomes directory, and as an outcome file.
    let outcomes = d.join("outcomes");
    std::fs::create_dir_all(&outcomes).unwrap();
    mkfifo(&outcomes.join("a.json"));
    symlink_to_zero(&d.join("zero.json.gz"));
    for p in [outcomes, d.join("zero.json.gz")] {
        let mut c = mjskill();
        c.arg("outcomes").arg(&p);
        let err = common::fails(&run_within(c, 30));
        assert!(err.contains("not a regular file"), "{err}");
    }
    // A render archive and a mesh.
    let pair = d.join("images/PickCube-v1__panda");
    std::fs::create_dir_all(&pair).unwrap();
    symlink_to_zero(&pair.join("s.npz"));
    let mut c = mjskill();
    c.arg("compare-images").arg(d.join("images"));
    let err = common::fails(&run_within(c, 60));
    assert!(
        err.contains("s.npz") && err.contains("a character device"),
        "{err}"
    );
    symlink_to_zero(&d.join("link.stl"));
    #[cfg(feature = "mesh-tools")]
    {
        let mut c = Command::new(env!("CARGO_BIN_EXE_mjskill-meshes"));
        c.args(["fit-primitives", "--mesh"]).arg(d.join("link.stl"));
        let err = common::fails(&run_within(c, 30));
        assert!(
            err.contains("link.stl") && err.contains("a character device"),
            "{err}"
        );
    }
}

/// The first seed whose next seed puts PickCube's goal higher (goal z grows), with both goal
/// heights and the goal's index in the observation.
fn rising_goal() -> (u64, f32, f32, usize) {
    let mut env = mjskill::make(
        "PickCube-v1",
        mjskill::EnvConfig {
            control_mode: Some("pd_ee_delta_pos".into()),
            ..Default::default()
        },
    )
    .unwrap();
    let range = env
        .obs_layout()
        .iter()
        .find(|(k, _)| k == "extra/goal_pos")
        .map(|(_, r)| r.clone())
        .unwrap();
    let z = |env: &mut mjskill::Env, seed| {
        env.reset(Some(seed));
        env.obs()[range.start + 2]
    };
    for seed in 0..50 {
        let (a, b) = (z(&mut env, seed), z(&mut env, seed + 1));
        if b > a + 0.01 && a > 0.0 {
            return (seed, a, b, range.start + 2);
        }
    }
    panic!("no rising goal in 50 seeds");
}

#[test]
fn a_policy_that_crashes_mid_rollout_leaves_an_incomplete_file() {
    let Some(py) = python() else { return };
    let d = common::scratch_dir("crash");
    let (seed, z0, z1, index) = rising_goal();
    // Out of range in the second episode only.
    let f = hostile(
        &py,
        &d,
        "gather-oob",
        &[
            "--index",
            &index.to_string(),
            "--threshold",
            &((z0 + z1) / 2.0).to_string(),
        ],
    );
    let out = d.join("run.mcap");
    let mut c = mjskill();
    c.args(["rollout", "--episodes", "3", "--no-frame", "--seed"])
        .arg(seed.to_string())
        .arg("--policy")
        .arg(&f)
        .arg("--out")
        .arg(&out);
    let err = common::fails(&run_within(c, 120));
    assert!(err.contains(&f.display().to_string()), "{err}");
    let i = json(&mjskill().arg("info").arg(&out).output().unwrap());
    assert_eq!(i["complete"], false, "{i}");
    assert_eq!(i["episodes"], 1, "{i}");
    assert!(leftovers(&d).is_empty(), "{:?}", leftovers(&d));
    // Out of range from the first step: no file at all, no temporary left.
    let f = hostile(&py, &d, "gather-oob", &["--index", &index.to_string()]);
    let out = d.join("first.mcap");
    let mut c = mjskill();
    c.args(["rollout", "--episodes", "2", "--no-frame", "--policy"])
        .arg(&f)
        .arg("--out")
        .arg(&out);
    let err = common::fails(&run_within(c, 120));
    assert!(err.contains(&f.display().to_string()), "{err}");
    assert!(!out.exists());
    assert!(leftovers(&d).is_empty(), "{:?}", leftovers(&d));
}

#[test]
fn policy_files_that_crash_or_exhaust_the_runtime_are_errors() {
    let Some(py) = python() else { return };
    let d = common::scratch_dir("runtime");
    let cases: Vec<(PathBuf, &str)> = vec![
        (hostile(&py, &d, "div-zero", &[]), "failed to run"),
        (
            hostile(
                &py,
                &d,
                "const-shape",
                &["--shape", "1000000000,1000000000"],
            ),
            "16777216 elements",
        ),
        (
            hostile(&py, &d, "const-shape", &["--shape", "10000000000"]),
            "16777216 elements",
        ),
        (hostile(&py, &d, "nan-mul-zero", &[]), "constant zero"),
        // Non-finite constants (issue 48, finding 4): a NaN floor, which tract's Max skips
        // and onnxruntime's returns, and an infinite one.
        (
            hostile(&py, &d, "floor", &["--value", "nan", "--index", "2"]),
            "holds NaN at index 2",
        ),
        (
            hostile(&py, &d, "floor", &["--value=-inf", "--index", "1"]),
            "holds -inf at index 1",
        ),
        (hostile(&py, &d, "int64-out", &[]), "f32"),
        (hostile(&py, &d, "rank3-out", &[]), "shape"),
        (hostile(&py, &d, "loop", &[]), "Loop"),
    ];
    for (f, want) in &cases {
        let mut c = mjskill();
        c.args(["eval", "--episodes", "1", "--policy"]).arg(f);
        let err = common::fails(&run_within(c, 60));
        assert!(
            err.contains(&f.display().to_string()) && err.contains(want),
            "{want}: {err}"
        );
    }
    // A finite floor is fine, and so is a tensor within the limit.
    for (kind, args) in [
        ("floor", ["--value", "0.25"]),
        ("const-shape", ["--shape", "1000,1000"]),
    ] {
        let f = hostile(&py, &d, kind, &args);
        let o = mjskill()
            .args(["eval", "--episodes", "1", "--policy"])
            .arg(&f)
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{kind}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
}

#[test]
fn policy_metadata_is_read_one_way_and_named_in_errors() {
    let Some(py) = python() else { return };
    let d = common::scratch_dir("meta");
    for key in ["control_mode", "env_id"] {
        let f = hostile(&py, &d, "dup-meta", &["--key", key]);
        let err = common::fails(
            &mjskill()
                .args(["eval", "--policy"])
                .arg(&f)
                .output()
                .unwrap(),
        );
        assert!(
            err.contains(&f.display().to_string())
                && err.contains(&format!("{key:?} more than once")),
            "{err}"
        );
    }
    // A 2 MB env id: refused naming the file, in a short message.
    let f = hostile(
        &py,
        &d,
        "long-meta",
        &["--key", "env_id", "--length", "2000000"],
    );
    let err = common::fails(
        &mjskill()
            .args(["eval", "--policy"])
            .arg(&f)
            .output()
            .unwrap(),
    );
    assert!(err.contains(&f.display().to_string()), "{err}");
    assert!(
        err.contains("(2000000 bytes)") && err.len() < 2000,
        "{}",
        err.len()
    );
    let f = hostile(
        &py,
        &d,
        "long-meta",
        &["--key", "robot_uids", "--length", "1000"],
    );
    let err = common::fails(
        &mjskill()
            .args(["eval", "--policy"])
            .arg(&f)
            .output()
            .unwrap(),
    );
    assert!(
        err.contains(&f.display().to_string()) && err.contains("robots: "),
        "{err}"
    );
    // NaN actions: the policy file, the episode and its seed are named.
    let f = hostile(&py, &d, "nan-out", &[]);
    for cmd in ["eval", "rollout"] {
        let mut c = mjskill();
        c.args([cmd, "--seed", "7", "--policy"]).arg(&f);
        if cmd == "rollout" {
            c.args(["--no-frame", "--out"]).arg(d.join("nan.mcap"));
        }
        let err = common::fails(&c.output().unwrap());
        assert!(
            err.contains(&f.display().to_string())
                && err.contains("episode 0 (seed 7)")
                && err.contains("NaN"),
            "{err}"
        );
    }
}
