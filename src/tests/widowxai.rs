//! WidowX AI (docs/robots.md §6) and PickCubeWidowXAI-v1: model kinematics against the URDF, the
//! TCP link, the mimic-coupled carriages, the arm/gripper controllers that both drive the
//! left carriage, the noise-free table scene, the scripted grasp and robot/env errors.
use super::common;

use nalgebra::{Point3, UnitQuaternion, Vector3};

use crate::env::{make, EnvConfig};
use crate::mujoco::ObjType;
use crate::robots::{self, widowxai};
use common::env;

#[test]
fn qpos_order_is_maniskills() {
    let e = env("PickCubeWidowXAI-v1", "pd_joint_delta_pos");
    assert_eq!(
        e.robot().joints.names,
        [
            "joint_0",
            "joint_1",
            "joint_2",
            "joint_3",
            "joint_4",
            "joint_5",
            "right_carriage_joint",
            "left_carriage_joint"
        ]
    );
    assert_eq!(e.robot().joints.limits[6], (0.0, 0.044));
    assert_eq!(e.robot().joints.limits[2], (0.0, 2.356194490192345));
    let b = e.robot().body("ee_gripper_link").unwrap();
    assert_eq!(e.model().body_mass()[b.index()], 1e-6);
}

#[test]
fn forward_kinematics_and_tcp_match_an_independent_urdf_computation() {
    common::check_fk("widowxai", 200, |d, ids, links| {
        let (p, q) = ids.tcp_pose(d);
        let want = links["ee_gripper_link"];
        assert!((Vector3::from(p) - want.translation.vector).norm() < 1e-6);
        let got =
            UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]));
        assert!(got.angle_to(&want.rotation) < 1e-6);
        // ee_gripper_link = link_6 + (0.156062, 0, 0).
        let from6 = links["link_6"] * Point3::new(0.156062, 0.0, 0.0);
        assert!((from6.coords - want.translation.vector).norm() < 1e-9);
        // The `tcp` site sits on it.
        let s = ids.tcp_site.unwrap();
        let site = Vector3::from_column_slice(&d.site_xpos()[3 * s..3 * s + 3]);
        assert!((site - want.translation.vector).norm() < 1e-9);
    });
}

#[test]
fn table_scene_is_ready_to_grasp_without_noise_and_the_tcp_matches_maniskill() {
    let mut e = make("PickCubeWidowXAI-v1", EnvConfig::default()).unwrap();
    for seed in [0u64, 1, 77] {
        e.reset(Some(seed));
        let q = e.obs_part("agent/qpos").unwrap();
        let want: Vec<f32> = widowxai::READY_TO_GRASP.iter().map(|&x| x as f32).collect();
        assert_eq!(q, want.as_slice(), "seed {seed}: exactly ready_to_grasp");
        // docs/robots.md §6: rest TCP p (−0.40146, 0, 0.08492), q (0.69671, 0, 0.71736, 0).
        let tcp = e.obs_part("extra/tcp_pose").unwrap();
        let want = [-0.40146, 0.0, 0.08492, 0.69671, 0.0, 0.71736, 0.0];
        for (k, (g, w)) in tcp.iter().zip(want).enumerate() {
            assert!(
                (*g as f64 - w).abs() < 1e-4,
                "tcp_pose[{k}] = {g}, want {w}"
            );
        }
    }
    let spec = robots::spec("widowxai").unwrap();
    assert_eq!(spec.init_noise, robots::InitNoise::None);
    assert_eq!(
        spec.table_base(),
        nalgebra::Isometry3::translation(-0.615, 0.0, 0.0)
    );
}

#[test]
fn holds_the_table_pose_and_tracks_joint_targets() {
    let spec = robots::spec("widowxai").unwrap();
    common::holds_and_tracks(spec, &[0.3, -0.3, -0.3, 0.3, 0.3, -0.4, 0.01, 0.01], 2e-3);
}

