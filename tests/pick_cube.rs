//! PickCube-v1 with the Panda: the env API, seeding, observations, controllers and state.

mod common;

use common::close;
use mjskill::{make, registry, EnvConfig, ObsMode, RewardMode};

fn env_with(mode: &str) -> mjskill::Env {
    make(
        "PickCube-v1",
        EnvConfig {
            control_mode: Some(mode.into()),
            ..Default::default()
        },
    )
    .unwrap()
}

#[test]
fn seeded_resets_reproduce_maniskills_initial_states() {
    // docs/tasks.md §5 (panda, noise 0.02).
    let cases = [
        (
            0u64,
            [
                0.035281, 0.400702, 0.019575, -1.918678, 0.037351, 2.336649, 0.8044, 0.04, 0.04,
            ],
            [-0.000749, 0.053644, 0.02],
            [0.568761, 0.0, 0.0, 0.822503],
            [0.026816, -0.001981, 0.288933],
        ),
        (
            1,
            [
                0.032487, 0.380464, -0.010563, -1.984955, 0.017308, 2.310164, 0.820294, 0.04, 0.04,
            ],
            [0.051526, -0.044138, 0.02],
            [0.995772, 0.0, 0.0, 0.091861],
            [0.059972, -0.020573, 0.246312],
        ),
    ];
    let mut env = make("PickCube-v1", EnvConfig::default()).unwrap();
    for (seed, qpos, cube, quat, goal) in cases {
        env.reset(Some(seed));
        close(env.obs_part("agent/qpos").unwrap(), &qpos, 2e-6, "qpos");
        let obj = env.obs_part("extra/obj_pose").unwrap();
        close(&obj[..3], &cube, 2e-6, "cube position");
        close(&obj[3..], &quat, 2e-6, "cube quaternion");
        close(env.obs_part("extra/goal_pos").unwrap(), &goal, 2e-6, "goal");
        assert_eq!(env.obs_part("agent/qvel").unwrap(), &[0.0; 9]);
    }
}

#[test]
fn construction_is_seeded_with_2022_and_unseeded_resets_continue_the_stream() {
    let mut a = make("PickCube-v1", EnvConfig::default()).unwrap();
    let built = a.obs().to_vec();
    let mut b = make("PickCube-v1", EnvConfig::default()).unwrap();
    b.reset(Some(2022));
    assert_eq!(b.obs(), built.as_slice(), "a new env equals reset(2022)");
    // Unseeded resets draw new noise and a new cube pose, the same way in both envs.
    a.reset(None);
    let next = a.obs().to_vec();
    assert_ne!(next, built);
    let mut c = make("PickCube-v1", EnvConfig::default()).unwrap();
    c.reset(None);
    assert_eq!(c.obs(), next.as_slice());
    assert_eq!(a.episode_seed(), Some(2022));
}

#[test]
fn state_observation_layout_and_spaces() {
    let env = make("PickCube-v1", EnvConfig::default()).unwrap();
    assert_eq!(env.observation_space().shape, vec![42]);
    assert_eq!(env.action_space().shape, vec![8]);
    let layout: Vec<(&str, usize, usize)> = env
        .obs_layout()
        .iter()
        .map(|(k, r)| (k.as_str(), r.start, r.end))
        .collect();
    assert_eq!(
        layout,
        vec![
            ("agent/qpos", 0, 9),
            ("agent/qvel", 9, 18),
            ("extra/is_grasped", 18, 19),
            ("extra/tcp_pose", 19, 26),
            ("extra/goal_pos", 26, 29),
            ("extra/obj_pose", 29, 36),
            ("extra/tcp_to_obj_pos", 36, 39),
            ("extra/obj_to_goal_pos", 39, 42),
        ]
    );
    let o = env.obs();
    for k in 0..3 {
        assert!(
            (o[36 + k] - (o[29 + k] - o[19 + k])).abs() < 1e-6,
            "tcp_to_obj = obj - tcp"
        );
        assert!(
            (o[39 + k] - (o[26 + k] - o[29 + k])).abs() < 1e-6,
            "obj_to_goal = goal - obj"
        );
    }
    // The TCP starts near (−0.615 + 0.615, 0, 0.17) = above the table centre, pointing down.
    assert!(o[19].abs() < 0.05 && (o[21] - 0.17).abs() < 0.05);
    // Action bounds: normalised arm deltas and gripper in [−1, 1].
    assert!(env.action_space().low.iter().all(|&l| l == -1.0));
    assert!(env.action_space().high.iter().all(|&h| h == 1.0));
}

