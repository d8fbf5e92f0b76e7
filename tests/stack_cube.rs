//! StackCube-v1 with the Panda, the Fetch and the panda_wristcam (ManiSkill's default robot for
//! it): seeded initial states against ManiSkill's
//! (`tests/data/maniskill_initial/`, recorded by the `record.py` there), the observation
//! layouts, `evaluate()` and every dense-reward stage on constructed states and along random
//! and solver episodes.

mod common;

use common::put_free_body;
use common::task::{check_initial_states, closeness, env as task_env, extra_keys, norm, part, sub};
use mjskill::{Env, EnvConfig, ObsMode, RewardMode};

const ID: &str = "StackCube-v1";
const ROBOTS: [&str; 3] = ["panda", "fetch", "panda_wristcam"];

/// Whether `robot` is one of the Panda's (its fingers, 9 joints, its solver).
fn is_panda(robot: &str) -> bool {
    robot.starts_with("panda")
}

fn env(robot: &str, obs_mode: ObsMode) -> Env {
    task_env(ID, robot, obs_mode)
}

/// The info keys, in ManiSkill's order.
const KEYS: [&str; 4] = [
    "is_cubeA_grasped",
    "is_cubeA_on_cubeB",
    "is_cubeA_static",
    "success",
];

#[test]
fn seeded_initial_states_equal_maniskills_on_fitted_and_held_out_seeds() {
    for robot in ROBOTS {
        // The table and both cubes.
        check_initial_states(ID, robot, &KEYS, 8.0, Some(3));
    }
}

#[test]
fn the_cubes_spawn_apart_within_the_region() {
    // Cube B is drawn until it lies more than two collision radii (2 · (‖(0.02, 0.02)‖ + 1 mm))
    // from cube A, both within ±0.1 (x) and ±0.2 (y) of a common centre in ±0.1.
    let mut e = env("panda", ObsMode::State);
    let clearance = 2.0 * (0.02f64.hypot(0.02) + 0.001);
    for seed in 0..200 {
        e.reset(Some(seed));
        let (a, b) = (part(&e, "extra/cubeA_pose"), part(&e, "extra/cubeB_pose"));
        let d = norm(&sub(&a[..2], &b[..2]));
        assert!(d > clearance - 1e-6, "seed {seed}: cubes {d} m apart");
        for c in [&a, &b] {
            assert!(
                c[0].abs() <= 0.2 + 1e-6 && c[1].abs() <= 0.3 + 1e-6,
                "seed {seed}"
            );
            assert!((c[2] - 0.02).abs() < 1e-6, "seed {seed}: on the table");
            // A yaw only: the quaternion's x and y are zero.
            assert!(c[4].abs() < 1e-7 && c[5].abs() < 1e-7, "seed {seed}: {c:?}");
        }
    }
}

/// Cube A's linear and angular speed (MuJoCo's body velocity, angular first).
fn cube_a_speeds(e: &Env) -> (f64, f64) {
    let a = e.model().require_body("cubeA").unwrap();
    let v = e.data().body_velocity(a.index());
    (norm(&v[3..6]), norm(&v[0..3]))
}

/// The dense reward recomputed independently from the observation, the grasp flag and cube
/// A's velocity (docs/tasks.md §8.5).
fn spec_dense_reward(e: &Env) -> f64 {
    let info = e.info();
    let flag = |k: &str| info.get(k).unwrap() > 0.0;
    let (tcp, a, b) = (
        part(e, "extra/tcp_pose"),
        part(e, "extra/cubeA_pose"),
        part(e, "extra/cubeB_pose"),
    );
    let qpos = part(e, "agent/qpos");
    if flag("success") {
        return 8.0;
    }
    if flag("is_cubeA_on_cubeB") {
        // Both robots' finger joints open to 0.04 (panda) or 0.05 (fetch) each.
        let width = if is_panda(e.robot_id().uid()) {
            0.08
        } else {
            0.1
        };
        let n = qpos.len();
        let ungrasp = if flag("is_cubeA_grasped") {
            (qpos[n - 2] + qpos[n - 1]) / width
        } else {
            1.0
        };
        let (v, w) = cube_a_speeds(e);
        return 6.0 + (ungrasp + 1.0 - (10.0 * v + w).tanh()) / 2.0;
    }
    if flag("is_cubeA_grasped") {
        let goal = [b[0], b[1], b[2] + 0.04];
        return 4.0 + closeness(norm(&sub(&goal, &a[..3])));
    }
    2.0 * closeness(norm(&sub(&a[..3], &tcp[..3])))
}

