//! xarm6_robotiq: joint order, kinematics against an independent URDF computation, the
//! four-bar linkage (loop closures, closure width), drives, grasping, control-mode shapes and
//! ManiSkill's seeded initial-pose noise.
use std::sync::Arc;

use nalgebra::{Isometry3, Point3, Translation3, Vector3};
use rand::Rng;

use super::common;
use common::run;

use crate::controllers::Drives;
use crate::env::EnvConfig;
use crate::mujoco::{Data, Model, ObjType};
use crate::robots::xarm6_robotiq::{LOOP_CLOSURES, REST};
use crate::robots::{self, RobotIds};

fn spec() -> &'static robots::RobotSpec {
    robots::spec("xarm6_robotiq").unwrap()
}

/// Table scene at rest (`REST` is the table qpos) with drives on their rest targets and
/// gravity compensation.
fn setup(extra: impl FnOnce(&mut crate::mjcf::Scene)) -> (Arc<Model>, RobotIds, Data, Drives) {
    common::table_scene_with(spec(), extra)
}

/// World distance between the two anchors of each loop closure.
fn anchor_gaps(ids: &RobotIds, d: &Data) -> Vec<f64> {
    LOOP_CLOSURES
        .iter()
        .map(|(l1, a1, l2, a2)| {
            let w1 = RobotIds::body_pose(d, ids.body(l1).unwrap()) * Point3::from(*a1);
            let w2 = RobotIds::body_pose(d, ids.body(l2).unwrap()) * Point3::from(*a2);
            (w1 - w2).norm()
        })
        .collect()
}

/// Sets the gripper target (both knuckles, as the mimic controller does).
fn set_gripper(dr: &mut Drives, target: f64) {
    dr.set_joint_target(6, target, 0.0);
    dr.set_joint_target(8, target, 0.0);
}

#[test]
fn qpos_order_is_maniskills_breadth_first_order() {
    let (_, ids, _, _) = setup(|_| {});
    assert_eq!(
        ids.joints.names,
        [
            "joint1",
            "joint2",
            "joint3",
            "joint4",
            "joint5",
            "joint6",
            "left_outer_knuckle_joint",
            "left_inner_knuckle_joint",
            "right_outer_knuckle_joint",
            "right_inner_knuckle_joint",
            "left_inner_finger_joint",
            "right_inner_finger_joint",
        ]
    );
    // Only the arm and the two outer knuckles are driven; the linkage is passive.
    let driven: Vec<bool> = ids.joints.actuator.iter().map(|a| a.is_some()).collect();
    assert_eq!(
        driven,
        [true, true, true, true, true, true, true, false, true, false, false, false]
    );
}

#[test]
fn forward_kinematics_matches_independent_urdf_fk() {
    let sample = |rng: &mut rand::rngs::StdRng, ids: &RobotIds| {
        let mut qv = vec![0.0; 12];
        for (v, &(lo, hi)) in qv.iter_mut().zip(&ids.joints.limits).take(6) {
            *v = rng.random_range(lo..=hi);
        }
        // A consistent linkage configuration: both knuckles at θ, inner fingers at −θ.
        for (knuckles, finger) in [([6, 7], 10), ([8, 9], 11)] {
            let t = rng.random_range(0.0..=0.81);
            qv[knuckles[0]] = t;
            qv[knuckles[1]] = t;
            qv[finger] = -t;
        }
        qv
    };
    common::check_fk_with("xarm6_robotiq", 200, sample, |d, ids, _| {
        // The parallelogram linkage keeps the loop-closure anchors together.
        for g in anchor_gaps(ids, d) {
            assert!(g < 1e-5, "loop closure gap {g} at {:?}", {
                let mut q = vec![0.0; 12];
                ids.joints.qpos(d, &mut q);
                q
            });
        }
    });
    let (_, ids, d, _) = setup(|_| {});
    // The TCP at rest (docs/robots.md §4, measured upstream): p (−0.00044, 0, 0.16943), q (0, −1, 0, 0).
    let (p, q) = ids.tcp_pose(&d);
    let want = [-0.00044, 0.0, 0.16943];
    for k in 0..3 {
        assert!((p[k] - want[k]).abs() < 1e-5, "tcp {p:?}");
    }
    assert!((q[2].abs() + q[3].abs() + q[0].abs()) < 1e-4 && (q[1].abs() - 1.0).abs() < 1e-6);
}

