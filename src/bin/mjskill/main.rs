//! The `mjskill` command line (`mjskill --help`), built on the library's public API. Its
//! modules are the binary's own: argument parsing, output files, and the commands that are
//! not library API (bench, plots). The mesh-authoring tools are the `mjskill-meshes` binary.
use std::io::Write;
use std::path::{Path, PathBuf};

use clap::{Parser, Subcommand};

#[macro_use]
#[path = "../shared/cli.rs"]
mod cli;
use cli::emit;

/// The command line's errors: any error of the library (or a message), printed with its
/// `Display` text.
pub(crate) type CliError = Box<dyn std::error::Error + Send + Sync>;

mod args;
mod bench;
mod compare_images;
mod datasets;
mod fidelity;
mod info_dir;
mod output;
mod plot;
mod render;
mod rollout;

/// mjskill: ManiSkill3 tabletop tasks on MuJoCo 2.2.
#[derive(Debug, Parser)]
#[command(name = "mjskill", version, about, long_about = None)]
pub struct Cli {
    /// The command to run.
    #[command(subcommand)]
    pub command: Command,
}

/// Which env, robot and control mode a command runs.
#[derive(Debug, Clone, clap::Args)]
pub struct EnvArgs {
    /// Env id (default: a policy file's, else PickCube-v1).
    #[arg(long)]
    pub env: Option<String>,
    /// Robot uid (default: a policy file's, else the env's default robot).
    #[arg(long)]
    pub robot: Option<String>,
    /// Control mode (default: the policy's if it needs one, else the robot's default).
    #[arg(long)]
    pub control_mode: Option<String>,
    /// Physics steps per second (ManiSkill's sim_freq); a multiple of the 20 Hz control
    /// frequency. Higher is slower and closer to continuous-time dynamics.
    #[arg(long, default_value_t = mjskill::SimConfig::DEFAULT_SIM_FREQ)]
    pub sim_freq: u32,
    /// Who takes the physics steps in which the gripper pinches the object: mujoco, or
    /// physx_tgs (a replica of PhysX's step; so100 and panda; experimental, docs/physics.md).
    #[arg(long, default_value = "mujoco", value_parser = pinch_solver)]
    pub pinch_solver: mjskill::PinchSolver,
}

/// Parses `--pinch-solver`.
fn pinch_solver(s: &str) -> Result<mjskill::PinchSolver, String> {
    mjskill::PinchSolver::parse(s).map_err(|e| e.to_string())
}

impl EnvArgs {
    /// The env id: `--env` or [`mjskill::solvers::DEFAULT_ENV`].
    pub fn env_id(&self) -> &str {
        self.env.as_deref().unwrap_or(mjskill::solvers::DEFAULT_ENV)
    }

    /// The env configuration (other fields at their defaults).
    pub fn config(&self) -> mjskill::EnvConfig {
        mjskill::EnvConfig {
            robot: self.robot.clone(),
            control_mode: self.control_mode.clone(),
            sim: mjskill::SimConfig {
                sim_freq: self.sim_freq,
                pinch_solver: self.pinch_solver,
            },
            ..Default::default()
        }
    }
}

