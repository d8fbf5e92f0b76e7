//! PokeCube-v1 and PlaceSphere-v1 with Fetch (docs/tasks.md §2–§5): state dims, seeded objects
//! independent of the robot, the Fetch's TCP link (`gripper_link`) in the PokeCube reward,
//! the static term over `qvel[:-2]` and Fetch's signed static rule, and the scripted solvers.
use super::common;

use crate::env::{make, Env, EnvConfig, RewardMode};
use crate::robots::fetch;
use crate::solvers::make_policy;
use common::{norm, part};

fn env(task: &str, robot: &str, mode: Option<&str>) -> Env {
    make(
        task,
        EnvConfig {
            robot: Some(robot.into()),
            control_mode: mode.map(str::to_string),
            reward_mode: RewardMode::Dense,
            ..Default::default()
        },
    )
    .unwrap()
}

#[test]
fn state_dims_match_tasks_md() {
    for (task, mode, dim) in [
        ("PokeCube-v1", "pd_joint_delta_pos", 66),
        ("PokeCube-v1", "pd_joint_target_delta_pos", 73),
        ("PlaceSphere-v1", "pd_joint_delta_pos", 51),
        ("PlaceSphere-v1", "pd_joint_target_delta_pos", 58),
    ] {
        let e = env(task, "fetch", Some(mode));
        assert_eq!(e.observation_space().shape, vec![dim], "{task} {mode}");
    }
    // The default control mode gives the same 66.
    assert_eq!(
        env("PokeCube-v1", "fetch", None).observation_space().shape,
        vec![66]
    );
}

#[test]
fn seeded_pokecube_objects_do_not_depend_on_the_robot() {
    let mut f = env("PokeCube-v1", "fetch", None);
    let mut p = env("PokeCube-v1", "panda", None);
    f.reset(Some(0));
    p.reset(Some(0));
    for key in [
        "extra/cube_pose",
        "extra/peg_pose",
        "extra/cube_to_goal_pos",
    ] {
        assert_eq!(part(&f, key), part(&p, key), "{key}");
    }
    // docs/tasks.md §5, PokeCube seed 0.
    let peg = part(&f, "extra/peg_pose");
    let cube = part(&f, "extra/cube_pose");
    let c2g = part(&f, "extra/cube_to_goal_pos");
    let want_peg = [-0.000749, 0.053644, 0.025, 1.0, 0.0, 0.0, 0.0];
    let want_cube = [0.219251, -0.038515, 0.02, 0.99973, 0.0, 0.0, -0.023231];
    let want_goal = [0.319251, -0.038515, 0.001];
    for k in 0..7 {
        assert!((peg[k] - want_peg[k]).abs() < 2e-6, "peg {peg:?}");
        assert!((cube[k] - want_cube[k]).abs() < 2e-6, "cube {cube:?}");
    }
    for k in 0..3 {
        assert!((cube[k] + c2g[k] - want_goal[k]).abs() < 2e-6, "goal");
    }
    // The Fetch stands at its table qpos, without noise.
    let q = part(&f, "agent/qpos");
    for (g, w) in q.iter().zip(fetch::TABLE_QPOS) {
        assert_eq!(*g, w as f32 as f64);
    }
}

/// Writes a free body's pose (unrotated, zero velocity) and the robot's joint velocities.
fn put(e: &mut Env, body: &str, pos: [f64; 3], robot_qvel: &[f64]) {
    common::put_free_body(e, body, pos, [1.0, 0.0, 0.0, 0.0]);
    common::set_robot_qvel(e, robot_qvel);
}

