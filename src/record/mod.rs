//! Episode recording to [MCAP](https://mcap.dev) files, and reading them back.
//!
//! A [`Recorder`] writes one file per run: a `Metadata` record named `"mjskill"` describing
//! the env (see [`Meta`]) and these channels, all JSON (`message_encoding` `"json"`, schema
//! encoding `"jsonschema"`), so any MCAP tool can decode them:
//!
//! | topic | schema | when |
//! |---|---|---|
//! | `/episode` | `mjskill.Episode` | once per episode, after reset: index, seed, initial [`EnvState`], obs, info |
//! | `/step` | `mjskill.Step` | every step: action, obs, reward, flags, info and the [`EnvState`] *before* the step |
//! | `/episode_end` | `mjskill.EpisodeEnd` | once per finished episode: steps, return, success |
//! | `/tf` | `foxglove.FrameTransforms` | after reset and every step: the world pose of every body |
//! | `/scene` | `foxglove.SceneUpdate` | once per episode: the drawn geoms of every body, in the body frame |
//! | `/<camera>/video` | `foxglove.CompressedVideo` | with [`Recorder::enable_video`]: a camera's H.264 frames ([`video`]) |
//!
//! Because `/step` carries the state before the step, `env.set_state(&step.state)` followed
//! by `env.step(&step.action)` reproduces the recorded step bitwise.
//!
//! Log times are simulated time in nanoseconds: an episode starts one control step
//! (`TIMESTEP × SUBSTEPS`) after the previous message, so times never go backwards across
//! episodes.
//!
//! Float encoding: observations, actions, rewards and info values are JSON numbers in their
//! shortest round-trip form (read back bitwise); a non-finite value is written as `null` and
//! read back as NaN. States must be finite: [`Recorder::record_step`] refuses a non-finite
//! state or body pose ([`RecordError::Refused`]) before writing anything, so every file stays
//! valid against its schemas and readable. Space bounds in the metadata are written as
//! numbers or the strings `"inf"`, `"-inf"`, `"nan"`.
//!
//! Durability: messages go into zstd-compressed chunks that are buffered in memory and
//! written whole. [`Recorder::end_episode`] closes the chunk and `fsync`s the file, so every
//! finished episode survives a later crash or `SIGKILL`; [`read`] recovers such a file (no
//! summary or footer) and reports [`Recording::complete`]` == false`.
//!
//! Damage: every chunk carries a CRC and a closed file carries data- and summary-section CRCs.
//! Readers ([`stream`], [`read`], [`read_raw`]) check them and the file's structure, with
//! records and chunks limited to [`MAX_RECORD`], and tell a file cut short (read up to the
//! cut) from a damaged one ([`RecordError::Corrupt`], naming the byte offset and chunk).

mod camera;
mod guard;
mod meta;
pub use meta::{Meta, MetaError, ObsSlice, Space};
pub mod image;
mod num;
mod reader;
pub mod replay;
mod scan;
mod schema;
use camera::Video;
#[cfg(feature = "video")]
pub mod video;

pub use reader::{
    read, read_raw, stream, EpisodeEnd, EpisodeRec, EpisodeStart, RawMessage, RawRecording,
    Recording, StepRec, StreamEnd, Visitor,
};
pub use scan::{MAX_MESSAGE, MAX_RECORD};

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use mcap::records::{MessageHeader, Metadata};
use mcap::{Compression, WriteOptions};
use serde::{Deserialize, Serialize};

use crate::env::{Env, EnvError, EnvState, Info};