/// mjskill's commands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Write the complete generated MuJoCo scene (MJCF) of a robot, or of a task with a robot.
    ExportMjcf {
        /// Robot uid (panda, panda_stick, panda_wristcam, fetch, xarm6_robotiq, so100, widowxai; default: the
        /// env's default robot, or panda without --env).
        #[arg(long)]
        robot: Option<String>,
        /// Env id whose scene to export (e.g. PickCube-v1); without it, the table scene and the robot.
        #[arg(long)]
        env: Option<String>,
        /// Output file (default: standard output).
        #[arg(short = 'o', long = "output")]
        output: Option<PathBuf>,
    },
    /// Measure env steps/s against raw MuJoCo stepping of the same model; prints one JSON line.
    Bench {
        /// Env, robot and control mode.
        #[command(flatten)]
        target: EnvArgs,
        /// Env steps to time (1..=1000000; after a warm-up of a tenth as many).
        #[arg(long, default_value_t = 2000, value_parser = args::bench_steps, allow_hyphen_values = true)]
        steps: usize,
        /// Also time a VecEnv of this many envs (1..=256; reports vec_env_steps_per_s and
        /// scaling).
        #[arg(long, value_parser = args::envs, allow_hyphen_values = true)]
        envs: Option<usize>,
        /// VecEnv threads, the calling thread included (1..=256, at most one per env; default:
        /// available cores). The report gives the number used.
        #[arg(long, value_parser = args::threads, allow_hyphen_values = true)]
        threads: Option<usize>,
        /// Observation mode: state, state_dict, none, rgb, depth, segmentation, their +
        /// combinations (rgb+depth+segmentation), rgbd or pointcloud (the visual modes render
        /// the 128x128 sensor camera, and Fetch its two robot cameras, every step).
        #[arg(long, default_value = "state")]
        obs_mode: String,
        /// Also time this many human-camera frames (1..=100000; Env::render, 512x512):
        /// render_frames_per_s.
        #[arg(long, value_parser = args::render_frames, allow_hyphen_values = true)]
        render: Option<usize>,
        /// Also replay the physics once more with MuJoCo's stage timers on (`mjData.timer`)
        /// and report where a substep's time goes: `profile` (docs/speed.md).
        #[arg(long)]
        profile: bool,
    },
    /// Run a policy over seeded episodes; prints success rate and mean return (JSON).
    Eval {
        /// Env, robot and control mode.
        #[command(flatten)]
        target: EnvArgs,
        /// Policy: solver, expert (the state expert, docs/solvers.md §8.2), random, zero, or a
        /// policy file (FILE.onnx, docs/training.md), whose env, robot and modes are the
        /// defaults.
        #[arg(long, default_value = "solver")]
        policy: String,
        /// Episodes (seeds seed, seed+1, ...; the last must be a 32-bit seed).
        #[arg(long, default_value_t = 100, value_parser = args::episodes, allow_hyphen_values = true)]
        episodes: usize,
        /// First seed (0..=4294967295: ManiSkill's seeds are 32-bit).
        #[arg(long, default_value_t = 0, value_parser = args::seed, allow_hyphen_values = true)]
        seed: u64,
    },
    /// Record seeded episodes of a policy to an MCAP file; prints a JSON summary. With no
    /// arguments: PickCube-v1, panda, the scripted solver, 10 episodes, rollout.mcap.
    Rollout {
        /// Env, robot and control mode.
        #[command(flatten)]
        target: EnvArgs,
        /// Observation mode: state, state_dict, none, rgb, depth, segmentation, their +
        /// combinations (rgb+depth+segmentation), rgbd or pointcloud (default: a policy
        /// file's, else state).
        #[arg(long)]
        obs_mode: Option<String>,
        /// Reward mode: normalized_dense, dense, sparse or none.
        #[arg(long, default_value = "normalized_dense")]
        reward_mode: String,
        /// Policy: solver, expert (the state expert, docs/solvers.md §8.2), random, zero, or a
        /// policy file (FILE.onnx, docs/training.md), whose env, robot and modes are the
        /// defaults.
        #[arg(long, default_value = "solver")]
        policy: String,
        /// Episodes (1 or more; the last seed must be a 32-bit seed).
        #[arg(long, default_value_t = 10, value_parser = args::episodes, allow_hyphen_values = true)]
        episodes: usize,
        /// Seed of the first episode (episode k uses seed + k; 0..=4294967295).
        #[arg(long, default_value_t = 0, value_parser = args::seed, allow_hyphen_values = true)]
        seed: u64,
        /// Output MCAP file, written under a temporary name next to it and moved into place
        /// once the first episode is finished (an existing file is replaced only then). The
        /// human camera's view at the end of the first episode is written next to it as PNG
        /// (rollout.mcap → rollout.png) when rendering is available.
        #[arg(long, default_value = "rollout.mcap")]
        out: PathBuf,
        /// Also record the human render camera's frames (512x512, H.264) on
        /// /render_camera/video (foxglove.CompressedVideo).
        #[arg(long)]
        video: bool,
        /// Also record a sensor camera's colour frames (H.264) on /<camera>/video
        /// (foxglove.CompressedVideo); repeatable. Needs an obs mode with colour (rgb, rgbd,
        /// rgb+..., pointcloud; cameras:
        /// base_camera; Fetch also fetch_head, fetch_hand).
        #[arg(long = "camera")]
        cameras: Vec<String>,
        /// Do not write the PNG of the first episode's last frame next to the recording.
        #[arg(long)]
        no_frame: bool,
        /// Noise-injected demonstrations (DART): the env executes the policy's action plus
        /// seeded Gaussian noise, clipped to the action space, and every step records the
        /// policy's own action as its expert_action. SPEC: one σ for every action entry
        /// (0.05), one per action part of the control mode (arm=0.02,gripper=0: every part
        /// named), or one per action entry (0.02,0.02,0.02,0).
        #[arg(long, value_name = "SPEC", allow_hyphen_values = true)]
        action_noise: Option<String>,
        /// Seed of --action-noise's noise (0..=4294967295); each episode's noise also depends
        /// on its reset seed.
        #[arg(long, default_value_t = 0, requires = "action_noise", value_parser = args::seed, allow_hyphen_values = true)]
        noise_seed: u64,
    },
    /// Summarise a recording or a directory of recordings (JSON); says whether it was cut short. A damaged file (a CRC or
    /// structure check fails) is an error naming the byte offset and chunk.
    Info {
        /// The .mcap file, or a directory of .mcap shards summarised as one dataset (with
        /// each shard's summary under "shards").
        file: PathBuf,
        /// Summarise what precedes damage instead of failing (the damage is reported).
        #[arg(long)]
        salvage: bool,
    },
    /// Re-simulate every episode of a recording from its seed and actions and compare each
    /// step; prints the largest deviations (JSON) and fails beyond the tolerance.
    Replay {
        /// The .mcap file.
        file: PathBuf,
        /// Largest allowed absolute deviation of observations, rewards and info values (a
        /// finite number ≥ 0).
        #[arg(long, default_value_t = 1e-6, value_parser = args::tolerance, allow_hyphen_values = true)]
        tolerance: f64,
        /// Replay the episodes that precede damage instead of failing (the damage is reported).
        #[arg(long)]
        salvage: bool,
    },
    /// Replay a ManiSkill reference trajectory file (`<env>__<robot>.json.gz`) in mjskill, or
    /// an mjskill recording (`.mcap`) with the given physics settings, and print the per-step
    /// deviations of joints, TCP, objects, rewards and flags (JSON).
    Fidelity {
        /// The reference file (.json.gz) or recording (.mcap).
        file: PathBuf,
        /// Re-import the reference state every K steps (1: one-step errors only).
        #[arg(long)]
        resync: Option<u32>,
        /// Physics steps per second of the replaying env.
        #[arg(long, default_value_t = mjskill::SimConfig::DEFAULT_SIM_FREQ)]
        sim_freq: u32,
        /// Only the episodes of this control mode.
        #[arg(long)]
        control_mode: Option<String>,
        /// Leave out the per-step arrays (per-episode and per-bucket summaries only).
        #[arg(long)]
        summary: bool,
        /// Draw the error curves (joint, TCP, object error against the step) to this PNG.
        #[arg(long)]
        plot: Option<PathBuf>,
    },
    /// Replay the fixed action sequences of outcome files (tests/data/outcomes, written by
    /// examples/maniskill_outcomes.py with ManiSkill) in mjskill and count how often the
    /// outcome and the per-step flags agree with ManiSkill's: one JSON line per file, or a
    /// Markdown table (docs/outcome-agreement.md).
    Outcomes {
        /// An outcome file (.json.gz) or a directory of them.
        path: PathBuf,
        /// Replay only the first N episodes of every file (1..=4294967296).
        #[arg(long, value_parser = args::episodes, allow_hyphen_values = true)]
        episodes: Option<usize>,
        /// Physics steps per second of the replaying env.
        #[arg(long, default_value_t = mjskill::SimConfig::DEFAULT_SIM_FREQ)]
        sim_freq: u32,
        /// Who takes the replaying env's pinched physics steps: mujoco, or physx_tgs (a
        /// replica of PhysX's step; robots with convex gripper parts only, docs/physics.md).
        #[arg(long, default_value = "mujoco", value_parser = pinch_solver)]
        pinch_solver: mjskill::PinchSolver,
        /// Include every episode's result.
        #[arg(long)]
        per_episode: bool,
        /// Print a Markdown table instead of JSON.
        #[arg(long)]
        table: bool,
    },
    /// Replay ManiSkill demos (trajectory.h5 + .json) in mjskill, by actions (open loop from
    /// each episode's seed) or by states (importing every env_states row), record them to
    /// MCAP and print per-episode success and divergence (JSON).
    ImportManiskill {
        /// ManiSkill's trajectory.h5.
        h5: PathBuf,
        /// Its json (default: the h5 path with extension .json).
        #[arg(long)]
        json: Option<PathBuf>,
        /// Output MCAP file (written under a temporary name, moved into place when complete).
        #[arg(long)]
        out: PathBuf,
        /// What the recording replays: actions or states (both are reported).
        #[arg(long, default_value = "actions")]
        by: String,
        /// Physics steps per second of the replaying env.
        #[arg(long, default_value_t = mjskill::SimConfig::DEFAULT_SIM_FREQ)]
        sim_freq: u32,
    },
    /// Export a recording's finished episodes to ManiSkill's trajectory format (h5 + json)
    /// or to a LeRobotDataset v3 directory; prints a JSON summary.
    Export {
        /// The .mcap recording.
        file: PathBuf,
        /// maniskill or lerobot.
        #[arg(long)]
        format: String,
        /// Output: the .h5 (maniskill; the json goes next to it) or the dataset directory
        /// (lerobot; must not exist or be empty). Default: next to the recording.
        #[arg(short = 'o', long = "output")]
        output: Option<PathBuf>,
        /// The json of --format maniskill (default: the h5 path with extension .json).
        #[arg(long)]
        json: Option<PathBuf>,
        /// LeRobot videos: yes (fail if the recording has no camera frames), no, or by
        /// default whatever frames the recording has.
        #[arg(long, value_parser = clap::builder::BoolishValueParser::new())]
        video: Option<bool>,
        /// --format maniskill: write the actions in this control mode. pd_joint_pos writes
        /// every step's joint targets as mjskill's controller set them (e.g. the IK solution
        /// of an EE mode), so that ManiSkill replays them even where it cannot build the
        /// recording's mode (Fetch's EE modes). Default: the recording's own mode.
        #[arg(long)]
        control_mode: Option<String>,
        // --format lerobot: how files are split.
        #[command(flatten)]
        limits: datasets::LimitArgs,
    },
    /// List the registered envs with their robots, control modes, observation and reward modes (JSON).
    Envs,
    /// Print this build's version and the Cargo features it was built with (JSON), so that a
    /// script or test can tell what the binary can do before asking it.
    Features,
    /// Compare mjskill's sensor camera images with ManiSkill's for the same states: loads
    /// each reference state dict, renders rgb+depth+segmentation and prints (one JSON line)
    /// per pair and overall: segmentation mean IoU and pixel accuracy, median depth error
    /// (mm), mean absolute colour difference. See docs/observations.md.
    CompareImages(compare_images::CompareArgs),
    /// Render one camera frame of a seeded initial state to a PNG file (headless, EGL);
    /// prints a JSON summary.
    Render {
        /// Env, robot and control mode.
        #[command(flatten)]
        target: EnvArgs,
        /// Reset seed (0..=4294967295).
        #[arg(long, default_value_t = 0, value_parser = args::seed, allow_hyphen_values = true)]
        seed: u64,
        /// Camera: the human render camera (render_camera, 512x512), the sensor camera
        /// (base_camera, 128x128) or a robot camera (Fetch: fetch_head, fetch_hand).
        #[arg(long, default_value = "render_camera")]
        camera: String,
        /// Output PNG file.
        #[arg(short = 'o', long = "output", default_value = "frame.png")]
        output: PathBuf,
    },
}

