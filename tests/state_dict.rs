//! The env state in ManiSkill's terms: `get_state_dict` / `set_state_dict`, actor poses by
//! name, the per-part action split, and `sim_freq`.
use mjskill::{make, EnvConfig, SimConfig, StateDict};

mod common;

fn env(id: &str, robot: &str, mode: &str) -> mjskill::Env {
    make(
        id,
        EnvConfig {
            robot: Some(robot.into()),
            control_mode: Some(mode.into()),
            ..Default::default()
        },
    )
    .unwrap()
}

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
            sim: SimConfig { sim_freq: 500 },
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!((fine.model().timestep(), fine.substeps()), (0.002, 25));
    for bad in [0, 30, 7, 1_000_000] {
        let err = make(
            "PickCube-v1",
            EnvConfig {
                sim: SimConfig { sim_freq: bad },
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
            sim: SimConfig { sim_freq },
            ..Default::default()
        };
        let r = mjskill::solvers::evaluate("PickCube-v1", config, "solver", 3, 0).unwrap();
        assert_eq!(r.successes, 3, "sim_freq {sim_freq}");
    }
}
