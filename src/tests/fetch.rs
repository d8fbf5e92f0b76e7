//! Fetch (docs/robots.md §3): generated kinematics against an independent URDF implementation,
//! ManiSkill's joint order, holding and tracking, every control mode's spaces, the EE modes,
//! base velocity drives, the scripted PickCube grasp, seeding, PlaceSphere, export-mjcf.
use nalgebra::{Isometry3, Vector3};
use rand::Rng;

use super::common;

use crate::controllers::ik::Chain;
use crate::env::{make, EnvConfig};
use crate::mujoco::BodyId;
use crate::robots::{self, fetch, RobotIds};

fn env(task: &str, mode: &str) -> crate::env::Env {
    make(
        task,
        EnvConfig {
            robot: Some("fetch".into()),
            control_mode: Some(mode.into()),
            ..Default::default()
        },
    )
    .unwrap()
}

fn qpos(env: &crate::env::Env) -> Vec<f64> {
    let mut q = vec![0.0; 15];
    env.robot().joints.qpos(env.data(), &mut q);
    q
}

/// Normalised gripper action that targets `q` m per finger (range [−0.01, 0.05]).
fn gripper_action(q: f64) -> f32 {
    ((q - 0.02) / 0.03) as f32
}

#[test]
fn forward_kinematics_matches_independent_urdf_fk() {
    // Continuous joints: several turns; the planar base: a few metres.
    let sample = |rng: &mut rand::rngs::StdRng, ids: &RobotIds| {
        let mut qv = vec![0.0; 15];
        for (k, name) in ids.joints.names.iter().enumerate() {
            let (lo, hi) = ids.joints.limits[k];
            let (lo, hi) = (lo.max(-7.0), hi.min(7.0));
            let (lo, hi) = if name.starts_with("root_") && !name.contains("rotation") {
                (lo.max(-2.0), hi.min(2.0))
            } else {
                (lo, hi)
            };
            qv[k] = rng.random_range(lo..=hi);
        }
        qv
    };
    common::check_fk_with("fetch", 200, sample, |_, ids, _| {
        assert_eq!(ids.link_bodies.len(), 29, "all 29 links are bodies");
    });
}

#[test]
fn joint_order_is_maniskills_breadth_first_order() {
    let e = env("PickCube-v1", "pd_joint_delta_pos");
    assert_eq!(e.robot().joints.names, fetch::JOINT_ORDER);
    // Continuous joints are unlimited; the fingers' upper limit sets PlaceSphere's width.
    for k in [2, 8, 10, 12] {
        assert_eq!(
            e.robot().joints.limits[k],
            (f64::NEG_INFINITY, f64::INFINITY)
        );
    }
    assert_eq!(e.robot().joints.limits[14], (0.0, 0.05));
}

#[test]
fn seeded_reset_is_deterministic_and_exactly_the_table_pose() {
    let mut a = env("PickCube-v1", "pd_joint_delta_pos");
    let mut b = env("PickCube-v1", "pd_joint_delta_pos");
    for seed in [0u64, 1, 77] {
        let oa = a.reset(Some(seed)).0.to_vec();
        let ob = b.reset(Some(seed)).0.to_vec();
        assert_eq!(oa, ob);
        let q = a.obs_part("agent/qpos").unwrap();
        let want: Vec<f32> = fetch::TABLE_QPOS.iter().map(|&x| x as f32).collect();
        assert_eq!(q, want.as_slice(), "no noise on Fetch");
        assert!(a.obs_part("agent/qvel").unwrap().iter().all(|&v| v == 0.0));
    }
    // Same actions ⇒ bitwise identical trajectories.
    let act: Vec<f32> = (0..13).map(|k| ((k as f32) * 0.37).sin() * 0.5).collect();
    a.reset(Some(5));
    b.reset(Some(5));
    for _ in 0..10 {
        let oa = a.step(&act).unwrap().obs.to_vec();
        let ob = b.step(&act).unwrap().obs.to_vec();
        assert_eq!(oa, ob);
    }
    // ManiSkill's rest TCP (docs/robots.md §3): p (−0.17747, 0, 0.23717), q (0.86603, 0, 0.5, 0).
    a.reset(Some(0));
    let tcp = a.obs_part("extra/tcp_pose").unwrap();
    let want = [-0.17747, 0.0, 0.23717, 0.86603, 0.0, 0.5, 0.0];
    for (g, w) in tcp.iter().zip(want) {
        assert!((*g as f64 - w).abs() < 2e-5, "{tcp:?}");
    }
}

