//! Reference trajectories: small recordings made by `mjskill rollout` for every registered
//! (env, robot) pair with the scripted solver (those listed `UNSOLVED` have none yet), plus one
//! random-policy episode per env, replayed step by step against the current build.
//!
//! Regenerate them all (after an intended change of behaviour) with
//! `cargo test --release --test reference -- --ignored`.
#![cfg(feature = "cli")]
use std::path::{Path, PathBuf};
use std::process::Command;

/// Allowed deviation of observations, rewards and info values from a reference recording:
/// bitwise on the machine that made them; 1e-3 leaves room for another CPU's last bits
/// growing through contact-rich steps while still catching any change of behaviour.
const REFERENCE_TOLERANCE: f64 = 1e-3;
/// Solver episodes per (env, robot) pair and random episodes per env.
const SOLVER_EPISODES: usize = 1;
const RANDOM_EPISODES: usize = 1;

fn dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/reference")
}

/// (file name, env id, robot, policy, episodes) of every reference recording, from the
/// registry: a new env or robot needs its reference file.
fn references() -> Vec<(String, &'static str, &'static str, &'static str, usize)> {
    let mut out = Vec::new();
    for env in mjskill::registry() {
        for (robot, _) in &env.robots {
            if mjskill::solvers::UNSOLVED.contains(&(env.id, *robot)) {
                continue;
            }
            out.push((
                format!("{}_{robot}_solver.mcap", env.id),
                env.id,
                *robot,
                "solver",
                SOLVER_EPISODES,
            ));
        }
        out.push((
            format!("{}_{}_random.mcap", env.id, env.default_robot),
            env.id,
            env.default_robot,
            "random",
            RANDOM_EPISODES,
        ));
    }
    out
}

#[test]
fn reference_trajectories_replay_within_tolerance() {
    let refs = references();
    assert!(refs.len() >= 16, "every env × robot pair is covered");
    for (name, env, robot, policy, episodes) in refs {
        let path = dir().join(&name);
        assert!(
            path.exists(),
            "reference recording {} is missing (regenerate: cargo test --release --test \
             reference -- --ignored)",
            path.display()
        );
        let rec = mjskill::record::read(&path).unwrap();
        assert!(rec.complete, "{name}");
        assert_eq!(
            (rec.meta.env_id.as_str(), rec.meta.robot.as_str()),
            (env, robot),
            "{name}"
        );
        assert_eq!(rec.finished().count(), episodes, "{name}");
        let rep =
            mjskill::record::replay::replay_recording(&path, &rec, REFERENCE_TOLERANCE).unwrap();
        assert!(rep.ok, "{name}: {rep:?}");
        assert_eq!(rep.flag_mismatches, 0, "{name}: success per step matches");
        assert_eq!(
            rep.steps,
            rec.finished().map(|e| e.steps.len()).sum::<usize>(),
            "{name}"
        );
        if policy == "solver" {
            // The solvers succeed on seed 0 for every pair: the reference shows a solved task.
            assert!(
                rec.finished().all(|e| e.success),
                "{name}: the solver episode succeeds"
            );
        }
    }
}

/// Rewrites every reference recording with `mjskill rollout` (seed 0).
#[test]
#[ignore = "regenerates tests/data/reference; run on purpose with --ignored"]
fn regenerate_reference_trajectories() {
    for (name, env, robot, policy, episodes) in references() {
        let out = Command::new(env!("CARGO_BIN_EXE_mjskill"))
            .args([
                "rollout", "--env", env, "--robot", robot, "--policy", policy,
            ])
            .args([
                "--episodes",
                &episodes.to_string(),
                "--seed",
                "0",
                "--no-frame",
            ])
            .arg("--out")
            .arg(dir().join(&name))
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        println!("{name}: {}", String::from_utf8_lossy(&out.stdout).trim());
    }
}
