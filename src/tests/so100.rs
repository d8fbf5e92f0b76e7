//! SO100 (docs/robots.md §5) and PickCubeSO100-v1: model kinematics against the URDF, the
//! jaw-tip TCP, drives, control modes, the table-scene noise rule, the scripted grasp and
//! robot/env errors.
use super::common;

use nalgebra::{Point3, UnitQuaternion, Vector3};

use crate::env::{make, EnvConfig};
use crate::robots::{self, so100};
use common::env;

#[test]
fn qpos_order_is_maniskills() {
    let e = env("PickCubeSO100-v1", "pd_joint_delta_pos");
    assert_eq!(
        e.robot().joints.names,
        [
            "shoulder_pan",
            "shoulder_lift",
            "elbow_flex",
            "wrist_flex",
            "wrist_roll",
            "gripper"
        ]
    );
    let lim = &e.robot().joints.limits;
    assert_eq!(lim[0], (-2.0, 2.0));
    assert_eq!(lim[3], (-1.8, 1.8));
    assert_eq!(lim[5], (-1.1, 1.1));
    // Fixed tip links are massless in SAPIEN's sense.
    let m = e.model();
    for l in ["Fixed_Jaw_tip", "Moving_Jaw_tip"] {
        let b = e.robot().body(l).unwrap();
        assert_eq!(m.body_mass()[b.index()], 1e-6, "{l}");
    }
}

#[test]
fn forward_kinematics_and_tcp_match_an_independent_urdf_computation() {
    let spec = robots::spec("so100").unwrap();
    common::check_fk("so100", 200, |d, ids, links| {
        // tcp_pose = midpoint of the two tip links (URDF fixed links), Fixed_Jaw orientation.
        let (p, q) = ids.tcp_pose(d);
        let mid = nalgebra::center(
            &Point3::from(links["Fixed_Jaw_tip"].translation.vector),
            &Point3::from(links["Moving_Jaw_tip"].translation.vector),
        );
        assert!((Vector3::from(p) - mid.coords).norm() < 1e-6);
        let want = links["Fixed_Jaw"].rotation;
        let got =
            UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]));
        assert!(got.angle_to(&want) < 1e-6);
        // The tip offsets written in the robot spec equal the URDF's fixed joints.
        let fj = links["Fixed_Jaw"] * Point3::from(so100::FIXED_JAW_TIP);
        let mj = links["Moving_Jaw"] * Point3::from(so100::MOVING_JAW_TIP);
        assert!((fj.coords - links["Fixed_Jaw_tip"].translation.vector).norm() < 1e-9);
        assert!((mj.coords - links["Moving_Jaw_tip"].translation.vector).norm() < 1e-9);
    });
    assert_eq!(spec.tcp_link, None, "SO100 has no TCP link");
}

#[test]
fn rest_tcp_equals_maniskills_measured_pose() {
    // docs/robots.md §5: table-scene rest without noise.
    let e = make(
        "PickCubeSO100-v1",
        EnvConfig {
            robot_init_qpos_noise: 0.0,
            ..Default::default()
        },
    )
    .unwrap();
    let tcp = e.obs_part("extra/tcp_pose").unwrap();
    let want = [-0.4863, 0.03058, 0.08936, -0.5, -0.5, 0.5, 0.5];
    for (k, (g, w)) in tcp.iter().zip(want).enumerate() {
        assert!(
            (*g as f64 - w).abs() < 1e-4,
            "tcp_pose[{k}] = {g}, want {w}"
        );
    }
}

#[test]
fn holds_the_table_pose_and_tracks_joint_targets() {
    let spec = robots::spec("so100").unwrap();
    common::holds_and_tracks(spec, &[0.3, -0.3, 0.3, -0.3, 0.3, -0.4], 2e-3);
}