#[test]
fn holds_the_table_pose_without_drift_or_warnings() {
    let mut e = env("PickCube-v1", "pd_joint_delta_pos");
    e.reset(Some(2));
    let mut a = [0.0f32; 13];
    a[7] = gripper_action(0.015);
    // 5 s: zero deltas, zero base velocity.
    for _ in 0..100 {
        let s = e.step(&a).unwrap();
        assert!(!s.info.warnings.diverged(), "{:?}", s.info.warnings);
        assert_eq!(s.info.warnings.fired(), vec![], "no MuJoCo warnings");
    }
    let q = qpos(&e);
    for (k, (g, w)) in q.iter().zip(fetch::TABLE_QPOS).enumerate() {
        assert!((g - w).abs() < 1e-3, "joint {k} drifted: {g} vs {w}");
    }
    // The base (virtual joints) does not creep.
    assert!(
        q[0].abs() < 1e-6 && q[1].abs() < 1e-6 && q[2].abs() < 1e-6,
        "{q:?}"
    );
    // Nothing of the robot touches the ground, the table or itself at rest.
    let d = e.data();
    let robot_bodies = &e.robot().bodies;
    for i in 0..d.ncon() {
        let (g1, g2) = d.contact_geoms(i);
        let b = |g: usize| BodyId::from_index(e.model().geom_bodyid()[g] as usize);
        assert!(
            !robot_bodies.contains(&b(g1)) && !robot_bodies.contains(&b(g2)),
            "robot contact at rest"
        );
    }
}

#[test]
fn tracks_absolute_joint_targets_of_arm_and_body() {
    let mut e = env("PickCube-v1", "pd_joint_delta_pos_stiff_body");
    e.reset(Some(0));
    // Absolute body targets (head pan, head tilt, torso), arm deltas 0. The stiff body drive
    // (kp = kd = 1e5) has a 1 s time constant: 6 s reach 99.75 %.
    let body = [0.3f32, 0.2, 0.3];
    let mut a = [0.0f32; 13];
    a[7] = gripper_action(0.03);
    a[8..11].copy_from_slice(&body);
    for _ in 0..120 {
        e.step(&a).unwrap();
    }
    let q = qpos(&e);
    for (k, t) in [(4, body[0]), (6, body[1]), (3, body[2])] {
        assert!(
            (q[k] - t as f64).abs() < 2e-3,
            "body joint {k}: {} vs {t}",
            q[k]
        );
    }
    assert!((q[13] - 0.03).abs() < 1e-3 && (q[14] - 0.03).abs() < 1e-3);
    // pd_joint_pos: absolute arm targets, incl. continuous joints (shoulder lift up, away from
    // the table).
    let mut e = env("PickCube-v1", "pd_joint_pos");
    e.reset(Some(0));
    let arm = [0.3, -1.0, 0.4, 1.0, -0.5, 1.2, 2.5];
    let mut a = [0.0f32; 13];
    for (x, t) in a.iter_mut().zip(arm) {
        *x = t as f32;
    }
    a[7] = gripper_action(0.015);
    for _ in 0..30 {
        let s = e.step(&a).unwrap();
        assert!(!s.info.warnings.diverged());
    }
    let q = qpos(&e);
    for (k, (i, t)) in [5, 7, 8, 9, 10, 11, 12].into_iter().zip(arm).enumerate() {
        assert!((q[i] - t).abs() < 3e-3, "arm joint {k}: {} vs {t}", q[i]);
    }
}