#[test]
fn right_carriage_follows_the_left_one_and_has_no_drive() {
    let e = env("PickCubeWidowXAI-v1", "pd_joint_pos");
    let m = e.model();
    let ids = e.robot();
    assert!(
        ids.joints.actuator[6].is_none(),
        "right_carriage_joint is undriven"
    );
    let left = ids.joints.actuator[7].expect("left carriage driven");
    // The gripper part (no force limit ⇒ 1e10) overrides the arm part's 100 on the left
    // carriage; the arm joints keep 100.
    assert_eq!(m.actuator_forcerange()[2 * left + 1], 1e10);
    let j0 = ids.joints.actuator[0].unwrap();
    assert_eq!(m.actuator_forcerange()[2 * j0 + 1], 100.0);
    assert!(m
        .id(ObjType::Equality, "mimic_right_carriage_joint")
        .is_some());
}

#[test]
fn the_gripper_part_wins_over_the_arms_seventh_entry() {
    let mut e = env("PickCubeWidowXAI-v1", "pd_joint_pos");
    let ready = widowxai::READY_TO_GRASP;
    let mut a: Vec<f32> = ready[..6].iter().map(|&x| x as f32).collect();
    // Arm says open (0.044), gripper says closed (−1 ⇒ 0 m).
    a.extend([0.044, -1.0]);
    for _ in 0..20 {
        e.step(&a).unwrap();
    }
    let q = e.obs_part("agent/qpos").unwrap().to_vec();
    assert!(q[7] < 1e-3, "left carriage closed: {}", q[7]);
    assert!((q[6] - q[7]).abs() < 1e-3, "right follows left: {q:?}");
    // And the other way round: arm says closed, gripper says open (+1 ⇒ 0.044 m).
    a[6] = 0.0;
    a[7] = 1.0;
    for _ in 0..20 {
        e.step(&a).unwrap();
    }
    let q = e.obs_part("agent/qpos").unwrap();
    assert!((q[7] - 0.044).abs() < 1e-3, "left carriage open: {}", q[7]);
    assert!((q[6] - q[7]).abs() < 1e-3, "right follows left: {q:?}");
}

#[test]
fn action_and_observation_shapes_per_control_mode() {
    for (mode, obs) in [
        ("pd_joint_delta_pos", 40),
        ("pd_joint_pos", 40),
        ("pd_joint_target_delta_pos", 47),
    ] {
        let e = env("PickCubeWidowXAI-v1", mode);
        let a = e.action_space();
        assert_eq!(a.shape, [8], "{mode}");
        assert_eq!(e.observation_space().shape, [obs], "{mode}");
        // The gripper entry is normalised in every mode.
        assert_eq!((a.low[7], a.high[7]), (-1.0, 1.0), "{mode}");
        if mode == "pd_joint_pos" {
            assert_eq!((a.low[1], a.high[1]), (0.0, std::f32::consts::PI));
            assert_eq!((a.low[6], a.high[6]), (0.0, 0.044));
        } else {
            assert_eq!((a.low[6], a.high[6]), (-1.0, 1.0));
        }
    }
    let mut e = env("PickCubeWidowXAI-v1", "pd_joint_target_delta_pos");
    let keys: Vec<&str> = e.obs_layout().iter().map(|(k, _)| k.as_str()).collect();
    assert_eq!(keys[2], "agent/controller/arm/target_qpos");
    let start = e
        .obs_part("agent/controller/arm/target_qpos")
        .unwrap()
        .to_vec();
    assert_eq!(start.len(), 7);
    let a = [1.0, -1.0, 0.5, 0.0, 0.0, 2.0, 1.0, 0.0];
    e.step(&a).unwrap();
    e.step(&a).unwrap();
    let t = e.obs_part("agent/controller/arm/target_qpos").unwrap();
    let per_step = [0.1, -0.1, 0.05, 0.0, 0.0, 0.1, 0.1];
    for k in 0..7 {
        let want = start[k] + 2.0 * per_step[k] as f32;
        assert!(
            (t[k] - want).abs() < 1e-6,
            "target[{k}] = {}, want {want}",
            t[k]
        );
    }
}

