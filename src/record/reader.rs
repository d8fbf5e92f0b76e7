//! Reading recordings back: [`stream`] hands a recording's episodes and steps to a
//! [`Visitor`] as they are read (memory bounded by one chunk), [`read`] collects them into a
//! [`Recording`], and [`read_raw`] returns the MCAP-level records.
//!
//! A file cut short (a killed rollout) is read up to the cut and reported as incomplete; a
//! damaged file (a CRC or structure check fails, see `scan.rs`) is a
//! [`RecordError::Corrupt`] naming the byte offset and chunk, unless salvaging, which keeps
//! what precedes the damage.

use std::collections::BTreeMap;
use std::path::Path;

use super::scan::{scan, At, Item};
use super::{
    BoxError, EpisodeEndMsg, EpisodeMsg, Meta, RecordError, StepMsgIn, EPISODE_METADATA_PREFIX,
    METADATA_NAME, PROFILE, TOPIC_EPISODE, TOPIC_EPISODE_END, TOPIC_STEP,
};
use crate::env::EnvState;

/// One recorded step.
#[derive(Debug, Clone, PartialEq)]
pub struct StepRec {
    /// Action (the one the env executed).
    pub action: Vec<f32>,
    /// The expert's label of the step, when the recording has one (`mjskill rollout
    /// --action-noise`: the policy's own action, where `action` adds noise to it).
    pub expert_action: Option<Vec<f32>>,
    /// Observation after the step.
    pub obs: Vec<f32>,
    /// Reward.
    pub reward: f32,
    /// Terminated flag.
    pub terminated: bool,
    /// Truncated flag.
    pub truncated: bool,
    /// Info after the step: `elapsed_steps`, then the task keys in env order.
    pub info: Vec<(String, f64)>,
    /// Env state *before* the step: `set_state` + `step(action)` replays it.
    pub state: EnvState,
}

/// The start of a recorded episode (the `/episode` message).
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeStart {
    /// Episode index in the file (0-based).
    pub index: u64,
    /// Reset seed.
    pub seed: Option<u64>,
    /// State right after reset.
    pub state: EnvState,
    /// Observation right after reset.
    pub obs: Vec<f32>,
    /// Info right after reset.
    pub info: Vec<(String, f64)>,
}

/// The end of a recorded episode (the `/episode_end` message).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EpisodeEnd {
    /// Episode index.
    pub index: u64,
    /// Steps recorded.
    pub steps: u32,
    /// Return (sum of rewards).
    pub ret: f64,
    /// Success at some step.
    pub success: bool,
}

/// One recorded episode.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeRec {
    /// Episode index in the file (0-based).
    pub index: u64,
    /// Reset seed.
    pub seed: Option<u64>,
    /// State right after reset.
    pub initial_state: EnvState,
    /// Observation right after reset.
    pub initial_obs: Vec<f32>,
    /// Info right after reset.
    pub initial_info: Vec<(String, f64)>,
    /// Steps in order.
    pub steps: Vec<StepRec>,
    /// Whether the episode has its `/episode_end` message.
    pub finished: bool,
    /// Return (sum of rewards): from `/episode_end`, or summed over the steps if unfinished.
    pub ret: f64,
    /// Success flag of `/episode_end` (false if unfinished).
    pub success: bool,
}

/// A recording read back by [`read`].
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    /// File metadata.
    pub meta: Meta,
    /// Episodes in order, including an unfinished last one.
    pub episodes: Vec<EpisodeRec>,
    /// Whether the file ended with its footer (false: cut short, e.g. a killed recorder).
    pub complete: bool,
}

impl Recording {
    /// The episodes that have their `/episode_end`.
    pub fn finished(&self) -> impl Iterator<Item = &EpisodeRec> {
        self.episodes.iter().filter(|e| e.finished)
    }
}