#[test]
fn action_and_observation_shapes_per_control_mode() {
    // shoulder_pan limits (the URDF's ±2.0).
    let lim = [(-2.0, 2.0)];
    for (mode, obs, low0, high0) in [
        ("pd_joint_delta_pos", 36, -1.0, 1.0),
        ("pd_joint_pos", 36, lim[0].0, lim[0].1),
        ("pd_joint_target_delta_pos", 42, -1.0, 1.0),
    ] {
        let e = env("PickCubeSO100-v1", mode);
        let a = e.action_space();
        assert_eq!(a.shape, [6], "{mode}");
        assert_eq!(e.observation_space().shape, [obs], "{mode}");
        assert_eq!((a.low[0], a.high[0]), (low0 as f32, high0 as f32), "{mode}");
        if mode == "pd_joint_pos" {
            assert_eq!(a.low[5], -1.1);
            assert_eq!(a.high[3], 1.8);
        }
    }
    let e = env("PickCubeSO100-v1", "pd_joint_target_delta_pos");
    let keys: Vec<&str> = e.obs_layout().iter().map(|(k, _)| k.as_str()).collect();
    assert_eq!(
        keys,
        [
            "agent/qpos",
            "agent/qvel",
            "agent/controller/target_qpos",
            "extra/is_grasped",
            "extra/tcp_pose",
            "extra/goal_pos",
            "extra/obj_pose",
            "extra/tcp_to_obj_pos",
            "extra/obj_to_goal_pos"
        ]
    );
    assert!(env("PickCubeSO100-v1", "pd_joint_delta_pos")
        .obs_part("agent/controller/target_qpos")
        .is_none());
    // An EE mode does not exist for the SO100: the error lists the valid modes.
    let err = make(
        "PickCubeSO100-v1",
        EnvConfig {
            control_mode: Some("pd_ee_delta_pos".into()),
            ..Default::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("pd_ee_delta_pos") && err.contains("pd_joint_target_delta_pos"));
}

#[test]
fn delta_bounds_are_005_on_the_arm_and_02_on_the_gripper() {
    // One controller over all six joints; the target accumulates in target_delta mode.
    let mut e = env("PickCubeSO100-v1", "pd_joint_target_delta_pos");
    e.reset(Some(3));
    let start = e.obs_part("agent/controller/target_qpos").unwrap().to_vec();
    let q0 = e.obs_part("agent/qpos").unwrap().to_vec();
    assert_eq!(start, q0, "reset: target = measured qpos");
    let a = [1.0, -1.0, 0.5, 3.0, 0.0, -1.0];
    e.step(&a).unwrap();
    e.step(&a).unwrap();
    let t = e.obs_part("agent/controller/target_qpos").unwrap();
    let per_step = [0.05, -0.05, 0.025, 0.05, 0.0, -0.2]; // 3.0 clips to 1
    for k in 0..6 {
        let want = start[k] + 2.0 * per_step[k] as f32;
        assert!(
            (t[k] - want).abs() < 1e-6,
            "target[{k}] = {}, want {want}",
            t[k]
        );
    }
}

#[test]
fn seeded_reset_adds_six_numpy_normals_to_the_table_qpos() {
    // numpy RandomState(0).normal(0, 1, 6) and RandomState(1).normal(0, 1, 6).
    let normals: [(u64, &[f64]); 2] = [
        (0, &common::NUMPY_SEED0_NORMALS[..6]),
        (
            1,
            &[
                1.6243453636632417,
                -0.6117564136500754,
                -0.5281717522634557,
                -1.0729686221561705,
                0.8654076293246785,
                -2.3015386968802827,
            ],
        ),
    ];
    let mut e = make("PickCubeSO100-v1", EnvConfig::default()).unwrap();
    for (seed, z) in normals {
        e.reset(Some(seed));
        let q = e.obs_part("agent/qpos").unwrap();
        for k in 0..6 {
            let want = (so100::TABLE_QPOS[k] + 0.02 * z[k]) as f32;
            assert_eq!(q[k], want, "seed {seed} joint {k}");
        }
    }
    // Root pose: p (−0.725, 0, 0), q = rotz(π/2).
    let base = robots::spec("so100").unwrap().table_base();
    assert!((base.translation.vector - Vector3::new(-0.725, 0.0, 0.0)).norm() < 1e-12);
    assert!((base.rotation.angle() - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
}

#[test]
fn scripted_grasp_closes_on_the_cube_and_lifts_it() {
    common::solver_grasps_and_lifts("PickCubeSO100-v1", "pd_joint_pos", 0.06, 0.05, |e, seed| {
        // The jaw closed (0 = open, −0.8 = the solver's closed target) and the cube sits
        // between the jaw tips.
        let gripper = e.obs_part("agent/qpos").unwrap()[5];
        assert!(gripper < -0.6, "seed {seed}: gripper at {gripper}");
        let to_obj = e.obs_part("extra/tcp_to_obj_pos").unwrap();
        let d = to_obj.iter().map(|x| x * x).sum::<f32>().sqrt();
        assert!(
            d < 0.02,
            "seed {seed}: cube {d} m from the jaw-tip midpoint"
        );
    });
}

#[test]
fn unsupported_robot_and_env_combinations_are_errors_listing_the_robots() {
    let with = common::env_with_robot;
    let err = with("PickCubeSO100-v1", "panda").unwrap_err().to_string();
    assert!(err.contains("\"panda\"") && err.contains("so100"), "{err}");
    let err = with("PlaceSphere-v1", "so100").unwrap_err().to_string();
    assert!(
        err.contains("\"so100\"") && err.contains("supported robots: panda"),
        "{err}"
    );
    // PickCube-v1 accepts the SO100 with the SO100 task config (cube half size 0.0125).
    let e = with("PickCube-v1", "so100").unwrap();
    assert_eq!(e.observation_space().shape, [36]);
    assert!((e.obs_part("extra/obj_pose").unwrap()[2] - 0.0125).abs() < 1e-6);
    assert_eq!(
        crate::env::default_robot("PickCubeSO100-v1").unwrap(),
        "so100"
    );
}

#[test]
fn same_seed_and_actions_give_a_bitwise_identical_trajectory() {
    common::assert_solver_rollout_is_deterministic("PickCubeSO100-v1", "pd_joint_pos");
}

#[test]
fn only_the_srdf_default_pairs_are_excluded_besides_parent_child() {
    let spec = robots::spec("so100").unwrap();
    let mut pairs = spec.description().unwrap().disabled_pairs;
    pairs.sort();
    let mut want: Vec<(String, String)> = [
        ("Rotation_Pitch", "Lower_Arm"),
        ("Rotation_Pitch", "Wrist_Pitch_Roll"),
        ("Upper_Arm", "Wrist_Pitch_Roll"),
        ("Upper_Arm", "Base"),
        ("Moving_Jaw", "Wrist_Pitch_Roll"),
    ]
    .iter()
    .map(|(a, b)| (a.to_string(), b.to_string()))
    .collect();
    want.sort();
    assert_eq!(pairs, want);
    let mjcf = robots::table_scene_with(spec, |_| {}).unwrap().mjcf;
    assert!(mjcf
        .xml
        .contains(r#"<exclude body1="Upper_Arm" body2="Base"/>"#));
    // Jaw materials: PhysX μ 2.0 against the default 0.3 ⇒ 1.15 under MuJoCo's max rule.
    assert!(mjcf.xml.contains(r#"name="Fixed_Jaw_collision0""#));
    assert_eq!(
        mjcf.xml.matches(r#"friction="1.15"#).count(),
        7,
        "3 + 4 jaw boxes"
    );
}
