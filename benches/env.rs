//! `cargo bench -p mjskill-benches`: criterion timings of the hot paths — `Env::step` for every registered
//! (env, robot) pair, `reset`, a step with a 128×128 camera observation, the 512×512 human
//! render, and the threaded `VecEnv`. `mjskill bench` reports the same figures as JSON and
//! compares them with raw MuJoCo; this is the statistically careful version.
use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use mjskill::VecEnv;
use mjskill::{make, registry, Env, EnvConfig, ObsMode};
use rand::{Rng, SeedableRng};

/// Episode length of the benchmark rollouts (ManiSkill's truncation for these tasks).
const EPISODE: usize = 50;

/// Uniform random actions in [-1, 1], fixed by seed, for `steps` steps.
fn actions(dim: usize, steps: usize) -> Vec<f32> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(0);
    (0..dim * steps)
        .map(|_| rng.random_range(-1.0..1.0))
        .collect()
}

fn env(id: &str, robot: &str, obs_mode: ObsMode) -> Env {
    let config = EnvConfig {
        robot: Some(robot.to_string()),
        obs_mode,
        ..Default::default()
    };
    make(id, config).unwrap_or_else(|e| panic!("{id}/{robot}: {e}"))
}

/// Steps `env` through one pre-drawn random action per call, resetting every `EPISODE` steps.
fn stepper(mut env: Env) -> impl FnMut() {
    let dim = env.action_space().shape[0];
    let acts = actions(dim, EPISODE);
    let mut t = 0;
    let mut seed = 0;
    env.reset(Some(seed));
    move || {
        if t == EPISODE {
            t = 0;
            seed += 1;
            env.reset(Some(seed));
        }
        env.step(&acts[t * dim..(t + 1) * dim])
            .expect("valid action");
        t += 1;
    }
}

fn step_every_pair(c: &mut Criterion) {
    let mut g = c.benchmark_group("step");
    g.throughput(Throughput::Elements(1));
    for info in registry() {
        for (robot, _) in &info.robots {
            let mut step = stepper(env(info.id, robot, ObsMode::State));
            g.bench_function(BenchmarkId::new(info.id, robot), |b| b.iter(&mut step));
        }
    }
    g.finish();
}

fn reset(c: &mut Criterion) {
    let mut e = env("PickCube-v1", "panda", ObsMode::State);
    let mut seed = 0;
    c.bench_function("reset/PickCube-v1/panda", |b| {
        b.iter(|| {
            seed += 1;
            e.reset(Some(seed)).0.len()
        })
    });
}

/// Camera work needs EGL; without it these are skipped with a note (state benches still run).
fn pixels(c: &mut Criterion) {
    let mut e = env("PickCube-v1", "panda", ObsMode::State);
    if let Err(err) = e.render() {
        eprintln!("skipping the rendering benches: {err}");
        return;
    }
    let zero = vec![0.0f32; e.action_space().shape[0]];
    c.bench_function("render/PickCube-v1/panda/512x512", |b| {
        // Frames are cached per state: step (untimed) before each timed render.
        b.iter_custom(|iters| {
            let mut spent = Duration::ZERO;
            for _ in 0..iters {
                e.step(&zero).expect("valid action");
                let t = Instant::now();
                black_box(e.render().expect("render"));
                spent += t.elapsed();
            }
            spent
        })
    });
    let mut step = stepper(env("PickCube-v1", "panda", ObsMode::Rgb));
    c.bench_function("step_rgb/PickCube-v1/panda/128x128", |b| b.iter(&mut step));
}

fn vec_env(c: &mut Criterion) {
    let (n, threads) = (8, 2);
    let mut v = VecEnv::new("PickCube-v1", EnvConfig::default(), n, threads).expect("VecEnv");
    let dim = v.single_action_space().shape[0];
    let acts = actions(dim * n, EPISODE);
    let mut t = 0;
    let mut g = c.benchmark_group("vec_env");
    g.throughput(Throughput::Elements(n as u64));
    g.bench_function(format!("PickCube-v1/panda/{n}x{threads}"), |b| {
        b.iter(|| {
            // Autoreset (next-step mode) restarts finished envs inside `step`.
            v.step(&acts[t * dim * n..(t + 1) * dim * n])
                .expect("valid actions");
            t = (t + 1) % EPISODE;
        })
    });
    g.finish();
}

criterion_group!(benches, step_every_pair, reset, pixels, vec_env);
criterion_main!(benches);
