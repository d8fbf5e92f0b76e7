//! Gaussian action noise for noise-injected demonstrations (DART): the env executes the
//! expert's action plus seeded Gaussian noise, clipped to the action space, while the
//! recording keeps the expert's own action as the label (`mjskill rollout --action-noise`,
//! docs/training.md, "Cloning from noisy demonstrations").
//!
//! The noise is counter based: entry `k` of step `t` of the episode reset with seed `s` draws
//! ε from a ChaCha8 stream keyed by the noise seed, on stream `s`, at word position
//! `t · 2^20`; the `k`-th standard normal drawn there is entry `k`'s. So the noise of a step
//! depends only on (noise seed, episode seed, step, entry), never on the σ of other entries
//! or on earlier episodes, and the same command records the same actions bit for bit.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::env::Env;

/// Words of the random stream reserved for one step (2^20, far more than any action needs).
const WORDS_PER_STEP: u32 = 20;

/// Why a noise specification is refused; every message names the bad value and the valid
/// choices.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NoiseError {
    /// The specification is empty.
    #[error(
        "--action-noise is empty; give one σ for every action entry (e.g. 0.05), one per \
         part ({parts}), or {dim} comma-separated values"
    )]
    Empty {
        /// The parts, as `name=σ` hints.
        parts: String,
        /// Action entries.
        dim: usize,
    },
    /// A σ that is not a number.
    #[error("--action-noise {spec:?}: {value:?} is not a number")]
    NotANumber {
        /// The whole specification.
        spec: String,
        /// The bad value.
        value: String,
    },
    /// A σ that is NaN, infinite or negative.
    #[error("--action-noise {spec:?}: σ {value} must be a finite number >= 0")]
    BadSigma {
        /// The whole specification.
        spec: String,
        /// The bad value.
        value: String,
    },
    /// A part name the control mode does not have.
    #[error(
        "--action-noise {spec:?}: {robot} in {mode} has no action part {name:?}; its parts: \
         {valid}"
    )]
    UnknownPart {
        /// The whole specification.
        spec: String,
        /// The unknown name.
        name: String,
        /// The robot.
        robot: String,
        /// The control mode.
        mode: String,
        /// The valid part names.
        valid: String,
    },
    /// A part named twice.
    #[error("--action-noise {spec:?}: part {name:?} is given twice")]
    DuplicatePart {
        /// The whole specification.
        spec: String,
        /// The repeated name.
        name: String,
    },
    /// Parts of the control mode left out of a per-part specification.
    #[error(
        "--action-noise {spec:?}: {robot} in {mode} also has the part(s) {missing}; give \
         every part a σ (name=0 for none)"
    )]
    MissingParts {
        /// The whole specification.
        spec: String,
        /// The robot.
        robot: String,
        /// The control mode.
        mode: String,
        /// The parts left out.
        missing: String,
    },
    /// A list of values of another length than the action's, or a mix of the forms.
    #[error(
        "--action-noise {spec:?}: {got} values, but {robot} in {mode} has {dim} action \
         entries ({layout}); give one σ for all, one per part (name=σ,...), or one per entry"
    )]
    WrongCount {
        /// The whole specification.
        spec: String,
        /// Values given.
        got: usize,
        /// Action entries.
        dim: usize,
        /// The robot.
        robot: String,
        /// The control mode.
        mode: String,
        /// The parts and their entry ranges.
        layout: String,
    },
}

/// Seeded Gaussian noise added to an expert's actions: see the [module docs](self).
/// [`ActionNoise::apply`] draws into the caller's buffer and allocates nothing.
#[derive(Debug, Clone)]
pub struct ActionNoise {
    sigma: Vec<f32>,
    low: Vec<f32>,
    high: Vec<f32>,
    seed: u64,
    episode_seed: u64,
    step: u64,
}