#[test]
fn linkage_closes_to_the_upstream_width_with_anchors_together() {
    let (_, ids, mut d, mut dr) = setup(|_| {});
    assert!(anchor_gaps(&ids, &d).iter().all(|&g| g < 1e-6), "q = 0");
    set_gripper(&mut dr, 0.81);
    run(&mut d, &mut dr, 1000);
    assert!(!d.warnings().diverged(), "{:?}", d.warnings());
    let mut q = vec![0.0; 12];
    ids.joints.qpos(&d, &mut q);
    for (k, want) in [
        (6, 0.81),
        (7, 0.81),
        (8, 0.81),
        (9, 0.81),
        (10, -0.81),
        (11, -0.81),
    ] {
        assert!(
            (q[k] - want).abs() < 5e-3,
            "joint {k}: {} (want {want})",
            q[k]
        );
    }
    for g in anchor_gaps(&ids, &d) {
        assert!(g < 1e-4, "loop closure gap {g} m at full closure");
    }
    // At full closure the pads sit at y ≈ ±0.0034 m in the gripper base frame.
    let base = RobotIds::body_pose(&d, ids.body("robotiq_arg2f_base_link").unwrap());
    for pad in ["left_inner_finger_pad", "right_inner_finger_pad"] {
        let p = base.inverse() * RobotIds::body_pose(&d, ids.body(pad).unwrap());
        let y = p.translation.vector.y.abs();
        assert!((y - 0.0034).abs() < 5e-4, "{pad} at |y| = {y}");
    }
    // The settled linkage is at rest, and opens again.
    let v: f64 = d.qvel().iter().map(|x| x.abs()).fold(0.0, f64::max);
    assert!(v < 1e-2, "max |qvel| {v}");
    set_gripper(&mut dr, 0.0);
    run(&mut d, &mut dr, 1000);
    ids.joints.qpos(&d, &mut q);
    assert!(q[6].abs() < 5e-3 && q[8].abs() < 5e-3, "{q:?}");
}

#[test]
fn holds_rest_pose_and_tracks_joint_targets() {
    let (model, ids, mut d, mut dr) = setup(|_| {});
    run(&mut d, &mut dr, (5.0 / model.timestep()) as usize);
    let mut q = vec![0.0; 12];
    ids.joints.qpos(&d, &mut q);
    for k in 0..12 {
        assert!(
            (q[k] - REST[k]).abs() < 1e-3,
            "joint {k} drifted to {}",
            q[k]
        );
    }
    let mut target = REST;
    for (k, t) in target.iter_mut().enumerate().take(6) {
        *t += if k == 1 { -0.2 } else { 0.2 };
        dr.set_joint_target(k, *t, 0.0);
    }
    run(&mut d, &mut dr, (1.5 / model.timestep()) as usize);
    ids.joints.qpos(&d, &mut q);
    for k in 0..6 {
        assert!(
            (q[k] - target[k]).abs() < 2e-3,
            "joint {k}: {} vs {}",
            q[k],
            target[k]
        );
    }
    assert!(!d.warnings().diverged(), "{:?}", d.warnings());
}

