//! The contact filter's box slab test (`mjskill::mujoco::filter`) skips only geom pairs that
//! MuJoCo's narrow phase would find apart: with it on and off, every registered pair's episodes
//! are the same bit for bit, contacts included.
//!
//! The test switches the process-wide slab test, so it is the only test of this binary.

use mjskill::mujoco::filter;
use mjskill::solvers::{self, SOLVED, UNSOLVED};
use mjskill::Env;

mod common;

/// Per step: every contact's geoms and distance, then qpos and qvel, as bits.
fn episode(id: &str, robot: &str, seed: u64) -> Vec<u64> {
    let policy = if SOLVED.contains(&(id, robot)) {
        "solver"
    } else {
        "random"
    };
    let mode = solvers::required_control_mode(policy, id, robot).unwrap_or("pd_joint_delta_pos");
    let mut env: Env = common::env_in(id, robot, mode);
    let mut p = solvers::make_policy(policy, &env, seed).unwrap();
    env.reset(Some(seed));
    p.reset(&env);
    let mut action = vec![0.0f32; env.action_space().shape[0]];
    let mut out = Vec::new();
    for _ in 0..env.max_episode_steps() {
        p.act(&env, &mut action);
        env.step(&action).unwrap();
        let d = env.data();
        out.push(d.ncon() as u64);
        for c in 0..d.ncon() {
            let k = d.contact(c);
            out.extend([k.geom1 as u64, k.geom2 as u64, k.dist.to_bits()]);
            out.extend(k.pos.iter().map(|x| x.to_bits()));
        }
        out.extend(d.qpos().iter().chain(d.qvel()).map(|x| x.to_bits()));
    }
    out
}

#[test]
fn the_slab_test_changes_no_contact_and_no_state() {
    assert!(filter::box_slab_test(), "the slab test is on by default");
    for (id, robot) in SOLVED.iter().chain(&UNSOLVED) {
        for seed in [7, 1001] {
            filter::set_box_slab_test(true);
            let on = episode(id, robot, seed);
            filter::set_box_slab_test(false);
            let off = episode(id, robot, seed);
            filter::set_box_slab_test(true);
            assert_eq!(
                on.len(),
                off.len(),
                "{id}/{robot} seed {seed}: record lengths"
            );
            if let Some(k) = on.iter().zip(&off).position(|(a, b)| a != b) {
                panic!("{id}/{robot} seed {seed}: the episodes part at record entry {k}");
            }
        }
    }
}
