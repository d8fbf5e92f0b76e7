//! The env state in ManiSkill's terms: `get_state_dict` / `set_state_dict`, actor poses by
//! name, the per-part action split, and `sim_freq`.
use mjskill::{make, EnvConfig, SimConfig, StateDict};

mod common;

use common::env_in as env;

#[test]
fn state_dict_has_maniskills_layout_and_round_trips() {
    let mut e = env("PokeCube-v1", "panda", "pd_joint_target_delta_pos");
    e.reset(Some(3));
    for k in 0..10 {
        let a: Vec<f32> = (0..8).map(|i| ((k * 3 + i) as f32 * 0.9).sin()).collect();
        e.step(&a).unwrap();
    }
    let sd = e.get_state_dict();
    let actors: Vec<&str> = sd.actors.keys().map(String::as_str).collect();
    assert_eq!(actors, ["table-workspace", "cube", "peg", "goal_region"]);
    assert_eq!(e.actor_names(), actors);
    assert_eq!(e.dynamic_actor_names(), ["cube", "peg"]);
    assert_eq!(sd.articulations["panda"].len(), 13 + 9 + 9);
    assert_eq!(
        sd.controller.keys().collect::<Vec<_>>(),
        ["arm.target_qpos"]
    );
    assert_eq!(sd.flat().len(), 4 * 13 + 31 + 7);
    // The JSON form nests the controller state under the part, as ManiSkill's dict does.
    let json = sd.to_json();
    assert_eq!(
        json["controller"]["arm"]["target_qpos"]
            .as_array()
            .unwrap()
            .len(),
        7
    );
    assert_eq!(StateDict::from_json(&json).unwrap(), sd);
    // Setting the state of another env makes its observation, reward and info equal.
    let (obs, reward, info) = (e.obs().to_vec(), e.dense_reward(), e.info().values.clone());
    let mut other = env("PokeCube-v1", "panda", "pd_joint_target_delta_pos");
    other.reset(Some(99));
    other.set_state_dict(&sd).unwrap();
    other.set_elapsed_steps(e.info().elapsed_steps);
    for (a, b) in other.obs().iter().zip(&obs) {
        assert!((a - b).abs() < 1e-6, "{a} vs {b}");
    }
    assert!((other.dense_reward() - reward).abs() < 1e-9);
    assert_eq!(other.info().values[..4], info[..4]);
    let back = other.get_state_dict();
    for (name, a) in &sd.actors {
        for (x, y) in a.iter().zip(&back.actors[name]) {
            assert!(
                (x - y).abs() < 1e-9,
                "{name}: {a:?} vs {:?}",
                back.actors[name]
            );
        }
    }
    assert_eq!(back.controller, sd.controller);
    // The pose of an actor by name, and an unknown name.
    let peg = e.actor_pose("peg").unwrap();
    assert_eq!(peg[..], sd.actors["peg"][..7]);
    assert!(e.actor_pose("bogus").is_none());
}

#[test]
fn the_controller_target_of_a_state_dict_drives_the_next_step() {
    let mut e = env("PickCube-v1", "panda", "pd_joint_target_delta_pos");
    e.reset(Some(1));
    let mut sd = e.get_state_dict();
    let mut target = sd.controller["arm.target_qpos"].clone();
    target[0] += 0.3;
    sd.controller
        .insert("arm.target_qpos".into(), target.clone());
    e.set_state_dict(&sd).unwrap();
    let obs_target = e.obs_part("agent/controller/arm/target_qpos").unwrap();
    assert!((obs_target[0] as f64 - target[0]).abs() < 1e-6);
    // A zero action keeps accumulating on the restored target: joint 1 moves towards it.
    let q0 = e.obs_part("agent/qpos").unwrap()[0];
    for _ in 0..20 {
        e.step(&[0.0; 8]).unwrap();
    }
    let q1 = e.obs_part("agent/qpos").unwrap()[0];
    assert!((q1 - q0 - 0.3).abs() < 0.01, "joint 1 moved {}", q1 - q0);
}

