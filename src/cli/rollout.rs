//! `mjskill rollout`, `mjskill info` and `mjskill replay`: recorded rollouts in MCAP files.
use std::path::Path;
use std::time::Instant;

use serde::Serialize;

use crate::env::{EnvConfig, ObsMode, RewardMode};
use crate::record::image::write_png;
use crate::record::{read, Recorder, Recording};
use crate::solvers::make_policy;

/// The one-line JSON summary of a rollout.
#[derive(Debug, Clone, Serialize)]
pub struct RolloutSummary {
    /// Output file.
    pub out: String,
    /// Env id.
    pub env: String,
    /// Robot uid.
    pub robot: String,
    /// Control mode.
    pub control_mode: String,
    /// Policy.
    pub policy: String,
    /// Episodes recorded.
    pub episodes: usize,
    /// Episodes that succeeded at some step.
    pub successes: usize,
    /// Mean return.
    pub mean_return: f64,
    /// Env steps recorded.
    pub steps: u64,
    /// Env steps per second, recording included.
    pub steps_per_s: f64,
    /// PNG of the human render camera at the end of the first episode, written next to the
    /// recording (None when rendering is unavailable; the reason goes to stderr).
    pub frame: Option<String>,
    /// Human-camera frames recorded on `/render_camera/image` (with `--video`).
    pub video_frames: u64,
}

/// What `rollout` runs.
#[derive(Debug, Clone)]
pub struct RolloutArgs {
    /// Env id.
    pub env: String,
    /// Env configuration (robot and modes).
    pub config: EnvConfig,
    /// Policy name.
    pub policy: String,
    /// Episodes.
    pub episodes: usize,
    /// Seed of the first episode (episode k uses seed + k).
    pub seed: u64,
    /// Output file.
    pub out: std::path::PathBuf,
    /// Show a progress bar (on a terminal).
    pub progress: bool,
    /// Record the human render camera's frames (`/render_camera/image`, PNG).
    pub video: bool,
    /// Write the first episode's last human-camera frame next to `out` ([`frame_path`]).
    pub frame: bool,
}

/// The PNG written next to a recording: `rollout.mcap` → `rollout.png`.
pub fn frame_path(out: &Path) -> std::path::PathBuf {
    out.with_extension("png")
}

