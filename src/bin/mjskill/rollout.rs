//! `mjskill rollout`, `mjskill info` and `mjskill replay`: recorded rollouts in MCAP files.
use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use super::output::Output;
use crate::CliError;
use mjskill::record::image::write_png;
use mjskill::record::RecordError;
use mjskill::record::{stream, EpisodeEnd, EpisodeStart, Recorder, StepRec, Visitor};
use mjskill::solvers::{check_seed_range, ActionNoise, EvalError, Policy, PolicySpec};
use mjskill::{Env, EnvConfig};

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
    /// Camera frames recorded (H.264, `/render_camera/video` with `--video` and
    /// `/<camera>/video` with `--camera`), all cameras together.
    pub video_frames: u64,
    /// With `--action-noise`: the σ of every action entry (absent without).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub action_noise: Option<Vec<f32>>,
    /// With `--action-noise`: the noise seed (absent without).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub noise_seed: Option<u64>,
}

/// What `rollout` runs.
#[derive(Debug, Clone)]
pub struct RolloutArgs {
    /// Env id.
    pub env: String,
    /// Env configuration (robot and modes).
    pub config: EnvConfig,
    /// The policy.
    pub policy: PolicySpec,
    /// Episodes.
    pub episodes: usize,
    /// Seed of the first episode (episode k uses seed + k).
    pub seed: u64,
    /// Output file.
    pub out: std::path::PathBuf,
    /// Show a progress bar (on a terminal).
    pub progress: bool,
    /// Record the human render camera's frames (`/render_camera/video`, H.264).
    pub video: bool,
    /// Also record these sensor cameras' colour frames (`/<camera>/video`, H.264); they need a
    /// visual obs mode with colour (`rgb`, `rgbd`).
    pub cameras: Vec<String>,
    /// Write the first episode's last human-camera frame next to `out` ([`frame_path`]).
    pub frame: bool,
    /// `--action-noise SPEC` and `--noise-seed`: execute the policy's action plus this noise
    /// and record the policy's own action as each step's label ([`ActionNoise`]).
    pub noise: Option<(String, u64)>,
}

/// The PNG written next to a recording: `rollout.mcap` → `rollout.png`.
pub fn frame_path(out: &Path) -> std::path::PathBuf {
    out.with_extension("png")
}

/// Where the frame PNG of a rollout goes, checked before anything is written: `None` with
/// `--no-frame`. Errors: the PNG would be the recording itself, or cannot be written (a
/// directory, a read-only file).
pub fn check_frame_path(out: &Path, frame: bool) -> Result<Option<PathBuf>, CliError> {
    if !frame {
        return Ok(None);
    }
    let png = frame_path(out);
    if png == out {
        return Err(format!(
            "--out {}: the PNG of the first episode's last frame is written next to the \
             recording with the extension .png, which would overwrite the recording itself; \
             name the recording e.g. {} or pass --no-frame",
            out.display(),
            out.with_extension("mcap").display()
        )
        .into());
    }
    if png.is_dir() {
        return Err(format!(
            "cannot write the frame PNG {}: it is a directory; pass --no-frame or another --out",
            png.display()
        )
        .into());
    }
    if png.exists() {
        std::fs::OpenOptions::new()
            .write(true)
            .open(&png)
            .map_err(|e| {
                format!(
                    "cannot write the frame PNG {}: {e}; pass --no-frame or another --out",
                    png.display()
                )
            })?;
    }
    Ok(Some(png))
}