/// MCAP header profile of mjskill recordings.
pub const PROFILE: &str = "mjskill";
/// Name of the file-level metadata record.
pub const METADATA_NAME: &str = "mjskill";
/// Prefix of the per-episode metadata records (`episode-0`, `episode-1`, ...).
pub const EPISODE_METADATA_PREFIX: &str = "episode-";
/// Version of the recording layout, stored as metadata key `format`.
pub const FORMAT_VERSION: u32 = 1;
/// Topic of the per-episode start message.
pub const TOPIC_EPISODE: &str = "/episode";
/// Topic of the per-step message.
pub const TOPIC_STEP: &str = "/step";
/// Topic of the per-episode end message.
pub const TOPIC_EPISODE_END: &str = "/episode_end";
/// Topic of the body poses (`foxglove.FrameTransforms`).
pub const TOPIC_TF: &str = "/tf";
/// Topic of the scene geometry (`foxglove.SceneUpdate`).
pub const TOPIC_SCENE: &str = "/scene";
/// Topic of the human render camera's frames in recordings made before H.264 video
/// (`foxglove.CompressedImage`, one PNG per frame); still read by the exporters.
pub const TOPIC_RENDER_IMAGE: &str = "/render_camera/image";
/// Topic of the human render camera's video (`foxglove.CompressedVideo`, H.264), written when
/// video is enabled ([`Recorder::enable_video`]); other cameras use [`camera_topic`].
pub const TOPIC_RENDER_VIDEO: &str = "/render_camera/video";
/// Frame rate of recorded video: one frame per control step (ManiSkill's 20 Hz).
pub const VIDEO_FPS: f32 = 20.0;

/// Topic of a camera's H.264 video: `/<camera>/video`.
pub fn camera_topic(camera: &str) -> String {
    format!("/{camera}/video")
}

/// An error of any type, as a [`Visitor`] returns it and as [`RecordError`] carries it.
pub type BoxError = Box<dyn std::error::Error + Send + Sync>;

/// Errors of recording and reading; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// Creating, writing, syncing or reading the file failed.
    #[error("{}: {source}", .path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The MCAP writer or parser failed.
    #[error("{}: MCAP error: {source}", .path.display())]
    Mcap {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: mcap::McapError,
    },
    /// The file is not an mjskill MCAP recording.
    #[error("{}: not an mjskill recording: {reason}", .path.display())]
    NotRecording {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// A record or message of the file does not decode.
    #[error("{}: bad {what}: {source}", .path.display())]
    Decode {
        /// The file.
        path: PathBuf,
        /// Which record or message.
        what: String,
        /// The decoding error (JSON, metadata, or an inconsistency it names).
        source: BoxError,
    },
    /// The recorder was used out of order (e.g. a step without an episode).
    #[error("{}: {msg}", .path.display())]
    Usage {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        msg: String,
    },
    /// The file is damaged (not merely cut short): a chunk, data-section or summary CRC, or a
    /// structure check failed at `offset`.
    #[error("{}: damaged at byte offset {offset} (not a cut): {detail}", .path.display())]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// Byte offset of the damaged record (or of the chunk holding it).
        offset: u64,
        /// What is wrong.
        detail: String,
    },
    /// The file was cut short before anything usable (e.g. before its metadata).
    #[error("{}: truncated: {detail}", .path.display())]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Where the file ends.
        offset: u64,
        /// Where the cut lies.
        detail: String,
    },
    /// A [`Visitor`] of [`stream`] stopped the reading.
    #[error("{}: {source}", .path.display())]
    Visitor {
        /// The file.
        path: PathBuf,
        /// The visitor's error.
        source: BoxError,
    },
    /// A value to record is not finite (a state that could not be restored), or a message is
    /// larger than [`MAX_MESSAGE`]; nothing was written.
    #[error("{}: cannot record {what}", .path.display())]
    Refused {
        /// The file.
        path: PathBuf,
        /// What was refused and why.
        what: String,
    },
    /// The env rejected a step made through [`Recorder::step`].
    #[error("{}: env error: {source}", .path.display())]
    Env {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: EnvError,
    },
}

// ---------------------------------------------------------------------------------------------
// Messages

fn info_pairs(info: &Info) -> Vec<(String, f64)> {
    std::iter::once(("elapsed_steps".to_string(), info.elapsed_steps as f64))
        .chain(
            info.keys
                .iter()
                .zip(&info.values)
                .map(|(k, v)| (k.to_string(), *v)),
        )
        .collect()
}

#[derive(Serialize, Deserialize)]
struct EpisodeMsg {
    episode: u64,
    seed: Option<u64>,
    state: EnvState,
    #[serde(with = "num::f32s")]
    obs: Vec<f32>,
    #[serde(with = "num::ordered_map")]
    info: Vec<(String, f64)>,
}