#[test]
fn state_dict_values_have_the_bounds_of_set_state() {
    let mut e = env("PickCube-v1", "panda", "pd_joint_target_delta_pos");
    e.reset(Some(0));
    let good = e.get_state_dict();
    let before = e.get_state();
    // A target beyond f32 would be observed as inf and could not be saved by get_state.
    let mut sd = good.clone();
    sd.controller
        .insert("arm.target_qpos".into(), vec![1e39; 7]);
    let err = e.set_state_dict(&sd).unwrap_err().to_string();
    assert!(
        err.contains("controller.arm.target_qpos[0] = 1000000000000000000000000000000000000000 is out of range (|value| ≤ 3.4028234663852886e38)"),
        "{err}"
    );
    // set_state rejects the same value.
    let mut s = before.clone();
    s.controller[0] = 1e39;
    assert!(e.set_state(&s).is_err());
    let mut sd = good.clone();
    sd.articulations.get_mut("panda").unwrap()[13] = 1e11;
    let err = e.set_state_dict(&sd).unwrap_err().to_string();
    assert!(
        err.contains("articulations.panda[13] = 100000000000 is out of range (|value| ≤ 1e10)"),
        "{err}"
    );
    let mut sd = good.clone();
    sd.actors.get_mut("cube").unwrap()[8] = -1e11;
    let err = e.set_state_dict(&sd).unwrap_err().to_string();
    assert!(
        err.contains("actors.cube[8] = -100000000000 is out of range"),
        "{err}"
    );
    assert_eq!(
        e.get_state(),
        before,
        "a rejected state dict changes nothing"
    );
    // The largest f32 target is accepted and round-trips through get_state/set_state.
    let mut sd = good;
    sd.controller
        .insert("arm.target_qpos".into(), vec![f32::MAX as f64; 7]);
    e.set_state_dict(&sd).unwrap();
    assert!(e.obs().iter().all(|v| v.is_finite()));
    let s = e.get_state();
    let json = serde_json::to_string(&s).unwrap();
    e.set_state(&serde_json::from_str(&json).unwrap()).unwrap();
}

#[test]
fn bad_state_dicts_are_errors_that_leave_the_env_unchanged() {
    let mut e = env("PickCube-v1", "panda", "pd_joint_delta_pos");
    e.reset(Some(0));
    let good = e.get_state_dict();
    let before = e.get_state();
    let check = |sd: StateDict, want: &str, e: &mut mjskill::Env| {
        let err = e.set_state_dict(&sd).unwrap_err().to_string();
        assert!(err.contains(want), "{err}");
        assert_eq!(e.get_state(), before);
    };
    let mut sd = good.clone();
    sd.actors.shift_remove("cube");
    check(sd, "lacks actor \"cube\"", &mut e);
    let mut sd = good.clone();
    sd.actors.insert("mug".into(), [0.0; 13]);
    check(sd, "unknown actor \"mug\"", &mut e);
    let mut sd = good.clone();
    sd.actors.get_mut("cube").unwrap()[7] = f64::NAN;
    check(sd, "actors.cube[7] = NaN is not finite", &mut e);
    let mut sd = good.clone();
    sd.articulations.get_mut("panda").unwrap().pop();
    check(sd, "articulations.panda has 30 values, expected 31", &mut e);
    let mut sd = good.clone();
    sd.articulations.get_mut("panda").unwrap()[0] += 0.1;
    check(sd, "the robot's root is fixed", &mut e);
    let mut sd = good.clone();
    sd.actors.get_mut("table-workspace").unwrap()[2] += 0.1;
    check(sd, "is fixed at", &mut e);
    let mut sd = good.clone();
    sd.controller.insert("arm.target_qpos".into(), vec![0.0; 7]);
    check(sd, "unknown controller state \"arm.target_qpos\"", &mut e);
    let mut sd = good;
    let a = sd.articulations.shift_remove("panda").unwrap();
    sd.articulations.insert("fetch".into(), a);
    check(sd, "unknown articulation \"fetch\"", &mut e);
    assert!(
        StateDict::from_json(&serde_json::json!({"actors": {"cube": [1.0]}}))
            .unwrap_err()
            .to_string()
            .contains("actors.cube has 1 values, expected 13")
    );
    assert!(StateDict::from_json(&serde_json::json!({"bodies": {}}))
        .unwrap_err()
        .to_string()
        .contains("unknown state dict key \"bodies\""));
}

