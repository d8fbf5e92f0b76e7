//! `mjskill bench`: env steps/s against the raw physics rate of the same model.
use std::time::Instant;

use rand::{Rng, SeedableRng};
use serde::Serialize;

use crate::CliError;
use mjskill::mujoco::Data;
use mjskill::{make, EnvConfig};

/// One bench result (printed as a JSON line).
#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    /// Env id.
    pub env: String,
    /// Robot uid.
    pub robot: String,
    /// Control mode.
    pub control_mode: String,
    /// Observation mode (rgb/depth/rgbd render the sensor camera every step).
    pub obs_mode: String,
    /// Timed env steps.
    pub steps: usize,
    /// Physics steps per env step.
    pub substeps: usize,
    /// Env steps per second (uniform random actions, one continuous rollout from seed 0).
    pub env_steps_per_s: f64,
    /// Env-step equivalents per second of raw `mj_step` replaying the env's own drive
    /// commands on the same model from the same state (identical trajectory, no env logic).
    pub physics_steps_per_s: f64,
    /// Raw `mj_step` calls per second.
    pub mj_step_per_s: f64,
    /// Whether the raw replay reproduced the env's trajectory bitwise (same physics work).
    pub replay_identical: bool,
    /// VecEnv size (with `--envs`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub envs: Option<usize>,
    /// VecEnv threads actually used (with `--envs`): `--threads`, at most one per env.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub threads: Option<usize>,
    /// Env steps per second summed over the VecEnv's envs (with `--envs`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vec_env_steps_per_s: Option<f64>,
    /// vec_env_steps_per_s / env_steps_per_s (with `--envs`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scaling: Option<f64>,
    /// Share of the fastest vector pass's wall time that each VecEnv thread spent stepping
    /// (`VecEnv::thread_busy_seconds`; thread 0 is the caller's). Below 1, the thread waited
    /// for another; all near 1 with a low `scaling`, the cores themselves ran slower.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vec_thread_busy: Option<Vec<f64>>,
    /// The hypervisor's steal time during that pass, in per cent of the machine's CPU time
    /// (`/proc/stat`; absent where it cannot be read): time this virtual machine's cores
    /// were runnable but not run.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub steal_percent: Option<f64>,
    /// Human render camera frames per second (`Env::render`, with `--render`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub render_frames_per_s: Option<f64>,
    /// Size of those frames.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub render_size: Option<(usize, usize)>,
    /// Where a physics substep's time goes (with `--profile`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub profile: Option<Profile>,
    /// env_steps_per_s / physics_steps_per_s.
    pub ratio: f64,
    /// Env overhead on top of physics, in percent: (1/ratio − 1)·100.
    pub overhead_percent: f64,
}

/// Where a physics substep's time goes: one more raw replay of the timed steps with
/// MuJoCo's stage timers on (`mjData.timer`, [`mjskill::mujoco::timer`]). The timers' own
/// clock reads make this replay slower than the timed ones; the shares are what compares.
#[derive(Debug, Clone, Serialize)]
pub struct Profile {
    /// Wall time of one substep in this replay (drives, `mj_step1`, `mj_step2`), µs.
    pub substep_us: f64,
    /// Per MuJoCo stage that ran: µs per substep, share of the substep, calls per substep.
    /// `position` holds the `pos_*` stages; `actuation` and `acceleration` include the
    /// drives' own calls (their unconstrained acceleration) where the drives make them (a
    /// robot with an actuator that is no drive, or a wrench on a robot link).
    pub stages: std::collections::BTreeMap<String, Stage>,
    /// The substep's time outside MuJoCo's timed stages (the drives' own arithmetic, the
    /// integration, the kinematics update after each env step), µs and share.
    pub rest_us: f64,
    /// rest_us / substep_us.
    pub rest_share: f64,
    /// Mean contacts per substep.
    pub contacts: f64,
    /// Mean constraint rows (`nefc`) per substep.
    pub constraint_rows: f64,
    /// Mean constraint-solver iterations per substep (MuJoCo's limit: 100).
    pub solver_iterations: f64,
    /// Most solver iterations in one substep.
    pub solver_iterations_max: usize,
}

/// One MuJoCo stage in a [`Profile`].
#[derive(Debug, Clone, Serialize)]
pub struct Stage {
    /// µs per substep.
    pub us: f64,
    /// Share of the substep's wall time.
    pub share: f64,
    /// Calls per substep.
    pub calls: f64,
}