#[test]
fn closes_on_a_4cm_cube_and_lifts_it() {
    let probe = setup(|_| {});
    let tcp = probe.1.tcp_pose(&probe.2).0;
    // The cube rests on the table below the TCP; lower the arm onto it first.
    let cube_pos = [tcp[0], tcp[1], 0.02];
    let (model, ids, mut d, mut dr) =
        setup(|s| s.add_box("box", [0.02; 3], [1.0, 0.0, 0.0, 1.0], cube_pos));
    let bx = model.require_id(ObjType::Body, "box").unwrap();
    // The rest TCP is 0.169 m up: IK on the URDF chain gives joint targets 0.1494 m lower,
    // which put the TCP at the cube centre.
    let desc = spec().description().unwrap();
    let chain = crate::controllers::ik::Chain::new(
        &desc,
        "eef",
        &["joint1", "joint2", "joint3", "joint4", "joint5", "joint6"],
    )
    .unwrap();
    let mut q = vec![0.0; 12];
    ids.joints.qpos(&d, &mut q);
    let here = chain.fk(&q);
    let down = Isometry3::from_parts(
        Translation3::from(here.translation.vector - Vector3::new(0.0, 0.0, 0.1494)),
        here.rotation,
    );
    let mut q_down = vec![0.0; 12];
    assert!(chain.solve(&down, &q, &mut q_down));
    for (k, &t) in q_down.iter().enumerate().take(6) {
        dr.set_joint_target(k, t, 0.0);
    }
    run(&mut d, &mut dr, 1000);
    let tcp_now = ids.tcp_pose(&d).0;
    assert!(
        (tcp_now[2] - 0.02).abs() < 3e-3,
        "TCP lowered to the cube: {tcp_now:?}"
    );
    set_gripper(&mut dr, 0.81);
    run(&mut d, &mut dr, 500);
    ids.joints.qpos(&d, &mut q);
    assert!(
        q[6] > 0.3 && q[6] < 0.6 && q[8] > 0.3 && q[8] < 0.6,
        "knuckles stop at the cube: {:?}",
        &q[6..]
    );
    // Lift back to rest.
    for (k, &r) in REST.iter().enumerate().take(6) {
        dr.set_joint_target(k, r, 0.0);
    }
    run(&mut d, &mut dr, 1500);
    let z = d.xpos()[3 * bx + 2];
    assert!(z > 0.12, "cube lifted with the gripper: z = {z}");
    let tcp_up = ids.tcp_pose(&d).0;
    let cube = &d.xpos()[3 * bx..3 * bx + 3];
    let off = Vector3::new(
        cube[0] - tcp_up[0],
        cube[1] - tcp_up[1],
        cube[2] - tcp_up[2],
    );
    assert!(
        off.norm() < 0.02,
        "cube stays between the pads: offset {off:?}"
    );
    assert!(!d.warnings().diverged(), "{:?}", d.warnings());
}

fn pickcube(mode: &str) -> crate::env::Env {
    crate::env::make(
        "PickCube-v1",
        EnvConfig {
            robot: Some("xarm6_robotiq".into()),
            control_mode: Some(mode.into()),
            ..Default::default()
        },
    )
    .unwrap()
}

