//! One policy, one score (docs/outcome-physics.md, "Policy-level agreement"): the eight policy
//! files shipped on 28 November 2026, kept as fixtures in `tests/data/policies/` however the
//! shipped files change, run in mjskill on seeds 10000–10099 and compared with ManiSkill 3's
//! success on the same seeds. ManiSkill's figures were recorded per seed, closed loop, with
//! `examples/eval_in_maniskill.py FILE --episodes 100 --seed 10000 --per-episode`
//! (`tests/data/policies/maniskill.json`, which names the ManiSkill version).
//!
//! Each fixture's gap (|mjskill successes − ManiSkill successes| over the 100 seeds) must stay
//! within its ceiling. The aim is [`TARGET_GAP`] for every file; the files whose grasp PhysX
//! does not honour as MuJoCo does (the SO100, PlaceSphere) are still further
//! apart, and their ceilings are today's measured gaps plus
//! [`MACHINE_MARGIN`], so that the agreement can only get better: lower a ceiling when a change
//! closes a gap.
#![cfg(feature = "onnx")]
use std::path::{Path, PathBuf};

use mjskill::solvers::{run_episode, PolicySpec};

/// The aim of issue 54: a policy's success here within 5 points of ManiSkill's.
const TARGET_GAP: usize = 5;
/// Episodes a change of machine, compiler or unrelated code may tip either way (a borderline
/// episode ends a step earlier or later).
const MACHINE_MARGIN: usize = 3;

/// (fixture, ceiling of |mjskill − ManiSkill| successes over seeds 10000–10099).
const FIXTURES: &[(&str, usize)] = &[
    ("PickCube-v1__panda.onnx", TARGET_GAP),
    ("PickCube-v1__xarm6_robotiq.onnx", TARGET_GAP),
    // 80 against ManiSkill's 86 until the IK became SAPIEN's (1 December 2026); 86 since.
    ("PokeCube-v1__panda.onnx", TARGET_GAP),
    // 14 apart before the pinch's kick (docs/physics.md), 6 before the WidowX AI's no-slip
    // pass (1 December 2026, twenty-second session), 3 since.
    ("PickCube-v1__widowxai.onnx", TARGET_GAP),
    ("PickCubeWidowXAI-v1__widowxai.onnx", TARGET_GAP),
    // Not yet within the aim (docs/outcome-physics.md): the gap measured on 29 November 2026
    // + MACHINE_MARGIN.
    ("PickCube-v1__so100.onnx", 47 + MACHINE_MARGIN),
    ("PickCubeSO100-v1__so100.onnx", 47 + MACHINE_MARGIN),
    ("PlaceSphere-v1__panda.onnx", 25 + MACHINE_MARGIN),
];

const SEED: u64 = 10000;
const EPISODES: usize = 100;

fn data() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/policies")
}

/// ManiSkill's success at any step per seed ('1'/'0', seeds 10000..), from maniskill.json.
fn maniskill_successes(file: &str) -> Vec<bool> {
    let text = std::fs::read_to_string(data().join("maniskill.json")).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(v["seed"], SEED);
    assert_eq!(v["episodes"], EPISODES);
    let s = v["files"][file]["success"]
        .as_str()
        .unwrap_or_else(|| panic!("maniskill.json has no {file}"));
    assert_eq!(s.len(), EPISODES, "{file}");
    s.chars().map(|c| c == '1').collect()
}

/// mjskill's success at any step per seed, as `mjskill eval --policy FILE` runs it.
fn mjskill_successes(file: &str) -> Vec<bool> {
    mjskill_successes_with(file, mjskill::PinchSolver::Mujoco)
}

/// As [`mjskill_successes`], with the pinch stepped by `pinch`.
fn mjskill_successes_with(file: &str, pinch: mjskill::PinchSolver) -> Vec<bool> {
    let spec = PolicySpec::parse(data().join(file).to_str().unwrap()).unwrap();
    let base = mjskill::EnvConfig {
        sim: mjskill::SimConfig {
            pinch_solver: pinch,
            ..Default::default()
        },
        ..Default::default()
    };
    let (env_id, config) = spec.target(None, base, false).unwrap();
    let mut env = spec.make_env(&env_id, config).unwrap();
    let mut policy = spec.make_policy(&env, SEED).unwrap();
    let mut action = vec![0.0f32; env.action_space().shape[0]];
    (0..EPISODES as u64)
        .map(|k| {
            run_episode(
                &mut env,
                policy.as_mut(),
                Some(SEED + k),
                &mut action,
                |_, _, _, _, _| Ok(()),
            )
            .unwrap()
            .success_once
        })
        .collect()
}

#[test]
fn the_fixtures_are_the_recorded_ones() {
    let mut files: Vec<String> = std::fs::read_dir(data())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".onnx"))
        .collect();
    files.sort();
    let mut listed: Vec<String> = FIXTURES.iter().map(|f| f.0.to_string()).collect();
    listed.sort();
    assert_eq!(files, listed);
    for (file, _) in FIXTURES {
        let ms = maniskill_successes(file);
        // ManiSkill's totals as the issue measured them: a fixture re-recorded by mistake
        // (another file, other seeds) shows up here.
        assert!(ms.iter().filter(|&&s| s).count() >= 40, "{file}");
    }
}

#[test]
fn each_policy_succeeds_here_about_as_often_as_in_maniskill() {
    let mut report = Vec::new();
    let mut failures = Vec::new();
    for &(file, ceiling) in FIXTURES {
        let ms = maniskill_successes(file);
        let mj = mjskill_successes(file);
        let (n_ms, n_mj) = (
            ms.iter().filter(|&&s| s).count(),
            mj.iter().filter(|&&s| s).count(),
        );
        let same = ms.iter().zip(&mj).filter(|(a, b)| a == b).count();
        let gap = n_ms.abs_diff(n_mj);
        report.push(format!(
            "{file}: mjskill {n_mj}, ManiSkill {n_ms}, gap {gap} (ceiling {ceiling}), \
             same outcome {same}/{EPISODES}"
        ));
        if gap > ceiling {
            failures.push(file);
        }
    }
    eprintln!("{}", report.join("\n"));
    assert!(
        failures.is_empty(),
        "policy files further from ManiSkill than allowed: {failures:?}\n{}",
        report.join("\n")
    );
}

/// With PhysX's step for the pinch (`pinch_solver = "physx_tgs"`, docs/physics.md, "The pinch in
/// PhysX's step"), the SO100 fixtures come within 9 points of ManiSkill (54 against 45, from 47
/// apart with MuJoCo's step): the ceiling is that gap plus [`MACHINE_MARGIN`].
#[test]
fn the_so100_fixtures_with_physx_pinch_come_close_to_maniskill() {
    for file in ["PickCube-v1__so100.onnx", "PickCubeSO100-v1__so100.onnx"] {
        let ms = maniskill_successes(file).iter().filter(|&&s| s).count();
        let mj = mjskill_successes_with(file, mjskill::PinchSolver::PhysxTgs)
            .iter()
            .filter(|&&s| s)
            .count();
        eprintln!("{file} with physx_tgs: mjskill {mj}, ManiSkill {ms}");
        assert!(
            mj.abs_diff(ms) <= 9 + MACHINE_MARGIN,
            "{file}: mjskill {mj} against ManiSkill {ms}"
        );
    }
}