fn main() {
    std::process::exit(run_cli());
}

/// Runs the command line; returns the process exit code.
fn run_cli() -> i32 {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => 0,
        Err(e) => {
            eprintln!("error: {e}");
            2
        }
    }
}

fn run(cli: Cli) -> Result<(), CliError> {
    match cli.command {
        Command::ExportMjcf { robot, env, output } => {
            export_mjcf(robot.as_deref(), env.as_deref(), output)
        }
        Command::Bench {
            target,
            steps,
            envs,
            threads,
            obs_mode,
            render,
            profile,
        } => bench_command(target, steps, envs, threads, &obs_mode, render, profile),
        Command::Eval {
            target,
            policy,
            episodes,
            seed,
        } => {
            let policy = mjskill::solvers::PolicySpec::parse(&policy)?;
            let (env, config) = policy.target(target.env.as_deref(), target.config(), false)?;
            let report = mjskill::solvers::evaluate_spec(&env, config, &policy, episodes, seed)?;
            out!("{}", serde_json::to_string(&report)?);
            Ok(())
        }
        Command::Rollout {
            target,
            obs_mode,
            reward_mode,
            policy,
            episodes,
            seed,
            out,
            video,
            cameras,
            no_frame,
            action_noise,
            noise_seed,
        } => rollout_command(
            target,
            (obs_mode, reward_mode),
            (&policy, action_noise, noise_seed),
            episodes,
            seed,
            out,
            (video, cameras, !no_frame),
        ),
        Command::Info { file, salvage } if file.is_dir() => {
            let s = info_dir::info_dir(&file, salvage)?;
            out!("{}", serde_json::to_string(&s)?);
            Ok(())
        }
        Command::Info { file, salvage } => {
            let s = rollout::info(&file, salvage)?;
            out!("{}", serde_json::to_string(&s)?);
            Ok(())
        }
        Command::Replay {
            file,
            tolerance,
            salvage,
        } => replay_command(&file, tolerance, salvage),
        cmd @ (Command::ImportManiskill { .. } | Command::Export { .. }) => datasets_command(cmd),
        Command::Render {
            target,
            seed,
            camera,
            output,
        } => {
            let s = render::run(target.env_id(), target.config(), seed, &camera, &output)?;
            out!("{}", serde_json::to_string(&s)?);
            Ok(())
        }
        Command::CompareImages(args) => {
            out!("{}", serde_json::to_string(&compare_images::run(&args)?)?);
            Ok(())
        }
        Command::Fidelity {
            file,
            resync,
            sim_freq,
            control_mode,
            summary,
            plot,
        } => fidelity::run(&fidelity::FidelityArgs {
            file,
            resync,
            sim: mjskill::SimConfig {
                sim_freq,
                ..Default::default()
            },
            control_mode,
            summary,
            plot,
        }),
        Command::Outcomes {
            path,
            episodes,
            sim_freq,
            pinch_solver,
            per_episode,
            table,
        } => outcomes(&path, episodes, sim_freq, pinch_solver, per_episode, table),
        Command::Envs => {
            out!("{}", serde_json::to_string_pretty(&mjskill::registry())?);
            Ok(())
        }
        Command::Features => {
            let report = serde_json::json!({
                "version": env!("CARGO_PKG_VERSION"),
                "features": built_features(),
            });
            out!("{report}");
            Ok(())
        }
    }
}