#[test]
fn action_parts_are_maniskills_action_space_dict() {
    let e = env("PickCube-v1", "fetch", "pd_joint_delta_pos");
    let parts: Vec<(&str, std::ops::Range<usize>)> = e
        .action_parts()
        .into_iter()
        .map(|p| (p.name, p.range))
        .collect();
    assert_eq!(
        parts,
        [
            ("arm", 0..7),
            ("gripper", 7..8),
            ("body", 8..11),
            ("base", 11..13)
        ]
    );
    let e = env("PickCube-v1", "xarm6_robotiq", "pd_ee_delta_pose");
    let parts = e.action_parts();
    assert_eq!(parts.len(), 2, "the passive linkage takes no action");
    assert_eq!(
        (parts[1].name, parts[1].range.clone()),
        ("gripper_active", 6..7)
    );
    // Absolute gripper radians in this mode: its bounds are the joint's range.
    assert_eq!((parts[1].low[0], parts[1].high[0]), (0.0, 0.81));
}

#[test]
fn sim_freq_sets_the_physics_step_and_bad_rates_are_errors() {
    let fast = make("PickCube-v1", EnvConfig::default()).unwrap();
    assert_eq!(fast.config().sim.sim_freq, 100);
    assert_eq!((fast.model().timestep(), fast.substeps()), (0.01, 5));
    let fine = make(
        "PickCube-v1",
        EnvConfig {
            sim: SimConfig {
                sim_freq: 500,
                ..Default::default()
            },
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!((fine.model().timestep(), fine.substeps()), (0.002, 25));
    for bad in [0, 30, 7, 1_000_000] {
        let err = make(
            "PickCube-v1",
            EnvConfig {
                sim: SimConfig {
                    sim_freq: bad,
                    ..Default::default()
                },
                ..Default::default()
            },
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains(&format!("sim_freq {bad}")), "{err}");
    }
    // Both rates solve the task: the same solver episode succeeds at either.
    for sim_freq in [100, 500] {
        let config = EnvConfig {
            sim: SimConfig {
                sim_freq,
                ..Default::default()
            },
            ..Default::default()
        };
        let r = mjskill::solvers::evaluate("PickCube-v1", config, "solver", 3, 0).unwrap();
        assert_eq!(r.successes, 3, "sim_freq {sim_freq}");
    }
}

/// A PickCube state in which the Panda holds the cube (the scripted solver until
/// `is_grasped`, then two more steps), the solver's last action and the state before it.
fn held_state() -> (mjskill::Env, Vec<f32>, StateDict) {
    let mut e = env("PickCube-v1", "panda", "pd_ee_delta_pos");
    e.reset(Some(0));
    let mut policy = mjskill::solvers::make_policy("solver", &e, 0).unwrap();
    policy.reset(&e);
    let mut a = vec![0.0f32; 4];
    let mut after = None;
    for _ in 0..50 {
        policy.act(&e, &mut a);
        let before = e.get_state_dict();
        let grasped = e.step(&a).unwrap().info.flag("is_grasped");
        after = match after {
            None if grasped => Some(0),
            Some(k) => Some(k + 1),
            None => None,
        };
        if after == Some(2) {
            return (e, a, before);
        }
    }
    panic!("the solver never grasped the cube");
}

#[test]
fn a_state_dict_carries_the_drive_targets_so_a_held_cube_stays_grasped() {
    let (e, _, _) = held_state();
    assert!(e.info().flag("is_grasped"));
    let sd = e.get_state_dict();
    let drive = sd
        .drive
        .clone()
        .expect("get_state_dict carries the drive targets");
    assert_eq!(drive.qpos.len(), 9);
    assert_eq!(drive.qpos, e.drive_targets().qpos);
    // The gripper is commanded closed (the solver's 7.5 mm), a centimetre and more below where
    // the fingers rest on the cube.
    assert!(drive.qpos[7] < e.robot_qpos()[7] - 0.01, "{drive:?}");
    // The flat vector stays ManiSkill's; JSON round-trips the drive targets.
    assert_eq!(sd.flat().len(), 3 * 13 + 31);
    let json = sd.to_json();
    assert_eq!(json["drive"]["target_qpos"].as_array().unwrap().len(), 9);
    assert_eq!(StateDict::from_json(&json).unwrap(), sd);

    // Imported into another env with its drive targets, the fingers squeeze the cube: the
    // grasp flag and the dense reward are the original's.
    let mut other = env("PickCube-v1", "panda", "pd_ee_delta_pos");
    other.reset(Some(5));
    other.set_state_dict(&sd).unwrap();
    assert!(other.info().flag("is_grasped"));
    assert!((other.dense_reward() - e.dense_reward()).abs() < 1e-3);
    // Without them (ManiSkill's own dicts) the drives hold the imported positions and the
    // fingers stop squeezing: the cube does not count as grasped.
    let mut bare = sd.clone();
    bare.drive = None;
    other.set_state_dict(&bare).unwrap();
    assert!(!other.info().flag("is_grasped"));
    assert!(e.dense_reward() - other.dense_reward() > 0.5);
}

#[test]
fn importing_after_an_action_applies_that_actions_drive_targets() {
    let (e, a, before) = held_state();
    // The state the action led to, without drive targets (as ManiSkill records it).
    let after = e.get_state_dict();
    let mut bare = after.clone();
    bare.drive = None;
    let mut other = env("PickCube-v1", "panda", "pd_ee_delta_pos");
    other.reset(Some(0));
    other.set_state_dict(&before).unwrap();
    let untouched = other.get_state();
    let expected = other.action_drive_targets(&a).unwrap();
    assert_eq!(
        other.get_state(),
        untouched,
        "action_drive_targets changes nothing"
    );
    // The targets the action set in the original env.
    assert_eq!(expected, after.drive.clone().unwrap());
    other.set_state_dict_after_action(&a, &bare).unwrap();
    assert!(other.info().flag("is_grasped"));
    assert_eq!(other.drive_targets(), expected);
    // A dict that has its own drive targets keeps them.
    let mut own = after.clone();
    own.drive.as_mut().unwrap().qpos[7] = 0.02;
    other.set_state_dict_after_action(&a, &own).unwrap();
    assert_eq!(other.drive_targets().qpos[7], 0.02);
    // Bad actions and drive targets are errors naming the problem; the env is unchanged.
    let unchanged = other.get_state();
    let err = other
        .action_drive_targets(&[0.0; 3])
        .unwrap_err()
        .to_string();
    assert!(err.contains('3') && err.contains('4'), "{err}");
    let err = other
        .set_state_dict_after_action(&[f32::NAN, 0.0, 0.0, 0.0], &bare)
        .unwrap_err()
        .to_string();
    assert!(err.contains("NaN"), "{err}");
    let mut short = after.clone();
    short.drive.as_mut().unwrap().qvel.pop();
    let err = other.set_state_dict(&short).unwrap_err().to_string();
    assert!(
        err.contains("drive.target_qvel has 8 values, expected 9"),
        "{err}"
    );
    assert_eq!(other.get_state(), unchanged);
    // JSON: target_qvel may be left out (zero); unknown drive keys are errors.
    let mut json = after.to_json();
    json["drive"].as_object_mut().unwrap().remove("target_qvel");
    let sd = StateDict::from_json(&json).unwrap();
    assert_eq!(sd.drive.unwrap().qvel, vec![0.0; 9]);
    json["drive"]["stiffness"] = serde_json::json!([1.0]);
    let err = StateDict::from_json(&json).unwrap_err().to_string();
    assert!(
        err.contains("drive.stiffness") && err.contains("target_qpos"),
        "{err}"
    );
}
