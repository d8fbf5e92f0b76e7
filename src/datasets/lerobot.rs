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
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow_array::builder::{ListBuilder, StringBuilder};
use arrow_array::{
    ArrayRef, BooleanArray, FixedSizeListArray, Float32Array, Float64Array, Int64Array, RecordBatch,
};
use arrow_schema::{DataType, Field, Schema};
use serde_json::{json, Map, Value};

use super::export::{env_of, ExportSummary};
use super::DatasetError;
use crate::record::video::{is_idr, H264Encoder};
use crate::record::{EpisodeRec, RawMessage, VIDEO_FPS};

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
        other => other.to_string(),
    }
}

/// One camera's frames in a recording.
struct Camera {
    /// Name (`render_camera`, `base_camera`, ...).
    name: String,
    /// `h264` or `png`.
    format: String,
    /// Per episode index: the frames, in order.
    frames: BTreeMap<u64, Vec<Vec<u8>>>,
}

/// The cameras of a recording: `foxglove.CompressedVideo` (H.264) and, from recordings made
/// before video, `foxglove.CompressedImage` (PNG) messages, grouped by episode.
fn cameras(path: &Path, messages: &[RawMessage]) -> Result<Vec<Camera>, DatasetError> {
    use base64::Engine;
    let mut cams: Vec<Camera> = Vec::new();
    let mut episode: Option<u64> = None;
    for m in messages {
        if m.topic == crate::record::TOPIC_EPISODE {
            let v: Value = serde_json::from_slice(&m.data)
                .map_err(|e| DatasetError::format(path, format!("/episode: {e}")))?;
            episode = v["episode"].as_u64();
            continue;
        }
        if m.schema != "foxglove.CompressedVideo" && m.schema != "foxglove.CompressedImage" {
            continue;
        }
        let bad = |msg: String| DatasetError::format(path, format!("{}: {msg}", m.topic));
        let v: Value = serde_json::from_slice(&m.data).map_err(|e| bad(e.to_string()))?;
        let name = v["frame_id"]
            .as_str()
            .ok_or_else(|| bad("no frame_id".into()))?;
        let format = v["format"]
            .as_str()
            .ok_or_else(|| bad("no format".into()))?;
        if !matches!(format, "h264" | "png") {
            return Err(bad(format!(
                "frame format {format:?} cannot be exported; valid: h264, png"
            )));
        }
        let data = base64::engine::general_purpose::STANDARD
            .decode(v["data"].as_str().ok_or_else(|| bad("no data".into()))?)
            .map_err(|e| bad(format!("data is not base64: {e}")))?;
        let ep = episode.ok_or_else(|| bad("a frame before the first episode".into()))?;
        let i = match cams.iter().position(|c| c.name == name) {
            Some(i) => i,
            None => {
                cams.push(Camera {
                    name: name.to_string(),
                    format: format.to_string(),
                    frames: BTreeMap::new(),
                });
                cams.len() - 1
            }
        };
        if cams[i].format != format {
            return Err(bad(format!(
                "camera {name} mixes {} and {format} frames",
                cams[i].format
            )));
        }
        cams[i].frames.entry(ep).or_default().push(data);
    }
    Ok(cams)
}

/// The quantiles LeRobot stores with every feature's statistics (its `q01` ... `q99`).
pub const QUANTILES: [(&str, f64); 5] = [
    ("q01", 0.01),
    ("q10", 0.10),
    ("q50", 0.50),
    ("q90", 0.90),
    ("q99", 0.99),
];

