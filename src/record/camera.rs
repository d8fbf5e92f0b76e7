//! Camera video in recordings: [`Recorder::enable_video`] adds a camera's
//! `foxglove.CompressedVideo` channel and [`Recorder::record_camera_frame`] writes its frames as
//! H.264 (the `video` feature; without it, enabling video is refused, naming the feature).
use std::collections::BTreeMap;

use super::{camera_topic, schema, RecordError, Recorder};
#[cfg(feature = "video")]
use super::{video, VIDEO_FPS};

/// A camera's video channel, its encoder (made at the first frame) and reused buffers.
#[derive(Debug)]
#[cfg_attr(not(feature = "video"), allow(dead_code))]
pub(super) struct Video {
    channel: u16,
    frame_id: String,
    #[cfg(feature = "video")]
    encoder: Option<video::H264Encoder>,
    /// The next frame starts an episode: encode it as a keyframe (IDR with SPS/PPS), so
    /// every episode decodes on its own.
    pub(super) keyframe: bool,
    h264: Vec<u8>,
    b64: String,
    frames: u64,
}

impl Recorder {
    /// Adds the `/<frame_id>/video` channel (`foxglove.CompressedVideo`, H.264) for the
    /// frames of the camera `frame_id` (the human camera's is
    /// [`TOPIC_RENDER_VIDEO`](super::TOPIC_RENDER_VIDEO)); returns the camera's index for
    /// [`Recorder::record_camera_frame`]. Idempotent. Video needs the crate's `video` feature
    /// (a default one); without it this refuses, naming it.
    pub fn enable_video(&mut self, frame_id: &str) -> Result<usize, RecordError> {
        if !cfg!(feature = "video") {
            return Err(RecordError::Refused {
                path: self.path.clone(),
                what: format!(
                    "H.264 video of camera {frame_id}: it needs mjskill's `video` feature, \
                     which this build leaves out (build with the default features, or add \
                     `--features video`)"
                ),
            });
        }
        if let Some(i) = self.videos.iter().position(|v| v.frame_id == frame_id) {
            return Ok(i);
        }
        let text = serde_json::to_vec(&schema::compressed_video()).expect("schema serializes");
        let topic = camera_topic(frame_id);
        let channel = (|| -> mcap::McapResult<u16> {
            let sid = self
                .writer
                .add_schema("foxglove.CompressedVideo", "jsonschema", &text)?;
            self.writer
                .add_channel(sid, &topic, "json", &BTreeMap::new())
        })()
        .map_err(|e| self.mcap_err(e))?;
        self.videos.push(Video {
            channel,
            frame_id: frame_id.to_string(),
            #[cfg(feature = "video")]
            encoder: None,
            keyframe: true,
            h264: Vec::new(),
            b64: String::new(),
            frames: 0,
        });
        Ok(self.videos.len() - 1)
    }

    /// Frames written by [`Recorder::record_frame`] / [`Recorder::record_camera_frame`],
    /// all cameras together.
    pub fn frames(&self) -> u64 {
        self.videos.iter().map(|v| v.frames).sum()
    }

    /// [`Recorder::record_camera_frame`] for the first camera enabled.
    pub fn record_frame(
        &mut self,
        rgb: &[u8],
        width: usize,
        height: usize,
    ) -> Result<(), RecordError> {
        self.record_camera_frame(0, rgb, width, height)
    }

    /// Writes an RGB frame (H×W×3 bytes, top row first) of camera `camera` (the index
    /// [`Recorder::enable_video`] returned) as an H.264 `foxglove.CompressedVideo` message
    /// stamped with the time of the last message (call it right after
    /// [`Recorder::begin_episode`] or [`Recorder::record_step`]). The first frame of every
    /// episode is a keyframe carrying SPS and PPS; the size must not change.
    pub fn record_camera_frame(
        &mut self,
        camera: usize,
        rgb: &[u8],
        width: usize,
        height: usize,
    ) -> Result<(), RecordError> {
        if camera >= self.videos.len() {
            return Err(RecordError::Usage {
                path: self.path.clone(),
                msg: format!(
                    "record_camera_frame({camera}) with {} camera(s) enabled (call enable_video)",
                    self.videos.len()
                ),
            });
        }
        let mut v = self.videos.swap_remove(camera);
        let ns = self.last_ns.unwrap_or(0);
        let r = self.encode_frame(&mut v, ns, rgb, width, height);
        if r.is_ok() {
            v.frames += 1;
            v.keyframe = false;
        }
        self.videos.push(v);
        let last = self.videos.len() - 1;
        self.videos.swap(camera, last);
        r
    }

    /// Encodes one frame of camera `v` and writes it, stamped `ns`.
    #[cfg(feature = "video")]
    fn encode_frame(
        &mut self,
        v: &mut Video,
        ns: u64,
        rgb: &[u8],
        width: usize,
        height: usize,
    ) -> Result<(), RecordError> {
        use base64::Engine;
        let bad = |e: video::VideoError| RecordError::Refused {
            path: self.path.clone(),
            what: format!("a frame of camera {}: {e}", v.frame_id),
        };
        if v.encoder.is_none() {
            v.encoder = Some(video::H264Encoder::new(width, height, VIDEO_FPS).map_err(bad)?);
        }
        let enc = v.encoder.as_mut().expect("made above");
        if enc.size() != (width, height) {
            return Err(bad(video::VideoError::Size {
                width,
                height,
                why: format!("the camera's video is {:?}", enc.size()),
            }));
        }
        enc.encode(rgb, v.keyframe, &mut v.h264).map_err(bad)?;
        v.b64.clear();
        base64::engine::general_purpose::STANDARD.encode_string(&v.h264, &mut v.b64);
        let msg = schema::CompressedImageMsg {
            timestamp: schema::time(ns),
            frame_id: &v.frame_id,
            data: &v.b64,
            format: "h264",
        };
        self.write_json(v.channel, ns, &msg)
    }

    /// Without the `video` feature no camera is enabled ([`Recorder::enable_video`] refuses),
    /// so no frame reaches this.
    #[cfg(not(feature = "video"))]
    fn encode_frame(
        &mut self,
        v: &mut Video,
        _ns: u64,
        _rgb: &[u8],
        _width: usize,
        _height: usize,
    ) -> Result<(), RecordError> {
        Err(RecordError::Refused {
            path: self.path.clone(),
            what: format!(
                "a frame of camera {}: H.264 video needs mjskill's `video` feature",
                v.frame_id
            ),
        })
    }
}