/// Receives a recording's contents from [`stream`], in file order: the metadata first, then
/// for every episode its start, its steps and (if it was finished) its end. An episode that
/// gets no [`Visitor::episode_end`] before the next [`Visitor::episode_start`] or the end of
/// the file was cut short. An `Err` (of any error type, boxed) stops the reading and is
/// returned as [`RecordError::Visitor`], with the visitor's error as its source.
pub trait Visitor {
    /// The file-level metadata, before any episode.
    fn meta(&mut self, meta: &Meta) -> Result<(), BoxError> {
        let _ = meta;
        Ok(())
    }
    /// An episode begins.
    fn episode_start(&mut self, start: EpisodeStart) -> Result<(), BoxError>;
    /// A step of the episode begun last; `index` counts from 0.
    fn step(&mut self, episode: u64, index: u32, step: StepRec) -> Result<(), BoxError>;
    /// The episode begun last ends.
    fn episode_end(&mut self, end: EpisodeEnd) -> Result<(), BoxError>;
}

/// How [`stream`] ended.
#[derive(Debug)]
pub struct StreamEnd {
    /// The file metadata.
    pub meta: Meta,
    /// Whether the file was read to its footer with every check passing.
    pub complete: bool,
    /// Where and how the file was cut short (`None` for a complete or damaged file).
    pub truncated: Option<String>,
    /// With salvage: the damage that stopped the reading (everything before it was read).
    pub damage: Option<RecordError>,
}

/// The mjskill-level decoding of the MCAP records.
struct Decoder<'v> {
    path: &'v Path,
    v: &'v mut dyn Visitor,
    header: bool,
    meta: Option<(Meta, BTreeMap<String, String>)>,
    /// Index and seed text of the last `episode-N` metadata record.
    episode_meta: Option<(u64, String)>,
    /// The open episode: index and steps so far.
    open: Option<(u64, u32)>,
    /// Index of the last `/episode` message.
    last_episode: Option<u64>,
}