#[test]
fn every_panda_control_mode_has_maniskills_action_and_obs_dims() {
    let modes = [
        ("pd_joint_delta_pos", 8, 42),
        ("pd_joint_pos", 8, 42),
        ("pd_ee_delta_pos", 4, 42),
        ("pd_ee_delta_pose", 7, 42),
        ("pd_ee_pose", 7, 42),
        ("pd_joint_target_delta_pos", 8, 49),
        ("pd_ee_target_delta_pos", 4, 49),
        ("pd_ee_target_delta_pose", 7, 49),
        ("pd_joint_vel", 8, 42),
        ("pd_joint_pos_vel", 15, 42),
        ("pd_joint_delta_pos_vel", 15, 42),
    ];
    for (mode, adim, odim) in modes {
        let mut env = env_with(mode);
        assert_eq!(env.action_space().shape, vec![adim], "{mode}");
        assert_eq!(env.observation_space().shape, vec![odim], "{mode}");
        // A zero action is valid in every mode and keeps the simulation finite.
        let zero = vec![0.0f32; adim];
        for _ in 0..3 {
            let s = env.step(&zero).unwrap();
            assert!(s.obs.iter().all(|x| x.is_finite()), "{mode}");
        }
    }
    // pd_joint_pos: the arm bounds are the joint limits, not normalised.
    let env = env_with("pd_joint_pos");
    assert!((env.action_space().low[0] + 2.8973).abs() < 1e-6);
    assert!((env.action_space().high[3] + 0.0698).abs() < 1e-6);
}

#[test]
fn joint_delta_moves_the_joint_and_the_gripper_closes() {
    let mut env = env_with("pd_joint_delta_pos");
    env.reset(Some(3));
    let q0 = env.obs_part("agent/qpos").unwrap().to_vec();
    // +1 on joint 1 = +0.1 rad target delta per step; gripper −1 = close.
    let mut a = [0.0f32; 8];
    a[0] = 1.0;
    a[7] = -1.0;
    for _ in 0..4 {
        env.step(&a).unwrap();
    }
    let q = env.obs_part("agent/qpos").unwrap();
    // Deltas are relative to the measured position (not accumulated): the joint keeps moving.
    assert!(q[0] - q0[0] > 0.1, "joint 1 moved by {}", q[0] - q0[0]);
    assert!(
        q[7] < 0.01 && q[8] < 0.01,
        "fingers closed: {} {}",
        q[7],
        q[8]
    );
    assert!((q[7] - q[8]).abs() < 1e-3, "mimic keeps the fingers equal");
}

#[test]
fn ee_delta_pos_moves_the_tcp_in_the_root_frame() {
    let mut env = env_with("pd_ee_delta_pos");
    env.reset(Some(4));
    let p0 = env.obs_part("extra/tcp_pose").unwrap()[..3].to_vec();
    // +1 in z = a target 0.1 m above the current TCP, every step.
    for _ in 0..3 {
        env.step(&[0.0, 0.0, 1.0, 1.0]).unwrap();
    }
    let p = env.obs_part("extra/tcp_pose").unwrap();
    assert!(p[2] - p0[2] > 0.05, "rose {}", p[2] - p0[2]);
    assert!((p[0] - p0[0]).abs() < 0.01 && (p[1] - p0[1]).abs() < 0.01);
}