#[test]
fn control_modes_have_the_upstream_action_and_observation_shapes() {
    // (mode, action dim, state obs dim, gripper bounds of the last action entry)
    let table: [(&str, usize, usize, (f32, f32)); 11] = [
        ("pd_joint_delta_pos", 7, 48, (-1.0, 1.0)),
        ("pd_joint_pos", 7, 48, (0.0, 0.81)),
        ("pd_ee_delta_pos", 4, 48, (-1.0, 1.0)),
        ("pd_ee_delta_pose", 7, 48, (0.0, 0.81)),
        ("pd_ee_pose", 7, 48, (0.0, 0.81)),
        ("pd_joint_target_delta_pos", 7, 54, (-1.0, 1.0)),
        ("pd_ee_target_delta_pos", 4, 55, (-1.0, 1.0)),
        ("pd_ee_target_delta_pose", 7, 55, (-1.0, 1.0)),
        ("pd_joint_vel", 7, 48, (0.0, 0.81)),
        ("pd_joint_pos_vel", 13, 48, (0.0, 0.81)),
        ("pd_joint_delta_pos_vel", 13, 48, (-1.0, 1.0)),
    ];
    assert_eq!(
        table.map(|t| t.0).to_vec(),
        spec()
            .control_modes
            .iter()
            .map(|m| m.name())
            .collect::<Vec<_>>(),
        "all 11 modes, default first"
    );
    for (mode, dim, obs, (lo, hi)) in table {
        let mut env = pickcube(mode);
        env.reset(Some(0));
        let a = env.action_space();
        assert_eq!(a.low.len(), dim, "{mode} action dim");
        assert_eq!(
            (a.low[dim - 1], a.high[dim - 1]),
            (lo, hi),
            "{mode} gripper bounds"
        );
        assert_eq!(env.obs().len(), obs, "{mode} state dim");
        let zero = vec![0.0f32; dim];
        env.step(&zero).unwrap();
        assert!(env.obs().iter().all(|x| x.is_finite()), "{mode}");
    }
    // The default mode is pd_joint_delta_pos.
    let env = crate::env::make(
        "PickCube-v1",
        EnvConfig {
            robot: Some("xarm6_robotiq".into()),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(env.action_space().low.len(), 7);
    assert_eq!(env.obs().len(), 48);
}

#[test]
fn gripper_action_semantics_absolute_and_delta() {
    // Absolute radians (not normalised): 0.81 closes fully.
    let mut env = pickcube("pd_joint_pos");
    env.reset(Some(3));
    let mut q = vec![0.0; 12];
    env.robot().joints.qpos(env.data(), &mut q);
    let mut a: Vec<f32> = q[..6].iter().map(|&x| x as f32).collect();
    a.push(0.81);
    for _ in 0..10 {
        env.step(&a).unwrap();
    }
    env.robot().joints.qpos(env.data(), &mut q);
    assert!(
        (q[8] - 0.81).abs() < 0.01 && (q[6] - 0.81).abs() < 0.01,
        "{:?}",
        &q[6..]
    );
    // Delta: +1 sets the target 0.15 rad beyond the measured position (the drive may
    // overshoot it by a few mrad).
    let mut env = pickcube("pd_joint_delta_pos");
    env.reset(Some(3));
    env.robot().joints.qpos(env.data(), &mut q);
    let start = q[8];
    let mut a = vec![0.0f32; 7];
    a[6] = 1.0;
    env.step(&a).unwrap();
    env.robot().joints.qpos(env.data(), &mut q);
    let moved = q[8] - start;
    assert!(
        moved > 0.1 && moved < 0.15 + 0.01,
        "delta step moved {moved}"
    );
    // The left knuckle mimics the right one.
    assert!((q[6] - q[8]).abs() < 0.02, "{:?}", &q[6..]);
}

#[test]
fn seeded_reset_reproduces_maniskills_noise() {
    // numpy: np.random.RandomState(0).normal(0, 1, 12)
    const N0: [f64; 12] = common::NUMPY_SEED0_NORMALS;
    let mut env = pickcube("pd_joint_delta_pos");
    env.reset(Some(0));
    let mut q = vec![0.0; 12];
    env.robot().joints.qpos(env.data(), &mut q);
    for k in 0..12 {
        let want = (REST[k] + 0.02 * N0[k]) as f32 as f64;
        assert_eq!(q[k], want, "joint {k}: noise on all 12 entries");
    }
    // Same seed ⇒ same start; another seed differs.
    let first = q.clone();
    env.reset(Some(0));
    env.robot().joints.qpos(env.data(), &mut q);
    assert_eq!(q, first);
    env.reset(Some(1));
    env.robot().joints.qpos(env.data(), &mut q);
    assert_ne!(q, first);
}

#[test]
fn pickcube_solver_turns_the_gripper_to_the_cube_faces() {
    let config = EnvConfig {
        robot: Some("xarm6_robotiq".into()),
        ..Default::default()
    };
    let r = crate::solvers::evaluate("PickCube-v1", config, "solver", 20, 0).unwrap();
    assert_eq!(r.control_mode, "pd_ee_delta_pose");
    // Measured 20/20 on seeds 0–19 (100/100 on seeds 0–99; docs/solvers.md §9).
    assert!(r.successes >= 18, "{r:?}");
    let first = r.mean_first_success_step.unwrap();
    assert!((20.0..40.0).contains(&first), "{first}");
}