#[test]
fn pokecube_reward_uses_gripper_link_and_fetchs_static_rule() {
    let mut e = env("PokeCube-v1", "fetch", None);
    e.reset(Some(0));
    let gl = e.robot().body("gripper_link").unwrap();
    let g: Vec<f64> = e.data().body_pos(gl).to_vec();
    // Reached-peg stage: the peg 3 cm ahead of gripper_link.
    let peg = [g[0] + 0.03, g[1], g[2]];
    put(&mut e, "peg", peg, &[0.0; 15]);
    let tcp = part(&e, "extra/tcp_pose");
    for k in 0..3 {
        assert!((tcp[k] - g[k]).abs() < 1e-6, "tcp_pose is gripper_link's");
    }
    let d = norm(&part(&e, "extra/tcp_to_peg_pos"));
    assert!((d - 0.03).abs() < 1e-6);
    assert!(!e.info().flag("is_peg_grasped"));
    let want = 2.0 * (1.0 - (5.0f64 * 0.03).tanh());
    assert!(
        (e.dense_reward() - want).abs() < 1e-9,
        "{}",
        e.dense_reward()
    );

    // Cube on the goal: the static term covers qvel[:-2] (base dofs included, fingers not).
    e.reset(Some(0));
    let cube = part(&e, "extra/cube_pose");
    let c2g = part(&e, "extra/cube_to_goal_pos");
    let goal = [cube[0] + c2g[0], cube[1] + c2g[1], 0.02];
    let mut qvel = [0.0; 15];
    qvel[0] = 0.3; // base x: not static (> 0.05)
    qvel[13] = 0.5; // fingers: ignored by the reward term
    qvel[14] = 0.5;
    put(&mut e, "cube", goal, &qvel);
    assert!(e.info().flag("is_cube_placed") && !e.info().flag("success"));
    let d = norm(&part(&e, "extra/tcp_to_peg_pos"));
    let want = 2.0 * (1.0 - (5.0 * d).tanh()) + 1.0 - (5.0f64 * 0.3).tanh();
    // d is read from the float32 observation.
    assert!(
        (e.dense_reward() - want).abs() < 1e-6,
        "{} vs {want}, d {d}, qvel {:?}",
        e.dense_reward(),
        part(&e, "agent/qvel")
    );
    // Fetch's signed rule: a large negative base velocity counts as static ⇒ success, 10.
    qvel[0] = -0.3;
    put(&mut e, "cube", goal, &qvel);
    assert!(e.info().flag("success"));
    assert_eq!(e.dense_reward(), 10.0);
    // An arm joint moving (> 0.2) is not static.
    qvel[0] = 0.0;
    qvel[7] = 0.25;
    put(&mut e, "cube", goal, &qvel);
    assert!(!e.info().flag("success"));
}

/// Successes of the scripted solver over `seeds` within the 50-step episodes.
fn solver_successes(task: &str, seeds: std::ops::Range<u64>) -> usize {
    let mode = crate::solvers::required_control_mode("solver", task, "fetch");
    let mut e = env(task, "fetch", mode);
    let mut policy = make_policy("solver", &e, 0).unwrap();
    let mut action = vec![0f32; e.action_space().shape[0]];
    let mut wins = 0;
    for seed in seeds {
        e.reset(Some(seed));
        policy.reset(&e);
        for _ in 0..e.max_episode_steps() {
            policy.act(&e, &mut action);
            if e.step(&action).unwrap().info.success() {
                wins += 1;
                break;
            }
        }
    }
    wins
}

// The Fetch solvers succeed on 99/100 (PlaceSphere) and 100/100 (PokeCube) of seeds 0–99
// at the 0.01 s step, 10 of seeds 0–9 each (docs/solvers.md §9).
#[test]
fn placesphere_solver_places_the_sphere() {
    let wins = solver_successes("PlaceSphere-v1", 0..10);
    assert!(wins >= 9, "{wins}/10");
}

#[test]
fn pokecube_solver_pokes_the_cube() {
    let wins = solver_successes("PokeCube-v1", 0..10);
    assert!(wins >= 9, "{wins}/10");
}

#[test]
fn the_fetchs_liftpeg_solver_needs_joint_targets_for_its_roll() {
    use crate::solvers::lift_peg_upright::FetchLiftPeg;
    use crate::solvers::SolverError;
    // Built directly in an end-effector mode it refuses, naming the mode it drives.
    let e = env("LiftPegUpright-v1", "fetch", Some("pd_ee_delta_pose"));
    match FetchLiftPeg::new(&e) {
        Err(SolverError::WrongControlMode { required, mode, .. }) => {
            assert_eq!(
                (required.as_str(), mode.as_str()),
                ("pd_joint_pos", "pd_ee_delta_pose")
            );
        }
        other => panic!("expected a refusal, got {other:?}"),
    }
    assert!(FetchLiftPeg::new(&env("LiftPegUpright-v1", "fetch", Some("pd_joint_pos"))).is_ok());
}