/// Records `episodes` seeded episodes; each finished episode is synced to disk before the next
/// begins. Every argument is checked before any file is created; the recording is written
/// under a temporary name next to `out` and takes its final name once its first episode is
/// finished (see [`super::output`]), so a failed run never leaves an empty or partial file
/// under `out`, and a run killed later keeps its finished episodes there.
pub fn rollout(a: &RolloutArgs) -> Result<RolloutSummary, CliError> {
    check_seed_range(a.seed, a.episodes as u64)?;
    if (a.video || !a.cameras.is_empty()) && !cfg!(feature = "video") {
        return Err(
            "--video and --camera record H.264 video, which needs mjskill's `video` \
                    feature; this build leaves it out (build with the default features, or \
                    add `--features video`)"
                .into(),
        );
    }
    let mut env = a.policy.make_env(&a.env, a.config.clone())?;
    let mut policy = a.policy.make_policy(&env, a.seed)?;
    let mut noise = match &a.noise {
        Some((spec, seed)) => Some(ActionNoise::parse(spec, &env, *seed)?),
        None => None,
    };
    let frame_png = check_frame_path(&a.out, a.frame)?;
    let (render_w, render_h) = env.render_size();
    let camera = env.cameras().1.name;
    if a.video {
        // Fail before creating anything when rendering is unavailable.
        env.render()?;
    }
    check_cameras(&env, &a.cameras)?;
    let (mut output, file) = Output::start(&a.out)?;
    if let Some(png) = &frame_png {
        if let Err(e) = mjskill::files::check_not_special(png) {
            output.discard();
            return Err(format!("cannot write the frame PNG: {e}; pass --no-frame").into());
        }
    }
    let command = command_line(without_out(std::env::args().skip(1)));
    let mut rec =
        match Recorder::from_file_with_command(file, output.current(), &env, Some(&command)) {
            Ok(r) => r,
            Err(e) => {
                output.discard();
                return Err(e.into());
            }
        };
    let mut run = Run {
        successes: 0,
        total_return: 0.0,
        steps: 0,
        frame: None,
        episode: 0,
    };
    let t0 = Instant::now();
    // A panic (a bug) must not leave a file that claims to be complete: it ends the run like
    // an error, and the finished episodes are kept as for a run cut short.
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        record_all(
            a,
            &mut env,
            (policy.as_mut(), noise.as_mut()),
            &mut rec,
            &mut output,
            &mut run,
            camera,
            (render_w, render_h),
            frame_png.as_deref(),
        )
    }))
    .unwrap_or_else(|p| {
        let msg = p
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        Err(format!(
            "the rollout crashed in episode {} (seed {}): {msg}",
            run.episode,
            a.seed + run.episode
        )
        .into())
    });
    if let Err(e) = r {
        // Keep what was finished (the file then reads as cut short), or nothing at all.
        let abandoned = rec.abandon();
        if output.published() {
            abandoned.map_err(|a| format!("{e}; and: {a}"))?;
        } else {
            output.discard();
        }
        return Err(e);
    }
    let video_frames = rec.frames();
    rec.finish()?;
    Ok(RolloutSummary {
        out: a.out.display().to_string(),
        env: a.env.clone(),
        robot: env.robot_id().uid().to_string(),
        control_mode: env.control_mode().to_string(),
        policy: a.policy.name(),
        episodes: a.episodes,
        successes: run.successes,
        mean_return: run.total_return / a.episodes.max(1) as f64,
        steps: run.steps,
        steps_per_s: run.steps as f64 / t0.elapsed().as_secs_f64(),
        frame: run.frame,
        video_frames,
        action_noise: noise.as_ref().map(|n| n.sigma().to_vec()),
        noise_seed: noise.as_ref().map(|n| n.seed()),
    })
}

/// Checks that every `--camera` names a sensor camera with colour images in this env's obs
/// mode.
fn check_cameras(env: &Env, cameras: &[String]) -> Result<(), CliError> {
    for c in cameras {
        match env.image(c) {
            Some(img) if img.rgb.is_some() => {}
            Some(_) => {
                return Err(format!(
                    "--camera {c}: obs mode {} renders no colour; use --obs-mode rgb or rgbd",
                    env.config().obs_mode.name()
                )
                .into())
            }
            None if env.config().obs_mode.is_visual() => {
                return Err(format!(
                    "--camera {c}: no such sensor camera; valid: {}",
                    env.sensor_names().join(", ")
                )
                .into())
            }
            None => {
                return Err(format!(
                    "--camera {c}: sensor cameras render only in a visual obs mode; use \
                     --obs-mode rgb or rgbd (cameras: {})",
                    env.sensor_names().join(", ")
                )
                .into())
            }
        }
    }
    Ok(())
}