#[test]
fn episode_truncates_at_50_and_keeps_running() {
    let mut env = make("PickCube-v1", EnvConfig::default()).unwrap();
    env.reset(Some(5));
    let a = [0.0f32; 8];
    for k in 1..=52 {
        let s = env.step(&a).unwrap();
        assert_eq!(s.info.elapsed_steps, k);
        assert_eq!(s.truncated, k >= 50, "step {k}");
        assert!(!s.terminated, "an idle robot does not succeed");
    }
    let mut short = make(
        "PickCube-v1",
        EnvConfig {
            max_episode_steps: Some(3),
            ..Default::default()
        },
    )
    .unwrap();
    assert!(!short.step(&a).unwrap().truncated);
    assert!(!short.step(&a).unwrap().truncated);
    assert!(short.step(&a).unwrap().truncated);
}

#[test]
fn info_keys_and_reward_modes() {
    let mut env = make("PickCube-v1", EnvConfig::default()).unwrap();
    let s = env.step(&[0.0; 8]).unwrap();
    assert_eq!(
        s.info.keys,
        &["success", "is_obj_placed", "is_robot_static", "is_grasped"]
    );
    let normalized = s.reward;
    assert!((0.0..=1.0).contains(&normalized));
    let dense = env.dense_reward();
    assert!((normalized as f64 - dense / 5.0).abs() < 1e-6);
    // The reaching term is below 1 with the TCP away from the cube.
    assert!(dense < 1.0 && dense > 0.0, "{dense}");
    for (mode, check) in [
        (
            "dense",
            Box::new(|r: f32, d: f64| (r as f64 - d).abs() < 1e-5) as Box<dyn Fn(f32, f64) -> bool>,
        ),
        ("sparse", Box::new(|r: f32, _| r == 0.0)),
        ("none", Box::new(|r: f32, _| r == 0.0)),
    ] {
        let mut e = make(
            "PickCube-v1",
            EnvConfig {
                reward_mode: RewardMode::parse(mode).unwrap(),
                ..Default::default()
            },
        )
        .unwrap();
        let r = e.step(&[0.0; 8]).unwrap().reward;
        assert!(check(r, e.dense_reward()), "{mode}: {r}");
    }
}

#[test]
fn a_scripted_grasp_lifts_the_cube_and_reports_is_grasped() {
    // EE-space policy (docs/solvers.md §7.1): above the cube, down, close, lift to the goal.
    let mut env = env_with("pd_ee_delta_pos");
    env.reset(Some(0));
    let mut grasped = false;
    let mut success = false;
    for step in 0..50 {
        let tcp = env.obs_part("extra/tcp_pose").unwrap()[..3].to_vec();
        let obj = env.obs_part("extra/obj_pose").unwrap()[..3].to_vec();
        let goal = env.obs_part("extra/goal_pos").unwrap().to_vec();
        let (target, grip): ([f32; 3], f32) = if step < 8 {
            ([obj[0], obj[1], obj[2] + 0.05], 1.0)
        } else if step < 14 {
            ([obj[0], obj[1], obj[2]], 1.0)
        } else if step < 18 {
            ([tcp[0], tcp[1], tcp[2]], -1.0)
        } else {
            ([goal[0], goal[1], goal[2]], -1.0)
        };
        let mut a = [0.0f32; 4];
        for k in 0..3 {
            a[k] = ((target[k] - tcp[k]) / 0.1).clamp(-1.0, 1.0);
        }
        a[3] = grip;
        let s = env.step(&a).unwrap();
        grasped |= s.info.flag("is_grasped");
        if s.terminated {
            success = true;
            assert!(s.info.flag("is_obj_placed") && s.info.flag("is_robot_static"));
            break;
        }
    }
    assert!(grasped, "the cube was grasped");
    let obj_z = env.obs_part("extra/obj_pose").unwrap()[2];
    assert!(obj_z > 0.05, "the cube was lifted: z = {obj_z}");
    assert!(success, "the cube reached the goal and the robot settled");
}

