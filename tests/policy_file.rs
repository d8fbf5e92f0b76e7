//! Policy files (ONNX, docs/training.md): `eval --policy` and `rollout --policy` run them with
//! the env, robot and modes of their metadata; their actions are the network's (checked
//! against an independent f64 computation of the same MLP from its weights) clipped to the
//! action space; wrong sizes, malformed files, missing metadata and mismatching options are
//! clear errors, never panics.
//!
//! The files are made at test time by `examples/make_test_policy.py` (numpy and `onnx`) in the
//! venv `.ci/setup` creates (`.ci/venv`). Without it the tests print a note and pass, unless
//! `MJSKILL_REQUIRE_PYTHON` is set (`.ci/run` sets it).
#![cfg(all(feature = "onnx", feature = "cli"))]

use std::path::{Path, PathBuf};
use std::process::Command;

use mjskill::solvers::{PolicySpec, SolverError};
use mjskill::EnvConfig;

const ENV: &str = "PickCube-v1";
const ROBOT: &str = "panda";
const MODE: &str = "pd_ee_delta_pos";

mod common;

fn mjskill() -> Command {
    Command::new(env!("CARGO_BIN_EXE_mjskill"))
}

fn python() -> Option<PathBuf> {
    common::venv_python("policy file test")
}

/// The observation and action sizes of the test env.
fn dims() -> (usize, usize) {
    dims_of(ENV)
}

/// The observation and action sizes of `env_id` with the test robot and mode.
fn dims_of(env_id: &str) -> (usize, usize) {
    let config = EnvConfig {
        robot: Some(ROBOT.into()),
        control_mode: Some(MODE.into()),
        ..Default::default()
    };
    let env = mjskill::make(env_id, config).unwrap();
    (env.obs().len(), env.action_space().shape[0])
}

/// Makes `name` with examples/make_test_policy.py (and its weights JSON next to it), for an
/// MLP of `obs` → `act` values; `extra` are further arguments.
fn make_policy(py: &Path, name: &str, obs: usize, act: usize, extra: &[&str]) -> PathBuf {
    let out = common::scratch(name);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/make_test_policy.py");
    let o = Command::new(py)
        .arg(script)
        .args(["--obs-dim", &obs.to_string(), "--act-dim", &act.to_string()])
        .args(["--env-id", ENV, "--robot", ROBOT, "--control-mode", MODE])
        .arg("--out")
        .arg(&out)
        .arg("--weights-json")
        .arg(out.with_extension("json"))
        .args(extra)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "make_test_policy.py failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    out
}

fn json(out: &[u8]) -> serde_json::Value {
    serde_json::from_slice(out).unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(out)))
}

/// The MLP of a weights JSON, computed in f64: normalise, clip, layers with tanh between.
struct Reference {
    mean: Vec<f64>,
    std: Vec<f64>,
    clip: f64,
    layers: Vec<(Vec<Vec<f64>>, Vec<f64>)>,
}

impl Reference {
    fn load(path: &Path) -> Reference {
        let v = json(&std::fs::read(path).unwrap());
        let vec = |v: &serde_json::Value| -> Vec<f64> {
            v.as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        };
        assert_eq!(v["activation"], "tanh");
        Reference {
            mean: vec(&v["obs_mean"]),
            std: vec(&v["obs_std"]),
            clip: v["obs_clip"].as_f64().unwrap(),
            layers: v["layers"]
                .as_array()
                .unwrap()
                .iter()
                .map(|l| {
                    let w = l["w"].as_array().unwrap().iter().map(vec).collect();
                    (w, vec(&l["b"]))
                })
                .collect(),
        }
    }

    fn forward(&self, obs: &[f32]) -> Vec<f64> {
        let mut x: Vec<f64> = obs
            .iter()
            .zip(&self.mean)
            .zip(&self.std)
            .map(|((&o, m), s)| ((o as f64 - m) / s).clamp(-self.clip, self.clip))
            .collect();
        for (k, (w, b)) in self.layers.iter().enumerate() {
            let mut y = b.clone();
            for (xi, row) in x.iter().zip(w) {
                for (yj, wij) in y.iter_mut().zip(row) {
                    *yj += xi * wij;
                }
            }
            if k + 1 < self.layers.len() {
                y.iter_mut().for_each(|v| *v = v.tanh());
            }
            x = y;
        }
        x
    }
}

