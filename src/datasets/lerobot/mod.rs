//! LeRobotDataset v3 export: a directory that `lerobot.datasets.LeRobotDataset` loads.
//!
//! ```text
//! meta/info.json                                   codebase_version v3.0, fps 20, robot_type, features
//! meta/stats.json                                  min / max / mean / std / count / q01 q10 q50 q90 q99 per feature
//! meta/tasks.parquet                               task (the pandas index) → task_index
//! meta/episodes/chunk-000/file-000.parquet         per episode: length, tasks, data and video locations, stats/<feature>/<stat>
//! data/chunk-000/file-000.parquet                  one row per step
//! videos/observation.images.<camera>/chunk-000/file-000.mp4   H.264, every episode one after another
//! ```
//!
//! Larger datasets continue in `file-001`, ... and `chunk-001`, ..., split by [`Limits`] as
//! LeRobot's writer splits them (episodes whole); meta/episodes says where each episode is.
//!
//! Row t of an episode holds `observation.state` (the obs before action t), `action`,
//! `next.reward`, `next.done` (true on the episode's last row), `next.success`, `timestamp`
//! (t / fps), `frame_index` (t), `episode_index`, `index` (the row's position in the dataset)
//! and `task_index`. The video frame of row t is the camera's frame before action t (a
//! recording has one frame more per episode: the one after the last step, which is left
//! out). Videos are H.264 (Constrained Baseline: no B-frames) in MP4; H.264 recordings are
//! muxed without re-encoding, PNG frames of older recordings are encoded.
use std::path::{Path, PathBuf};

use arrow_array::ArrayRef;
use arrow_schema::Field;
use serde_json::{json, Map, Value};

use super::export::{env_of, ExportSummary};
use super::DatasetError;
use crate::record::EpisodeRec;

mod meta;
mod parquet;
mod rows;
mod stats;
mod video;

use meta::EpisodesMeta;
use parquet::{names, write_split_parquet};
use rows::Rows;
pub use stats::QUANTILES;
use stats::{ImageStats, Stats};
use video::{cameras, write_video, Camera};

/// Frames per second of the dataset (ManiSkill's control frequency).
pub const FPS: u32 = 20;
/// LeRobot's format version written.
pub const CODEBASE_VERSION: &str = "v3.0";

/// LeRobot's `DEFAULT_CHUNK_SIZE`: files per `chunk-NNN` folder.
pub const DEFAULT_CHUNK_SIZE: usize = 1000;
/// LeRobot's `DEFAULT_DATA_FILE_SIZE_IN_MB` (data and meta/episodes parquet files).
pub const DEFAULT_DATA_FILE_SIZE_IN_MB: f64 = 100.0;
/// LeRobot's `DEFAULT_VIDEO_FILE_SIZE_IN_MB` (lerobot 0.4.4; 0.4.0 to 0.4.3 used 500).
pub const DEFAULT_VIDEO_FILE_SIZE_IN_MB: f64 = 200.0;

/// How a LeRobot export splits its files, as LeRobot's own writer does (info.json's
/// `chunks_size`, `data_files_size_in_mb`, `video_files_size_in_mb`). Episodes are never
/// split: an episode goes into a new file when the current file already holds episodes and
/// its size plus the episode's would reach the limit; after `chunks_size` files the next
/// file opens a new chunk folder. A megabyte is 1024² bytes, as in LeRobot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Files per chunk folder (≥ 1).
    pub chunks_size: usize,
    /// Size limit of data and meta/episodes parquet files in MB (> 0; fractions allowed).
    pub data_files_size_in_mb: f64,
    /// Size limit of video files in MB (> 0; fractions allowed).
    pub video_files_size_in_mb: f64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            chunks_size: DEFAULT_CHUNK_SIZE,
            data_files_size_in_mb: DEFAULT_DATA_FILE_SIZE_IN_MB,
            video_files_size_in_mb: DEFAULT_VIDEO_FILE_SIZE_IN_MB,
        }
    }
}

impl Limits {
    /// An error naming the first bad limit.
    pub fn validate(&self) -> Result<(), DatasetError> {
        let bad = |name: &str, v: String, valid: &str| -> Result<(), DatasetError> {
            Err(DatasetError::Invalid {
                msg: format!("{name} {v} is invalid; valid: {valid}"),
            })
        };
        if self.chunks_size == 0 {
            return bad("chunks_size", "0".into(), "an integer >= 1");
        }
        for (name, v) in [
            ("data_files_size_in_mb", self.data_files_size_in_mb),
            ("video_files_size_in_mb", self.video_files_size_in_mb),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return bad(name, v.to_string(), "a number of megabytes > 0");
            }
        }
        Ok(())
    }
}

/// Bytes per megabyte (LeRobot's `get_file_size_in_mb` divides by 1024²).
const MB: f64 = 1024.0 * 1024.0;

/// The (chunk, file) after `at` (LeRobot's `update_chunk_file_indices`).
fn next_file(at: (usize, usize), chunks_size: usize) -> (usize, usize) {
    if at.1 + 1 >= chunks_size {
        (at.0 + 1, 0)
    } else {
        (at.0, at.1 + 1)
    }
}