impl Decoder<'_> {
    fn corrupt(&self, at: At, detail: String) -> RecordError {
        RecordError::Corrupt {
            path: self.path.to_path_buf(),
            offset: at.offset,
            detail,
        }
    }

    fn visit(path: &Path, r: Result<(), BoxError>) -> Result<(), RecordError> {
        r.map_err(|source| RecordError::Visitor {
            path: path.to_path_buf(),
            source,
        })
    }

    fn item(&mut self, item: Item<'_>, at: At) -> Result<(), RecordError> {
        match item {
            Item::Header { profile, .. } => {
                if profile != PROFILE {
                    return Err(RecordError::NotRecording {
                        path: self.path.to_path_buf(),
                        reason: format!("MCAP profile is {profile:?}, expected {PROFILE:?}"),
                    });
                }
                self.header = true;
                Ok(())
            }
            Item::Metadata { name, map } => self.metadata(name, map, at),
            Item::Message { topic, data, .. } => self.message(topic, data, at),
        }
    }

    fn metadata(
        &mut self,
        name: &str,
        map: &BTreeMap<String, String>,
        at: At,
    ) -> Result<(), RecordError> {
        if name == METADATA_NAME {
            if self.meta.is_some() {
                return Err(self.corrupt(at, format!("a second {METADATA_NAME:?} metadata record")));
            }
            let meta = Meta::from_map(map).map_err(|e| RecordError::Decode {
                path: self.path.to_path_buf(),
                what: format!("metadata at {at}"),
                source: e.into(),
            })?;
            Self::visit(self.path, self.v.meta(&meta))?;
            self.meta = Some((meta, map.clone()));
            return Ok(());
        }
        let Some(n) = name.strip_prefix(EPISODE_METADATA_PREFIX) else {
            return Err(self.corrupt(at, format!("unexpected metadata record {name:?}")));
        };
        let expect = self.episode_meta.as_ref().map_or(0, |(i, _)| i + 1);
        let Some((_, file_map)) = self.meta.as_ref() else {
            return Err(self.corrupt(
                at,
                format!("metadata record {name:?} before the {METADATA_NAME:?} record"),
            ));
        };
        if n != expect.to_string() || map.get("episode") != Some(&expect.to_string()) {
            return Err(self.corrupt(
                at,
                format!("metadata record {name:?} where episode-{expect} belongs"),
            ));
        }
        let mut rest = map.clone();
        rest.remove("episode");
        let seed = rest.remove("seed").unwrap_or_default();
        if &rest != file_map {
            let key = file_map
                .keys()
                .chain(rest.keys())
                .find(|k| file_map.get(*k) != rest.get(*k))
                .cloned()
                .unwrap_or_default();
            return Err(self.corrupt(
                at,
                format!(
                    "metadata record {name:?} differs from the file's {METADATA_NAME:?} record \
                     in {key:?}"
                ),
            ));
        }
        self.episode_meta = Some((expect, seed));
        Ok(())
    }

    fn message(&mut self, topic: &str, data: &[u8], at: At) -> Result<(), RecordError> {
        if !matches!(topic, TOPIC_EPISODE | TOPIC_STEP | TOPIC_EPISODE_END) {
            return Ok(());
        }
        let path = self.path;
        let bad = |source: BoxError| RecordError::Decode {
            path: path.to_path_buf(),
            what: format!("{topic} message in {at}"),
            source,
        };
        let Some((meta, _)) = self.meta.as_ref() else {
            return Err(self.corrupt(at, format!("{topic} message before the metadata")));
        };
        match topic {
            TOPIC_EPISODE => {
                let e: EpisodeMsg = serde_json::from_slice(data).map_err(|e| bad(e.into()))?;
                let seed_text = e.seed.map_or("null".to_string(), |s| s.to_string());
                match &self.episode_meta {
                    Some((i, s)) if *i == e.episode && *s == seed_text => {}
                    _ => {
                        return Err(self.corrupt(
                            at,
                            format!(
                                "episode {} (seed {seed_text}) does not match the last episode \
                                 metadata record {:?}",
                                e.episode, self.episode_meta
                            ),
                        ))
                    }
                }
                if self.last_episode == Some(e.episode) {
                    return Err(self.corrupt(at, format!("episode {} begins twice", e.episode)));
                }
                let st = &e.state;
                if (
                    st.env_id.as_str(),
                    st.robot.as_str(),
                    st.control_mode.as_str(),
                ) != (
                    meta.env_id.as_str(),
                    meta.robot.as_str(),
                    meta.control_mode.as_str(),
                ) {
                    return Err(bad(format!(
                        "state of {}/{}/{} in a recording of {}/{}/{}",
                        st.env_id,
                        st.robot,
                        st.control_mode,
                        meta.env_id,
                        meta.robot,
                        meta.control_mode
                    )
                    .into()));
                }
                self.last_episode = Some(e.episode);
                self.open = Some((e.episode, 0));
                Self::visit(
                    self.path,
                    self.v.episode_start(EpisodeStart {
                        index: e.episode,
                        seed: e.seed,
                        state: e.state,
                        obs: e.obs,
                        info: e.info,
                    }),
                )
            }
            TOPIC_STEP => {
                let s: StepMsgIn = serde_json::from_slice(data).map_err(|e| bad(e.into()))?;
                let n = match self.open {
                    Some((i, n)) if i == s.episode => n,
                    _ => return Err(bad(format!("episode {} is not open", s.episode).into())),
                };
                if s.step != n {
                    return Err(bad(format!(
                        "step {} of episode {} follows {n} steps",
                        s.step, s.episode
                    )
                    .into()));
                }
                if let Some(label) = &s.expert_action {
                    if label.len() != s.action.len() {
                        return Err(bad(format!(
                            "step {} of episode {}: expert_action has {} values, action {}",
                            s.step,
                            s.episode,
                            label.len(),
                            s.action.len()
                        )
                        .into()));
                    }
                }
                self.open = Some((s.episode, n + 1));
                Self::visit(
                    self.path,
                    self.v.step(
                        s.episode,
                        s.step,
                        StepRec {
                            action: s.action,
                            expert_action: s.expert_action,
                            obs: s.obs,
                            reward: s.reward,
                            terminated: s.terminated,
                            truncated: s.truncated,
                            info: s.info,
                            state: s.state_before,
                        },
                    ),
                )
            }
            _ => {
                let e: EpisodeEndMsg = serde_json::from_slice(data).map_err(|e| bad(e.into()))?;
                match self.open {
                    Some((i, n)) if i == e.episode && n == e.steps => {}
                    _ => {
                        return Err(bad(format!(
                            "end of episode {} after {} steps does not match the open episode \
                             {:?}",
                            e.episode, e.steps, self.open
                        )
                        .into()))
                    }
                }
                self.open = None;
                Self::visit(
                    self.path,
                    self.v.episode_end(EpisodeEnd {
                        index: e.episode,
                        steps: e.steps,
                        ret: e.ret,
                        success: e.success,
                    }),
                )
            }
        }
    }
}