/// Records the current frame of every `--camera`.
fn record_sensors(
    env: &Env,
    rec: &mut Recorder,
    cameras: &[String],
    ids: &[usize],
) -> Result<(), CliError> {
    for (c, &id) in cameras.iter().zip(ids) {
        let img = env
            .image(c)
            .ok_or_else(|| format!("camera {c} has no image"))?;
        let rgb = img
            .rgb
            .ok_or_else(|| format!("camera {c} has no colour image"))?;
        rec.record_camera_frame(id, rgb, img.width, img.height)?;
    }
    Ok(())
}

/// Totals of a rollout.
struct Run {
    successes: usize,
    total_return: f64,
    steps: u64,
    frame: Option<String>,
    /// The episode being recorded (0 is the first).
    episode: u64,
}

#[allow(clippy::too_many_arguments)]
fn record_all(
    a: &RolloutArgs,
    env: &mut Env,
    (policy, mut noise): (&mut dyn Policy, Option<&mut ActionNoise>),
    rec: &mut Recorder,
    output: &mut Output,
    run: &mut Run,
    camera: &str,
    (render_w, render_h): (usize, usize),
    frame_png: Option<&Path>,
) -> Result<(), CliError> {
    if a.video {
        rec.enable_video(camera)?;
    }
    let sensors: Vec<usize> = a
        .cameras
        .iter()
        .map(|c| rec.enable_video(c))
        .collect::<Result<_, _>>()?;
    let bar = if a.progress {
        indicatif::ProgressBar::new(a.episodes as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    bar.set_style(indicatif::ProgressStyle::with_template(
        "{bar:40} {pos}/{len} episodes {msg} [{elapsed} < {eta}]",
    )?);
    let mut action = vec![0.0f32; env.action_space().shape[0]];
    // With noise: the policy's own action (the label); `action` is then the executed one.
    let mut label = action.clone();
    for k in 0..a.episodes as u64 {
        let seed = a.seed + k;
        run.episode = k;
        env.try_reset(Some(seed))?;
        policy.reset(env);
        if let Some(n) = noise.as_deref_mut() {
            n.reset(seed);
        }
        rec.begin_episode(env, Some(seed))?;
        if a.video {
            let rgb = env.render()?;
            rec.record_frame(rgb, render_w, render_h)?;
        }
        record_sensors(env, rec, &a.cameras, &sensors)?;
        let (mut ret, mut success) = (0.0f64, false);
        loop {
            let stepped = match noise.as_deref_mut() {
                None => {
                    policy.try_act(env, &mut action)?;
                    rec.step(env, &action)
                }
                Some(n) => {
                    policy.try_act(env, &mut label)?;
                    n.apply(&label, &mut action);
                    rec.step_labelled(env, &action, &label)
                }
            };
            let (reward, terminated, truncated) = stepped.map_err(|e| match e {
                // A rejected action reads as the env's own error, naming the policy.
                RecordError::Env { source, .. } => EvalError::Env(source)
                    .in_episode(&a.policy, k, seed)
                    .to_string(),
                e => e.to_string(),
            })?;
            if a.video {
                let rgb = env.render()?;
                rec.record_frame(rgb, render_w, render_h)?;
            }
            record_sensors(env, rec, &a.cameras, &sensors)?;
            ret += reward as f64;
            success |= terminated;
            run.steps += 1;
            if truncated {
                break;
            }
        }
        rec.end_episode(success)?;
        if k == 0 {
            output.publish()?;
            rec.renamed(output.current());
            if let Some(path) = frame_png {
                // A side output never stops the recording: a failure is a warning.
                match env.render() {
                    Ok(rgb) => match write_png(path, rgb, render_w, render_h) {
                        Ok(()) => run.frame = Some(path.display().to_string()),
                        Err(e) => bar.suspend(|| eprintln!("warning: {e}; recording goes on")),
                    },
                    Err(e) => bar.suspend(|| eprintln!("note: no {} written: {e}", path.display())),
                }
            }
        }
        run.successes += success as usize;
        run.total_return += ret;
        bar.set_message(format!("{} successes", run.successes));
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(())
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
    /// With `--salvage`: the damage where reading stopped (what precedes it is summarised).
    pub damage: Option<String>,
}

/// Counts what `info` reports, episode by episode, and checks every recorded state as
/// `set_state` would ([`Env::check_state`], in an env made from the file's metadata), so that
/// a recording whose states could not be restored is refused, naming the episode, step and
/// value. (A file whose env cannot be made here, say of another mjskill version, is counted
/// without that check: `mjskill replay` says why it cannot be made.)
#[derive(Default)]
struct Count {
    episodes: usize,
    successes: usize,
    steps: usize,
    returns: f64,
    /// Steps of the episode begun last, while it is open.
    open: Option<usize>,
    /// The env of the file's metadata, which checks the recorded states.
    env: Option<Env>,
}

impl Count {
    fn check(
        &self,
        what: impl FnOnce() -> String,
        state: &mjskill::EnvState,
    ) -> Result<(), String> {
        match &self.env {
            Some(env) => env
                .check_state(state)
                .map_err(|e| format!("{}: {e}", what())),
            None => Ok(()),
        }
    }
}

impl Visitor for Count {
    fn meta(&mut self, m: &mjskill::record::Meta) -> Result<(), mjskill::record::BoxError> {
        self.env = m
            .config()
            .ok()
            .and_then(|c| mjskill::make(&m.env_id, c).ok());
        Ok(())
    }
    fn episode_start(&mut self, s: EpisodeStart) -> Result<(), mjskill::record::BoxError> {
        self.check(
            || format!("episode {}, its initial state", s.index),
            &s.state,
        )?;
        self.open = Some(0);
        Ok(())
    }
    fn step(
        &mut self,
        episode: u64,
        index: u32,
        st: StepRec,
    ) -> Result<(), mjskill::record::BoxError> {
        self.check(
            || format!("episode {episode}, the state before step {index}"),
            &st.state,
        )?;
        if let Some(n) = self.open.as_mut() {
            *n += 1;
        }
        Ok(())
    }
    fn episode_end(&mut self, end: EpisodeEnd) -> Result<(), mjskill::record::BoxError> {
        self.open = None;
        self.episodes += 1;
        self.successes += end.success as usize;
        self.steps += end.steps as usize;
        self.returns += end.ret;
        Ok(())
    }
}

/// Reads and summarises a recording, streaming (memory bounded by one chunk). A damaged file
/// is an error naming the byte offset and chunk; with `salvage`, what precedes the damage is
/// summarised and the damage reported in [`InfoSummary::damage`].
pub fn info(path: &Path, salvage: bool) -> Result<InfoSummary, CliError> {
    let mut c = Count::default();
    let end = stream(path, salvage, &mut c)?;
    let m = end.meta;
    Ok(InfoSummary {
        file: path.display().to_string(),
        env: m.env_id,
        robot: m.robot,
        control_mode: m.control_mode,
        obs_mode: m.obs_mode,
        reward_mode: m.reward_mode,
        version: m.version,
        episodes: c.episodes,
        successes: c.successes,
        steps: c.steps,
        mean_return: if c.episodes == 0 {
            0.0 // not the -0.0 an empty f64 sum gives
        } else {
            c.returns / c.episodes as f64
        },
        complete: end.complete,
        unfinished_steps: c.open,
        damage: end.damage.map(|e| e.to_string()),
    })
}

/// `args` without `--out FILE` (or `--out=FILE`): the same command writes the same bytes to
/// any file.
fn without_out(args: impl Iterator<Item = String>) -> impl Iterator<Item = String> {
    let mut skip_next = false;
    args.filter(move |a| {
        if std::mem::take(&mut skip_next) {
            return false;
        }
        if a == "--out" {
            skip_next = true;
            return false;
        }
        !a.starts_with("--out=")
    })
}

/// The command line `args` (without the program) as `mjskill ARGS`, each argument quoted for
/// a POSIX shell where it needs it: what a recording's metadata keeps as its `command`.
pub fn command_line(args: impl Iterator<Item = String>) -> String {
    let quote = |a: String| {
        let plain = !a.is_empty()
            && a.chars()
                .all(|c| c.is_ascii_alphanumeric() || "_./=:,+-@%".contains(c));
        if plain {
            a
        } else {
            format!("'{}'", a.replace('\'', "'\\''"))
        }
    };
    std::iter::once("mjskill".to_string())
        .chain(args.map(quote))
        .collect::<Vec<_>>()
        .join(" ")
}
