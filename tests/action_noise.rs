//! Noise-injected demonstrations (`mjskill rollout --action-noise`, DART): each step records
//! the solver's own action as its label (`expert_action`) and the action the env executed, the
//! label plus seeded Gaussian noise; the same command writes the same bytes; bad noise
//! specifications are clear errors.
#![cfg(feature = "cli")]

mod common;
use std::path::Path;
use std::process::Command;

use mjskill::record::read;
use mjskill::solvers::make_policy;

fn mjskill() -> Command {
    Command::new(env!("CARGO_BIN_EXE_mjskill"))
}

/// Records `args` into `out` (success asserted); returns the JSON summary.
fn rollout(out: &Path, args: &[&str]) -> serde_json::Value {
    let o = mjskill()
        .args(["rollout", "--no-frame", "--out"])
        .arg(out)
        .args(args)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// Re-runs every episode of the recording `path` with a fresh solver in an env made from the
/// file's metadata, stepping the env with the recorded (executed) actions, and checks at every
/// step that the recorded label is the solver's own action for the state reached, bitwise,
/// and that the step's observation is the recorded one. Returns, for the entries with σ > 0
/// whose label lies at least 4σ inside the bounds (noise never clipped there in practice),
/// the executed action minus the label, divided by σ; entries with σ = 0 are checked to be
/// the label itself.
fn check_labels(path: &Path, sigma: &[f32]) -> Vec<f64> {
    check_policy_labels(path, sigma, "solver")
}

/// [`check_labels`] for the built-in policy `policy` (`solver` or `expert`).
fn check_policy_labels(path: &Path, sigma: &[f32], policy: &str) -> Vec<f64> {
    let rec = read(path).unwrap();
    let mut env = mjskill::make(&rec.meta.env_id, rec.meta.config().unwrap()).unwrap();
    let mut solver = make_policy(policy, &env, 0).unwrap();
    let (low, high) = (
        env.action_space().low.clone(),
        env.action_space().high.clone(),
    );
    let mut label = vec![0.0f32; sigma.len()];
    let mut z = Vec::new();
    for ep in rec.finished() {
        env.reset(ep.seed);
        solver.reset(&env);
        for (t, step) in ep.steps.iter().enumerate() {
            solver.act(&env, &mut label);
            let recorded = step.expert_action.as_ref().expect("a labelled step");
            assert_eq!(
                recorded, &label,
                "episode {} step {t}: the label is the solver's action",
                ep.index
            );
            for k in 0..sigma.len() {
                let (a, l, s) = (step.action[k], label[k], sigma[k]);
                assert!((low[k]..=high[k]).contains(&a), "clipped to the bounds");
                if s == 0.0 {
                    assert_eq!(a, l.clamp(low[k], high[k]), "σ 0: the label executed");
                } else if l >= low[k] + 4.0 * s && l <= high[k] - 4.0 * s {
                    z.push((a - l) as f64 / s as f64);
                }
            }
            let s = env.step(&step.action).unwrap();
            assert_eq!(s.obs, &step.obs[..], "episode {} step {t}", ep.index);
        }
    }
    z
}

/// The executed actions differ from the labels by noise of the given σ: mean 0 and standard
/// deviation 1 in units of σ, within what `z.len()` samples allow.
fn check_noise(z: &[f64], what: &str) {
    let n = z.len() as f64;
    assert!(n >= 100.0, "{what}: {n} samples");
    let mean = z.iter().sum::<f64>() / n;
    let std = (z.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
    assert!(mean.abs() < 4.0 / n.sqrt(), "{what}: mean {mean} over {n}");
    assert!((std - 1.0).abs() < 0.2, "{what}: std {std} over {n}");
    assert!(z.iter().all(|x| *x != 0.0), "{what}: every entry moved");
}

#[test]
fn labels_are_the_solvers_actions_and_the_env_executes_them_with_noise() {
    // The Panda's own mode, the SO100's joint positions, and the Panda's solver converted to
    // joint positions (solvers::ModeConverted).
    let cases: [(&str, &[&str], &str, Vec<f32>); 3] = [
        (
            "panda_ee.mcap",
            &["--env", "PickCube-v1"],
            "arm=0.05,gripper=0",
            vec![0.05, 0.05, 0.05, 0.0],
        ),
        (
            "so100.mcap",
            &["--env", "PickCubeSO100-v1"],
            "0.04",
            vec![0.04; 6],
        ),
        (
            "panda_joint.mcap",
            &["--env", "PickCube-v1", "--control-mode", "pd_joint_pos"],
            "arm=0.02,gripper=0",
            [vec![0.02; 7], vec![0.0]].concat(),
        ),
    ];
    for (name, env, spec, sigma) in cases {
        let out = common::scratch(name);
        let mut args = env.to_vec();
        args.extend([
            "--episodes",
            "3",
            "--action-noise",
            spec,
            "--noise-seed",
            "11",
        ]);
        let s = rollout(&out, &args);
        let got: Vec<f32> = serde_json::from_value(s["action_noise"].clone()).unwrap();
        assert_eq!(got, sigma, "{s}");
        assert_eq!(s["noise_seed"], 11, "{s}");
        let z = check_labels(&out, &sigma);
        check_noise(&z, name);
        // Replays stay exact: the recorded action is the executed one.
        let r = mjskill()
            .args(["replay", "--tolerance", "0"])
            .arg(&out)
            .output()
            .unwrap();
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    }
}

#[test]
fn expert_demos_label_every_recorded_state_with_the_state_experts_action() {
    // `--policy expert`: the Fetch's PlaceSphere expert converted to joint positions, the mode
    // its policies are cloned in; each label is the expert's action for the state reached.
    let out = common::scratch("fetch_expert.mcap");
    let spec = "arm=0.005,gripper=0,body=0,base=0";
    let sigma = [vec![0.005; 7], vec![0.0; 6]].concat();
    let s = rollout(
        &out,
        &[
            "--env",
            "PlaceSphere-v1",
            "--robot",
            "fetch",
            "--policy",
            "expert",
            "--control-mode",
            "pd_joint_pos",
            "--episodes",
            "2",
            "--action-noise",
            spec,
        ],
    );
    assert_eq!(s["policy"], "expert", "{s}");
    let got: Vec<f32> = serde_json::from_value(s["action_noise"].clone()).unwrap();
    assert_eq!(got, sigma, "{s}");
    check_policy_labels(&out, &sigma, "expert");
    // A pair without an expert is refused, naming those that have one.
    let o = mjskill()
        .args([
            "rollout",
            "--env",
            "StackCube-v1",
            "--policy",
            "expert",
            "--out",
        ])
        .arg(common::scratch("none.mcap"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("no state expert for StackCube-v1 with panda"),
        "{err}"
    );
}

#[test]
fn the_same_command_records_the_same_bytes_and_the_noise_seed_changes_the_noise() {
    let args = [
        "--env",
        "PickCube-v1",
        "--episodes",
        "2",
        "--seed",
        "40",
        "--action-noise",
        "0.05",
    ];
    let (a, b, c) = (
        common::scratch("same_a.mcap"),
        common::scratch("same_b.mcap"),
        common::scratch("other_seed.mcap"),
    );
    rollout(&a, &args);
    rollout(&b, &args);
    assert!(
        std::fs::read(&a).unwrap() == std::fs::read(&b).unwrap(),
        "byte-identical"
    );
    rollout(&c, &[&args[..], &["--noise-seed", "1"]].concat());
    let (ra, rc) = (read(&a).unwrap(), read(&c).unwrap());
    let (sa, sc) = (&ra.episodes[0].steps[0], &rc.episodes[0].steps[0]);
    // The same first state, so the same label; other noise, so another executed action.
    assert_eq!(sa.expert_action, sc.expert_action);
    assert_ne!(sa.action, sc.action);
    // The metadata keeps the command that recorded the file, without its --out; an argument
    // a shell would split is quoted.
    let meta_command = |p: &Path| read(p).unwrap().meta.command.expect("a rollout's command");
    let command = meta_command(&a);
    assert_eq!(
        command,
        "mjskill rollout --no-frame --env PickCube-v1 --episodes 2 --seed 40 --action-noise 0.05"
    );
    assert_eq!(meta_command(&c), format!("{command} --noise-seed 1"));
    let spaced = common::scratch("spaced.mcap");
    rollout(
        &spaced,
        &["--episodes", "1", "--action-noise", "arm=0.05, gripper=0"],
    );
    assert!(
        meta_command(&spaced).ends_with("--action-noise 'arm=0.05, gripper=0'"),
        "{}",
        meta_command(&spaced)
    );
    // Without --action-noise the steps carry no label.
    let plain = common::scratch("plain.mcap");
    rollout(&plain, &["--episodes", "1"]);
    assert!(read(&plain).unwrap().episodes[0]
        .steps
        .iter()
        .all(|s| s.expert_action.is_none()));
}

#[test]
fn bad_noise_specs_are_clear_errors_before_anything_is_written() {
    let out = common::scratch("never.mcap");
    let cases: [(&[&str], &[&str]); 7] = [
        (
            &["--action-noise", "hand=0.1,arm=0"],
            &["no action part \"hand\"", "its parts: arm, gripper"],
        ),
        (
            &["--robot", "fetch", "--action-noise", "arm=0.01"],
            &["gripper, body, base", "name=0"],
        ),
        (&["--action-noise", "nan"], &["nan", "finite number >= 0"]),
        (&["--action-noise", "-0.1"], &["-0.1", "finite number >= 0"]),
        (
            &["--action-noise", "0.1,0.1"],
            &["2 values", "4 action entries", "arm 0..3, gripper 3..4"],
        ),
        (
            &[
                "--control-mode",
                "pd_joint_pos",
                "--action-noise",
                "arm=0.1,gripper=0,arm=0",
            ],
            &["\"arm\" is given twice"],
        ),
        (&["--action-noise", "0.1,abc"], &["\"abc\" is not a number"]),
    ];
    for (args, wants) in cases {
        let o = mjskill()
            .args(["rollout", "--episodes", "1", "--no-frame", "--out"])
            .arg(&out)
            .args(args)
            .output()
            .unwrap();
        let err = common::fails(&o);
        for w in wants {
            assert!(err.contains(w), "{args:?}: {err}");
        }
        assert!(!out.exists(), "{args:?}: nothing written");
    }
    // --noise-seed belongs to --action-noise.
    let o = mjskill()
        .args(["rollout", "--noise-seed", "3", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("--action-noise"),
        "{err}"
    );
    assert!(!out.exists());
}

#[test]
fn labelled_steps_follow_the_step_schema_and_a_label_of_another_length_is_refused() {
    let out = common::scratch("schema.mcap");
    rollout(&out, &["--episodes", "1", "--action-noise", "0.05"]);
    let bytes = std::fs::read(&out).unwrap();
    let mut steps = 0;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        if m.channel.topic != "/step" {
            continue;
        }
        let schema: serde_json::Value =
            serde_json::from_slice(&m.channel.schema.as_ref().unwrap().data).unwrap();
        let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        let props = schema["properties"].as_object().unwrap();
        for k in v.as_object().unwrap().keys() {
            assert!(props.contains_key(k), "{k} is not in mjskill.Step's schema");
        }
        assert_eq!(schema["additionalProperties"], false);
        let label = v["expert_action"].as_array().expect("expert_action");
        assert_eq!(label.len(), v["action"].as_array().unwrap().len());
        steps += 1;
    }
    assert_eq!(steps, 50);
    // The library refuses a label that is not one value per action entry, writing nothing.
    let path = common::scratch("bad_label.mcap");
    let mut env = mjskill::make("PickCube-v1", mjskill::EnvConfig::default()).unwrap();
    let mut rec = mjskill::Recorder::create(&path, &env).unwrap();
    rec.reset(&mut env, Some(0)).unwrap();
    let dim = env.action_space().shape[0];
    let before = env.get_state();
    let s = env.step(&vec![0.0; dim]).unwrap();
    let (reward, term, trunc) = (s.reward, s.terminated, s.truncated);
    let action = vec![0.0; dim];
    let e = rec
        .record_labelled_step(&env, &action, &[0.0], reward, term, trunc, &before)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("an expert action of 1 values for an action of 8"),
        "{e}"
    );
    // Stepping with a bad label is refused before the env steps: env and file stay in step.
    let elapsed = env.info().elapsed_steps;
    let e = rec
        .step_labelled(&mut env, &action, &[0.0])
        .unwrap_err()
        .to_string();
    assert!(e.contains("an expert action of 1 values"), "{e}");
    assert_eq!(env.info().elapsed_steps, elapsed, "the env stepped");
    rec.end_episode(false).unwrap();
    rec.finish().unwrap();
    assert!(read(&path).unwrap().episodes[0].steps.is_empty());
}