/// Reads an mjskill recording from start to end, handing its metadata, episodes and steps to
/// `visitor` as they are read; memory stays bounded by one chunk of the file whatever its
/// size.
///
/// * A file cut short (e.g. the recorder was killed) is read up to the cut:
///   [`StreamEnd::truncated`] says where; only the episodes that got their
///   [`Visitor::episode_end`] were finished. A file cut before its metadata is a
///   [`RecordError::Truncated`].
/// * A damaged file (a chunk CRC, a data or summary section CRC, or a structure check fails)
///   is a [`RecordError::Corrupt`] naming the byte offset and the chunk. With `salvage`, the
///   reading stops there instead and returns what preceded the damage, with the damage in
///   [`StreamEnd::damage`]; a message that does not decode is salvaged the same way.
/// * Errors name the file: unreadable, empty, not MCAP, not an mjskill recording.
pub fn stream(
    path: &Path,
    salvage: bool,
    visitor: &mut dyn Visitor,
) -> Result<StreamEnd, RecordError> {
    let mut d = Decoder {
        path,
        v: visitor,
        header: false,
        meta: None,
        episode_meta: None,
        open: None,
        last_episode: None,
    };
    let r = scan(path, &mut |item, at| d.item(item, at));
    let (complete, truncated, damage) = match r {
        Ok(end) => (end.complete, end.truncated, None),
        Err(e @ (RecordError::Corrupt { .. } | RecordError::Decode { .. }))
            if salvage && d.meta.is_some() =>
        {
            (false, None, Some(e))
        }
        Err(e) => return Err(e),
    };
    let Some((meta, _)) = d.meta else {
        return Err(match truncated {
            Some((offset, detail)) => RecordError::Truncated {
                path: path.to_path_buf(),
                offset,
                detail: format!("{detail}, before its {METADATA_NAME:?} metadata record"),
            },
            None if !d.header => RecordError::NotRecording {
                path: path.to_path_buf(),
                reason: "no MCAP header".into(),
            },
            None => RecordError::NotRecording {
                path: path.to_path_buf(),
                reason: format!("no {METADATA_NAME:?} metadata record"),
            },
        });
    };
    Ok(StreamEnd {
        meta,
        complete,
        truncated: truncated.map(|(_, what)| what),
        damage,
    })
}

/// Collects episodes for [`read`].
#[derive(Default)]
struct Collect {
    episodes: Vec<EpisodeRec>,
}

impl Visitor for Collect {
    fn episode_start(&mut self, s: EpisodeStart) -> Result<(), BoxError> {
        self.episodes.push(EpisodeRec {
            index: s.index,
            seed: s.seed,
            initial_state: s.state,
            initial_obs: s.obs,
            initial_info: s.info,
            steps: Vec::new(),
            finished: false,
            ret: 0.0,
            success: false,
        });
        Ok(())
    }
    fn step(&mut self, _episode: u64, _index: u32, step: StepRec) -> Result<(), BoxError> {
        let ep = self
            .episodes
            .last_mut()
            .ok_or("a step outside an episode")?;
        ep.ret += step.reward as f64;
        ep.steps.push(step);
        Ok(())
    }
    fn episode_end(&mut self, end: EpisodeEnd) -> Result<(), BoxError> {
        let ep = self
            .episodes
            .last_mut()
            .ok_or("an end outside an episode")?;
        ep.finished = true;
        ep.ret = end.ret;
        ep.success = end.success;
        Ok(())
    }
}

