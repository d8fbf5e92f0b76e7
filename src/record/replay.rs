//! Replay verification: re-simulates the episodes of a recording from their seeds (or
//! initial states) and recorded actions and reports the largest deviations of observations,
//! rewards, info and flags (`mjskill replay`, and the reference-trajectory test).
use std::path::Path;

use serde::Serialize;

use super::{
    stream, BoxError, EpisodeEnd, EpisodeStart, Meta, RecordError, Recording, StepRec, Visitor,
};
use crate::env::{Env, EnvError};

/// Why a recording could not be replayed (deviations beyond the tolerance are not errors:
/// they are reported in [`ReplayReport::ok`]).
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// A negative or non-finite tolerance.
    #[error("--tolerance must be a finite number ≥ 0, got {0}")]
    BadTolerance(f64),
    /// The file could not be read (or the replay stopped while reading it: the source).
    #[error(transparent)]
    Record(#[from] RecordError),
    /// The env of the recording's metadata could not be built.
    #[error(transparent)]
    Env(#[from] EnvError),
    /// The recording's messages are out of order.
    #[error("{0}")]
    Order(&'static str),
    /// An episode's initial state or one of its actions was rejected by the env.
    #[error("episode {index}: {source}")]
    Episode {
        /// The episode.
        index: u64,
        /// The env's error.
        source: EnvError,
    },
    /// The file holds no finished episode.
    #[error("{}: no finished episode to replay", .0.display())]
    NoEpisodes(std::path::PathBuf),
    /// With salvage: the damage comes before the first finished episode.
    #[error("no finished episode to replay before the damage: {0}")]
    NoEpisodesBeforeDamage(#[source] RecordError),
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
    /// With `--salvage`: the damage where reading stopped (what precedes it was replayed).
    pub damage: Option<String>,
}

fn max_dev(a: &[f32], b: &[f32]) -> f64 {
    if a.len() != b.len() {
        return f64::INFINITY;
    }
    a.iter()
        .zip(b)
        .map(|(x, y)| {
            let d = (*x as f64 - *y as f64).abs();
            // A NaN on either side (a non-finite value was recorded) is a deviation unless
            // both sides hold the same non-finite value.
            if d.is_nan() && x.to_bits() != y.to_bits() {
                f64::INFINITY
            } else if d.is_nan() {
                0.0
            } else {
                d
            }
        })
        .fold(0.0, f64::max)
}

/// Deviations of the episode being replayed; they count once it is finished.
#[derive(Debug, Default)]
struct EpisodeDev {
    index: u64,
    obs: f64,
    reward: f64,
    info: f64,
    flags: usize,
    steps: usize,
    /// The first error (e.g. a rejected action); reported only if the episode was finished.
    error: Option<EnvError>,
}

/// Re-simulates episodes as they are read.
struct Replayer {
    env: Option<Env>,
    rep: ReplayReport,
    cur: Option<EpisodeDev>,
}

impl Replayer {
    fn new(path: &Path, tolerance: f64) -> Replayer {
        Replayer {
            env: None,
            rep: ReplayReport {
                file: path.display().to_string(),
                tolerance,
                ..Default::default()
            },
            cur: None,
        }
    }

    fn finish(mut self) -> ReplayReport {
        let t = self.rep.tolerance;
        let r = &mut self.rep;
        r.ok = r.max_obs_dev <= t
            && r.max_reward_dev <= t
            && r.max_info_dev <= t
            && r.flag_mismatches == 0;
        self.rep
    }
}

impl Visitor for Replayer {
    fn meta(&mut self, m: &Meta) -> Result<(), BoxError> {
        Ok(self.begin(m)?)
    }
    fn episode_start(&mut self, s: EpisodeStart) -> Result<(), BoxError> {
        Ok(self.episode_start(s)?)
    }
    fn step(&mut self, _: u64, _: u32, st: StepRec) -> Result<(), BoxError> {
        Ok(self.step(st)?)
    }
    fn episode_end(&mut self, _: EpisodeEnd) -> Result<(), BoxError> {
        Ok(self.episode_end()?)
    }
}

impl Replayer {
    fn begin(&mut self, m: &Meta) -> Result<(), ReplayError> {
        let config = m.config()?;
        self.env = Some(crate::env::make(&m.env_id, config)?);
        Ok(())
    }

    fn episode_start(&mut self, s: EpisodeStart) -> Result<(), ReplayError> {
        let env = self
            .env
            .as_mut()
            .ok_or(ReplayError::Order("an episode before the metadata"))?;
        let mut dev = EpisodeDev {
            index: s.index,
            ..Default::default()
        };
        // The recorded state is checked as `set_state` checks it, also where the episode
        // replays from its seed: a recording whose states could not be restored is refused.
        let r = match s.seed {
            Some(seed) => env
                .check_state(&s.state)
                .map_err(|e| recorded_state("the recorded initial state", e))
                .map(|()| {
                    env.reset(Some(seed));
                }),
            None => env.set_state(&s.state),
        };
        match r {
            Ok(()) => dev.obs = max_dev(env.obs(), &s.obs),
            Err(e) => dev.error = Some(e),
        }
        self.cur = Some(dev);
        Ok(())
    }

    fn step(&mut self, st: StepRec) -> Result<(), ReplayError> {
        let (Some(env), Some(dev)) = (self.env.as_mut(), self.cur.as_mut()) else {
            return Err(ReplayError::Order("a step outside an episode"));
        };
        if dev.error.is_some() {
            return Ok(());
        }
        if let Err(e) = env.check_state(&st.state) {
            let what = format!("the recorded state before step {}", dev.steps);
            dev.error = Some(recorded_state(&what, e));
            return Ok(());
        }
        let s = match env.step(&st.action) {
            Ok(s) => s,
            Err(e) => {
                dev.error = Some(e);
                return Ok(());
            }
        };
        dev.obs = dev.obs.max(max_dev(s.obs, &st.obs));
        dev.reward = dev.reward.max(max_dev(&[s.reward], &[st.reward]));
        dev.flags += usize::from(s.terminated != st.terminated || s.truncated != st.truncated);
        for (k, v) in &st.info {
            let now = if k == "elapsed_steps" {
                Some(s.info.elapsed_steps as f64)
            } else {
                s.info.get(k)
            };
            let d = now.map_or(f64::INFINITY, |n| {
                let d = (n - v).abs();
                if d.is_nan() {
                    f64::INFINITY
                } else {
                    d
                }
            });
            dev.info = dev.info.max(d);
        }
        dev.steps += 1;
        Ok(())
    }

    fn episode_end(&mut self) -> Result<(), ReplayError> {
        let dev = self
            .cur
            .take()
            .ok_or(ReplayError::Order("an episode end outside an episode"))?;
        if let Some(source) = dev.error {
            return Err(ReplayError::Episode {
                index: dev.index,
                source,
            });
        }
        let r = &mut self.rep;
        r.max_obs_dev = r.max_obs_dev.max(dev.obs);
        r.max_reward_dev = r.max_reward_dev.max(dev.reward);
        r.max_info_dev = r.max_info_dev.max(dev.info);
        r.flag_mismatches += dev.flags;
        r.steps += dev.steps;
        r.episodes += 1;
        Ok(())
    }
}

/// A recorded state that [`Env::check_state`] refuses, saying which (`what`).
fn recorded_state(what: &str, e: EnvError) -> EnvError {
    match e {
        EnvError::BadState(why) => EnvError::BadState(format!("{what}: {why}")),
        other => other,
    }
}

/// Re-simulates every finished episode of a recording read by [`super::read`] from
/// its seed (or initial state) and recorded actions.
pub fn replay_recording(
    path: &Path,
    r: &Recording,
    tolerance: f64,
) -> Result<ReplayReport, ReplayError> {
    check_tolerance(tolerance)?;
    let mut p = Replayer::new(path, tolerance);
    p.begin(&r.meta)?;
    for ep in r.finished() {
        p.episode_start(EpisodeStart {
            index: ep.index,
            seed: ep.seed,
            state: ep.initial_state.clone(),
            obs: ep.initial_obs.clone(),
            info: ep.initial_info.clone(),
        })?;
        for st in &ep.steps {
            p.step(st.clone())?;
        }
        p.episode_end()?;
    }
    Ok(p.finish())
}

/// Checks a replay tolerance: a finite number ≥ 0.
pub fn check_tolerance(tolerance: f64) -> Result<(), ReplayError> {
    if !(tolerance.is_finite() && tolerance >= 0.0) {
        return Err(ReplayError::BadTolerance(tolerance));
    }
    Ok(())
}

/// `mjskill replay`: reads the file and re-simulates each finished episode as it is read
/// (memory bounded by one chunk and one env). A damaged file is an error naming the byte
/// offset and chunk; with `salvage`, the episodes that precede the damage are replayed and the
/// damage reported in [`ReplayReport::damage`].
pub fn replay(path: &Path, tolerance: f64, salvage: bool) -> Result<ReplayReport, ReplayError> {
    check_tolerance(tolerance)?;
    let mut p = Replayer::new(path, tolerance);
    let end = stream(path, salvage, &mut p)?;
    let mut rep = p.finish();
    rep.damage = end.damage.as_ref().map(|e| e.to_string());
    if rep.episodes == 0 {
        return Err(match end.damage {
            Some(d) => ReplayError::NoEpisodesBeforeDamage(d),
            None => ReplayError::NoEpisodes(path.to_path_buf()),
        });
    }
    Ok(rep)
}