/// Replays `targets` (the drive targets of `steps` env steps) from `start` on a copy of the
/// env's physics with MuJoCo's timers on, and splits the time by stage.
fn profile(
    env: &mut mjskill::Env,
    start: &mjskill::EnvState,
    targets: &[f64],
    steps: usize,
) -> Result<Profile, CliError> {
    use mjskill::mujoco::timer::{enable_timers, Timer};
    enable_timers();
    let substeps = env.substeps();
    let nd = env.drives().targets_len();
    env.set_state(start)?;
    let mut data: Data = env.data().clone();
    let mut drives = env.drives().clone();
    data.clear_timers();
    let (mut contacts, mut rows, mut iters, mut iters_max) = (0usize, 0usize, 0usize, 0usize);
    let t = Instant::now();
    for i in 0..steps {
        drives.load_targets(&targets[i * nd..(i + 1) * nd]);
        for _ in 0..substeps {
            drives.step(&mut data);
            contacts += data.ncon();
            rows += data.nefc();
            iters += data.solver_iterations();
            iters_max = iters_max.max(data.solver_iterations());
        }
        data.update_kinematics();
    }
    let n = (steps * substeps) as f64;
    let substep_us = t.elapsed().as_secs_f64() * 1e6 / n;
    let mut stages = std::collections::BTreeMap::new();
    let mut top = 0.0;
    for timer in Timer::ALL {
        let stat = data.timer(timer);
        if stat.calls == 0 {
            continue;
        }
        let us = stat.seconds * 1e6 / n;
        if matches!(
            timer,
            Timer::Position
                | Timer::Velocity
                | Timer::Actuation
                | Timer::Acceleration
                | Timer::Constraint
        ) {
            top += us;
        }
        stages.insert(
            timer.name().to_string(),
            Stage {
                us,
                share: us / substep_us,
                calls: stat.calls as f64 / n,
            },
        );
    }
    let rest_us = (substep_us - top).max(0.0);
    Ok(Profile {
        substep_us,
        stages,
        rest_us,
        rest_share: rest_us / substep_us,
        contacts: contacts as f64 / n,
        constraint_rows: rows as f64 / n,
        solver_iterations: iters as f64 / n,
        solver_iterations_max: iters_max,
    })
}

/// Largest `--steps`: the timed actions and drive commands are held in memory
/// (about 100 bytes per step).
pub const MAX_STEPS: usize = 1_000_000;
/// Largest `--envs`.
pub const MAX_ENVS: usize = 256;
/// Largest `--threads`.
pub const MAX_THREADS: usize = 256;
/// Largest `--render`.
pub const MAX_RENDER: usize = 100_000;

fn check_count(flag: &str, n: usize, max: usize) -> Result<(), CliError> {
    if !(1..=max).contains(&n) {
        return Err(format!("{flag} must be in 1..={max}, got {n}").into());
    }
    Ok(())
}

/// The vector passes' figures: env steps/s summed over the envs, each thread's busy share
/// and the steal time, all of the fastest pass.
struct VecRate {
    steps_per_s: f64,
    busy: Vec<f64>,
    steal_percent: Option<f64>,
}

/// The `cpu` line of `/proc/stat`: (steal, total) jiffies, or None where it cannot be read.
fn cpu_steal() -> Option<(u64, u64)> {
    let stat = std::fs::read_to_string("/proc/stat").ok()?;
    let fields: Vec<u64> = stat
        .lines()
        .next()?
        .strip_prefix("cpu ")?
        .split_whitespace()
        .map(|f| f.parse().ok())
        .collect::<Option<_>>()?;
    // user nice system idle iowait irq softirq steal (guest times are within user and nice).
    Some((*fields.get(7)?, fields.iter().take(8).sum()))
}