#[test]
fn every_control_mode_has_the_specified_action_and_observation_dims() {
    // docs/robots.md §3 action dims; docs/tasks.md §4 state dims (54, +7 for target_qpos/target_pose).
    let modes = [
        ("pd_joint_delta_pos", 13, 54),
        ("pd_joint_pos", 13, 54),
        ("pd_joint_target_delta_pos", 13, 61),
        ("pd_joint_vel", 13, 54),
        ("pd_joint_pos_vel", 20, 54),
        ("pd_joint_delta_pos_vel", 20, 54),
        ("pd_joint_delta_pos_stiff_body", 13, 54),
        ("pd_ee_delta_pos", 9, 54),
        ("pd_ee_delta_pose", 12, 54),
        ("pd_ee_target_delta_pos", 9, 61),
        ("pd_ee_target_delta_pose", 12, 61),
    ];
    assert_eq!(
        modes.iter().map(|m| m.0).collect::<Vec<_>>(),
        fetch::CONTROL_MODES.map(|m| m.name())
    );
    for (mode, adim, odim) in modes {
        let mut e = env("PickCube-v1", mode);
        assert_eq!(e.action_space().shape, vec![adim], "{mode}");
        assert_eq!(e.observation_space().shape, vec![odim], "{mode}");
        let zero = vec![0.0f32; adim];
        for _ in 0..3 {
            let s = e.step(&zero).unwrap();
            assert!(s.obs.iter().all(|x| x.is_finite()), "{mode}");
            assert!(!s.info.warnings.diverged(), "{mode}");
        }
        let bad = vec![0.0f32; adim + 1];
        let err = e.step(&bad).unwrap_err().to_string();
        assert!(err.contains(&adim.to_string()), "{err}");
    }
    let e = env("PlaceSphere-v1", "pd_joint_delta_pos");
    assert_eq!(e.observation_space().shape, vec![51]);
    // Unknown modes name the valid ones.
    let err = make(
        "PickCube-v1",
        EnvConfig {
            robot: Some("fetch".into()),
            control_mode: Some("pd_ee_pose".into()),
            ..Default::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("pd_ee_pose") && err.contains("pd_joint_delta_pos_stiff_body"));
}

#[test]
fn pd_joint_pos_vel_takes_continuous_joint_positions_as_is() {
    let mut e = env("PickCube-v1", "pd_joint_pos_vel");
    let (lo, hi) = e.action_space().clone().into_bounds();
    // Limited arm joints are normalised; the continuous ones (upperarm, forearm, wrist roll)
    // have unbounded position entries; velocities ±1.
    for k in [0, 1, 3, 5] {
        assert_eq!((lo[k], hi[k]), (-1.0, 1.0));
    }
    for k in [2, 4, 6] {
        assert_eq!((lo[k], hi[k]), (f32::NEG_INFINITY, f32::INFINITY));
    }
    e.reset(Some(0));
    // Normalised 0 on shoulder lift = the middle of its limits; +0.7 rad on the upper-arm roll.
    let mut a = [0.0f32; 20];
    a[1] = -0.6;
    a[2] = 0.7;
    a[3] = 0.3;
    a[14] = gripper_action(0.015);
    for _ in 0..30 {
        e.step(&a).unwrap();
    }
    let q = qpos(&e);
    assert!(q.iter().all(|x| x.is_finite()));
    let scale = |a: f64, lo: f64, hi: f64| 0.5 * (hi + lo) + 0.5 * (hi - lo) * a;
    let lift = scale(-0.6, -1.221, 1.518);
    let elbow = scale(0.3, -2.251, 2.251);
    assert!(
        (q[7] - lift).abs() < 3e-3,
        "shoulder lift {} vs {lift}",
        q[7]
    );
    assert!((q[8] - 0.7).abs() < 3e-3, "upper-arm roll {}", q[8]);
    assert!((q[9] - elbow).abs() < 3e-3, "elbow {} vs {elbow}", q[9]);
}

trait Bounds {
    fn into_bounds(self) -> (Vec<f32>, Vec<f32>);
}
impl Bounds for crate::env::BoxSpace {
    fn into_bounds(self) -> (Vec<f32>, Vec<f32>) {
        (self.low, self.high)
    }
}

#[test]
fn ee_modes_move_the_tcp_in_the_commanded_direction() {
    for (mode, adim) in [
        ("pd_ee_delta_pos", 9),
        ("pd_ee_delta_pose", 12),
        ("pd_ee_target_delta_pos", 9),
        ("pd_ee_target_delta_pose", 12),
    ] {
        let grip = if adim == 9 { 3 } else { 6 };
        for (axis, sign) in [(1usize, 1.0f32), (1, -1.0), (2, 1.0), (2, -1.0), (0, -1.0)] {
            let mut e = env("PickCube-v1", mode);
            e.reset(Some(1));
            let p0 = e.obs_part("extra/tcp_pose").unwrap()[..3].to_vec();
            let mut a = vec![0.0f32; adim];
            a[axis] = 0.5 * sign;
            a[grip] = gripper_action(0.015);
            for _ in 0..3 {
                e.step(&a).unwrap();
            }
            let p = e.obs_part("extra/tcp_pose").unwrap();
            let moved = (p[axis] - p0[axis]) * sign;
            assert!(
                moved > 0.03,
                "{mode} axis {axis} sign {sign}: moved {moved}"
            );
            for k in (0..3).filter(|&k| k != axis) {
                assert!(
                    (p[k] - p0[k]).abs() < 0.01,
                    "{mode} axis {axis}: drift on {k}"
                );
            }
        }
    }
    // Rotation: +1 about y commands −0.1 rad (rot_lower sign flip): the gripper pitches up.
    let mut e = env("PickCube-v1", "pd_ee_delta_pose");
    e.reset(Some(1));
    let pitch = |e: &crate::env::Env| {
        let b = e.robot().body("gripper_link").unwrap();
        let x = RobotIds::body_pose(e.data(), b).rotation * Vector3::x();
        (-x.z).atan2(x.x)
    };
    let before = pitch(&e);
    let mut a = [0.0f32; 12];
    a[4] = 1.0;
    a[6] = gripper_action(0.015);
    for _ in 0..3 {
        e.step(&a).unwrap();
    }
    let after = pitch(&e);
    assert!(before - after > 0.1, "pitch {before} -> {after}");
}

#[test]
fn ik_chain_starts_at_the_torso_and_rejects_a_non_ancestor_root() {
    let spec = robots::spec("fetch").unwrap();
    let desc = spec.description().unwrap();
    let arm = spec.arm_joints;
    // From the URDF root the chain has 11 joints (base, torso, arm): over the limit.
    assert!(Chain::new(&desc, "gripper_link", arm).is_err());
    let chain = Chain::from_root(&desc, Some("torso_lift_link"), "gripper_link", arm).unwrap();
    assert_eq!(chain.limits().len(), 7);
    // EE pose relative to the torso does not depend on base or torso joints.
    let mut q = fetch::TABLE_QPOS.to_vec();
    let p0 = chain.fk(&q);
    q[0] = 0.5;
    q[2] = 1.0;
    q[3] = 0.1;
    assert_eq!(chain.fk(&q), p0);
    let fk = desc.forward_kinematics(&Isometry3::identity(), &fetch::TABLE_QPOS);
    let rel = fk[desc.link("torso_lift_link").unwrap()].inverse()
        * fk[desc.link("gripper_link").unwrap()];
    assert!((rel.translation.vector - p0.translation.vector).norm() < 1e-12);
    let e = Chain::from_root(&desc, Some("head_pan_link"), "gripper_link", arm).unwrap_err();
    assert!(
        matches!(&e, crate::controllers::ControllerError::NotAncestor { root, ee }
            if root == "head_pan_link" && ee == "gripper_link"),
        "{e:?}"
    );
    let e = e.to_string();
    assert!(e.contains("head_pan_link") && e.contains("ancestor"), "{e}");
}

#[test]
fn base_velocity_drive_moves_and_turns_the_base() {
    let mut e = env("PickCube-v1", "pd_joint_delta_pos");
    e.reset(Some(0));
    // Backwards at 0.2 m/s (away from the table) for 0.5 s.
    let mut a = [0.0f32; 13];
    a[7] = gripper_action(0.015);
    a[11] = -0.2;
    for _ in 0..10 {
        e.step(&a).unwrap();
    }
    let q = qpos(&e);
    let v = e.obs_part("agent/qvel").unwrap();
    assert!(q[0] < -0.07 && q[0] > -0.1, "base x {}", q[0]);
    assert!((v[0] + 0.2).abs() < 0.01, "base speed {}", v[0]);
    // Turning at 0.314 rad/s, then driving: the velocity follows the heading.
    a[11] = 0.0;
    a[12] = 0.1;
    for _ in 0..20 {
        e.step(&a).unwrap();
    }
    let yaw = qpos(&e)[2];
    assert!(yaw > 0.25, "yaw {yaw}");
    a[11] = -0.2;
    a[12] = 0.0;
    for _ in 0..10 {
        e.step(&a).unwrap();
    }
    let yaw = qpos(&e)[2];
    let v = e.obs_part("agent/qvel").unwrap();
    assert!((v[0] as f64 + 0.2 * yaw.cos()).abs() < 0.01, "vx {}", v[0]);
    assert!((v[1] as f64 + 0.2 * yaw.sin()).abs() < 0.01, "vy {}", v[1]);
}

#[test]
fn scripted_solver_grasps_lifts_and_places_the_cube() {
    use crate::solvers as eval;
    use crate::solvers::make_policy;
    let cfg = EnvConfig {
        robot: Some("fetch".into()),
        ..Default::default()
    };
    let mut e = eval::make_env("PickCube-v1", cfg, "solver").unwrap();
    assert_eq!(e.config().control_mode.as_deref(), Some("pd_ee_delta_pose"));
    let mut policy = make_policy("solver", &e, 0).unwrap();
    let mut action = vec![0.0f32; 12];
    let cube = crate::tasks::body_id(e.model(), "cube").unwrap();
    let (mut grasped, mut max_z, mut fingers) = (false, 0.0f64, (1.0, 1.0));
    let r = eval::run_episode(
        &mut e,
        policy.as_mut(),
        Some(0),
        &mut action,
        |e, _, _, _, _| {
            if e.info().flag("is_grasped") {
                grasped = true;
                let q = e.obs_part("agent/qpos").unwrap();
                fingers = (q[13], q[14]);
                max_z = max_z.max(e.data().body_pos(cube)[2]);
            }
            Ok(())
        },
    )
    .unwrap();
    assert!(grasped, "the fingers closed on the cube");
    // Fingers stop at the 4 cm cube (≈ 2 cm each), not closed.
    assert!(fingers.0 > 0.012 && fingers.1 > 0.012, "{fingers:?}");
    assert!(max_z > 0.15, "lifted to {max_z}");
    assert!(r.success_once && r.success_at_end, "{r:?}");
}

#[test]
fn place_sphere_runs_with_fetch() {
    let mut e = env("PlaceSphere-v1", "pd_joint_delta_pos");
    e.reset(Some(0));
    let mut a = [0.0f32; 13];
    a[7] = gripper_action(0.05);
    for _ in 0..20 {
        let s = e.step(&a).unwrap();
        assert!(s.obs.iter().all(|x| x.is_finite()));
        assert!(!s.terminated);
    }
    // Open fingers: gripper_width = 2 × 0.05; the reward's grasp-release term sees 1.
    let q = qpos(&e);
    assert!((q[13] + q[14]) / 0.10 > 0.98, "{q:?}");
}
