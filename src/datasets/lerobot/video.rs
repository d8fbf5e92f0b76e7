//! The camera frames of a recording as LeRobot videos: H.264 access units (PNG frames of older
//! recordings re-encoded), image statistics, and MP4 files split as LeRobot's writer splits
//! them.
use std::collections::BTreeMap;
use std::ops::Range;
use std::path::Path;
use std::sync::Arc;

use arrow_array::{ArrayRef, Float64Array, Int64Array};
use arrow_schema::{DataType, Field};
use serde_json::{json, Value};

use super::stats::ImageStats;
use super::{chunk_file, next_file, FPS, MB};
use crate::datasets::DatasetError;
use crate::record::video::{is_idr, H264Encoder};
use crate::record::{EpisodeRec, RawMessage, VIDEO_FPS};

/// One camera's frames in a recording.
pub(super) struct Camera {
    /// Name (`render_camera`, `base_camera`, ...).
    pub(super) name: String,
    /// `h264` or `png`.
    format: String,
    /// Per episode index: the frames, in order.
    frames: BTreeMap<u64, Vec<Vec<u8>>>,
}

/// The cameras of a recording: `foxglove.CompressedVideo` (H.264) and, from recordings made
/// before video, `foxglove.CompressedImage` (PNG) messages, grouped by episode.
pub(super) fn cameras(path: &Path, messages: &[RawMessage]) -> Result<Vec<Camera>, DatasetError> {
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

/// Where one episode's frames went in a camera's videos: (chunk, file), and its first and
/// end timestamps in that file (seconds).
pub(super) type VideoPlace = ((usize, usize), f64, f64);

/// A camera's exported video: frame size, image statistics per episode, every episode's place.
pub(super) struct Video {
    /// Frame width in pixels.
    pub(super) width: usize,
    /// Frame height in pixels.
    pub(super) height: usize,
    /// Image statistics of each episode's frames.
    pub(super) stats: Vec<ImageStats>,
    /// Where each episode's frames went.
    pub(super) places: Vec<VideoPlace>,
}

impl Video {
    /// info.json's feature of the video.
    pub(super) fn feature(&self) -> Value {
        json!({
            "dtype": "video",
            "shape": [self.height, self.width, 3],
            "names": ["height", "width", "channels"],
            "info": {
                "video.height": self.height, "video.width": self.width, "video.codec": "h264",
                "video.pix_fmt": "yuv420p", "video.is_depth_map": false,
                "video.fps": FPS, "video.channels": 3, "has_audio": false
            }
        })
    }

    /// The `videos/<key>/{chunk_index, file_index, from_timestamp, to_timestamp}` columns of
    /// meta/episodes.
    pub(super) fn episode_columns(&self, key: &str) -> Vec<(Field, ArrayRef)> {
        let index = |f: &dyn Fn(&VideoPlace) -> usize| -> ArrayRef {
            let v: Vec<i64> = self.places.iter().map(|p| f(p) as i64).collect();
            Arc::new(Int64Array::from(v))
        };
        let time = |f: &dyn Fn(&VideoPlace) -> f64| -> ArrayRef {
            Arc::new(Float64Array::from(
                self.places.iter().map(f).collect::<Vec<_>>(),
            ))
        };
        let field =
            |name: &str, ty: DataType| Field::new(format!("videos/{key}/{name}"), ty, false);
        vec![
            (field("chunk_index", DataType::Int64), index(&|p| p.0 .0)),
            (field("file_index", DataType::Int64), index(&|p| p.0 .1)),
            (field("from_timestamp", DataType::Float64), time(&|p| p.1)),
            (field("to_timestamp", DataType::Float64), time(&|p| p.2)),
        ]
    }
}

/// One camera's video, muxed into files `tmp/<prefix>/chunk-CCC/file-FFF.mp4`, split as
/// LeRobot's writer does: an episode opens the next file when the current one holds
/// episodes and its size plus the episode's (the bytes of its encoded frames) reaches the
/// limit; every file's timestamps start at 0.
pub(super) fn write_video(
    tmp: &Path,
    dir: &Path,
    prefix: &str,
    cam: &Camera,
    episodes: &[&EpisodeRec],
    limits: (f64, usize),
) -> Result<Video, DatasetError> {
    let final_path = dir.join(prefix);
    let verr = |msg: String| DatasetError::Video {
        path: final_path.clone(),
        msg,
    };
    // Row after the last of each episode: frame i belongs to the first episode ending after it.
    let ends: Vec<usize> = episodes
        .iter()
        .scan(0, |n, ep| {
            *n += ep.steps.len();
            Some(*n)
        })
        .collect();
    let mut stats = vec![ImageStats::default(); episodes.len()];
    let (units, mut size) = access_units(cam, episodes, &mut stats, &verr)?;
    if cam.format == "h264" {
        let decoded = decode_stats(cam, &units, &ends, &mut stats, &verr)?;
        size = size.or(decoded);
    }
    let (w, h) = size.ok_or_else(|| verr(format!("camera {} has no frame", cam.name)))?;
    let (groups, places) = split_files(&units, &ends, limits);
    for (at, range) in groups {
        mux_file(
            tmp,
            dir,
            &chunk_file(prefix, at, "mp4"),
            &units[range],
            (w, h),
        )?;
    }
    Ok(Video {
        width: w,
        height: h,
        stats,
        places,
    })
}

/// A camera's H.264 access units, and the frame size when it is known before decoding.
type AccessUnits = (Vec<Vec<u8>>, Option<(usize, usize)>);

/// The access units of a camera's frames, episode after episode (the frame after each
/// episode's last step left out), and the frame size when PNG frames were re-encoded (whose
/// image statistics are added to `stats` on the way).
fn access_units(
    cam: &Camera,
    episodes: &[&EpisodeRec],
    stats: &mut [ImageStats],
    verr: &dyn Fn(String) -> DatasetError,
) -> Result<AccessUnits, DatasetError> {
    let mut units: Vec<Vec<u8>> = Vec::new();
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
                let at = |e: &dyn std::fmt::Display| {
                    verr(format!("episode {} frame {t}: {e}", ep.index))
                };
                let (rgb, w, h) = decode_png(f, &at)?;
                let enc = match &mut encoder {
                    Some(enc) => enc,
                    None => {
                        size = Some((w, h));
                        encoder.insert(
                            H264Encoder::new(w, h, VIDEO_FPS).map_err(|e| verr(e.to_string()))?,
                        )
                    }
                };
                let mut unit = Vec::new();
                enc.encode(&rgb, t == 0, &mut unit).map_err(|e| at(&e))?;
                stats[k].add(&rgb);
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
    Ok((units, size))
}

/// An 8-bit RGB PNG frame as (pixels, width, height); `err` words an error (it names the
/// frame).
fn decode_png(
    png_bytes: &[u8],
    err: &dyn Fn(&dyn std::fmt::Display) -> DatasetError,
) -> Result<(Vec<u8>, usize, usize), DatasetError> {
    let dec = png::Decoder::new(std::io::Cursor::new(png_bytes));
    let mut reader = dec.read_info().map_err(|e| err(&e))?;
    let mut buf = vec![0; reader.output_buffer_size().unwrap_or(0)];
    let info = reader.next_frame(&mut buf).map_err(|e| err(&e))?;
    if info.color_type != png::ColorType::Rgb || info.bit_depth != png::BitDepth::Eight {
        return Err(err(&format_args!(
            "PNG is {:?} {:?}, expected 8-bit RGB",
            info.color_type, info.bit_depth
        )));
    }
    let (w, h) = (info.width as usize, info.height as usize);
    buf.truncate(w * h * 3);
    Ok((buf, w, h))
}

/// Decodes an H.264 camera's access units once: image statistics of every episode (into
/// `stats`), the frame size, and a check that the stream decodes to one picture per unit.
fn decode_stats(
    cam: &Camera,
    units: &[Vec<u8>],
    ends: &[usize],
    stats: &mut [ImageStats],
    verr: &dyn Fn(String) -> DatasetError,
) -> Result<Option<(usize, usize)>, DatasetError> {
    use openh264::formats::YUVSource;
    let episode_of = |i: usize| ends.partition_point(|&e| e <= i).min(ends.len() - 1);
    let mut dec = openh264::decoder::Decoder::new().map_err(|e| verr(e.to_string()))?;
    let mut rgb = Vec::new();
    let mut size = None;
    let mut decoded = 0;
    let mut add = |p: &openh264::decoder::DecodedYUV<'_>, decoded: &mut usize| {
        let (w, h) = p.dimensions();
        rgb.resize(w * h * 3, 0);
        p.write_rgb8(&mut rgb);
        size.get_or_insert((w, h));
        stats[episode_of(*decoded)].add(&rgb);
        *decoded += 1;
    };
    for (i, u) in units.iter().enumerate() {
        let pic = dec
            .decode(u)
            .map_err(|e| verr(format!("frame {i} does not decode: {e}")))?;
        if let Some(p) = pic {
            add(&p, &mut decoded);
        }
    }
    for p in dec
        .flush_remaining()
        .map_err(|e| verr(format!("flushing the decoder: {e}")))?
    {
        add(&p, &mut decoded);
    }
    if decoded != units.len() {
        return Err(verr(format!(
            "camera {}: {} frames decode to {} pictures",
            cam.name,
            units.len(),
            decoded
        )));
    }
    Ok(size)
}