#[test]
fn same_seed_and_actions_give_a_bitwise_identical_trajectory() {
    let run = || {
        let mut env = env_with("pd_ee_delta_pose");
        env.reset(Some(11));
        let mut out = Vec::new();
        for k in 0..30 {
            let t = k as f32 * 0.37;
            let a = [
                t.sin(),
                t.cos(),
                (2.0 * t).sin() * 0.5,
                0.2,
                -0.1,
                0.3,
                (3.0 * t).cos(),
            ];
            let s = env.step(&a).unwrap();
            out.extend_from_slice(s.obs);
            out.push(s.reward);
        }
        out
    };
    let (a, b) = (run(), run());
    assert_eq!(a.len(), b.len());
    assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()));
}

#[test]
fn set_state_then_step_equals_the_original_trajectory_bitwise() {
    for mode in ["pd_joint_target_delta_pos", "pd_ee_target_delta_pose"] {
        let mut env = env_with(mode);
        env.reset(Some(7));
        // A state captured right after reset survives a restore unchanged (MuJoCo normalises
        // quaternions on forward; the restore must not).
        let s0 = env.get_state();
        env.set_state(&s0).unwrap();
        assert!(
            env.get_state() == s0,
            "{mode}: restore right after reset is exact"
        );
        let dim = env.action_space().shape[0];
        let action = |k: usize| -> Vec<f32> {
            (0..dim)
                .map(|i| ((k * 7 + i * 3) as f32 * 0.61).sin())
                .collect()
        };
        for k in 0..10 {
            env.step(&action(k)).unwrap();
        }
        let saved = env.get_state();
        let mut reference = Vec::new();
        for k in 10..25 {
            reference.extend_from_slice(env.step(&action(k)).unwrap().obs);
        }
        // Also the following unseeded reset must match (RNG streams are part of the state).
        env.reset(None);
        reference.extend_from_slice(env.obs());

        // Restore into a different env instance that has lived another life.
        let mut other = env_with(mode);
        other.reset(Some(99));
        other.step(&action(3)).unwrap();
        other.set_state(&saved).unwrap();
        let mut replay = Vec::new();
        for k in 10..25 {
            replay.extend_from_slice(other.step(&action(k)).unwrap().obs);
        }
        other.reset(None);
        replay.extend_from_slice(other.obs());
        assert!(
            reference
                .iter()
                .zip(&replay)
                .all(|(x, y)| x.to_bits() == y.to_bits()),
            "{mode}"
        );
        // Serialised state round-trips.
        let json = serde_json::to_string(&saved).unwrap();
        assert!(
            serde_json::from_str::<mjskill::EnvState>(&json).unwrap() == saved,
            "JSON round trip"
        );
    }
}

