//! Replay verification: re-simulates the episodes of a recording from their seeds (or
//! initial states) and recorded actions and reports the largest deviations of observations,
//! rewards, info and flags (`mjskill replay`, and the reference-trajectory test).
use std::path::Path;

use serde::Serialize;

use super::{stream, EpisodeEnd, EpisodeStart, Meta, Recording, StepRec, Visitor};
use crate::env::Env;

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
    error: Option<String>,
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
    fn meta(&mut self, m: &Meta) -> Result<(), String> {
        let config = m.config().map_err(|e| e.to_string())?;
        self.env = Some(crate::env::make(&m.env_id, config).map_err(|e| e.to_string())?);
        Ok(())
    }

    fn episode_start(&mut self, s: EpisodeStart) -> Result<(), String> {
        let env = self.env.as_mut().ok_or("an episode before the metadata")?;
        let mut dev = EpisodeDev {
            index: s.index,
            ..Default::default()
        };
        let r = match s.seed {
            Some(seed) => {
                env.reset(Some(seed));
                Ok(())
            }
            None => env.set_state(&s.state).map_err(|e| e.to_string()),
        };
        match r {
            Ok(()) => dev.obs = max_dev(env.obs(), &s.obs),
            Err(e) => dev.error = Some(e),
        }
        self.cur = Some(dev);
        Ok(())
    }

    fn step(&mut self, _: u64, _: u32, st: StepRec) -> Result<(), String> {
        let (Some(env), Some(dev)) = (self.env.as_mut(), self.cur.as_mut()) else {
            return Err("a step outside an episode".into());
        };
        if dev.error.is_some() {
            return Ok(());
        }
        let s = match env.step(&st.action) {
            Ok(s) => s,
            Err(e) => {
                dev.error = Some(e.to_string());
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

    fn episode_end(&mut self, _: EpisodeEnd) -> Result<(), String> {
        let dev = self.cur.take().ok_or("an episode end outside an episode")?;
        if let Some(e) = dev.error {
            return Err(format!("episode {}: {e}", dev.index));
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

/// Re-simulates every finished episode of a recording read by [`super::read`] from
/// its seed (or initial state) and recorded actions.
pub fn replay_recording(
    path: &Path,
    r: &Recording,
    tolerance: f64,
) -> Result<ReplayReport, String> {
    check_tolerance(tolerance)?;
    let mut p = Replayer::new(path, tolerance);
    p.meta(&r.meta)?;
    for ep in r.finished() {
        p.episode_start(EpisodeStart {
            index: ep.index,
            seed: ep.seed,
            state: ep.initial_state.clone(),
            obs: ep.initial_obs.clone(),
            info: ep.initial_info.clone(),
        })?;
        for (t, st) in ep.steps.iter().enumerate() {
            p.step(ep.index, t as u32, st.clone())?;
        }
        p.episode_end(EpisodeEnd {
            index: ep.index,
            steps: ep.steps.len() as u32,
            ret: ep.ret,
            success: ep.success,
        })?;
    }
    Ok(p.finish())
}

/// Checks a replay tolerance: a finite number ≥ 0.
pub fn check_tolerance(tolerance: f64) -> Result<(), String> {
    if !(tolerance.is_finite() && tolerance >= 0.0) {
        return Err(format!(
            "--tolerance must be a finite number ≥ 0, got {tolerance}"
        ));
    }
    Ok(())
}

/// `mjskill replay`: reads the file and re-simulates each finished episode as it is read
/// (memory bounded by one chunk and one env). A damaged file is an error naming the byte
/// offset and chunk; with `salvage`, the episodes that precede the damage are replayed and the
/// damage reported in [`ReplayReport::damage`].
pub fn replay(path: &Path, tolerance: f64, salvage: bool) -> Result<ReplayReport, String> {
    check_tolerance(tolerance)?;
    let mut p = Replayer::new(path, tolerance);
    let end = stream(path, salvage, &mut p).map_err(|e| e.to_string())?;
    let mut rep = p.finish();
    rep.damage = end.damage.map(|e| e.to_string());
    if rep.episodes == 0 {
        return Err(match rep.damage {
            Some(d) => format!("no finished episode to replay before the damage: {d}"),
            None => format!("{}: no finished episode to replay", path.display()),
        });
    }
    Ok(rep)
}
