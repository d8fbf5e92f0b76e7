//! PlaceSphere-v1 with the Panda: seeding, layout, the bin, evaluate and reward stages.

mod common;

use common::close;
use mjskill::mujoco::ObjType;
use mjskill::{make, EnvConfig};

fn env() -> mjskill::Env {
    make("PlaceSphere-v1", EnvConfig::default()).unwrap()
}

#[test]
fn seeded_resets_reproduce_maniskills_initial_states() {
    // docs/tasks.md §5.
    let mut e = env();
    for (seed, qpos, sphere, bin) in [
        (
            0u64,
            [
                0.035281, 0.400702, 0.019575, -1.918678, 0.037351, 2.336649, 0.8044, 0.04, 0.04,
            ],
            [-0.075187, 0.053644, 0.02],
            [0.008848, -0.073594, 0.0025],
        ),
        (
            1,
            [
                0.032487, 0.380464, -0.010563, -1.984955, 0.017308, 2.310164, 0.820294, 0.04, 0.04,
            ],
            [-0.062118, -0.044138, 0.02],
            [0.040307, 0.046937, 0.0025],
        ),
    ] {
        e.reset(Some(seed));
        close(e.obs_part("agent/qpos").unwrap(), &qpos, 2e-6, "qpos");
        close(
            &e.obs_part("extra/obj_pose").unwrap()[..3],
            &sphere,
            2e-6,
            "sphere",
        );
        close(e.obs_part("extra/bin_pos").unwrap(), &bin, 2e-6, "bin");
    }
}

#[test]
fn state_layout_is_39_long_in_maniskills_order() {
    let e = env();
    assert_eq!(e.observation_space().shape, vec![39]);
    let keys: Vec<&str> = e.obs_layout().iter().map(|(k, _)| k.as_str()).collect();
    assert_eq!(
        keys,
        [
            "agent/qpos",
            "agent/qvel",
            "extra/is_grasped",
            "extra/tcp_pose",
            "extra/bin_pos",
            "extra/obj_pose",
            "extra/tcp_to_obj_pos"
        ]
    );
    assert_eq!(
        e.info().keys,
        &[
            "is_obj_grasped",
            "is_obj_on_bin",
            "is_obj_static",
            "success"
        ]
    );
    assert!(mjskill::registry().iter().any(|r| r.id == "PlaceSphere-v1"));
}

/// Puts the sphere at `pos` with zero velocity through the env state.
fn place_sphere(e: &mut mjskill::Env, pos: [f64; 3]) {
    common::put_free_body(e, "sphere", pos, [1.0, 0.0, 0.0, 0.0]);
}

#[test]
fn a_sphere_dropped_over_the_bin_rests_inside_and_succeeds() {
    let mut e = env();
    e.reset(Some(0));
    let bin: Vec<f64> = e
        .obs_part("extra/bin_pos")
        .unwrap()
        .iter()
        .map(|&x| x as f64)
        .collect();
    // 3 cm above its resting height, 1 mm off centre.
    place_sphere(&mut e, [bin[0] + 0.001, bin[1], bin[2] + 0.0225 + 0.03]);
    let zero = [0.0f32; 8];
    let mut last = None;
    for _ in 0..20 {
        let s = e.step(&zero).unwrap();
        last = Some((
            s.info.flag("is_obj_on_bin"),
            s.info.flag("is_obj_static"),
            s.info.success(),
            s.reward,
        ));
    }
    let sphere = &e.obs_part("extra/obj_pose").unwrap()[..3];
    // Resting on the floor: centre at bin.z + floor half height + radius = 0.025.
    assert!(
        (sphere[2] as f64 - 0.025).abs() < 1e-3,
        "sphere z {}",
        sphere[2]
    );
    let dxy = ((sphere[0] as f64 - bin[0]).powi(2) + (sphere[1] as f64 - bin[1]).powi(2)).sqrt();
    assert!(dxy <= 0.005, "inside the walls: {dxy}");
    let (on, stat, success, reward) = last.unwrap();
    assert!(on && stat && success);
    assert_eq!(reward, 1.0, "normalized dense reward is 13/13 on success");
}