#[test]
fn state_keys_and_visual_keys_follow_maniskill() {
    for robot in ROBOTS {
        let e = env(robot, ObsMode::StateDict);
        let extra = extra_keys(&e);
        assert_eq!(
            extra,
            [
                "extra/tcp_pose",
                "extra/cubeA_pose",
                "extra/cubeB_pose",
                "extra/tcp_to_cubeA_pos",
                "extra/tcp_to_cubeB_pos",
                "extra/cubeA_to_cubeB_pos"
            ]
        );
        let n = if is_panda(robot) { 9 } else { 15 };
        assert_eq!(e.observation_space().shape, vec![2 * n + 30], "{robot}");
        let rgb = env(robot, ObsMode::Rgb);
        let keys: Vec<&str> = rgb.obs_layout().iter().map(|(k, _)| k.as_str()).collect();
        assert_eq!(
            keys,
            ["agent/qpos", "agent/qvel", "extra/tcp_pose"],
            "{robot}"
        );
    }
}

/// Moves a cube to `pos` (upright, zero velocity) and re-evaluates without stepping.
fn put(e: &mut Env, cube: &str, pos: [f64; 3]) {
    put_free_body(e, cube, pos, [1.0, 0.0, 0.0, 0.0]);
}

#[test]
fn success_needs_cube_a_on_cube_b_within_the_tolerances() {
    for robot in ROBOTS {
        let mut e = env(robot, ObsMode::State);
        e.reset(Some(7));
        let b = part(&e, "extra/cubeB_pose");
        let ctx = robot;
        let flags = |e: &Env| KEYS.map(|k| e.info().get(k).unwrap() > 0.0);
        // Cube A rests on the table, apart from cube B: static only.
        assert_eq!(
            flags(&e),
            [false, false, true, false],
            "{ctx}: at the start"
        );
        // On top, 3.3 mm inside the xy tolerance ‖(0.02, 0.02)‖ + 5 mm = 33.3 mm.
        put(&mut e, "cubeA", [b[0] + 0.03, b[1], b[2] + 0.04]);
        assert_eq!(flags(&e), [false, true, true, true], "{ctx}: on top");
        assert_eq!(e.dense_reward(), 8.0);
        // Just outside the xy tolerance.
        put(&mut e, "cubeA", [b[0], b[1] + 0.034, b[2] + 0.04]);
        assert_eq!(flags(&e), [false, false, true, false], "{ctx}: beside");
        // 6 mm too high, then 4 mm too high (within the 5 mm).
        put(&mut e, "cubeA", [b[0], b[1], b[2] + 0.046]);
        assert!(!e.info().success(), "{ctx}: too high");
        put(&mut e, "cubeA", [b[0], b[1], b[2] + 0.044]);
        assert!(e.info().success(), "{ctx}: nearly on");
        assert!((e.dense_reward() - spec_dense_reward(&e)).abs() < 1e-9);
    }
}

#[test]
fn rewards_along_random_episodes_match_the_spec_formula() {
    use mjskill::solvers::make_policy;
    for robot in ROBOTS {
        let mut e = env(robot, ObsMode::State);
        let mut policy = make_policy("random", &e, 3).unwrap();
        let mut action = vec![0.0f32; e.action_space().shape[0]];
        for seed in 0..2 {
            e.reset(Some(seed));
            policy.reset(&e);
            for t in 0..50 {
                policy.act(&e, &mut action);
                let s = e.step(&action).unwrap();
                let reward = s.reward as f64;
                let want = spec_dense_reward(&e);
                assert!(
                    (reward - want).abs() < 1e-5,
                    "{robot} seed {seed} t {t}: {reward} vs {want}"
                );
            }
        }
    }
}

#[test]
fn solver_episodes_pass_every_reward_stage_as_the_spec_formula() {
    use mjskill::solvers::{make_env, make_policy};
    for robot in ROBOTS {
        let config = EnvConfig {
            robot: Some(robot.into()),
            reward_mode: RewardMode::Dense,
            ..Default::default()
        };
        let mut e = make_env(ID, config, "solver").unwrap();
        let mut policy = make_policy("solver", &e, 0).unwrap();
        let mut action = vec![0.0f32; e.action_space().shape[0]];
        // Reaching (< 2), grasped (4–5), on cube B (6–7), success (8).
        let mut stages = [0usize; 4];
        let mut successes = 0;
        for seed in 0..6 {
            e.reset(Some(seed));
            policy.reset(&e);
            for t in 0..50 {
                policy.act(&e, &mut action);
                let reward = e.step(&action).unwrap().reward as f64;
                let want = spec_dense_reward(&e);
                assert!(
                    (reward - want).abs() < 1e-5,
                    "{robot} seed {seed} t {t}: {reward} vs {want}"
                );
                stages[match reward {
                    r if r < 2.0 => 0,
                    r if r < 5.0 => 1,
                    r if r < 8.0 => 2,
                    _ => 3,
                }] += 1;
            }
            successes += e.info().success() as usize;
        }
        assert!(stages.iter().all(|&n| n > 0), "{robot}: stages {stages:?}");
        // The Panda's solver succeeds in 98 of seeds 0–99 (with the panda_wristcam: see
        // docs/solvers.md §9); the Fetch's, short of reach and of time, in 43.
        let want = if is_panda(robot) { 5 } else { 1 };
        assert!(successes >= want, "{robot}: {successes} of 6");
    }
}