/// Reads a whole mjskill recording into memory (see [`stream`] for files of any size). A
/// file cut short (e.g. the recorder was killed) is read up to its last complete chunk, with
/// [`Recording::complete`]` == false`; only episodes with an `/episode_end` message are
/// [`EpisodeRec::finished`]. Errors name the file: unreadable, empty, not MCAP, not an mjskill
/// recording (profile or metadata missing), cut short before its metadata
/// ([`RecordError::Truncated`]), damaged ([`RecordError::Corrupt`], naming the byte offset and
/// chunk), or a message that does not decode.
pub fn read(path: &Path) -> Result<Recording, RecordError> {
    let mut c = Collect::default();
    let end = stream(path, false, &mut c)?;
    Ok(Recording {
        meta: end.meta,
        episodes: c.episodes,
        complete: end.complete,
    })
}

/// One message of any channel, undecoded.
#[derive(Debug, Clone, PartialEq)]
pub struct RawMessage {
    /// Channel topic.
    pub topic: String,
    /// Schema name of the channel (empty if none).
    pub schema: String,
    /// Message encoding of the channel.
    pub encoding: String,
    /// Log time (ns).
    pub log_time: u64,
    /// Payload.
    pub data: Vec<u8>,
}

/// The records of an MCAP file read by [`read_raw`].
#[derive(Debug, Clone, PartialEq)]
pub struct RawRecording {
    /// Header profile.
    pub profile: String,
    /// Header library.
    pub library: String,
    /// The `"mjskill"` metadata map (empty if absent).
    pub metadata: BTreeMap<String, String>,
    /// The per-episode metadata maps (`episode-N` records), in file order.
    pub episode_metadata: Vec<BTreeMap<String, String>>,
    /// All messages in file order.
    pub messages: Vec<RawMessage>,
    /// Whether the file was read to its footer with every check passing.
    pub complete: bool,
}

/// Reads every record of an MCAP file into memory, tolerating a file cut short (no summary or
/// footer, a partial last record): records up to the cut are returned with
/// `complete == false`. Errors if the file is unreadable, not MCAP, cut before its header, or
/// damaged ([`RecordError::Corrupt`]).
pub fn read_raw(path: &Path) -> Result<RawRecording, RecordError> {
    let mut raw = RawRecording {
        profile: String::new(),
        library: String::new(),
        metadata: BTreeMap::new(),
        episode_metadata: Vec::new(),
        messages: Vec::new(),
        complete: false,
    };
    let mut header = false;
    let end = scan(path, &mut |item, _| {
        match item {
            Item::Header { profile, library } => {
                header = true;
                raw.profile = profile.to_string();
                raw.library = library.to_string();
            }
            Item::Metadata { name, map } if name == METADATA_NAME => raw.metadata = map.clone(),
            Item::Metadata { name, map } if name.starts_with(EPISODE_METADATA_PREFIX) => {
                raw.episode_metadata.push(map.clone())
            }
            Item::Metadata { .. } => {}
            Item::Message {
                topic,
                schema,
                encoding,
                log_time,
                data,
            } => raw.messages.push(RawMessage {
                topic: topic.to_string(),
                schema: schema.to_string(),
                encoding: encoding.to_string(),
                log_time,
                data: data.to_vec(),
            }),
        }
        Ok(())
    })?;
    if !header {
        return Err(match end.truncated {
            Some((offset, detail)) => RecordError::Truncated {
                path: path.to_path_buf(),
                offset,
                detail: format!("{detail}, before its header"),
            },
            None => RecordError::NotRecording {
                path: path.to_path_buf(),
                reason: "no MCAP header".into(),
            },
        });
    }
    raw.complete = end.complete;
    Ok(raw)
}