#[test]
fn scripted_grasp_closes_on_the_cube_and_lifts_it() {
    let (id, mode) = ("PickCubeWidowXAI-v1", "pd_joint_pos");
    common::solver_grasps_and_lifts(id, mode, 0.08, 0.07, |e, seed| {
        // The carriages stop at the cube faces (half size 0.018) instead of their 0 target,
        // and the right one mirrors the left one.
        let q = e.obs_part("agent/qpos").unwrap();
        assert!(
            (q[7] - 0.018).abs() < 0.003,
            "seed {seed}: left carriage {}",
            q[7]
        );
        assert!((q[6] - q[7]).abs() < 5e-4, "seed {seed}: carriages {q:?}");
    });
}

#[test]
fn every_widowxai_scene_runs_the_no_slip_pass_and_a_task_can_ask_for_more() {
    // The robot's pass (docs/outcome-physics.md, "The WidowX AI's grip") in both of its tasks;
    // the Panda's PickCube runs none. A scene asked twice (by its task and by its robot) keeps
    // the larger count, so a robot that asks for fewer never lowers a task's pass.
    for id in ["PickCubeWidowXAI-v1", "PickCube-v1"] {
        let e = common::env_with_robot(id, "widowxai").unwrap();
        assert_eq!(e.model().noslip_iterations(), 10, "{id}");
    }
    let e = common::env_with_robot("PickCube-v1", "panda").unwrap();
    assert_eq!(e.model().noslip_iterations(), 0);
    let mut scene = crate::mjcf::Scene::new("noslip", 0.01);
    scene.set_noslip_iterations(10);
    scene.set_noslip_iterations(3);
    let (mjcf, _) = scene.finish_with_physics();
    assert!(
        mjcf.xml.contains("noslip_iterations=\"10\""),
        "{}",
        mjcf.xml
    );
}

#[test]
fn unsupported_robot_and_env_combinations_are_errors_listing_the_robots() {
    let with = common::env_with_robot;
    let err = with("PickCubeWidowXAI-v1", "so100")
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("\"so100\"") && err.contains("supported robots: widowxai"),
        "{err}"
    );
    let err = with("PlaceSphere-v1", "widowxai").unwrap_err().to_string();
    assert!(
        err.contains("\"widowxai\"") && err.contains("panda"),
        "{err}"
    );
    let e = with("PickCube-v1", "widowxai").unwrap();
    assert_eq!(e.observation_space().shape, [40]);
    assert!((e.obs_part("extra/obj_pose").unwrap()[2] - 0.018).abs() < 1e-6);
    assert_eq!(
        crate::env::default_robot("PickCubeWidowXAI-v1").unwrap(),
        "widowxai"
    );
}

#[test]
fn same_seed_and_actions_give_a_bitwise_identical_trajectory() {
    common::assert_solver_rollout_is_deterministic("PickCubeWidowXAI-v1", "pd_joint_pos");
}

#[test]
fn only_the_srdf_default_pairs_are_excluded_besides_parent_child() {
    let spec = robots::spec("widowxai").unwrap();
    let pairs = spec.description().unwrap().disabled_pairs;
    assert_eq!(pairs.len(), 13, "{pairs:?}");
    for (a, b) in [
        ("base_link", "link_2"),
        ("link_1", "link_5"),
        ("carriage_right", "carriage_left"),
        ("carriage_right", "gripper_left"),
    ] {
        assert!(pairs.contains(&(a.to_string(), b.to_string())), "{a}-{b}");
    }
    // "Adjacent"/"Fixed"/"ParallelMotion" pairs of the upstream SRDF are not applied.
    assert!(!pairs.contains(&("base_link".to_string(), "link_1".to_string())));
}