#[derive(Serialize)]
struct StepMsgOut<'a> {
    episode: u64,
    step: u32,
    #[serde(serialize_with = "num::f32s::serialize")]
    action: &'a [f32],
    #[serde(
        serialize_with = "num::f32s::serialize_some",
        skip_serializing_if = "Option::is_none"
    )]
    expert_action: Option<&'a [f32]>,
    #[serde(serialize_with = "num::f32s::serialize")]
    obs: &'a [f32],
    #[serde(with = "num::f32n")]
    reward: f32,
    terminated: bool,
    truncated: bool,
    #[serde(serialize_with = "num::ordered_map::serialize")]
    info: &'a [(String, f64)],
    state_before: &'a EnvState,
}

#[derive(Deserialize)]
struct StepMsgIn {
    episode: u64,
    step: u32,
    #[serde(with = "num::f32s")]
    action: Vec<f32>,
    #[serde(default, deserialize_with = "num::f32s::deserialize_some")]
    expert_action: Option<Vec<f32>>,
    #[serde(with = "num::f32s")]
    obs: Vec<f32>,
    #[serde(with = "num::f32n")]
    reward: f32,
    terminated: bool,
    truncated: bool,
    #[serde(with = "num::ordered_map")]
    info: Vec<(String, f64)>,
    state_before: EnvState,
}

#[derive(Serialize, Deserialize)]
struct EpisodeEndMsg {
    episode: u64,
    steps: u32,
    #[serde(rename = "return", with = "num::f64n")]
    ret: f64,
    success: bool,
}

// ---------------------------------------------------------------------------------------------
// Writer

#[derive(Debug, Clone, Copy)]
struct Channels {
    episode: u16,
    step: u16,
    episode_end: u16,
    tf: u16,
    scene: u16,
}

/// What a step returned: reward and flags.
#[derive(Debug, Clone, Copy)]
struct Outcome {
    reward: f32,
    terminated: bool,
    truncated: bool,
}

#[derive(Debug, Clone, Copy)]
struct Open {
    index: u64,
    start_ns: u64,
    steps: u32,
    ret: f64,
}

/// Writes episodes of one env to an MCAP file (see the [module docs](self)).
///
/// Typical use: [`Recorder::reset`] (or `env.reset` + [`Recorder::begin_episode`]), then
/// [`Recorder::step`] (or `get_state` + `env.step` + [`Recorder::record_step`]) until the
/// episode is over, then [`Recorder::end_episode`]; finally [`Recorder::finish`]. Dropping a
/// recorder without `finish` still writes the summary (errors are then ignored), except while
/// the thread panics: the file then reads as cut short, as after a kill.
pub struct Recorder {
    writer: mcap::Writer<BufWriter<guard::UnwindGuard>>,
    file: File,
    path: PathBuf,
    ch: Channels,
    frames: Vec<String>,
    dt_ns: u64,
    seq: u32,
    /// Log time of the last message written (None before the first).
    last_ns: Option<u64>,
    next_episode: u64,
    open: Option<Open>,
    info_buf: Vec<(String, f64)>,
    videos: Vec<Video>,
    /// [`Meta::command`] of the file, repeated in every episode's metadata record.
    command: Option<String>,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder")
            .field("path", &self.path)
            .field("next_episode", &self.next_episode)
            .field("open", &self.open)
            .finish_non_exhaustive()
    }
}