/// VecEnv steps per second summed over its envs (best of three timed passes after a
/// warm-up), every env following the single env's action sequence `actions` (`steps` rows of
/// `dim`), so that the workload per env step is the single env's.
fn vec_env_rate(
    v: &mut mjskill::VecEnv,
    actions: &[f32],
    dim: usize,
    steps: usize,
) -> Result<VecRate, CliError> {
    let n = v.num_envs();
    let vsteps = (steps / n).max(1);
    let mut acts = vec![0.0f32; n * dim];
    let fill = |t: usize, acts: &mut [f32]| {
        let row = &actions[(t % steps) * dim..(t % steps + 1) * dim];
        for chunk in acts.chunks_mut(dim) {
            chunk.copy_from_slice(row);
        }
    };
    v.reset(Some(0));
    for t in 0..vsteps / 10 + 1 {
        fill(t, &mut acts);
        v.step(&acts)?;
    }
    let mut best = VecRate {
        steps_per_s: 0.0,
        busy: Vec::new(),
        steal_percent: None,
    };
    for _ in 0..3 {
        v.reset(Some(0));
        let (busy0, steal0) = (v.thread_busy_seconds(), cpu_steal());
        let t0 = Instant::now();
        for t in 0..vsteps {
            fill(t, &mut acts);
            v.step(&acts)?;
        }
        let wall = t0.elapsed().as_secs_f64();
        let rate = (vsteps * n) as f64 / wall;
        if rate > best.steps_per_s {
            let busy1 = v.thread_busy_seconds();
            best = VecRate {
                steps_per_s: rate,
                busy: busy1
                    .iter()
                    .zip(&busy0)
                    .map(|(b, b0)| (b - b0) / wall)
                    .collect(),
                steal_percent: match (steal0, cpu_steal()) {
                    (Some((s0, t0)), Some((s1, t1))) if t1 > t0 => {
                        Some(100.0 * s1.saturating_sub(s0) as f64 / (t1 - t0) as f64)
                    }
                    _ => None,
                },
            };
        }
    }
    Ok(best)
}

/// Runs the benchmark. Every argument is checked (and the VecEnv built) before any timing.
pub fn run(
    env_id: &str,
    config: EnvConfig,
    steps: usize,
    vec: Option<(usize, usize)>,
    render_frames: Option<usize>,
    with_profile: bool,
) -> Result<BenchReport, CliError> {
    check_count("--steps", steps, MAX_STEPS)?;
    if let Some((n, t)) = vec {
        check_count("--envs", n, MAX_ENVS)?;
        check_count("--threads", t, MAX_THREADS)?;
    }
    if let Some(n) = render_frames {
        check_count("--render", n, MAX_RENDER)?;
    }
    let mut env = make(env_id, config.clone())?;
    // Built before timing, so that a bad VecEnv fails at once; the threads it uses (at most
    // one per env) are what the report shows.
    let mut vec_env = match vec {
        None => None,
        Some((n, t)) => Some(mjskill::VecEnv::new(env_id, config.clone(), n, t)?),
    };
    if render_frames.is_some() {
        env.render()?; // fail before timing without rendering
    }
    let dim = env.action_space().shape[0];
    let mut rng = rand::rngs::StdRng::seed_from_u64(0);
    let actions: Vec<f32> = (0..dim * steps)
        .map(|_| rng.random_range(-1.0..1.0))
        .collect();
    env.reset(Some(0));
    let start = env.get_state();
    let substeps = env.substeps();
    // Untimed pass: record the drive commands the env writes, so that raw physics can replay
    // the identical trajectory (same contacts, same solver work). The episode is not reset
    // at truncation (ManiSkill keeps stepping too), so both runs are one continuous rollout.
    let nd = env.drives().targets_len();
    let mut targets = Vec::with_capacity(nd * steps);
    for i in 0..steps {
        env.step(&actions[i * dim..(i + 1) * dim])?;
        env.drives().save_targets(&mut targets);
    }
    // Timed passes, alternating env and raw physics three times; the best of each counts.
    let (mut env_rate, mut mj_rate, mut replay_identical) = (0.0f64, 0.0f64, false);
    for _ in 0..3 {
        env.set_state(&start)?;
        let t = Instant::now();
        for i in 0..steps {
            env.step(&actions[i * dim..(i + 1) * dim])?;
        }
        env_rate = env_rate.max(steps as f64 / t.elapsed().as_secs_f64());
        let (env_qpos, env_qvel) = (env.data().qpos().to_vec(), env.data().qvel().to_vec());

        env.set_state(&start)?;
        let mut data: Data = env.data().clone();
        let mut drives = env.drives().clone();
        let t = Instant::now();
        for i in 0..steps {
            drives.load_targets(&targets[i * nd..(i + 1) * nd]);
            for _ in 0..substeps {
                drives.step(&mut data);
            }
            // As the env does after its substeps (poses for reading; normalises quaternions).
            data.update_kinematics();
        }
        mj_rate = mj_rate.max((steps * substeps) as f64 / t.elapsed().as_secs_f64());
        replay_identical = data.qpos() == env_qpos.as_slice() && data.qvel() == env_qvel.as_slice();
    }
    let phys = mj_rate / substeps as f64;
    let vec_rate = match vec_env.as_mut() {
        None => None,
        Some(v) => Some(vec_env_rate(v, &actions, dim, steps)?),
    };
    let render_rate = match render_frames {
        None => None,
        Some(n) => {
            env.set_state(&start)?;
            let zero = vec![0.0f32; dim];
            env.render()?; // warm-up (context creation)
            let mut best = 0.0f64;
            for _ in 0..3 {
                let t = Instant::now();
                for _ in 0..n {
                    // A step in between, so that every frame draws a new state.
                    env.step(&zero)?;
                    env.render()?;
                }
                let with_steps = t.elapsed().as_secs_f64();
                let t = Instant::now();
                for _ in 0..n {
                    env.step(&zero)?;
                }
                let steps_only = t.elapsed().as_secs_f64();
                best = best.max(n as f64 / (with_steps - steps_only).max(1e-9));
            }
            Some(best)
        }
    };
    let profile = match with_profile {
        true => Some(profile(&mut env, &start, &targets, steps)?),
        false => None,
    };
    let ratio = env_rate / phys;
    Ok(BenchReport {
        env: env_id.to_string(),
        robot: env.robot_id().uid().to_string(),
        control_mode: env.control_mode().to_string(),
        obs_mode: env.config().obs_mode.name().to_string(),
        steps,
        substeps: env.substeps(),
        env_steps_per_s: env_rate,
        physics_steps_per_s: phys,
        mj_step_per_s: mj_rate,
        replay_identical,
        envs: vec_env.as_ref().map(|v| v.num_envs()),
        threads: vec_env.as_ref().map(|v| v.num_threads()),
        vec_env_steps_per_s: vec_rate.as_ref().map(|r| r.steps_per_s),
        scaling: vec_rate.as_ref().map(|r| r.steps_per_s / env_rate),
        vec_thread_busy: vec_rate.as_ref().map(|r| r.busy.clone()),
        steal_percent: vec_rate.as_ref().and_then(|r| r.steal_percent),
        render_frames_per_s: render_rate,
        render_size: render_rate.map(|_| env.render_size()),
        profile,
        ratio,
        overhead_percent: (1.0 / ratio - 1.0) * 100.0,
    })
}