#[test]
fn policy_actions_are_the_networks_clipped_to_the_action_space() {
    let Some(py) = python() else { return };
    let (obs_dim, act_dim) = dims();
    let file = make_policy(&py, "reference.onnx", obs_dim, act_dim, &["--seed", "3"]);
    let reference = Reference::load(&file.with_extension("json"));
    let spec = PolicySpec::parse(file.to_str().unwrap()).unwrap();
    // Env, robot and modes come from the metadata.
    let (env_id, config) = spec.target(None, EnvConfig::default(), false).unwrap();
    assert_eq!(env_id, ENV);
    assert_eq!(config.robot.as_deref(), Some(ROBOT));
    assert_eq!(config.control_mode.as_deref(), Some(MODE));
    let mut env = spec.make_env(&env_id, config).unwrap();
    let mut policy = spec.make_policy(&env, 0).unwrap();
    let (low, high) = (
        env.action_space().low.clone(),
        env.action_space().high.clone(),
    );
    let mut action = vec![0.0f32; act_dim];
    let (mut clipped, mut inside, mut max_err) = (0usize, 0usize, 0.0f64);
    for seed in 0..2 {
        env.reset(Some(seed));
        policy.reset(&env);
        for _ in 0..50 {
            policy.try_act(&env, &mut action).unwrap();
            let want = reference.forward(env.obs());
            for k in 0..act_dim {
                let (lo, hi) = (low[k] as f64, high[k] as f64);
                if want[k] < lo || want[k] > hi {
                    clipped += 1;
                } else {
                    inside += 1;
                }
                max_err = max_err.max((action[k] as f64 - want[k].clamp(lo, hi)).abs());
            }
            let s = env.step(&action).unwrap();
            if s.truncated {
                break;
            }
        }
    }
    assert!(
        max_err < 1e-4,
        "ONNX actions differ from the reference by {max_err}"
    );
    // The weights are scaled so both cases occur: the clipping is exercised.
    assert!(
        clipped > 0 && inside > 0,
        "clipped {clipped}, inside {inside}"
    );
}

#[test]
fn eval_and_rollout_take_a_policy_file() {
    let Some(py) = python() else { return };
    let (obs_dim, act_dim) = dims();
    let file = make_policy(&py, "eval.onnx", obs_dim, act_dim, &[]);
    let run = || {
        let o = mjskill()
            .args(["eval", "--episodes", "3", "--seed", "7", "--policy"])
            .arg(&file)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        json(&o.stdout)
    };
    let r = run();
    assert_eq!(r["env"], ENV);
    assert_eq!(r["robot"], ROBOT);
    assert_eq!(r["control_mode"], MODE);
    assert_eq!(r["policy"], file.display().to_string());
    assert_eq!(r["episodes"], 3);
    // Deterministic: the same file and seeds give the same report.
    assert_eq!(run(), r);
    // Options that agree with the metadata are accepted.
    let o = mjskill()
        .args(["eval", "--episodes", "1", "--env", ENV, "--robot", ROBOT])
        .args(["--control-mode", MODE, "--policy"])
        .arg(&file)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));

    // A recording of the policy replays bitwise, and its return is eval's.
    let out = common::scratch("policy.mcap");
    let o = mjskill()
        .args(["rollout", "--episodes", "3", "--seed", "7", "--no-frame"])
        .arg("--policy")
        .arg(&file)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = json(&o.stdout);
    assert_eq!(s["robot"], ROBOT);
    assert_eq!(s["control_mode"], MODE);
    assert_eq!(s["steps"], 150);
    let (a, b) = (
        s["mean_return"].as_f64().unwrap(),
        r["mean_return"].as_f64().unwrap(),
    );
    assert!((a - b).abs() < 1e-9, "rollout {a} vs eval {b}");
    let i = json(&mjskill().arg("info").arg(&out).output().unwrap().stdout);
    assert_eq!(i["obs_mode"], "state");
    let rp = mjskill()
        .args(["replay", "--tolerance", "0"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        rp.status.success(),
        "{}",
        String::from_utf8_lossy(&rp.stderr)
    );
}

#[test]
fn wrong_sizes_are_refused_naming_both() {
    let Some(py) = python() else { return };
    let (obs_dim, act_dim) = dims();
    let wide = make_policy(&py, "wide_obs.onnx", obs_dim + 3, act_dim, &[]);
    let err = common::fails(
        &mjskill()
            .args(["eval", "--policy"])
            .arg(&wide)
            .output()
            .unwrap(),
    );
    assert!(err.contains(&wide.display().to_string()), "{err}");
    assert!(
        err.contains(&format!("observations of {} values", obs_dim + 3))
            && err.contains(&format!("gives {obs_dim}")),
        "{err}"
    );
    let act = make_policy(&py, "wide_act.onnx", obs_dim, act_dim + 2, &[]);
    let err = common::fails(
        &mjskill()
            .args(["eval", "--policy"])
            .arg(&act)
            .output()
            .unwrap(),
    );
    assert!(
        err.contains(&format!("actions of {} values", act_dim + 2))
            && err.contains(&format!("takes {act_dim}")),
        "{err}"
    );
}