/// The optional Cargo features this binary was built with (docs/rust-api.md#features).
fn built_features() -> Vec<&'static str> {
    [
        ("cli", cfg!(feature = "cli")),
        ("datasets", cfg!(feature = "datasets")),
        ("onnx", cfg!(feature = "onnx")),
        ("video", cfg!(feature = "video")),
        ("mesh-tools", cfg!(feature = "mesh-tools")),
    ]
    .into_iter()
    .filter_map(|(name, on)| on.then_some(name))
    .collect()
}

/// `mjskill bench`: times the env (a VecEnv with `--envs`/`--threads`) and prints the report.
fn bench_command(
    target: EnvArgs,
    steps: usize,
    envs: Option<usize>,
    threads: Option<usize>,
    obs_mode: &str,
    render: Option<usize>,
    profile: bool,
) -> Result<(), CliError> {
    let cores = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1);
    let vec = match (envs, threads) {
        (None, None) => None,
        (n, t) => Some((n.unwrap_or(2 * cores), t.unwrap_or(cores))),
    };
    let config = mjskill::EnvConfig {
        obs_mode: mjskill::ObsMode::parse(obs_mode)?,
        ..target.config()
    };
    let report = bench::run(target.env_id(), config, steps, vec, render, profile)?;
    out!("{}", serde_json::to_string(&report)?);
    Ok(())
}