#[test]
fn reward_stages_follow_the_spec() {
    let mut e = make(
        "PlaceSphere-v1",
        EnvConfig {
            reward_mode: mjskill::RewardMode::Dense,
            ..Default::default()
        },
    )
    .unwrap();
    e.reset(Some(3));
    // Stage 1 (not grasped, not on the bin): 2·(1 − tanh(5·‖tcp − sphere‖)) ∈ (0, 2).
    let s = e.step(&[0.0; 8]).unwrap();
    assert!(!s.info.flag("is_obj_grasped") && !s.info.flag("is_obj_on_bin"));
    let v = e.obs_part("extra/tcp_to_obj_pos").unwrap();
    let d = v.iter().map(|&x| (x as f64).powi(2)).sum::<f64>().sqrt();
    let want = 2.0 * (1.0 - (5.0 * d).tanh());
    assert!(
        (e.dense_reward() - want).abs() < 1e-5,
        "{} vs {want}",
        e.dense_reward()
    );
    // A sphere moving fast over the bin is on the bin but not static: 6 + (16 + static + robot_static)/3.
    let bin: Vec<f64> = e
        .obs_part("extra/bin_pos")
        .unwrap()
        .iter()
        .map(|&x| x as f64)
        .collect();
    place_sphere(&mut e, [bin[0], bin[1], bin[2] + 0.0225]);
    let s = e.step(&[0.0; 8]).unwrap();
    assert!(s.info.flag("is_obj_on_bin"));
    if s.info.success() {
        assert_eq!(e.dense_reward(), 13.0);
    } else {
        let r = e.dense_reward();
        assert!(r > 6.0 + 16.0 / 3.0 && r <= 6.0 + 18.0 / 3.0 + 1e-9, "{r}");
    }
}

/// The dense reward recomputed independently (docs/tasks.md §3.5) from the observation, the info
/// flags and the sphere's velocity.
fn spec_dense_reward(e: &mjskill::Env, sphere_body: usize) -> f64 {
    let part = |k: &str| -> Vec<f64> { e.obs_part(k).unwrap().iter().map(|&x| x as f64).collect() };
    let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    let (qpos, qvel) = (part("agent/qpos"), part("agent/qvel"));
    let (sphere, bin) = (part("extra/obj_pose"), part("extra/bin_pos"));
    let info = e.info();
    let grasped = info.flag("is_obj_grasped");
    let mut r = 2.0 * (1.0 - (5.0 * norm(&part("extra/tcp_to_obj_pos"))).tanh());
    let to_top = [
        bin[0] - sphere[0],
        bin[1] - sphere[1],
        bin[2] + 0.0025 + 0.02 - sphere[2],
    ];
    if grasped {
        r = 4.0 + 1.0 - (5.0 * norm(&to_top)).tanh();
    }
    let ungrasp = if grasped {
        (qpos[7] + qpos[8]) / 0.08
    } else {
        16.0
    };
    let v = e.data().body_velocity(sphere_body); // (angular, linear), world frame
    let stat = 1.0 - (10.0 * norm(&v[3..]) + norm(&v[..3])).tanh();
    let robot_static = qvel[..7].iter().all(|x| x.abs() <= 0.2) as u8 as f64;
    if info.flag("is_obj_on_bin") {
        r = 6.0 + (ungrasp + stat + robot_static) / 3.0;
    }
    if info.success() {
        r = 13.0;
    }
    r
}

#[test]
fn every_reward_stage_of_a_solved_episode_matches_the_spec_formula() {
    use mjskill::solvers as eval;
    let config = EnvConfig {
        reward_mode: mjskill::RewardMode::Dense,
        ..Default::default()
    };
    let mut e = eval::make_env("PlaceSphere-v1", config, "solver").unwrap();
    let sphere = e.model().require_id(ObjType::Body, "sphere").unwrap();
    let mut policy = mjskill::solvers::make_policy("solver", &e, 0).unwrap();
    let mut action = vec![0.0f32; e.action_space().shape[0]];
    // Stages: reaching, grasped in the air, grasped over the bin, released on the bin
    // (not yet static), success. At the 0.01 s step the sphere is mostly released before it
    // is within `is_obj_on_bin`'s 5 mm of the floor: of seeds 0–11 only seed 6 passes
    // through "grasped over the bin" (the other stages occur on every seed).
    let mut seen = [false; 5];
    // Seeds until every stage has been seen (stage 2, the sphere lowered onto the bin still
    // in the gripper, lasts a step or two and not every episode samples it).
    for seed in 0..20 {
        if seen == [true; 5] {
            break;
        }
        e.reset(Some(seed));
        policy.reset(&e);
        for _ in 0..50 {
            policy.act(&e, &mut action);
            let reward = e.step(&action).unwrap().reward as f64;
            let want = spec_dense_reward(&e, sphere);
            assert!(
                (reward - want).abs() < 1e-5,
                "seed {seed}: reward {reward} vs spec {want}"
            );
            let i = e.info();
            let stage = match (
                i.success(),
                i.flag("is_obj_on_bin"),
                i.flag("is_obj_grasped"),
            ) {
                (true, ..) => 4,
                (false, true, false) => 3,
                (false, true, true) => 2,
                (false, false, true) => 1,
                (false, false, false) => 0,
            };
            seen[stage] = true;
            let bounds = [
                (0.0, 2.0),
                (4.0, 5.0),
                (6.0, 7.0),
                (6.0, 12.0),
                (13.0, 13.0),
            ];
            assert!(
                (bounds[stage].0..=bounds[stage].1).contains(&reward),
                "stage {stage}: reward {reward}"
            );
        }
    }
    assert_eq!(seen, [true; 5], "every stage reached: {seen:?}");
}