/// `<prefix>/chunk-CCC/file-FFF.<ext>`.
fn chunk_file(prefix: &str, at: (usize, usize), ext: &str) -> String {
    format!("{prefix}/chunk-{:03}/file-{:03}.{ext}", at.0, at.1)
}

/// A JSON number: an integer when whole (info.json's sizes as LeRobot writes them).
fn mb_json(v: f64) -> Value {
    if v.fract() == 0.0 && v.abs() < 1e15 {
        json!(v as i64)
    } else {
        json!(v)
    }
}

/// The task description of an env (ManiSkill's own wording), stored in `meta/tasks.parquet`.
pub fn task_description(env_id: &str) -> String {
    match env_id {
        "PickCube-v1" | "PickCubeSO100-v1" | "PickCubeWidowXAI-v1" => {
            "Grasp the red cube and move it to the goal position.".into()
        }
        "PokeCube-v1" => "Grasp the peg and push the cube with it into the goal region.".into(),
        "PlaceSphere-v1" => "Pick up the sphere and place it in the bin.".into(),
        "PushCube-v1" => "Push the cube to the goal region in front of it.".into(),
        "PullCube-v1" => "Pull the cube onto the target.".into(),
        "StackCube-v1" => "Pick up the red cube and stack it on top of the green cube.".into(),
        "LiftPegUpright-v1" => "Stand the peg lying on the table upright.".into(),
        "PushT-v1" => "Precisely push the T-shaped block into the target region.".into(),
        other => other.to_string(),
    }
}

/// Exports the finished episodes of the recording `path` as a LeRobotDataset v3 in `dir`
/// (which must not exist, or be empty). `video`: `Some(true)` requires camera frames,
/// `Some(false)` leaves them out, `None` exports whatever cameras the recording has. Files
/// are split by LeRobot's default [`Limits`].
pub fn write(path: &Path, dir: &Path, video: Option<bool>) -> Result<ExportSummary, DatasetError> {
    write_with_limits(path, dir, video, &Limits::default())
}

/// [`write()`], splitting data, video and meta/episodes files by `limits`.
pub fn write_with_limits(
    path: &Path,
    dir: &Path,
    video: Option<bool>,
    limits: &Limits,
) -> Result<ExportSummary, DatasetError> {
    limits.validate()?;
    check_output_dir(dir)?;
    let (rec, _) = super::export::read_recording(path)?;
    let cams = recording_cameras(path, video)?;
    let env = env_of(path, &rec)?;
    let m = &rec.meta;
    let episodes: Vec<&EpisodeRec> = rec.finished().collect();
    if episodes.is_empty() {
        return Err(DatasetError::format(
            path,
            "has no finished episode to export",
        ));
    }
    let obs_dim = episodes[0].initial_obs.len();
    let act_dim = m.action_space.low.len();
    let rows = Rows::of(&episodes, obs_dim, act_dim);
    let mut features = rows.features(obs_names(m, obs_dim), act_names(&env, act_dim));
    let aerr = |source| DatasetError::Arrow {
        path: dir.to_path_buf(),
        source,
    };
    let data = rows.batch().map_err(aerr)?;
    // Statistics of the whole dataset (meta/stats.json) and of every episode (the
    // `stats/<feature>/<stat>` columns of meta/episodes, from which LeRobot's
    // delete_episodes / split_dataset rebuild stats.json).
    let mut stats = Map::new();
    let mut ep_stats: Vec<(String, Vec<Stats>)> = Vec::new();
    for (name, values, dim) in &rows.stat_columns() {
        stats.insert((*name).into(), Stats::of_rows(values, *dim).to_json());
        let per_episode = rows.episodes.iter();
        let per_episode = per_episode.map(|(a, b)| Stats::of_rows(&values[a * dim..b * dim], *dim));
        ep_stats.push(((*name).into(), per_episode.collect()));
    }

    // Write everything under a temporary directory.
    // The temporary directory replaces an empty `dir` on commit (rename(2) does that).
    let mut staged = super::Staged::default();
    let tmp = staged.add(dir);
    std::fs::create_dir_all(&tmp).map_err(DatasetError::io(dir))?;
    let data_limits = (limits.data_files_size_in_mb, limits.chunks_size);
    let ep_rows = &rows.episodes;
    let data_at = write_split_parquet(
        &tmp,
        dir,
        "data",
        ep_rows.len(),
        |k| ep_rows[k].1 - ep_rows[k].0,
        |k, _| Ok(data.slice(ep_rows[k].0, ep_rows[k].1 - ep_rows[k].0)),
        data_limits,
        true,
    )?;
    let mut videos = Vec::new();
    let mut video_cols: Vec<(Field, ArrayRef)> = Vec::new();
    for cam in &cams {
        let key = format!("observation.images.{}", cam.name);
        let prefix = format!("videos/{key}");
        let video_limits = (limits.video_files_size_in_mb, limits.chunks_size);
        let v = write_video(&tmp, dir, &prefix, cam, &episodes, video_limits)?;
        let mut total = ImageStats::default();
        for st in &v.stats {
            total.merge(st);
        }
        features.insert(key.clone(), v.feature());
        stats.insert(key.clone(), total.stats().to_json());
        ep_stats.push((key.clone(), v.stats.iter().map(ImageStats::stats).collect()));
        video_cols.extend(v.episode_columns(&key));
        videos.push((cam.name.clone(), rows.len()));
    }
    let task = task_description(&m.env_id);
    let episodes_meta = EpisodesMeta {
        task: &task,
        rows: &rows.episodes,
        data_at: &data_at,
        video_cols,
        stats: &ep_stats,
    };
    meta::write_episodes(&tmp, dir, episodes_meta, data_limits)?;
    meta::write_tasks(&tmp, dir, &task)?;

    let n = episodes.len();
    let info = json!({
        "codebase_version": CODEBASE_VERSION,
        "robot_type": m.robot,
        "total_episodes": n,
        "total_frames": rows.len(),
        "total_tasks": 1,
        "chunks_size": limits.chunks_size,
        "data_files_size_in_mb": mb_json(limits.data_files_size_in_mb),
        "video_files_size_in_mb": mb_json(limits.video_files_size_in_mb),
        "fps": FPS,
        "splits": {"train": format!("0:{n}")},
        "data_path": "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet",
        "video_path": if cams.is_empty() { Value::Null } else {
            json!("videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4")
        },
        "features": features,
        "mjskill": {"env_id": m.env_id, "control_mode": m.control_mode, "obs_mode": m.obs_mode,
                    "reward_mode": m.reward_mode, "source": path.display().to_string()}
    });
    let write_json = |rel: &str, v: &Value| -> Result<(), DatasetError> {
        let text = serde_json::to_string_pretty(v).expect("json serializes");
        std::fs::write(tmp.join(rel), text).map_err(DatasetError::io(&dir.join(rel)))
    };
    write_json("meta/info.json", &info)?;
    write_json("meta/stats.json", &Value::Object(stats))?;
    staged.commit()?;
    Ok(ExportSummary {
        file: path.display().to_string(),
        format: "lerobot",
        outputs: vec![dir.display().to_string()],
        episodes: n,
        steps: rows.len(),
        videos,
    })
}