impl ActionNoise {
    /// The noise of `spec` for `env`'s action, seeded with `seed`. `spec` is one σ for every
    /// action entry (`0.05`), one σ per action part of the env's control mode
    /// (`arm=0.02,gripper=0`: every part named once, [`Env::action_parts`]), or one σ per
    /// action entry (`0.02,0.02,0.02,0`). Every σ must be finite and >= 0.
    pub fn parse(spec: &str, env: &Env, seed: u64) -> Result<ActionNoise, NoiseError> {
        let space = env.action_space();
        let dim = space.shape[0];
        let parts = env.action_parts();
        let robot = env.robot_spec().uid().to_string();
        let mode = env.control_mode().to_string();
        let names = || parts.iter().map(|p| p.name).collect::<Vec<_>>().join(", ");
        let sigma_of = |value: &str| -> Result<f32, NoiseError> {
            let v: f64 = value.trim().parse().map_err(|_| NoiseError::NotANumber {
                spec: spec.to_string(),
                value: value.trim().to_string(),
            })?;
            // Within f32's range too: a σ that rounds to infinity is no finite σ.
            if !(v.is_finite() && v >= 0.0 && (v as f32).is_finite()) {
                return Err(NoiseError::BadSigma {
                    spec: spec.to_string(),
                    value: value.trim().to_string(),
                });
            }
            Ok(v as f32)
        };
        let items: Vec<&str> = spec.split(',').collect();
        if spec.trim().is_empty() {
            return Err(NoiseError::Empty {
                parts: parts
                    .iter()
                    .map(|p| format!("{}=σ", p.name))
                    .collect::<Vec<_>>()
                    .join(","),
                dim,
            });
        }
        let named = items.iter().filter(|s| s.contains('=')).count();
        let wrong_count = |got: usize| NoiseError::WrongCount {
            spec: spec.to_string(),
            got,
            dim,
            robot: robot.clone(),
            mode: mode.clone(),
            layout: parts
                .iter()
                .map(|p| format!("{} {}..{}", p.name, p.range.start, p.range.end))
                .collect::<Vec<_>>()
                .join(", "),
        };
        let mut sigma = vec![0.0f32; dim];
        if named == 0 {
            let values = items
                .iter()
                .map(|s| sigma_of(s))
                .collect::<Result<Vec<_>, _>>()?;
            match values.len() {
                1 => sigma.fill(values[0]),
                n if n == dim => sigma.copy_from_slice(&values),
                n => return Err(wrong_count(n)),
            }
        } else if named < items.len() {
            // A mix of name=σ and bare values.
            return Err(wrong_count(items.len()));
        } else {
            let mut seen: Vec<&str> = Vec::with_capacity(items.len());
            for item in &items {
                let (name, value) = item.split_once('=').expect("counted as named");
                let name = name.trim();
                let part = parts.iter().find(|p| p.name == name).ok_or_else(|| {
                    NoiseError::UnknownPart {
                        spec: spec.to_string(),
                        name: name.to_string(),
                        robot: robot.clone(),
                        mode: mode.clone(),
                        valid: names(),
                    }
                })?;
                if seen.contains(&name) {
                    return Err(NoiseError::DuplicatePart {
                        spec: spec.to_string(),
                        name: name.to_string(),
                    });
                }
                seen.push(name);
                sigma[part.range.clone()].fill(sigma_of(value)?);
            }
            let missing: Vec<&str> = parts
                .iter()
                .map(|p| p.name)
                .filter(|n| !seen.contains(n))
                .collect();
            if !missing.is_empty() {
                return Err(NoiseError::MissingParts {
                    spec: spec.to_string(),
                    robot,
                    mode,
                    missing: missing.join(", "),
                });
            }
        }
        Ok(ActionNoise {
            sigma,
            low: space.low.clone(),
            high: space.high.clone(),
            seed,
            episode_seed: 0,
            step: 0,
        })
    }

    /// The σ of every action entry.
    pub fn sigma(&self) -> &[f32] {
        &self.sigma
    }

    /// The noise seed.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// Starts the noise of the episode reset with `episode_seed` (its step 0 next).
    pub fn reset(&mut self, episode_seed: u64) {
        self.episode_seed = episode_seed;
        self.step = 0;
    }