/// Statistics of one feature over a set of rows: `min`, `max`, `mean`, `std` (population),
/// the [`QUANTILES`] (linear interpolation between order statistics, numpy's default) per
/// component, and `count` (rows, or frames for images).
#[derive(Debug, Clone)]
struct Stats {
    /// Image statistics: per channel, stored with shape (3, 1, 1) as LeRobot's.
    image: bool,
    /// (name, per-component values), in LeRobot's order.
    entries: Vec<(&'static str, Vec<f64>)>,
    count: u64,
}

/// The `q`-quantile of sorted values (numpy's linear method).
fn quantile(sorted: &[f64], q: f64) -> f64 {
    let pos = q * (sorted.len().max(1) - 1) as f64;
    let lo = pos.floor() as usize;
    let hi = (lo + 1).min(sorted.len().saturating_sub(1));
    let f = pos - lo as f64;
    sorted.get(lo).map_or(0.0, |a| a + (sorted[hi] - a) * f)
}

impl Stats {
    /// Statistics of the rows of a (rows × dim) matrix.
    fn of_rows(values: &[f64], dim: usize) -> Stats {
        let dim = dim.max(1);
        let rows = values.len() / dim;
        let n = rows.max(1) as f64;
        let mut names: Vec<(&'static str, Vec<f64>)> = ["min", "max", "mean", "std"]
            .iter()
            .chain(QUANTILES.iter().map(|(q, _)| q))
            .map(|k| (*k, Vec::with_capacity(dim)))
            .collect();
        let mut column = Vec::with_capacity(rows);
        for j in 0..dim {
            column.clear();
            column.extend(values.iter().skip(j).step_by(dim).copied());
            let mean = column.iter().sum::<f64>() / n;
            let var = column.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n;
            column.sort_by(f64::total_cmp);
            let mut v = vec![
                column.first().copied().unwrap_or(0.0),
                column.last().copied().unwrap_or(0.0),
                mean,
                var.sqrt(),
            ];
            v.extend(QUANTILES.iter().map(|(_, q)| quantile(&column, *q)));
            for (e, x) in names.iter_mut().zip(v) {
                e.1.push(x);
            }
        }
        Stats {
            image: false,
            entries: names,
            count: rows as u64,
        }
    }

    /// `{"min": [...], ..., "count": [n]}` (images: every value as `[[x]]`).
    fn to_json(&self) -> Value {
        let mut m = Map::new();
        for (k, v) in &self.entries {
            let v = if self.image {
                json!(v.iter().map(|x| json!([[x]])).collect::<Vec<_>>())
            } else {
                json!(v)
            };
            m.insert((*k).into(), v);
            if *k == "std" {
                m.insert("count".into(), json!([self.count]));
            }
        }
        Value::Object(m)
    }
}

/// Running per-channel statistics of RGB frames (values scaled to 0..1, as LeRobot's): a
/// histogram of the 256 levels per channel, from which every statistic is exact.
#[derive(Clone)]
struct ImageStats {
    hist: Vec<[u64; 256]>,
    pixels: u64,
    frames: u64,
}

impl Default for ImageStats {
    fn default() -> Self {
        ImageStats {
            hist: vec![[0; 256]; 3],
            pixels: 0,
            frames: 0,
        }
    }
}

impl ImageStats {
    fn add(&mut self, rgb: &[u8]) {
        for px in rgb.chunks_exact(3) {
            for (c, &p) in px.iter().enumerate() {
                self.hist[c][p as usize] += 1;
            }
        }
        self.pixels += (rgb.len() / 3) as u64;
        self.frames += 1;
    }

    fn merge(&mut self, o: &ImageStats) {
        for (h, oh) in self.hist.iter_mut().zip(&o.hist) {
            for (a, b) in h.iter_mut().zip(oh) {
                *a += b;
            }
        }
        self.pixels += o.pixels;
        self.frames += o.frames;
    }

    /// The value of rank `k` (0-based) of channel `c`.
    fn ranked(&self, c: usize, k: u64) -> f64 {
        let mut seen = 0;
        for (level, &n) in self.hist[c].iter().enumerate() {
            seen += n;
            if seen > k {
                return level as f64 / 255.0;
            }
        }
        1.0
    }