/// The episodes' split over video files: each file's (chunk, file) and range of units, and
/// every episode's place.
#[allow(clippy::type_complexity)]
fn split_files(
    units: &[Vec<u8>],
    ends: &[usize],
    limits: (f64, usize),
) -> (Vec<((usize, usize), Range<usize>)>, Vec<VideoPlace>) {
    let (limit_mb, chunks_size) = limits;
    let mut groups: Vec<((usize, usize), Range<usize>)> = Vec::new();
    let mut places = Vec::with_capacity(ends.len());
    let (mut file_bytes, mut file_rows) = (0usize, 0usize);
    let mut start = 0;
    for &end in ends {
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
    (groups, places)
}

/// Muxes access units into the MP4 file `tmp/<rel>` (timestamps from 0 at [`FPS`]).
fn mux_file(
    tmp: &Path,
    dir: &Path,
    rel: &str,
    units: &[Vec<u8>],
    (w, h): (usize, usize),
) -> Result<(), DatasetError> {
    let (out, final_path) = (tmp.join(rel), dir.join(rel));
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
    for (i, u) in units.iter().enumerate() {
        mux.write_video(i as f64 / FPS as f64, u, is_idr(u))
            .map_err(|e| verr(format!("frame {i}: {e}")))?;
    }
    mux.finish().map_err(|e| verr(e.to_string()))
}
