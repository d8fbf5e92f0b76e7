//! `Env::step` allocates nothing: a counting global allocator watches every control mode.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

struct Counting;

static COUNTING: AtomicBool = AtomicBool::new(false);
static ALLOCS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTING.load(Ordering::SeqCst) {
            ALLOCS.fetch_add(1, Ordering::SeqCst);
        }
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if COUNTING.load(Ordering::SeqCst) {
            ALLOCS.fetch_add(1, Ordering::SeqCst);
        }
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// The one test in this binary, so no other thread allocates while counting.
#[test]
fn step_allocates_nothing_in_any_env_and_control_mode() {
    // The counter works: one Vec is one allocation.
    COUNTING.store(true, Ordering::SeqCst);
    let v = std::hint::black_box(vec![1u8; 10]);
    COUNTING.store(false, Ordering::SeqCst);
    assert_eq!((ALLOCS.swap(0, Ordering::SeqCst), v.len()), (1, 10));
    for info in mjskill::registry() {
        for (robot, modes) in &info.robots {
            for mode in modes {
                let config = mjskill::EnvConfig {
                    robot: Some(robot.to_string()),
                    control_mode: Some(mode.to_string()),
                    ..Default::default()
                };
                let mut env = mjskill::make(info.id, config).unwrap();
                let dim = env.action_space().shape[0];
                let actions: Vec<Vec<f32>> = (0..20)
                    .map(|k| (0..dim).map(|i| ((k * 5 + i) as f32 * 0.7).sin()).collect())
                    .collect();
                // Warm up (first-touch paths), then count.
                env.step(&actions[0]).unwrap();
                ALLOCS.store(0, Ordering::SeqCst);
                COUNTING.store(true, Ordering::SeqCst);
                let mut sum = 0.0f32;
                for a in &actions {
                    let s = env.step(a).unwrap();
                    sum += s.reward + s.obs[0];
                }
                COUNTING.store(false, Ordering::SeqCst);
                let n = ALLOCS.load(Ordering::SeqCst);
                assert!(sum.is_finite());
                assert_eq!(
                    n, 0,
                    "{} / {robot} / {mode}: {n} allocations in 20 steps",
                    info.id
                );
            }
        }
    }
    // PhysX's step replica for the pinch (pinch_solver = "physx_tgs"): the solver grasps (the
    // SO100's cube: convex parts against a box; the Panda's sphere: finger boxes against a
    // sphere), then the held steps are counted.
    for (env_id, robot, mode, seed) in [
        ("PickCubeSO100-v1", "so100", "pd_joint_pos", 5000),
        ("PlaceSphere-v1", "panda", "pd_ee_delta_pos", 0),
    ] {
        let config = mjskill::EnvConfig {
            robot: Some(robot.into()),
            control_mode: Some(mode.into()),
            sim: mjskill::SimConfig {
                pinch_solver: mjskill::PinchSolver::PhysxTgs,
                ..Default::default()
            },
            ..Default::default()
        };
        let mut env = mjskill::make(env_id, config).unwrap();
        env.reset(Some(seed));
        let mut solver = mjskill::solvers::make_policy("solver", &env, seed).unwrap();
        solver.reset(&env);
        let mut action = vec![0.0f32; env.action_space().shape[0]];
        for _ in 0..50 {
            solver.act(&env, &mut action);
            env.step(&action).unwrap();
            if env.drives().pinch_replica_active() {
                break;
            }
        }
        assert!(
            env.drives().pinch_replica_active(),
            "{env_id} / {robot}: the solver never pinched"
        );
        ALLOCS.store(0, Ordering::SeqCst);
        COUNTING.store(true, Ordering::SeqCst);
        for _ in 0..5 {
            env.step(&action).unwrap();
        }
        COUNTING.store(false, Ordering::SeqCst);
        assert!(
            env.drives().pinch_replica_active(),
            "{env_id} / {robot}: the pinch ended"
        );
        assert_eq!(
            ALLOCS.load(Ordering::SeqCst),
            0,
            "{env_id} / {robot}: the pinch replica's steps allocated"
        );
    }
    // The VecEnv's steady-state step (workers included: the counter is process-wide).
    let mut v = mjskill::VecEnv::new("PickCube-v1", mjskill::EnvConfig::default(), 4, 2).unwrap();
    let acts: Vec<f32> = (0..32).map(|i| (i as f32 * 0.3).sin()).collect();
    v.step(&acts).unwrap();
    ALLOCS.store(0, Ordering::SeqCst);
    COUNTING.store(true, Ordering::SeqCst);
    for _ in 0..20 {
        v.step(&acts).unwrap();
    }
    COUNTING.store(false, Ordering::SeqCst);
    assert_eq!(ALLOCS.load(Ordering::SeqCst), 0, "VecEnv::step allocated");
    assert!(v.rewards().iter().all(|r| r.is_finite()));
    // Visual obs mode: the sensor images are rendered in place every step, and the human
    // render reuses its buffer (Mesa's own C allocations are not Rust's and not counted).
    let config = mjskill::EnvConfig {
        obs_mode: mjskill::ObsMode::Rgbd,
        ..Default::default()
    };
    let mut env = mjskill::make("PickCube-v1", config).unwrap();
    let a = vec![0.1f32; env.action_space().shape[0]];
    env.step(&a).unwrap();
    env.render().unwrap();
    ALLOCS.store(0, Ordering::SeqCst);
    COUNTING.store(true, Ordering::SeqCst);
    let mut sum = 0u64;
    for _ in 0..5 {
        env.step(&a).unwrap();
        sum += env.sensor_rgb().unwrap()[0] as u64;
        sum += env.render().unwrap()[0] as u64;
    }
    COUNTING.store(false, Ordering::SeqCst);
    assert_eq!(
        ALLOCS.load(Ordering::SeqCst),
        0,
        "rgbd step or render allocated"
    );
    // Fetch renders its two mounted cameras too, into buffers of their own; the point cloud
    // mode renders colour, depth and segmentation of all three and fuses them in place.
    let config = mjskill::EnvConfig {
        robot: Some("fetch".into()),
        obs_mode: mjskill::ObsMode::PointCloud,
        ..Default::default()
    };
    let mut env = mjskill::make("PickCube-v1", config).unwrap();
    let a = vec![0.1f32; env.action_space().shape[0]];
    env.step(&a).unwrap();
    ALLOCS.store(0, Ordering::SeqCst);
    COUNTING.store(true, Ordering::SeqCst);
    for _ in 0..3 {
        env.step(&a).unwrap();
        for cam in ["fetch_head", "fetch_hand"] {
            let img = env.image(cam).unwrap();
            sum += img.rgb.unwrap()[0] as u64 + img.depth.unwrap()[0] as u64;
            sum += img.segmentation.unwrap()[0] as u64 + img.depth_mm.unwrap()[0] as u64;
        }
        sum += env.point_cloud().unwrap().xyzw[0] as u64;
    }
    COUNTING.store(false, Ordering::SeqCst);
    assert_eq!(
        ALLOCS.load(Ordering::SeqCst),
        0,
        "fetch pointcloud step allocated"
    );
    // A visual-mode VecEnv: workers render into their envs' buffers, pack the pixels into the
    // image cells made by `VecEnv::new`, and the caller unpacks them into its own buffers.
    let config = mjskill::EnvConfig {
        robot: Some("fetch".into()),
        obs_mode: mjskill::ObsMode::RgbDepthSegmentation,
        ..Default::default()
    };
    let mut v = mjskill::VecEnv::new("PickCube-v1", config, 3, 2).unwrap();
    let acts: Vec<f32> = (0..3 * v.single_action_space().shape[0])
        .map(|i| (i as f32 * 0.3).sin())
        .collect();
    v.step(&acts).unwrap();
    ALLOCS.store(0, Ordering::SeqCst);
    COUNTING.store(true, Ordering::SeqCst);
    for _ in 0..3 {
        v.step(&acts).unwrap();
        for i in 0..3 {
            for cam in v.sensor_names() {
                let img = v.image(i, cam).unwrap();
                sum += img.rgb.unwrap()[0] as u64 + img.depth.unwrap()[0] as u64;
                sum += img.segmentation.unwrap()[0] as u64;
            }
        }
    }
    COUNTING.store(false, Ordering::SeqCst);
    assert_eq!(
        ALLOCS.load(Ordering::SeqCst),
        0,
        "rgb+depth+segmentation VecEnv step allocated"
    );
    // A noise-injected step (rollout --action-noise): the noise is drawn into the caller's
    // buffer, and the env steps the noisy action.
    let mut env = mjskill::make("PickCube-v1", mjskill::EnvConfig::default()).unwrap();
    let mut noise = mjskill::solvers::ActionNoise::parse("arm=0.05,gripper=0", &env, 3).unwrap();
    let label = vec![0.1f32; env.action_space().shape[0]];
    let mut action = label.clone();
    noise.reset(7);
    noise.apply(&label, &mut action);
    env.step(&action).unwrap();
    ALLOCS.store(0, Ordering::SeqCst);
    COUNTING.store(true, Ordering::SeqCst);
    let mut moved = 0.0f32;
    for _ in 0..20 {
        noise.apply(&label, &mut action);
        moved += (action[0] - label[0]).abs();
        env.step(&action).unwrap();
    }
    COUNTING.store(false, Ordering::SeqCst);
    assert_eq!(ALLOCS.load(Ordering::SeqCst), 0, "a noisy step allocated");
    assert!(moved > 0.0, "the noise moved the actions");
    std::hint::black_box(sum);
}