/// An error unless `dir` is missing or an empty directory.
fn check_output_dir(dir: &Path) -> Result<(), DatasetError> {
    if dir.exists() {
        let empty = dir.is_dir()
            && std::fs::read_dir(dir)
                .map_err(DatasetError::io(dir))?
                .next()
                .is_none();
        if !empty {
            return Err(DatasetError::Invalid {
                msg: format!(
                    "{}: exists and is not an empty directory; choose another -o or remove it",
                    dir.display()
                ),
            });
        }
    }
    Ok(())
}

/// The cameras of the recording `path` to export (`video`: as [`write()`]'s).
fn recording_cameras(path: &Path, video: Option<bool>) -> Result<Vec<Camera>, DatasetError> {
    let raw = crate::record::read_raw(path)?;
    if video == Some(false) {
        return Ok(Vec::new());
    }
    let cams = cameras(path, &raw.messages)?;
    if video == Some(true) && cams.is_empty() {
        return Err(DatasetError::Invalid {
            msg: format!(
                "{}: the recording has no camera frames, so there is no video to export; record \
                 with `mjskill rollout --video` (or --camera base_camera --obs-mode rgb), or \
                 pass --video no",
                path.display()
            ),
        });
    }
    Ok(cams)
}

/// The observation's component names (`<slice>_<i>` from the layout; `state_<i>` when the
/// layout does not cover the observation).
fn obs_names(m: &crate::record::Meta, obs_dim: usize) -> Vec<String> {
    let mut obs_names = Vec::new();
    for sl in &m.obs_layout {
        obs_names.extend(names(&sl.name, sl.end - sl.start));
    }
    if obs_names.len() != obs_dim {
        obs_names = names("state", obs_dim);
    }
    obs_names
}

/// The action's component names (`<part>_<i>` of the controller's parts; `action_<i>` when
/// they do not cover the action).
fn act_names(env: &crate::env::Env, act_dim: usize) -> Vec<String> {
    let mut act_names = Vec::new();
    for p in env.action_parts() {
        act_names.extend(names(p.name, p.range.len()));
    }
    if act_names.len() != act_dim {
        act_names = names("action", act_dim);
    }
    act_names
}

/// The directory layout's relative paths written for a dataset with these cameras (for
/// tests and documentation).
pub fn layout(cameras: &[&str]) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = [
        "meta/info.json",
        "meta/stats.json",
        "meta/tasks.parquet",
        "meta/episodes/chunk-000/file-000.parquet",
        "data/chunk-000/file-000.parquet",
    ]
    .iter()
    .map(PathBuf::from)
    .collect();
    for c in cameras {
        v.push(PathBuf::from(format!(
            "videos/observation.images.{c}/chunk-000/file-000.mp4"
        )));
    }
    v
}