#[test]
fn metadata_mismatches_are_refused_naming_both() {
    let Some(py) = python() else { return };
    let (obs_dim, act_dim) = dims();
    let file = make_policy(&py, "meta.onnx", obs_dim, act_dim, &[]);
    for (flag, value, key, file_value) in [
        ("--robot", "fetch", "robot_uids", ROBOT),
        ("--env", "PokeCube-v1", "env_id", ENV),
        ("--control-mode", "pd_joint_pos", "control_mode", MODE),
    ] {
        let err = common::fails(
            &mjskill()
                .args(["eval", flag, value, "--policy"])
                .arg(&file)
                .output()
                .unwrap(),
        );
        assert!(
            err.contains(key)
                && err.contains(&format!("{file_value:?}"))
                && err.contains(&format!("{value:?}"))
                && err.contains(&file.display().to_string()),
            "{flag}: {err}"
        );
    }
    // A visual obs mode is not the policy's state vector; state_dict is the same vector.
    let out = common::scratch("meta.mcap");
    let err = common::fails(
        &mjskill()
            .args(["rollout", "--obs-mode", "rgb", "--no-frame", "--policy"])
            .arg(&file)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap(),
    );
    assert!(err.contains("obs_mode") && err.contains("\"rgb\""), "{err}");
    assert!(!out.exists());
    let o = mjskill()
        .args(["rollout", "--obs-mode", "state_dict", "--episodes", "1"])
        .args(["--no-frame", "--policy"])
        .arg(&file)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));

    // The metadata's env is the default env.
    let (poke_obs, poke_act) = dims_of("PokeCube-v1");
    let poke = make_policy(
        &py,
        "poke.onnx",
        poke_obs,
        poke_act,
        &["--meta", "env_id=PokeCube-v1"],
    );
    let o = mjskill()
        .args(["eval", "--episodes", "1", "--policy"])
        .arg(&poke)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(json(&o.stdout)["env"], "PokeCube-v1");

    // Missing metadata keys are named.
    let bare = make_policy(
        &py,
        "bare.onnx",
        obs_dim,
        act_dim,
        &[
            "--drop-meta",
            "robot_uids",
            "--drop-meta",
            "training_command",
        ],
    );
    let err = common::fails(
        &mjskill()
            .args(["eval", "--policy"])
            .arg(&bare)
            .output()
            .unwrap(),
    );
    assert!(
        err.contains("lacks the metadata_props robot_uids, training_command"),
        "{err}"
    );
    let vis = make_policy(&py, "vis.onnx", obs_dim, act_dim, &["--obs-mode", "rgbd"]);
    let err = common::fails(
        &mjskill()
            .args(["eval", "--policy"])
            .arg(&vis)
            .output()
            .unwrap(),
    );
    assert!(err.contains("obs_mode \"rgbd\""), "{err}");
}

#[test]
fn malformed_and_missing_files_are_errors_naming_the_file() {
    // No Python needed: these files are not ONNX models.
    let garbage = common::scratch("garbage.onnx");
    std::fs::write(&garbage, b"this is not an ONNX model \x00\xff\x13").unwrap();
    let empty = common::scratch("empty.onnx");
    std::fs::write(&empty, b"").unwrap();
    let truncated = common::scratch("truncated.onnx");
    // A protobuf field header promising more bytes than there are.
    std::fs::write(&truncated, [0x3a, 0xff, 0x01, 0x0a]).unwrap();
    for f in [&garbage, &empty, &truncated] {
        let err = common::fails(
            &mjskill()
                .args(["eval", "--policy"])
                .arg(f)
                .output()
                .unwrap(),
        );
        assert!(err.contains(&f.display().to_string()), "{err}");
        assert!(
            err.contains("is not a valid ONNX model") || err.contains("lacks the metadata_props"),
            "{err}"
        );
        let e = PolicySpec::parse(f.to_str().unwrap()).unwrap_err();
        assert!(matches!(
            e,
            mjskill::solvers::EvalError::Policy(SolverError::PolicyFile(_))
        ));
    }
    let missing = common::scratch("missing.onnx");
    let err = common::fails(
        &mjskill()
            .args(["rollout", "--policy"])
            .arg(&missing)
            .output()
            .unwrap(),
    );
    assert!(
        err.contains("cannot read policy file") && err.contains(&missing.display().to_string()),
        "{err}"
    );
    let err = common::fails(
        &mjskill()
            .args(["eval", "--policy", "no-such-policy"])
            .output()
            .unwrap(),
    );
    assert!(
        err.contains("solver, expert, random, zero, or a policy file (FILE.onnx)"),
        "{err}"
    );
}