    fn stats(&self) -> Stats {
        let n = self.pixels.max(1) as f64;
        let moment = |c: usize, f: &dyn Fn(f64) -> f64| -> f64 {
            self.hist[c]
                .iter()
                .enumerate()
                .map(|(level, &k)| k as f64 * f(level as f64 / 255.0))
                .sum::<f64>()
                / n
        };
        let mean: Vec<f64> = (0..3).map(|c| moment(c, &|v| v)).collect();
        let std: Vec<f64> = (0..3)
            .map(|c| moment(c, &|v| (v - mean[c]) * (v - mean[c])).sqrt())
            .collect();
        let last = self.pixels.saturating_sub(1);
        let quant = |q: f64| -> Vec<f64> {
            (0..3)
                .map(|c| {
                    let pos = q * last as f64;
                    let lo = pos.floor() as u64;
                    let a = self.ranked(c, lo);
                    a + (self.ranked(c, (lo + 1).min(last)) - a) * (pos - lo as f64)
                })
                .collect()
        };
        let mut entries = vec![
            ("min", quant(0.0)),
            ("max", quant(1.0)),
            ("mean", mean),
            ("std", std),
        ];
        entries.extend(QUANTILES.iter().map(|(k, q)| (*k, quant(*q))));
        Stats {
            image: true,
            entries,
            count: self.frames,
        }
    }
}

/// The per-episode columns of one feature's statistics, in LeRobot's order (`min`, `max`,
/// `mean`, `std`, `count`, quantiles): lists of float64 (images: 3 × [[x]], shape (3, 1, 1)),
/// `count` a list of one int64.
fn stats_columns(per_episode: &[Stats]) -> Vec<(&'static str, ArrayRef)> {
    use arrow_array::builder::{Float64Builder, Int64Builder};
    let Some(first) = per_episode.first() else {
        return Vec::new();
    };
    let mut out: Vec<(&'static str, ArrayRef)> = Vec::new();
    for (i, (name, _)) in first.entries.iter().enumerate() {
        let col: ArrayRef = if first.image {
            let mut b = ListBuilder::new(ListBuilder::new(ListBuilder::new(Float64Builder::new())));
            for st in per_episode {
                for &x in &st.entries[i].1 {
                    b.values().values().values().append_value(x);
                    b.values().values().append(true);
                    b.values().append(true);
                }
                b.append(true);
            }
            Arc::new(b.finish())
        } else {
            let mut b = ListBuilder::new(Float64Builder::new());
            for st in per_episode {
                b.values().append_slice(&st.entries[i].1);
                b.append(true);
            }
            Arc::new(b.finish())
        };
        out.push((name, col));
        if *name == "std" {
            let mut b = ListBuilder::new(Int64Builder::new());
            for st in per_episode {
                b.values().append_value(st.count as i64);
                b.append(true);
            }
            out.push(("count", Arc::new(b.finish())));
        }
    }
    out
}

fn names(prefix: &str, n: usize) -> Vec<String> {
    if n == 1 {
        vec![prefix.to_string()]
    } else {
        (0..n).map(|i| format!("{prefix}_{i}")).collect()
    }
}

fn fixed_list(values: Vec<f32>, dim: usize) -> Result<ArrayRef, arrow_schema::ArrowError> {
    Ok(Arc::new(FixedSizeListArray::try_new(
        Arc::new(Field::new_list_field(DataType::Float32, false)),
        dim as i32,
        Arc::new(Float32Array::from(values)),
        None,
    )?))
}

fn write_parquet(out: &Path, final_path: &Path, batch: &RecordBatch) -> Result<(), DatasetError> {
    use parquet::arrow::ArrowWriter;
    use parquet::basic::Compression;
    use parquet::file::properties::WriterProperties;
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir).map_err(DatasetError::io(final_path))?;
    }
    let file = std::fs::File::create(out).map_err(DatasetError::io(final_path))?;
    let props = WriterProperties::builder()
        .set_compression(Compression::SNAPPY)
        .build();
    let perr = |source| DatasetError::Parquet {
        path: final_path.to_path_buf(),
        source,
    };
    let mut w = ArrowWriter::try_new(file, batch.schema(), Some(props)).map_err(perr)?;
    w.write(batch).map_err(perr)?;
    w.close().map_err(perr)?;
    Ok(())
}

/// Writes one parquet file per (chunk, file) under `tmp/<prefix>/`: piece `k` (one episode's
/// rows, or one episode's row of meta/episodes) of `rows_of(k)` rows is built by
/// `make(k, (chunk, file))` and appended to the current file, unless that file already holds
/// rows and its size plus the piece's expected size (the file's average bytes per row times
/// the piece's rows, LeRobot's rule) reaches `limit_mb`: then the next file is opened.
/// `flush_each`: every piece is its own row group (LeRobot's data files: one table per
/// episode) and the file's size is the bytes written; otherwise the rows stay in one row
/// group and the size is the writer's estimate of the buffered rows. Returns every piece's
/// (chunk, file).
#[allow(clippy::too_many_arguments)]
fn write_split_parquet(
    tmp: &Path,
    dir: &Path,
    prefix: &str,
    pieces: usize,
    rows_of: impl Fn(usize) -> usize,
    make: impl Fn(usize, (usize, usize)) -> Result<RecordBatch, DatasetError>,
    limits: (f64, usize),
    flush_each: bool,
) -> Result<Vec<(usize, usize)>, DatasetError> {
    use parquet::arrow::ArrowWriter;
    use parquet::basic::Compression;
    use parquet::file::properties::WriterProperties;
    let (limit_mb, chunks_size) = limits;
    let mut at = (0, 0);
    let mut current: Option<(ArrowWriter<std::fs::File>, PathBuf)> = None;
    let mut rows_in_file = 0usize;
    let mut out = Vec::with_capacity(pieces);
    let close = |w: ArrowWriter<std::fs::File>, path: &Path| {
        w.close().map_err(|source| DatasetError::Parquet {
            path: path.to_path_buf(),
            source,
        })
    };
    for k in 0..pieces {
        let n = rows_of(k);
        let full = current.as_ref().is_some_and(|(w, _)| {
            let size = (w.bytes_written() + w.in_progress_size()) as f64;
            let per_row = size / rows_in_file.max(1) as f64;
            rows_in_file > 0 && size + per_row * n as f64 >= limit_mb * MB
        });
        if full {
            let (w, path) = current.take().expect("checked above");
            close(w, &path)?;
            at = next_file(at, chunks_size);
            rows_in_file = 0;
        }
        let batch = make(k, at)?;
        if current.is_none() {
            let rel = chunk_file(prefix, at, "parquet");
            let (out_path, final_path) = (tmp.join(&rel), dir.join(&rel));
            if let Some(d) = out_path.parent() {
                std::fs::create_dir_all(d).map_err(DatasetError::io(&final_path))?;
            }
            let file = std::fs::File::create(&out_path).map_err(DatasetError::io(&final_path))?;
            let props = WriterProperties::builder()
                .set_compression(Compression::SNAPPY)
                .build();
            let w = ArrowWriter::try_new(file, batch.schema(), Some(props)).map_err(|source| {
                DatasetError::Parquet {
                    path: final_path.clone(),
                    source,
                }
            })?;
            current = Some((w, final_path));
        }
        let (w, path) = current.as_mut().expect("opened above");
        let perr = |source| DatasetError::Parquet {
            path: path.clone(),
            source,
        };
        w.write(&batch).map_err(perr)?;
        if flush_each {
            w.flush().map_err(|source| DatasetError::Parquet {
                path: path.clone(),
                source,
            })?;
        }
        rows_in_file += n;
        out.push(at);
    }
    if let Some((w, path)) = current {
        close(w, &path)?;
    }
    Ok(out)
}

/// Where one episode's frames went in a camera's videos: (chunk, file), and its first and
/// end timestamps in that file (seconds).
type VideoPlace = ((usize, usize), f64, f64);

/// One camera's video, muxed into files `tmp/<prefix>/chunk-CCC/file-FFF.mp4`, split as
/// LeRobot's writer does: an episode opens the next file when the current one holds
/// episodes and its size plus the episode's (the bytes of its encoded frames) reaches the
/// limit; every file's timestamps start at 0. Returns (width, height, image stats per
/// episode, every episode's place).
fn write_video(
    tmp: &Path,
    dir: &Path,
    prefix: &str,
    cam: &Camera,
    episodes: &[&EpisodeRec],
    limits: (f64, usize),
) -> Result<(usize, usize, Vec<ImageStats>, Vec<VideoPlace>), DatasetError> {
    use openh264::formats::YUVSource;
    let final_path = dir.join(prefix);
    let verr = |msg: String| DatasetError::Video {
        path: final_path.clone(),
        msg,
    };
    // The access units, re-encoding PNG frames.
    let mut units: Vec<Vec<u8>> = Vec::new();
    let mut stats = vec![ImageStats::default(); episodes.len()];
    // Row after the last of each episode: frame i belongs to the first episode ending after it.
    let ends: Vec<usize> = episodes
        .iter()
        .scan(0, |n, ep| {
            *n += ep.steps.len();
            Some(*n)
        })
        .collect();
    let episode_of = |i: usize| ends.partition_point(|&e| e <= i).min(ends.len() - 1);
    let mut size: Option<(usize, usize)> = None;
    let mut encoder: Option<H264Encoder> = None;
    for (k, ep) in episodes.iter().enumerate() {
        let frames = cam.frames.get(&ep.index).map_or(&[][..], Vec::as_slice);
        let rows = ep.steps.len();
        if frames.len() != rows + 1 {
            return Err(verr(format!(
                "camera {} has {} frames in episode {}, expected {} (one after the reset and \
                 one per step)",
                cam.name,
                frames.len(),
                ep.index,
                rows + 1
            )));
        }
        for (t, f) in frames[..rows].iter().enumerate() {
            if cam.format == "png" {
                let dec = png::Decoder::new(std::io::Cursor::new(f.as_slice()));
                let mut reader = dec
                    .read_info()
                    .map_err(|e| verr(format!("episode {} frame {t}: {e}", ep.index)))?;
                let mut buf = vec![0; reader.output_buffer_size().unwrap_or(0)];
                let info = reader
                    .next_frame(&mut buf)
                    .map_err(|e| verr(format!("episode {} frame {t}: {e}", ep.index)))?;
                if info.color_type != png::ColorType::Rgb || info.bit_depth != png::BitDepth::Eight
                {
                    return Err(verr(format!(
                        "episode {} frame {t}: PNG is {:?} {:?}, expected 8-bit RGB",
                        ep.index, info.color_type, info.bit_depth
                    )));
                }
                let (w, h) = (info.width as usize, info.height as usize);
                let rgb = &buf[..w * h * 3];
                if encoder.is_none() {
                    encoder =
                        Some(H264Encoder::new(w, h, VIDEO_FPS).map_err(|e| verr(e.to_string()))?);
                    size = Some((w, h));
                }
                let mut unit = Vec::new();
                encoder
                    .as_mut()
                    .expect("made above")
                    .encode(rgb, t == 0, &mut unit)
                    .map_err(|e| verr(format!("episode {} frame {t}: {e}", ep.index)))?;
                stats[k].add(rgb);
                units.push(unit);
            } else {
                if t == 0 && !is_idr(f) {
                    return Err(verr(format!(
                        "camera {}: episode {} does not start with a keyframe",
                        cam.name, ep.index
                    )));
                }
                units.push(f.clone());
            }
        }
    }
    if cam.format == "h264" {
        // Decode everything once: image statistics, frame size, and a check that the
        // stream decodes to one picture per row.
        let mut dec = openh264::decoder::Decoder::new().map_err(|e| verr(e.to_string()))?;
        let mut rgb = Vec::new();
        let mut decoded = 0;
        for (i, u) in units.iter().enumerate() {
            let pic = dec
                .decode(u)
                .map_err(|e| verr(format!("frame {i} does not decode: {e}")))?;
            if let Some(p) = pic {
                let (w, h) = p.dimensions();
                rgb.resize(w * h * 3, 0);
                p.write_rgb8(&mut rgb);
                size.get_or_insert((w, h));
                stats[episode_of(decoded)].add(&rgb);
                decoded += 1;
            }
        }
        for p in dec
            .flush_remaining()
            .map_err(|e| verr(format!("flushing the decoder: {e}")))?
        {
            let (w, h) = p.dimensions();
            rgb.resize(w * h * 3, 0);
            p.write_rgb8(&mut rgb);
            stats[episode_of(decoded)].add(&rgb);
            decoded += 1;
        }
        if decoded != units.len() {
            return Err(verr(format!(
                "camera {}: {} frames decode to {} pictures",
                cam.name,
                units.len(),
                decoded
            )));
        }
    }
    let (w, h) = size.ok_or_else(|| verr(format!("camera {} has no frame", cam.name)))?;
    // Split the episodes over files.
    let (limit_mb, chunks_size) = limits;
    let mut groups: Vec<((usize, usize), std::ops::Range<usize>)> = Vec::new();
    let mut places = Vec::with_capacity(episodes.len());
    let (mut file_bytes, mut file_rows) = (0usize, 0usize);
    let mut start = 0;
    for &end in &ends {
        let ep_bytes: usize = units[start..end].iter().map(Vec::len).sum();
        let roll = file_rows > 0 && (file_bytes + ep_bytes) as f64 >= limit_mb * MB;
        match groups.last().map(|g| g.0) {
            None => groups.push(((0, 0), start..end)),
            Some(at) if roll => {
                groups.push((next_file(at, chunks_size), start..end));
                file_bytes = 0;
                file_rows = 0;
            }
            Some(_) => groups.last_mut().expect("non-empty").1.end = end,
        }
        let at = groups.last().expect("pushed above").0;
        places.push((
            at,
            file_rows as f64 / FPS as f64,
            (file_rows + end - start) as f64 / FPS as f64,
        ));
        file_bytes += ep_bytes;
        file_rows += end - start;
        start = end;
    }
    for (at, range) in groups {
        let rel = chunk_file(prefix, at, "mp4");
        let (out, final_path) = (tmp.join(&rel), dir.join(&rel));
        let verr = |msg: String| DatasetError::Video {
            path: final_path.clone(),
            msg,
        };
        if let Some(d) = out.parent() {
            std::fs::create_dir_all(d).map_err(DatasetError::io(&final_path))?;
        }
        let file = std::fs::File::create(&out).map_err(DatasetError::io(&final_path))?;
        let mut mux = muxide::api::MuxerBuilder::new(std::io::BufWriter::new(file))
            .video(
                muxide::api::VideoCodec::H264,
                w as u32,
                h as u32,
                FPS as f64,
            )
            .with_fast_start(true)
            .build()
            .map_err(|e| verr(e.to_string()))?;
        for (i, u) in units[range].iter().enumerate() {
            mux.write_video(i as f64 / FPS as f64, u, is_idr(u))
                .map_err(|e| verr(format!("frame {i}: {e}")))?;
        }
        mux.finish().map_err(|e| verr(e.to_string()))?;
    }
    Ok((w, h, stats, places))
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
    let (rec, _) = super::export::read_recording(path)?;
    let raw = crate::record::read_raw(path)?;
    let cams = if video == Some(false) {
        Vec::new()
    } else {
        cameras(path, &raw.messages)?
    };
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

    // Rows.
    let mut state = Vec::new();
    let mut action = Vec::new();
    let (mut reward, mut done, mut success) = (Vec::new(), Vec::new(), Vec::new());
    let (mut timestamp, mut frame_index, mut episode_index, mut index) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut ep_rows = Vec::new();
    for (k, ep) in episodes.iter().enumerate() {
        let from = index.len();
        let mut obs = &ep.initial_obs;
        for (t, s) in ep.steps.iter().enumerate() {
            state.extend_from_slice(obs);
            action.extend_from_slice(&s.action);
            reward.push(s.reward);
            done.push(t + 1 == ep.steps.len());
            success.push(
                s.info
                    .iter()
                    .find(|(k, _)| k == "success")
                    .is_some_and(|(_, v)| *v != 0.0),
            );
            timestamp.push(t as f32 / FPS as f32);
            frame_index.push(t as i64);
            episode_index.push(k as i64);
            index.push(index.len() as i64);
            obs = &s.obs;
        }
        ep_rows.push((from, index.len()));
    }
    let rows = index.len();
    let task_index = vec![0i64; rows];

    // Feature metadata.
    let mut obs_names = Vec::new();
    for sl in &m.obs_layout {
        obs_names.extend(names(&sl.name, sl.end - sl.start));
    }
    if obs_names.len() != obs_dim {
        obs_names = names("state", obs_dim);
    }
    let mut act_names = Vec::new();
    for p in env.action_parts() {
        act_names.extend(names(p.name, p.range.len()));
    }
    if act_names.len() != act_dim {
        act_names = names("action", act_dim);
    }
    let scalar = |dtype: &str| json!({"dtype": dtype, "shape": [1], "names": null});
    let mut features = Map::new();
    if obs_dim > 0 {
        features.insert(
            "observation.state".into(),
            json!({"dtype": "float32", "shape": [obs_dim], "names": obs_names}),
        );
    }
    features.insert(
        "action".into(),
        json!({"dtype": "float32", "shape": [act_dim], "names": act_names}),
    );
    features.insert("next.reward".into(), scalar("float32"));
    features.insert("next.done".into(), scalar("bool"));
    features.insert("next.success".into(), scalar("bool"));

    // Arrow columns.
    let aerr = |source| DatasetError::Arrow {
        path: dir.to_path_buf(),
        source,
    };
    let mut fields = Vec::new();
    let mut cols: Vec<ArrayRef> = Vec::new();
    let list_field = |name: &str, dim: usize| {
        Field::new(
            name,
            DataType::FixedSizeList(
                Arc::new(Field::new_list_field(DataType::Float32, false)),
                dim as i32,
            ),
            false,
        )
    };
    if obs_dim > 0 {
        fields.push(list_field("observation.state", obs_dim));
        cols.push(fixed_list(state.clone(), obs_dim).map_err(aerr)?);
    }
    fields.push(list_field("action", act_dim));
    cols.push(fixed_list(action.clone(), act_dim).map_err(aerr)?);
    fields.push(Field::new("next.reward", DataType::Float32, false));
    cols.push(Arc::new(Float32Array::from(reward.clone())));
    fields.push(Field::new("next.done", DataType::Boolean, false));
    cols.push(Arc::new(BooleanArray::from(done.clone())));
    fields.push(Field::new("next.success", DataType::Boolean, false));
    cols.push(Arc::new(BooleanArray::from(success.clone())));
    fields.push(Field::new("timestamp", DataType::Float32, false));
    cols.push(Arc::new(Float32Array::from(timestamp.clone())));
    for (name, v) in [
        ("frame_index", &frame_index),
        ("episode_index", &episode_index),
        ("index", &index),
        ("task_index", &task_index),
    ] {
        fields.push(Field::new(name, DataType::Int64, false));
        cols.push(Arc::new(Int64Array::from(v.clone())));
        features.insert(name.into(), scalar("int64"));
    }
    features.insert("timestamp".into(), scalar("float32"));
    let data = RecordBatch::try_new(Arc::new(Schema::new(fields)), cols).map_err(aerr)?;

    // Stats.
    let widen = |v: &[f32]| v.iter().map(|&x| x as f64).collect::<Vec<_>>();
    let bools = |v: &[bool]| v.iter().map(|&x| x as u8 as f64).collect::<Vec<_>>();
    let ints = |v: &[i64]| v.iter().map(|&x| x as f64).collect::<Vec<_>>();
    // Statistics of the whole dataset (meta/stats.json) and of every episode (the
    // `stats/<feature>/<stat>` columns of meta/episodes, from which LeRobot's
    // delete_episodes / split_dataset rebuild stats.json).
    let mut columns: Vec<(&str, Vec<f64>, usize)> = Vec::new();
    if obs_dim > 0 {
        columns.push(("observation.state", widen(&state), obs_dim));
    }
    columns.push(("action", widen(&action), act_dim));
    columns.push(("next.reward", widen(&reward), 1));
    columns.push(("next.done", bools(&done), 1));
    columns.push(("next.success", bools(&success), 1));
    columns.push(("timestamp", widen(&timestamp), 1));
    for (name, v) in [
        ("frame_index", &frame_index),
        ("episode_index", &episode_index),
        ("index", &index),
        ("task_index", &task_index),
    ] {
        columns.push((name, ints(v), 1));
    }
    let mut stats = Map::new();
    let mut ep_stats: Vec<(String, Vec<Stats>)> = Vec::new();
    for (name, values, dim) in &columns {
        stats.insert((*name).into(), Stats::of_rows(values, *dim).to_json());
        ep_stats.push((
            (*name).into(),
            ep_rows
                .iter()
                .map(|(a, b)| Stats::of_rows(&values[a * dim..b * dim], *dim))
                .collect(),
        ));
    }

    // Write everything under a temporary directory.
    // The temporary directory replaces an empty `dir` on commit (rename(2) does that).
    let mut staged = super::Staged::default();
    let tmp = staged.add(dir);
    std::fs::create_dir_all(&tmp).map_err(DatasetError::io(dir))?;
    let data_limits = (limits.data_files_size_in_mb, limits.chunks_size);
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
    let mut ep_video_cols: Vec<(Field, ArrayRef)> = Vec::new();
    for cam in &cams {
        let key = format!("observation.images.{}", cam.name);
        let (w, h, per_episode, places) = write_video(
            &tmp,
            dir,
            &format!("videos/{key}"),
            cam,
            &episodes,
            (limits.video_files_size_in_mb, limits.chunks_size),
        )?;
        let mut total = ImageStats::default();
        for st in &per_episode {
            total.merge(st);
        }
        features.insert(
            key.clone(),
            json!({
                "dtype": "video",
                "shape": [h, w, 3],
                "names": ["height", "width", "channels"],
                "info": {
                    "video.height": h, "video.width": w, "video.codec": "h264",
                    "video.pix_fmt": "yuv420p", "video.is_depth_map": false,
                    "video.fps": FPS, "video.channels": 3, "has_audio": false
                }
            }),
        );
        stats.insert(key.clone(), total.stats().to_json());
        ep_stats.push((
            key.clone(),
            per_episode.iter().map(ImageStats::stats).collect(),
        ));
        videos.push((cam.name.clone(), rows));
        let place_col = |f: &dyn Fn(&VideoPlace) -> usize| -> ArrayRef {
            Arc::new(Int64Array::from(
                places.iter().map(|p| f(p) as i64).collect::<Vec<_>>(),
            ))
        };
        ep_video_cols.push((
            Field::new(format!("videos/{key}/chunk_index"), DataType::Int64, false),
            place_col(&|p| p.0 .0),
        ));
        ep_video_cols.push((
            Field::new(format!("videos/{key}/file_index"), DataType::Int64, false),
            place_col(&|p| p.0 .1),
        ));
        let from: Vec<f64> = places.iter().map(|p| p.1).collect();
        let to: Vec<f64> = places.iter().map(|p| p.2).collect();
        ep_video_cols.push((
            Field::new(
                format!("videos/{key}/from_timestamp"),
                DataType::Float64,
                false,
            ),
            Arc::new(Float64Array::from(from)),
        ));
        ep_video_cols.push((
            Field::new(
                format!("videos/{key}/to_timestamp"),
                DataType::Float64,
                false,
            ),
            Arc::new(Float64Array::from(to)),
        ));
    }

    // Episodes metadata.
    let task = task_description(&m.env_id);
    let n = episodes.len();
    let mut tasks_col = ListBuilder::new(StringBuilder::new());
    for _ in 0..n {
        tasks_col.values().append_value(&task);
        tasks_col.append(true);
    }
    let mut ep_fields = vec![
        Field::new("episode_index", DataType::Int64, false),
        Field::new(
            "tasks",
            DataType::List(Arc::new(Field::new_list_field(DataType::Utf8, true))),
            true,
        ),
        Field::new("length", DataType::Int64, false),
        Field::new("data/chunk_index", DataType::Int64, false),
        Field::new("data/file_index", DataType::Int64, false),
        Field::new("dataset_from_index", DataType::Int64, false),
        Field::new("dataset_to_index", DataType::Int64, false),
    ];
    let data_col = |f: fn(&(usize, usize)) -> usize| -> ArrayRef {
        Arc::new(Int64Array::from(
            data_at.iter().map(|p| f(p) as i64).collect::<Vec<_>>(),
        ))
    };
    let mut ep_cols: Vec<ArrayRef> = vec![
        Arc::new(Int64Array::from((0..n as i64).collect::<Vec<_>>())),
        Arc::new(tasks_col.finish()),
        Arc::new(Int64Array::from(
            ep_rows
                .iter()
                .map(|(a, b)| (b - a) as i64)
                .collect::<Vec<_>>(),
        )),
        data_col(|p| p.0),
        data_col(|p| p.1),
        Arc::new(Int64Array::from(
            ep_rows.iter().map(|(a, _)| *a as i64).collect::<Vec<_>>(),
        )),
        Arc::new(Int64Array::from(
            ep_rows.iter().map(|(_, b)| *b as i64).collect::<Vec<_>>(),
        )),
    ];
    for (f, c) in ep_video_cols {
        ep_fields.push(f);
        ep_cols.push(c);
    }
    for (key, per) in &ep_stats {
        for (name, col) in stats_columns(per) {
            ep_fields.push(Field::new(
                format!("stats/{key}/{name}"),
                col.data_type().clone(),
                true,
            ));
            ep_cols.push(col);
        }
    }
    ep_fields.push(Field::new(
        "meta/episodes/chunk_index",
        DataType::Int64,
        false,
    ));
    ep_fields.push(Field::new(
        "meta/episodes/file_index",
        DataType::Int64,
        false,
    ));
    let ep_schema = Arc::new(Schema::new(ep_fields));
    // Every episode's row, with the meta/episodes file it goes into.
    let ep_row = |k: usize, at: (usize, usize)| -> Result<RecordBatch, DatasetError> {
        let mut cols: Vec<ArrayRef> = ep_cols.iter().map(|c| c.slice(k, 1)).collect();
        cols.push(Arc::new(Int64Array::from(vec![at.0 as i64])));
        cols.push(Arc::new(Int64Array::from(vec![at.1 as i64])));
        RecordBatch::try_new(ep_schema.clone(), cols).map_err(aerr)
    };
    write_split_parquet(
        &tmp,
        dir,
        "meta/episodes",
        n,
        |_| 1,
        ep_row,
        data_limits,
        false,
    )?;

    // Tasks: the task string is the pandas index (LeRobot reads it with pandas).
    let pandas = json!({
        "index_columns": ["task"],
        "column_indexes": [],
        "columns": [
            {"name": "task_index", "field_name": "task_index", "pandas_type": "int64", "numpy_type": "int64", "metadata": null},
            {"name": "task", "field_name": "task", "pandas_type": "unicode", "numpy_type": "object", "metadata": null}
        ],
        "creator": {"library": "mjskill", "version": env!("CARGO_PKG_VERSION")},
        "pandas_version": "2.2.0"
    });
    let tasks_schema = Schema::new(vec![
        Field::new("task_index", DataType::Int64, false),
        Field::new("task", DataType::Utf8, false),
    ])
    .with_metadata(std::collections::HashMap::from([(
        "pandas".to_string(),
        pandas.to_string(),
    )]));
    let tasks = RecordBatch::try_new(
        Arc::new(tasks_schema),
        vec![
            Arc::new(Int64Array::from(vec![0i64])),
            Arc::new(arrow_array::StringArray::from(vec![task.clone()])),
        ],
    )
    .map_err(aerr)?;
    write_parquet(
        &tmp.join("meta/tasks.parquet"),
        &dir.join("meta/tasks.parquet"),
        &tasks,
    )?;

    let info = json!({
        "codebase_version": CODEBASE_VERSION,
        "robot_type": m.robot,
        "total_episodes": n,
        "total_frames": rows,
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
        steps: rows,
        videos,
    })
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