/// `mjskill rollout`: records `episodes` episodes of `policy` (with `--action-noise` and
/// `--noise-seed`) from `seed` on into `out`, with `--obs-mode` and `--reward-mode`, and
/// `--video`, `--camera`s and whether to frame the video.
fn rollout_command(
    target: EnvArgs,
    (obs_mode, reward_mode): (Option<String>, String),
    (policy, action_noise, noise_seed): (&str, Option<String>, u64),
    episodes: usize,
    seed: u64,
    out: PathBuf,
    (video, cameras, frame): (bool, Vec<String>, bool),
) -> Result<(), CliError> {
    use std::io::IsTerminal;
    let config = mjskill::EnvConfig {
        obs_mode: mjskill::ObsMode::parse(obs_mode.as_deref().unwrap_or("state"))?,
        reward_mode: mjskill::RewardMode::parse(&reward_mode)?,
        ..target.config()
    };
    let policy = mjskill::solvers::PolicySpec::parse(policy)?;
    let (env, config) = policy.target(target.env.as_deref(), config, obs_mode.is_some())?;
    let args = rollout::RolloutArgs {
        env,
        config,
        policy,
        episodes,
        seed,
        out,
        progress: std::io::stderr().is_terminal(),
        video,
        cameras,
        frame,
        noise: action_noise.map(|spec| (spec, noise_seed)),
    };
    let summary = rollout::rollout(&args)?;
    out!("{}", serde_json::to_string(&summary)?);
    Ok(())
}