/// Records `episodes` seeded episodes; each finished episode is synced to disk before the next
/// begins.
pub fn rollout(a: &RolloutArgs) -> Result<RolloutSummary, String> {
    // Fail on an unwritable path before any simulation.
    std::fs::File::create(&a.out).map_err(|e| format!("cannot write {}: {e}", a.out.display()))?;
    let mut env = super::eval::make_env(&a.env, a.config.clone(), &a.policy)?;
    let mut policy = make_policy(&a.policy, &env, a.seed)?;
    let mut rec = Recorder::create(&a.out, &env).map_err(|e| e.to_string())?;
    let (render_w, render_h) = env.render_size();
    let camera = env.cameras().1.name;
    if a.video {
        // Fail before simulating when rendering is unavailable.
        env.render().map_err(|e| e.to_string())?;
        rec.enable_video(camera).map_err(|e| e.to_string())?;
    }
    let mut frame = None;
    let bar = if a.progress {
        indicatif::ProgressBar::new(a.episodes as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{bar:40} {pos}/{len} episodes {msg} [{elapsed} < {eta}]",
        )
        .map_err(|e| e.to_string())?,
    );
    let mut action = vec![0.0f32; env.action_space().shape[0]];
    let (mut successes, mut total_return, mut steps) = (0usize, 0.0f64, 0u64);
    let t0 = Instant::now();
    for k in 0..a.episodes as u64 {
        let seed = a.seed + k;
        env.reset(Some(seed));
        policy.reset(&env);
        rec.begin_episode(&env, Some(seed))
            .map_err(|e| e.to_string())?;
        if a.video {
            let rgb = env.render().map_err(|e| e.to_string())?;
            rec.record_frame(rgb, render_w, render_h)
                .map_err(|e| e.to_string())?;
        }
        let (mut ret, mut success) = (0.0f64, false);
        loop {
            policy.act(&env, &mut action);
            let before = env.get_state();
            let (reward, terminated, truncated) = {
                let s = env.step(&action).map_err(|e| e.to_string())?;
                (s.reward, s.terminated, s.truncated)
            };
            rec.record_step(&env, &action, reward, terminated, truncated, &before)
                .map_err(|e| e.to_string())?;
            if a.video {
                let rgb = env.render().map_err(|e| e.to_string())?;
                rec.record_frame(rgb, render_w, render_h)
                    .map_err(|e| e.to_string())?;
            }
            ret += reward as f64;
            success |= terminated;
            steps += 1;
            if truncated {
                break;
            }
        }
        rec.end_episode(success).map_err(|e| e.to_string())?;
        if k == 0 && a.frame {
            let path = frame_path(&a.out);
            match env.render() {
                Ok(rgb) => {
                    write_png(&path, rgb, render_w, render_h)?;
                    frame = Some(path.display().to_string());
                }
                Err(e) => bar.suspend(|| eprintln!("note: no {} written: {e}", path.display())),
            }
        }
        successes += success as usize;
        total_return += ret;
        bar.set_message(format!("{successes} successes"));
        bar.inc(1);
    }
    let video_frames = rec.frames();
    rec.finish().map_err(|e| e.to_string())?;
    bar.finish_and_clear();
    Ok(RolloutSummary {
        out: a.out.display().to_string(),
        env: a.env.clone(),
        robot: env.robot_spec().uid.to_string(),
        control_mode: env.control_mode().to_string(),
        policy: a.policy.clone(),
        episodes: a.episodes,
        successes,
        mean_return: total_return / a.episodes.max(1) as f64,
        steps,
        steps_per_s: steps as f64 / t0.elapsed().as_secs_f64(),
        frame,
        video_frames,
    })
}

/// `mjskill info`: a summary of a recording.
#[derive(Debug, Clone, Serialize)]
pub struct InfoSummary {
    /// File.
    pub file: String,
    /// Env id.
    pub env: String,
    /// Robot uid.
    pub robot: String,
    /// Control mode.
    pub control_mode: String,
    /// Observation mode.
    pub obs_mode: String,
    /// Reward mode.
    pub reward_mode: String,
    /// mjskill version that wrote it.
    pub version: String,
    /// Finished episodes.
    pub episodes: usize,
    /// Successful finished episodes.
    pub successes: usize,
    /// Steps of the finished episodes.
    pub steps: usize,
    /// Mean return of the finished episodes.
    pub mean_return: f64,
    /// Whether the file was closed properly (false: the rollout was cut short).
    pub complete: bool,
    /// Steps of an episode that was cut short, if any.
    pub unfinished_steps: Option<usize>,
}

/// Reads and summarises a recording.
pub fn info(path: &Path) -> Result<InfoSummary, String> {
    let r = read(path).map_err(|e| e.to_string())?;
    let fin: Vec<_> = r.finished().collect();
    Ok(InfoSummary {
        file: path.display().to_string(),
        env: r.meta.env_id.clone(),
        robot: r.meta.robot.clone(),
        control_mode: r.meta.control_mode.clone(),
        obs_mode: r.meta.obs_mode.clone(),
        reward_mode: r.meta.reward_mode.clone(),
        version: r.meta.version.clone(),
        episodes: fin.len(),
        successes: fin.iter().filter(|e| e.success).count(),
        steps: fin.iter().map(|e| e.steps.len()).sum(),
        mean_return: if fin.is_empty() {
            0.0 // not the -0.0 an empty f64 sum gives
        } else {
            fin.iter().map(|e| e.ret).sum::<f64>() / fin.len() as f64
        },
        complete: r.complete,
        unfinished_steps: r
            .episodes
            .iter()
            .find(|e| !e.finished)
            .map(|e| e.steps.len()),
    })
}

