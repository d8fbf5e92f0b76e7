//! Gravity as ManiSkill has it: the robot's links weightless, the props with their weight.
//! The scene's gravity is switched off and each prop carries `m·g` in `xfrc_applied`
//! (docs/controllers.md §6), which the env writes at every reset and state restore.

use mjskill::mujoco::JointType;
use mjskill::Env;

mod common;

use common::env_in as env;

const G: f64 = 9.81;

/// Bodies that a free joint moves: the props of these scenes.
fn free_bodies(env: &Env) -> Vec<usize> {
    let m = env.model();
    (0..m.njnt())
        .filter(|&j| m.joint_type(j) == JointType::Free)
        .map(|j| m.jnt_bodyid()[j] as usize)
        .collect()
}

/// Offset of `xfrc_applied` in the physics state (time, qpos, qvel, act, ctrl,
/// qacc_warmstart, qfrc_applied, xfrc_applied, ...).
fn xfrc_offset(env: &Env) -> usize {
    let m = env.model();
    1 + m.nq() + m.nv() + m.na() + m.nu() + m.nv() + m.nv()
}

#[test]
fn only_the_props_carry_their_weight() {
    for (id, robot, props) in [
        ("PickCube-v1", "panda", 1),
        ("StackCube-v1", "panda", 2),
        ("PlaceSphere-v1", "fetch", 1),
        ("PickCube-v1", "so100", 1),
    ] {
        let mut e = env(id, robot, "pd_joint_delta_pos");
        e.reset(Some(3));
        let bodies = free_bodies(&e);
        assert_eq!(bodies.len(), props, "{id}/{robot}: free bodies");
        let m = e.model();
        let xfrc = e.data().xfrc_applied();
        for b in 0..m.nbody() {
            let w = &xfrc[6 * b..6 * b + 6];
            let want = if bodies.contains(&b) {
                [0.0, 0.0, -m.body_mass()[b] * G, 0.0, 0.0, 0.0]
            } else {
                [0.0; 6]
            };
            assert_eq!(w, want, "{id}/{robot}: xfrc_applied of body {b}");
        }
    }
}

#[test]
fn a_raised_cube_falls_as_under_gravity_while_the_arm_holds() {
    let mut e = env("PickCube-v1", "panda", "pd_joint_delta_pos");
    e.reset(Some(5));
    let (qadr, _) = common::joint_addresses(&e, "cube");
    let q = e.data().qpos()[qadr..qadr + 7].to_vec();
    let z0 = q[2] + 0.1;
    common::put_free_body(&mut e, "cube", [q[0], q[1], z0], [q[3], q[4], q[5], q[6]]);
    let arm0: Vec<f64> = e.data().qpos()[..7].to_vec();
    let zero = vec![0.0f32; e.action_space().shape[0]];
    // Two control steps: ten 0.01 s substeps of semi-implicit Euler fall g h² n(n+1)/2.
    e.step(&zero).unwrap();
    e.step(&zero).unwrap();
    let fall = z0 - e.data().qpos()[qadr + 2];
    let want = G * 1e-4 * 55.0;
    assert!(
        (fall - want).abs() < 1e-6,
        "the cube fell {fall} m in 0.1 s, free fall gives {want}"
    );
    let sag = e.data().qpos()[..7]
        .iter()
        .zip(&arm0)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(
        sag < 1e-3,
        "the weightless arm moved {sag} rad holding still"
    );
}

#[test]
fn a_state_with_other_applied_forces_restores_the_envs_own_gravity() {
    for (robot, mode) in [
        ("panda", "pd_ee_delta_pos"),
        ("fetch", "pd_joint_delta_pos"),
    ] {
        let mut e = env("PickCube-v1", robot, mode);
        e.reset(Some(11));
        let dim = e.action_space().shape[0];
        let act = |k: usize| -> Vec<f32> {
            (0..dim)
                .map(|i| ((k * 5 + i * 3) as f32 * 0.37).sin() * 0.5)
                .collect()
        };
        for k in 0..4 {
            e.step(&act(k)).unwrap();
        }
        let saved = e.get_state();
        let mut reference = Vec::new();
        for k in 4..12 {
            reference.extend_from_slice(e.step(&act(k)).unwrap().obs);
        }
        // What a build before 29 November saved: the props' xfrc zero and an upward m·g on
        // every other body (the robot's compensation), with the scene's gravity on.
        let mut old = saved.clone();
        let off = xfrc_offset(&e);
        let props = free_bodies(&e);
        let m = e.model().clone();
        for b in 1..m.nbody() {
            let w = if props.contains(&b) {
                0.0
            } else {
                m.body_mass()[b] * G
            };
            old.physics[off + 6 * b..off + 6 * b + 6]
                .copy_from_slice(&[0.0, 0.0, w, 0.0, 0.0, 0.0]);
        }
        let mut other = env("PickCube-v1", robot, mode);
        other.reset(Some(2));
        other.set_state(&old).unwrap();
        assert!(
            other.get_state() == saved,
            "{robot}: the restored state holds the env's own applied forces"
        );
        let mut replay = Vec::new();
        for k in 4..12 {
            replay.extend_from_slice(other.step(&act(k)).unwrap().obs);
        }
        assert!(
            replay == reference,
            "{robot}: the trajectory after the restore"
        );
    }
}