/// `mjskill replay`: re-simulates a recording and prints the report; an error when it
/// deviates beyond `tolerance`.
fn replay_command(file: &Path, tolerance: f64, salvage: bool) -> Result<(), CliError> {
    let r = mjskill::record::replay::replay(file, tolerance, salvage)?;
    out!("{}", serde_json::to_string(&r)?);
    if r.ok {
        Ok(())
    } else {
        Err(format!(
            "{}: replay deviates beyond the tolerance {tolerance}",
            file.display()
        )
        .into())
    }
}

/// `mjskill import-maniskill` and `mjskill export`.
#[cfg(feature = "datasets")]
fn datasets_command(cmd: Command) -> Result<(), CliError> {
    match cmd {
        Command::ImportManiskill {
            h5,
            json,
            out,
            by,
            sim_freq,
        } => {
            let r = datasets::import_maniskill(&h5, json.as_deref(), &out, &by, sim_freq)?;
            out!("{}", serde_json::to_string(&r)?);
        }
        Command::Export {
            file,
            format,
            output,
            json,
            video,
            control_mode,
            limits,
        } => {
            let r = datasets::export(
                &file,
                &format,
                output,
                json.as_deref(),
                video,
                control_mode.as_deref(),
                limits,
            )?;
            out!("{}", serde_json::to_string(&r)?);
        }
        _ => unreachable!("called for import-maniskill and export"),
    }
    Ok(())
}