/// Largest deviations found by `replay`.
#[derive(Debug, Clone, Default, Serialize)]
pub struct ReplayReport {
    /// File.
    pub file: String,
    /// Episodes re-simulated.
    pub episodes: usize,
    /// Steps compared.
    pub steps: usize,
    /// Largest |Δ| of an observation entry (initial observations included).
    pub max_obs_dev: f64,
    /// Largest |Δ| of a reward.
    pub max_reward_dev: f64,
    /// Largest |Δ| of an info value.
    pub max_info_dev: f64,
    /// Steps whose terminated or truncated flag differs.
    pub flag_mismatches: usize,
    /// The tolerance applied.
    pub tolerance: f64,
    /// Whether every deviation is within the tolerance and every flag matches.
    pub ok: bool,
}

fn max_dev(a: &[f32], b: &[f32]) -> f64 {
    if a.len() != b.len() {
        return f64::INFINITY;
    }
    a.iter()
        .zip(b)
        .map(|(x, y)| (*x as f64 - *y as f64).abs())
        .fold(0.0, f64::max)
}

/// Re-simulates every finished episode of a recording from its seed and recorded actions.
pub fn replay_recording(
    path: &Path,
    r: &Recording,
    tolerance: f64,
) -> Result<ReplayReport, String> {
    let m = &r.meta;
    let config = EnvConfig {
        robot: Some(m.robot.clone()),
        obs_mode: ObsMode::parse(&m.obs_mode).map_err(|e| e.to_string())?,
        reward_mode: RewardMode::parse(&m.reward_mode).map_err(|e| e.to_string())?,
        control_mode: Some(m.control_mode.clone()),
        robot_init_qpos_noise: m.robot_init_qpos_noise,
        max_episode_steps: Some(m.max_episode_steps),
        sim: m.sim(),
    };
    let mut env = crate::env::make(&m.env_id, config).map_err(|e| e.to_string())?;
    let mut rep = ReplayReport {
        file: path.display().to_string(),
        tolerance,
        ..Default::default()
    };
    for ep in r.finished() {
        match ep.seed {
            Some(s) => {
                env.reset(Some(s));
            }
            None => env
                .set_state(&ep.initial_state)
                .map_err(|e| e.to_string())?,
        }
        rep.max_obs_dev = rep.max_obs_dev.max(max_dev(env.obs(), &ep.initial_obs));
        for st in &ep.steps {
            let s = env
                .step(&st.action)
                .map_err(|e| format!("episode {}: {e}", ep.index))?;
            rep.max_obs_dev = rep.max_obs_dev.max(max_dev(s.obs, &st.obs));
            rep.max_reward_dev = rep
                .max_reward_dev
                .max((s.reward as f64 - st.reward as f64).abs());
            rep.flag_mismatches +=
                usize::from(s.terminated != st.terminated || s.truncated != st.truncated);
            for (k, v) in &st.info {
                let now = if k == "elapsed_steps" {
                    Some(s.info.elapsed_steps as f64)
                } else {
                    s.info.get(k)
                };
                let dev = now.map_or(f64::INFINITY, |n| (n - v).abs());
                rep.max_info_dev = rep.max_info_dev.max(dev);
            }
            rep.steps += 1;
        }
        rep.episodes += 1;
    }
    rep.ok = rep.max_obs_dev <= tolerance
        && rep.max_reward_dev <= tolerance
        && rep.max_info_dev <= tolerance
        && rep.flag_mismatches == 0;
    Ok(rep)
}

/// `mjskill replay`: reads the file and re-simulates it.
pub fn replay(path: &Path, tolerance: f64) -> Result<ReplayReport, String> {
    let r = read(path).map_err(|e| e.to_string())?;
    if r.finished().next().is_none() {
        return Err(format!("{}: no finished episode to replay", path.display()));
    }
    replay_recording(path, &r, tolerance)
}