impl Recorder {
    /// Creates (truncates) `path` and writes the MCAP header (profile `"mjskill"`), the
    /// metadata of `env` and the channel definitions, flushed to disk before returning.
    pub fn create(path: &Path, env: &Env) -> Result<Recorder, RecordError> {
        let file = File::create(path).map_err(|source| RecordError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Recorder::from_file(file, path, env)
    }

    /// Like [`Recorder::create`], into a file already open for writing (e.g. a temporary file
    /// the caller renames later, or one it holds a lock on); `path` names it in errors.
    pub fn from_file(file: File, path: &Path, env: &Env) -> Result<Recorder, RecordError> {
        Recorder::from_file_with_command(file, path, env, None)
    }

    /// Like [`Recorder::from_file`], with the command that writes the file in its metadata
    /// ([`Meta::command`]).
    pub fn from_file_with_command(
        file: File,
        path: &Path,
        env: &Env,
        command: Option<&str>,
    ) -> Result<Recorder, RecordError> {
        let io = |source| RecordError::Io {
            path: path.to_path_buf(),
            source,
        };
        let mcap_err = |source| RecordError::Mcap {
            path: path.to_path_buf(),
            source,
        };
        let sync_handle = file.try_clone().map_err(io)?;
        let opts = WriteOptions::new()
            .profile(PROFILE)
            .library(format!("mjskill {}", env!("CARGO_PKG_VERSION")))
            .compression(Some(Compression::Zstd))
            .compression_threads(0)
            // Chunks close at 1 MiB of records; with messages of at most MAX_MESSAGE, every
            // chunk stays below the readers' MAX_RECORD.
            .chunk_size(Some(1 << 20))
            // Buffer each chunk in memory and write it whole: the file never holds a
            // half-written chunk whose lengths are yet to be patched.
            .disable_seeking(true);
        let mut writer = opts
            .create(BufWriter::new(guard::UnwindGuard(file)))
            .map_err(mcap_err)?;
        let meta = Meta {
            command: command.map(str::to_string),
            ..Meta::of(env)
        };
        writer
            .write_metadata(&Metadata {
                name: METADATA_NAME.to_string(),
                metadata: meta.to_map(),
            })
            .map_err(mcap_err)?;
        let no_meta = BTreeMap::new();
        let mut add = |name: &str, schema: serde_json::Value, topic: &str| {
            let text = serde_json::to_vec(&schema).expect("schema serializes");
            let sid = writer.add_schema(name, "jsonschema", &text)?;
            writer.add_channel(sid, topic, "json", &no_meta)
        };
        let ch = (|| -> mcap::McapResult<Channels> {
            Ok(Channels {
                episode: add("mjskill.Episode", schema::episode(), TOPIC_EPISODE)?,
                step: add("mjskill.Step", schema::step(), TOPIC_STEP)?,
                episode_end: add(
                    "mjskill.EpisodeEnd",
                    schema::episode_end(),
                    TOPIC_EPISODE_END,
                )?,
                tf: add(
                    "foxglove.FrameTransforms",
                    schema::frame_transforms(),
                    TOPIC_TF,
                )?,
                scene: add("foxglove.SceneUpdate", schema::scene_update(), TOPIC_SCENE)?,
            })
        })()
        .map_err(mcap_err)?;
        let mut rec = Recorder {
            writer,
            file: sync_handle,
            path: path.to_path_buf(),
            ch,
            frames: schema::body_frames(env.model()),
            dt_ns: meta.control_dt_ns(),
            seq: 0,
            last_ns: None,
            next_episode: 0,
            open: None,
            info_buf: Vec::new(),
            videos: Vec::new(),
            command: meta.command,
        };
        rec.sync()?;
        Ok(rec)
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Tells the recorder that its file was renamed (or linked) to `path`, the name its
    /// errors use from now on; writing continues into the same open file.
    pub fn renamed(&mut self, path: &Path) {
        self.path = path.to_path_buf();
    }

    /// Adds a JSON channel of the caller's own (a `jsonschema` schema named `schema_name`,
    /// e.g. for data an importer keeps next to the standard topics); returns its id for
    /// [`Recorder::write_message`].
    pub fn add_json_channel(
        &mut self,
        schema_name: &str,
        schema: &serde_json::Value,
        topic: &str,
    ) -> Result<u16, RecordError> {
        let text = serde_json::to_vec(schema).expect("schema serializes");
        (|| -> mcap::McapResult<u16> {
            let sid = self.writer.add_schema(schema_name, "jsonschema", &text)?;
            self.writer
                .add_channel(sid, topic, "json", &BTreeMap::new())
        })()
        .map_err(|e| self.mcap_err(e))
    }

    /// Writes `msg` as JSON on a channel made by [`Recorder::add_json_channel`], stamped with
    /// the time of the last message (call it right after [`Recorder::begin_episode`] or
    /// [`Recorder::record_step`]).
    pub fn write_message<T: Serialize>(
        &mut self,
        channel: u16,
        msg: &T,
    ) -> Result<(), RecordError> {
        let ns = self.last_ns.unwrap_or(0);
        self.write_json(channel, ns, msg)
    }

    /// Number of episodes begun so far.
    pub fn episodes(&self) -> u64 {
        self.next_episode
    }

    fn mcap_err(&self, source: mcap::McapError) -> RecordError {
        RecordError::Mcap {
            path: self.path.clone(),
            source,
        }
    }

    fn write(&mut self, channel_id: u16, ns: u64, data: &[u8]) -> Result<(), RecordError> {
        if data.len() > MAX_MESSAGE {
            return Err(RecordError::Refused {
                path: self.path.clone(),
                what: format!(
                    "a message of {} bytes: readers accept messages of up to {} MiB",
                    data.len(),
                    MAX_MESSAGE >> 20
                ),
            });
        }
        let header = MessageHeader {
            channel_id,
            sequence: self.seq,
            log_time: ns,
            publish_time: ns,
        };
        self.seq = self.seq.wrapping_add(1);
        self.last_ns = Some(self.last_ns.map_or(ns, |t| t.max(ns)));
        self.writer
            .write_to_known_channel(&header, data)
            .map_err(|e| self.mcap_err(e))
    }

    fn write_json<T: Serialize>(
        &mut self,
        channel_id: u16,
        ns: u64,
        msg: &T,
    ) -> Result<(), RecordError> {
        let data = serde_json::to_vec(msg).map_err(|e| RecordError::Decode {
            path: self.path.clone(),
            what: "message to write".into(),
            source: e.into(),
        })?;
        self.write(channel_id, ns, &data)
    }

    /// Refuses a state with a non-finite number, or any other that [`Env::check_state`]
    /// refuses (it could not be restored with [`Env::set_state`], and `mjskill info` and
    /// `replay` refuse it), or body poses that are not finite (the Foxglove schema needs
    /// numbers), before anything of the step is written.
    fn check_finite(&self, state: &EnvState, name: &str, env: &Env) -> Result<(), RecordError> {
        let refuse = |what: String| {
            Err(RecordError::Refused {
                path: self.path.clone(),
                what,
            })
        };
        if let Some((field, value)) = crate::env::checks::first_non_finite(state) {
            return refuse(format!(
                "{name}.{field} = {value}: recorded states must be finite (the env has \
                 diverged; nothing of this step was written)"
            ));
        }
        if let Err(e) = env.check_state(state) {
            return refuse(format!(
                "{name}: {e}: recorded states must restore with `set_state` (readers check \
                 them; nothing of this step was written)"
            ));
        }
        let d = env.data();
        if let Some(x) = d.xpos().iter().chain(d.xquat()).find(|x| !x.is_finite()) {
            return refuse(format!(
                "a body pose with {x}: recorded poses must be finite (nothing of this step was \
                 written)"
            ));
        }
        Ok(())
    }

    /// Ends the current chunk and forces the file to disk.
    fn sync(&mut self) -> Result<(), RecordError> {
        self.writer.flush().map_err(|e| self.mcap_err(e))?;
        self.file.sync_data().map_err(|source| RecordError::Io {
            path: self.path.clone(),
            source,
        })
    }

    /// Starts an episode; call right after `env.reset(seed)`. Writes `/episode`, `/scene`
    /// and `/tf`. An episode still open is left unfinished (no `/episode_end`).
    pub fn begin_episode(&mut self, env: &Env, seed: Option<u64>) -> Result<(), RecordError> {
        let state = env.get_state();
        self.check_finite(&state, "state", env)?;
        let start_ns = self.last_ns.map_or(0, |t| t.saturating_add(self.dt_ns));
        let index = self.next_episode;
        self.next_episode += 1;
        for v in &mut self.videos {
            v.keyframe = true;
        }
        self.open = Some(Open {
            index,
            start_ns,
            steps: 0,
            ret: 0.0,
        });
        // A metadata record per episode: the file's metadata plus the episode index and seed,
        // so a tool reading only metadata (e.g. `mcap info`) sees how each episode started.
        let mut meta = Meta {
            command: self.command.clone(),
            ..Meta::of(env)
        }
        .to_map();
        meta.insert("episode".into(), index.to_string());
        meta.insert("seed".into(), seed.map_or("null".into(), |s| s.to_string()));
        self.writer
            .write_metadata(&Metadata {
                name: format!("{EPISODE_METADATA_PREFIX}{index}"),
                metadata: meta,
            })
            .map_err(|e| self.mcap_err(e))?;
        let msg = EpisodeMsg {
            episode: index,
            seed,
            state,
            obs: env.obs().to_vec(),
            info: info_pairs(env.info()),
        };
        self.write_json(self.ch.episode, start_ns, &msg)?;
        let scene = schema::scene_update_msg(env.model(), &self.frames, start_ns);
        self.write_json(self.ch.scene, start_ns, &scene)?;
        let tf = schema::frame_transforms_msg(env.data(), &self.frames, start_ns);
        self.write_json(self.ch.tf, start_ns, &tf)
    }

    /// Records one step that has just been made: `action` and the step's `reward`,
    /// `terminated` and `truncated`, with obs, info and body poses read from `env` (after the
    /// step), and `state_before`, the [`Env::get_state`] taken right before the step.
    pub fn record_step(
        &mut self,
        env: &Env,
        action: &[f32],
        reward: f32,
        terminated: bool,
        truncated: bool,
        state_before: &EnvState,
    ) -> Result<(), RecordError> {
        let step = Outcome {
            reward,
            terminated,
            truncated,
        };
        self.write_step(env, action, None, step, state_before)
    }

    /// As [`Recorder::record_step`], with the expert's label of the step: `expert_action`,
    /// the action the expert chose for the state before the step, where `action` is the one
    /// the env executed (e.g. the label plus noise: `mjskill rollout --action-noise`). It is
    /// written as the step's `expert_action` field; both have the action's length.
    #[allow(clippy::too_many_arguments)]
    pub fn record_labelled_step(
        &mut self,
        env: &Env,
        action: &[f32],
        expert_action: &[f32],
        reward: f32,
        terminated: bool,
        truncated: bool,
        state_before: &EnvState,
    ) -> Result<(), RecordError> {
        self.check_label(action, expert_action)?;
        let step = Outcome {
            reward,
            terminated,
            truncated,
        };
        self.write_step(env, action, Some(expert_action), step, state_before)
    }

    fn write_step(
        &mut self,
        env: &Env,
        action: &[f32],
        expert_action: Option<&[f32]>,
        Outcome {
            reward,
            terminated,
            truncated,
        }: Outcome,
        state_before: &EnvState,
    ) -> Result<(), RecordError> {
        let Some(mut open) = self.open else {
            return Err(RecordError::Usage {
                path: self.path.clone(),
                msg: "record_step called outside an episode (call begin_episode first)".into(),
            });
        };
        self.check_finite(state_before, "state_before", env)?;
        let info = env.info();
        let ns = open.start_ns.saturating_add(
            self.dt_ns
                .saturating_mul(info.elapsed_steps.max(open.steps.saturating_add(1)) as u64),
        );
        let mut pairs = std::mem::take(&mut self.info_buf);
        pairs.clear();
        pairs.push(("elapsed_steps".to_string(), info.elapsed_steps as f64));
        pairs.extend(
            info.keys
                .iter()
                .zip(&info.values)
                .map(|(k, v)| (k.to_string(), *v)),
        );
        let msg = StepMsgOut {
            episode: open.index,
            step: open.steps,
            action,
            expert_action,
            obs: env.obs(),
            reward,
            terminated,
            truncated,
            info: &pairs,
            state_before,
        };
        let r = self.write_json(self.ch.step, ns, &msg);
        self.info_buf = pairs;
        r?;
        let tf = schema::frame_transforms_msg(env.data(), &self.frames, ns);
        self.write_json(self.ch.tf, ns, &tf)?;
        open.steps += 1;
        open.ret += reward as f64;
        self.open = Some(open);
        Ok(())
    }

    /// Resets `env` with `seed` and begins an episode.
    pub fn reset(&mut self, env: &mut Env, seed: Option<u64>) -> Result<(), RecordError> {
        env.reset(seed);
        self.begin_episode(env, seed)
    }

    /// Steps `env` with `action` and records the step (state before it included). Returns
    /// `(reward, terminated, truncated)`. An action the env rejects is returned as
    /// [`RecordError::Env`] and nothing is written.
    pub fn step(
        &mut self,
        env: &mut Env,
        action: &[f32],
    ) -> Result<(f32, bool, bool), RecordError> {
        self.step_with(env, action, None)
    }

    /// As [`Recorder::step`], recording `expert_action` as the step's label
    /// ([`Recorder::record_labelled_step`]); the env executes `action`.
    pub fn step_labelled(
        &mut self,
        env: &mut Env,
        action: &[f32],
        expert_action: &[f32],
    ) -> Result<(f32, bool, bool), RecordError> {
        self.step_with(env, action, Some(expert_action))
    }

    /// A label must have the action's length.
    fn check_label(&self, action: &[f32], expert_action: &[f32]) -> Result<(), RecordError> {
        if expert_action.len() == action.len() {
            return Ok(());
        }
        Err(RecordError::Usage {
            path: self.path.clone(),
            msg: format!(
                "an expert action of {} values for an action of {}",
                expert_action.len(),
                action.len()
            ),
        })
    }

    fn step_with(
        &mut self,
        env: &mut Env,
        action: &[f32],
        expert_action: Option<&[f32]>,
    ) -> Result<(f32, bool, bool), RecordError> {
        // A bad label is refused before the env steps, so the env and the file stay in step.
        if let Some(e) = expert_action {
            self.check_label(action, e)?;
        }
        let before = env.get_state();
        let s = env.step(action).map_err(|source| RecordError::Env {
            path: self.path.clone(),
            source,
        })?;
        let out = (s.reward, s.terminated, s.truncated);
        match expert_action {
            None => self.record_step(env, action, out.0, out.1, out.2, &before)?,
            Some(e) => self.record_labelled_step(env, action, e, out.0, out.1, out.2, &before)?,
        }
        Ok(out)
    }

    /// Ends the open episode: writes `/episode_end` (steps, return = sum of rewards,
    /// `success`), closes the chunk and syncs the file, so the episode survives a crash.
    pub fn end_episode(&mut self, success: bool) -> Result<(), RecordError> {
        let Some(open) = self.open.take() else {
            return Err(RecordError::Usage {
                path: self.path.clone(),
                msg: "end_episode called outside an episode".into(),
            });
        };
        let ns = self.last_ns.unwrap_or(open.start_ns);
        let msg = EpisodeEndMsg {
            episode: open.index,
            steps: open.steps,
            ret: open.ret,
            success,
        };
        self.write_json(self.ch.episode_end, ns, &msg)?;
        self.sync()
    }

    /// Stops recording without closing the file, as if the process had been killed: the
    /// finished episodes (already synced) stay readable and readers report the file as cut
    /// short (`complete == false`); an open episode is dropped. For a run that failed before
    /// it was done, so that its file does not claim to be complete.
    pub fn abandon(self) -> Result<(), RecordError> {
        let path = self.path;
        let file = self.file;
        // `into_inner` without `finish` writes neither the open chunk nor the summary.
        let mut buf = self.writer.into_inner();
        buf.flush()
            .and_then(|()| file.sync_data())
            .map_err(|source| RecordError::Io { path, source })
    }

    /// Writes the summary and footer and syncs the file. An open episode stays unfinished.
    pub fn finish(mut self) -> Result<(), RecordError> {
        self.writer.finish().map_err(|e| self.mcap_err(e))?;
        let path = self.path.clone();
        let io = |source| RecordError::Io {
            path: path.clone(),
            source,
        };
        let mut buf = self.writer.into_inner();
        buf.flush().map_err(io)?;
        self.file.sync_all().map_err(io)
    }
}