/// Without the `datasets` feature, `import-maniskill` and `export` are an error naming it.
#[cfg(not(feature = "datasets"))]
fn datasets_command(cmd: Command) -> Result<(), CliError> {
    let command = match cmd {
        Command::ImportManiskill { .. } => "import-maniskill",
        _ => "export",
    };
    Err(format!(
        "`mjskill {command}` needs mjskill's `datasets` feature, which this build leaves out \
         (build with the default features, or add `--features datasets`)"
    )
    .into())
}

fn write_output(output: Option<PathBuf>, text: &str) -> Result<(), CliError> {
    match output {
        Some(path) => std::fs::write(&path, text)
            .map_err(|e| format!("cannot write {}: {e}", path.display()))?,
        None => std::io::stdout()
            .write_all(text.as_bytes())
            .map_err(|e| format!("cannot write to stdout: {e}"))?,
    }
    Ok(())
}

fn export_mjcf(
    robot: Option<&str>,
    env: Option<&str>,
    output: Option<PathBuf>,
) -> Result<(), CliError> {
    let mjcf = match env {
        None => mjskill::robot_scene_mjcf(robot.unwrap_or("panda"))?,
        Some(id) => {
            // As rollout does: without --robot, the env's own default robot.
            let robot = match robot {
                Some(r) => r,
                None => mjskill::default_robot(id)?,
            };
            mjskill::scene_mjcf(id, robot)?
        }
    };
    // Meshes and textures live in MuJoCo's in-memory VFS; with -o they are written next to the
    // XML so the file loads. Printed to stdout, the XML comes alone: nothing is written into
    // the working directory unasked.
    match (&output, mjcf.assets.is_empty()) {
        (Some(path), false) => {
            let dir = path
                .parent()
                .map(|d| d.to_path_buf())
                .unwrap_or_else(|| PathBuf::from("."));
            for (name, bytes) in &mjcf.assets {
                std::fs::write(dir.join(name), bytes)
                    .map_err(|e| format!("cannot write asset {name}: {e}"))?;
            }
        }
        (None, false) => eprintln!(
            "note: the scene references {} mesh and texture files, not written when the XML \
             goes to stdout; use -o FILE.xml to write them next to it",
            mjcf.assets.len()
        ),
        _ => {}
    }
    write_output(output, &mjcf.xml)
}

/// `mjskill outcomes`: replays every outcome file under `path` and prints the agreement.
fn outcomes(
    path: &std::path::Path,
    episodes: Option<usize>,
    sim_freq: u32,
    pinch_solver: mjskill::PinchSolver,
    per_episode: bool,
    table: bool,
) -> Result<(), CliError> {
    use mjskill::maniskill::outcome::{files, measure, OutcomeFile};
    let sim = mjskill::SimConfig {
        sim_freq,
        pinch_solver,
    };
    sim.validate()?;
    let paths = files(path)?;
    if paths.is_empty() {
        return Err(format!("{} holds no outcome files (*.json.gz)", path.display()).into());
    }
    if table {
        out!("| source | env | robot | control mode | episodes | ManiSkill successes | mjskill successes | same outcome | steps with all flags equal | per flag: steps equal |");
        out!("|---|---|---|---|---|---|---|---|---|---|");
    }
    for p in paths {
        let f = OutcomeFile::open(&p)?;
        let mut r = measure(&f, &p, episodes, sim)?;
        if table {
            let flags: Vec<String> = r
                .flags
                .iter()
                .map(|(k, a)| format!("{k} {}/{}", a.agree, a.steps))
                .collect();
            out!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {}/{} | {} |",
                r.source,
                r.env_id,
                r.robot,
                r.control_mode,
                r.episodes,
                r.maniskill_successes,
                r.mjskill_successes,
                r.same_outcome,
                r.steps_all_flags_agree,
                r.steps,
                flags.join(", ")
            );
        } else {
            if !per_episode {
                r.per_episode.clear();
            }
            out!("{}", serde_json::to_string(&r)?);
        }
    }
    Ok(())
}