#[test]
fn bad_input_is_an_error_naming_the_problem_and_the_env_stays_usable() {
    let e = make("PickBall-v9", EnvConfig::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("PickBall-v9") && e.contains("PickCube-v1"),
        "{e}"
    );
    let e = make(
        "PickCube-v1",
        EnvConfig {
            robot: Some("ur5".into()),
            ..Default::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("ur5") && e.contains("panda"), "{e}");
    let e = make(
        "PickCube-v1",
        EnvConfig {
            control_mode: Some("pd_teleport".into()),
            ..Default::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("pd_teleport") && e.contains("pd_joint_delta_pos") && e.contains("pd_ee_pose"),
        "{e}"
    );
    let e = ObsMode::parse("rgbd_magic").unwrap_err().to_string();
    assert!(e.contains("rgbd_magic") && e.contains("state_dict"), "{e}");
    let e = RewardMode::parse("shaped").unwrap_err().to_string();
    assert!(
        e.contains("shaped") && e.contains("normalized_dense"),
        "{e}"
    );

    let mut env = make("PickCube-v1", EnvConfig::default()).unwrap();
    let before = env.get_state();
    let e = env.step(&[0.0; 7]).unwrap_err().to_string();
    assert!(e.contains('7') && e.contains('8'), "{e}");
    let e = env
        .step(&[0.0, f32::NAN, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
        .unwrap_err()
        .to_string();
    assert!(e.contains("NaN") && e.contains('1'), "{e}");
    let e = env
        .step(&[0.0, 0.0, 0.0, f32::INFINITY, 0.0, 0.0, 0.0, 0.0])
        .unwrap_err()
        .to_string();
    assert!(e.contains("inf") && e.contains('3'), "{e}");
    assert_eq!(env.get_state(), before, "rejected actions change nothing");
    assert_eq!(
        env.step(&[0.0; 8]).unwrap().info.elapsed_steps,
        1,
        "still usable"
    );

    let other = env_with("pd_ee_delta_pos").get_state();
    let e = env.set_state(&other).unwrap_err().to_string();
    assert!(e.contains("pd_ee_delta_pos"), "{e}");
    assert!(env.step(&[0.0; 8]).is_ok());
}

#[test]
fn obs_modes_state_dict_and_none() {
    let env = make(
        "PickCube-v1",
        EnvConfig {
            obs_mode: ObsMode::StateDict,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(env.obs().len(), 42);
    assert!(env.obs_part("extra/tcp_pose").is_some());
    let mut env = make(
        "PickCube-v1",
        EnvConfig {
            obs_mode: ObsMode::None,
            ..Default::default()
        },
    )
    .unwrap();
    assert!(env.step(&[0.0; 8]).unwrap().obs.is_empty());
    assert_eq!(env.observation_space().shape, vec![0]);
}

#[test]
fn registry_lists_envs_robots_and_modes() {
    let r = registry();
    let pick = r
        .iter()
        .find(|e| e.id == "PickCube-v1")
        .expect("PickCube-v1 registered");
    assert_eq!(pick.default_robot, "panda");
    assert_eq!(pick.robots[0].0, "panda");
    let json = serde_json::to_string(&r).unwrap();
    assert!(json.contains("pd_ee_target_delta_pose") && json.contains("normalized_dense"));
}

#[test]
fn ee_delta_pose_rotation_follows_maniskills_sign_and_root_axes() {
    // rot_lower = −0.1 ⇒ a positive normalised rotation action turns by −0.1·a rad about the
    // root-frame axis through the EE (docs/controllers.md §1, §3.2).
    let mut env = env_with("pd_ee_delta_pose");
    env.reset(Some(2));
    let q0 = quat(env.obs_part("extra/tcp_pose").unwrap());
    let p0 = env.obs_part("extra/tcp_pose").unwrap()[..3].to_vec();
    for _ in 0..4 {
        env.step(&[0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0]).unwrap();
    }
    let q1 = quat(env.obs_part("extra/tcp_pose").unwrap());
    // Rotation in the world (= root orientation) frame: q1 = Δ ⊗ q0.
    let delta = q1 * q0.inverse();
    let axis = delta.axis().unwrap().into_inner() * delta.angle();
    assert!(axis.z < -0.1, "turned about −z of the root frame: {axis:?}");
    assert!(axis.x.abs() < 0.03 && axis.y.abs() < 0.03, "{axis:?}");
    let p1 = &env.obs_part("extra/tcp_pose").unwrap()[..3];
    for k in 0..3 {
        assert!(
            (p1[k] - p0[k]).abs() < 0.01,
            "the EE stays in place while turning"
        );
    }
}

fn quat(pose: &[f32]) -> nalgebra::UnitQuaternion<f64> {
    nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
        pose[3] as f64,
        pose[4] as f64,
        pose[5] as f64,
        pose[6] as f64,
    ))
}