    /// Writes `clip(label + σ·ε, low, high)` into `out` for the episode's next step, where ε
    /// is this step's standard normal draw (module docs); `label` and `out` have the action's
    /// length. Entries with σ 0 are `label`'s, clipped.
    pub fn apply(&mut self, label: &[f32], out: &mut [f32]) {
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        rng.set_stream(self.episode_seed);
        rng.set_word_pos(u128::from(self.step) << WORDS_PER_STEP);
        self.step += 1;
        for (k, (o, &a)) in out.iter_mut().zip(label).enumerate() {
            let eps: f32 = StandardNormal.sample(&mut rng);
            let s = self.sigma[k];
            let x = if s > 0.0 { a + s * eps } else { a };
            *o = x.clamp(self.low[k], self.high[k]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::env::{make, EnvConfig};

    fn env(robot: &str, mode: &str) -> Env {
        make(
            "PickCube-v1",
            EnvConfig {
                robot: Some(robot.into()),
                control_mode: Some(mode.into()),
                ..Default::default()
            },
        )
        .unwrap()
    }

    #[test]
    fn the_three_forms_give_per_entry_sigmas() {
        let e = env("panda", "pd_ee_delta_pos");
        let all = ActionNoise::parse("0.05", &e, 0).unwrap();
        assert_eq!(all.sigma(), &[0.05; 4]);
        let parts = ActionNoise::parse("gripper=0, arm=0.02", &e, 0).unwrap();
        assert_eq!(parts.sigma(), &[0.02, 0.02, 0.02, 0.0]);
        let each = ActionNoise::parse("0.1,0.2,0.3,0", &e, 0).unwrap();
        assert_eq!(each.sigma(), &[0.1, 0.2, 0.3, 0.0]);
    }

    #[test]
    fn noise_has_the_sigma_stays_in_bounds_and_repeats() {
        let e = env("panda", "pd_ee_delta_pos");
        let mut n = ActionNoise::parse("arm=0.1,gripper=0", &e, 7).unwrap();
        let label = [0.0f32, 0.5, -0.5, 1.0];
        let mut out = [0.0f32; 4];
        let mut sum = [0.0f64; 3];
        let mut sq = [0.0f64; 3];
        let steps = 2000;
        let mut first = Vec::new();
        n.reset(3);
        for t in 0..steps {
            n.apply(&label, &mut out);
            if t < 5 {
                first.push(out);
            }
            assert_eq!(out[3], 1.0, "σ 0: the label");
            for k in 0..3 {
                assert!((-1.0..=1.0).contains(&out[k]));
                let d = (out[k] - label[k]) as f64;
                sum[k] += d;
                sq[k] += d * d;
            }
        }
        for k in 0..3 {
            let mean = sum[k] / steps as f64;
            let std = (sq[k] / steps as f64 - mean * mean).sqrt();
            assert!(
                mean.abs() < 0.01 && (std - 0.1).abs() < 0.01,
                "{k}: {mean} {std}"
            );
        }
        // The same episode seed gives the same noise; another one other noise.
        n.reset(3);
        let mut again = Vec::new();
        for _ in 0..5 {
            n.apply(&label, &mut out);
            again.push(out);
        }
        assert_eq!(first, again);
        n.reset(4);
        n.apply(&label, &mut out);
        assert_ne!(first[0], out);
    }

    #[test]
    fn bad_specs_name_the_value_and_the_choices() {
        let e = env("fetch", "pd_joint_pos");
        let err = |s: &str| ActionNoise::parse(s, &e, 0).unwrap_err().to_string();
        let m = err("hand=0.1,arm=0");
        assert!(
            m.contains("\"hand\"") && m.contains("arm, gripper, body, base"),
            "{m}"
        );
        let m = err("arm=0.1");
        assert!(
            m.contains("body") && m.contains("base") && m.contains("=0"),
            "{m}"
        );
        let m = err("arm=0.1,arm=0.2,gripper=0,body=0,base=0");
        assert!(m.contains("\"arm\" is given twice"), "{m}");
        for bad in ["nan", "-0.1", "inf", "1e39"] {
            let m = err(bad);
            assert!(m.contains(bad) && m.contains("finite number >= 0"), "{m}");
        }
        let m = err("0.1,x");
        assert!(m.contains("\"x\" is not a number"), "{m}");
        let m = err("0.1,0.2");
        assert!(
            m.contains("2 values") && m.contains("13 action entries") && m.contains("arm 0..7"),
            "{m}"
        );
        let m = err("arm=0.1,0.2");
        assert!(m.contains("2 values"), "{m}");
        let m = err(" ");
        assert!(m.contains("empty") && m.contains("arm=σ"), "{m}");
    }
}
