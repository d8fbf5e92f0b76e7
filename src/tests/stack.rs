//! The `mjData` stack that `Mjcf::compile` sizes (`Model::shrink_stack`) against what every
//! env and robot uses: scripted grasps (contacts, the constraint solver at work) and random
//! actions, with at least twice the peak to spare.

use crate::env::{make, registry, EnvConfig};
use crate::solvers::{make_policy, required_control_mode};

#[test]
fn the_shrunk_stack_holds_twice_what_every_env_uses() {
    for info in registry() {
        for (robot, _) in &info.robots {
            for policy in ["solver", "random"] {
                let config = EnvConfig {
                    robot: Some(robot.to_string()),
                    control_mode: required_control_mode(policy, info.id, robot).map(str::to_string),
                    ..EnvConfig::default()
                };
                let mut env = make(info.id, config).unwrap();
                let size = env.model().stack_size();
                assert!(size <= env.model().stack_bound(), "{}", info.id);
                let Ok(mut p) = make_policy(policy, &env, 7) else {
                    continue;
                };
                let mut action = vec![0.0; env.action_space().shape[0]];
                let mut peak = 0;
                for _ in 0..info.max_episode_steps {
                    p.act(&env, &mut action);
                    env.step(&action).unwrap();
                    peak = peak.max(env.data().max_stack_use());
                }
                assert!(peak > 0);
                assert!(
                    2 * peak <= size,
                    "{} {robot} {policy}: peak stack use {peak} of {size}",
                    info.id
                );
            }
        }
    }
}