#[cfg(test)]
mod tests {
    use std::time::{Duration, Instant};

    #[test]
    fn a_bad_vec_env_size_fails_before_any_timing() {
        let t = Instant::now();
        let e = super::run(
            "PickCube-v1",
            Default::default(),
            100_000,
            Some((0, 1)),
            None,
            false,
        )
        .unwrap_err();
        assert!(
            e.to_string().contains("--envs") && t.elapsed() < Duration::from_secs(5),
            "{e}"
        );
    }

    #[test]
    fn the_profile_splits_a_substep_by_mujocos_stages() {
        let r = super::run("PokeCube-v1", Default::default(), 50, None, None, true).unwrap();
        let p = r.profile.expect("--profile reports a profile");
        assert!(p.substep_us > 0.0 && p.contacts > 0.0 && p.constraint_rows > 0.0);
        assert!(p.solver_iterations >= 1.0 && p.solver_iterations_max >= 1);
        // Every substep runs the position stages once, and the acceleration stage once: the
        // drives take their unconstrained acceleration from the smooth forces, without
        // MuJoCo's actuation and acceleration calls (docs/speed.md).
        for (stage, calls) in [
            ("pos_collision", 1.0),
            ("constraint", 1.0),
            ("acceleration", 1.0),
            ("actuation", 1.0),
        ] {
            let s = &p.stages[stage];
            assert_eq!(s.calls, calls, "{stage}");
            assert!(
                s.us > 0.0 && s.share > 0.0 && s.share < 1.0,
                "{stage}: {s:?}"
            );
        }
        // The top-level stages and the rest make up the substep.
        let top: f64 = [
            "position",
            "velocity",
            "actuation",
            "acceleration",
            "constraint",
        ]
        .iter()
        .map(|k| p.stages[*k].us)
        .sum();
        assert!(
            (top + p.rest_us - p.substep_us).abs() < 1e-6 * p.substep_us.max(1.0)
                || p.rest_us == 0.0
        );
        // Without --profile there is none.
        let r = super::run("PokeCube-v1", Default::default(), 5, None, None, false).unwrap();
        assert!(r.profile.is_none());
    }
}
