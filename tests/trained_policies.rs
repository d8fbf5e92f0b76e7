//! The trained policies shipped in `models/policies/` (docs/training.md, "Trained policies"):
//! every file describes itself (env, robot, control mode, obs mode, the command that trained
//! it), and each still solves its task in mjskill at about the rate measured when it was
//! shipped, through `mjskill eval --policy` as a user runs it. A change to the physics, a
//! controller or an observation that breaks a policy trained here fails here.
use std::path::{Path, PathBuf};
use std::process::Command;

use mjskill::solvers::PolicyFile;

/// (file, env id, control mode, success rate of `mjskill eval --policy FILE --episodes 100
/// --seed 10000` measured when the file was shipped).
const SHIPPED: &[(&str, &str, &str, f64)] = &[
    (
        "PickCube-v1__panda.onnx",
        "PickCube-v1",
        "pd_joint_delta_pos",
        0.97,
    ),
    (
        "PlaceSphere-v1__panda.onnx",
        "PlaceSphere-v1",
        "pd_joint_delta_pos",
        0.93,
    ),
    (
        "PokeCube-v1__panda.onnx",
        "PokeCube-v1",
        "pd_ee_delta_pose",
        0.92,
    ),
];

/// Episodes the test runs (seeds 10000..10040, the first of the 100 measured).
const EPISODES: usize = 40;
/// How far below the shipped rate the 40 episodes may fall: a few episodes' worth, for
/// floating-point differences between machines that tip a borderline episode.
const MARGIN: f64 = 0.1;

fn dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("models/policies")
}

#[test]
fn shipped_policies_are_the_listed_ones_and_describe_themselves() {
    let mut files: Vec<String> = std::fs::read_dir(dir())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".onnx"))
        .collect();
    files.sort();
    let mut listed: Vec<String> = SHIPPED.iter().map(|s| s.0.to_string()).collect();
    listed.sort();
    assert_eq!(files, listed);
    for &(file, env_id, mode, _) in SHIPPED {
        let p = PolicyFile::load(dir().join(file)).unwrap();
        let m = p.meta();
        assert_eq!(m.env_id, env_id, "{file}");
        assert_eq!(m.robot_uids, "panda", "{file}");
        assert_eq!(m.control_mode, mode, "{file}");
        assert_eq!(m.obs_mode, "state", "{file}");
        assert!(
            m.training_command
                .starts_with(&format!("python examples/ppo.py --env-id {env_id} ")),
            "{file}: {}",
            m.training_command
        );
        let steps = m.props.iter().find(|(k, _)| k == "env_steps").unwrap();
        assert!(steps.1.parse::<u64>().unwrap() > 0, "{file}");
        let len = std::fs::metadata(dir().join(file)).unwrap().len();
        assert!(len < 1 << 20, "{file}: {len} bytes");
    }
}

#[test]
fn shipped_policies_solve_their_tasks_in_mjskill() {
    for &(file, env_id, _, rate) in SHIPPED {
        let o = Command::new(env!("CARGO_BIN_EXE_mjskill"))
            .args([
                "eval",
                "--episodes",
                &EPISODES.to_string(),
                "--seed",
                "10000",
            ])
            .arg("--policy")
            .arg(dir().join(file))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(v["env"], env_id);
        assert_eq!(v["episodes"], EPISODES);
        let got = v["success_rate"].as_f64().unwrap();
        assert!(
            got >= rate - MARGIN,
            "{file}: success {got} over {EPISODES} episodes; shipped at {rate} (100 episodes)"
        );
    }
}
