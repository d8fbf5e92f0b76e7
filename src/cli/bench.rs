//! `mjskill bench`: env steps/s against the raw physics rate of the same model.
use std::time::Instant;

use rand::{Rng, SeedableRng};
use serde::Serialize;

use crate::env::{make, EnvConfig};
use crate::mjcf::SUBSTEPS;
use crate::mujoco::Data;

/// One bench result (printed as a JSON line).
#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    /// Env id.
    pub env: String,
    /// Robot uid.
    pub robot: String,
    /// Control mode.
    pub control_mode: String,
    /// Timed env steps.
    pub steps: usize,
    /// Physics steps per env step.
    pub substeps: usize,
    /// Env steps per second (random actions, resets at truncation).
    pub env_steps_per_s: f64,
    /// Env-step equivalents per second of raw `mj_step` on the same model (same substeps,
    /// no env logic, controls held).
    pub physics_steps_per_s: f64,
    /// Raw `mj_step` calls per second.
    pub mj_step_per_s: f64,
    /// env_steps_per_s / physics_steps_per_s.
    pub ratio: f64,
    /// Env overhead on top of physics, in percent: (1/ratio − 1)·100.
    pub overhead_percent: f64,
}

/// Runs the benchmark.
pub fn run(
    env_id: &str,
    robot: Option<String>,
    control_mode: Option<String>,
    steps: usize,
) -> Result<BenchReport, String> {
    let steps = steps.max(1);
    let mut env = make(
        env_id,
        EnvConfig {
            robot,
            control_mode,
            ..EnvConfig::default()
        },
    )
    .map_err(|e| e.to_string())?;
    let dim = env.action_space().shape[0];
    let mut rng = rand::rngs::StdRng::seed_from_u64(0);
    let mut actions = vec![0f32; dim * 64];
    for a in actions.iter_mut() {
        *a = rng.random_range(-1.0..1.0);
    }
    env.reset(Some(0));
    let timed = |n: usize, env: &mut crate::env::Env| -> Result<f64, String> {
        let t = Instant::now();
        for i in 0..n {
            let a = &actions[(i % 64) * dim..(i % 64 + 1) * dim];
            let s = env.step(a).map_err(|e| e.to_string())?;
            if s.truncated {
                env.reset(None);
            }
        }
        Ok(n as f64 / t.elapsed().as_secs_f64())
    };
    timed(steps / 10 + 1, &mut env)?;
    let env_rate = timed(steps, &mut env)?;
    // Raw physics: a copy of the env's current simulation state, stepped with no env logic.
    let mut data: Data = env.data().clone();
    for _ in 0..(steps / 10 + 1) * SUBSTEPS {
        data.step();
    }
    let t = Instant::now();
    for _ in 0..steps * SUBSTEPS {
        data.step();
    }
    let mj_rate = (steps * SUBSTEPS) as f64 / t.elapsed().as_secs_f64();
    let phys = mj_rate / SUBSTEPS as f64;
    let ratio = env_rate / phys;
    Ok(BenchReport {
        env: env_id.to_string(),
        robot: env.robot_spec().uid.to_string(),
        control_mode: env.config().control_mode.clone().unwrap_or_default(),
        steps,
        substeps: SUBSTEPS,
        env_steps_per_s: env_rate,
        physics_steps_per_s: phys,
        mj_step_per_s: mj_rate,
        ratio,
        overhead_percent: (1.0 / ratio - 1.0) * 100.0,
    })
}
