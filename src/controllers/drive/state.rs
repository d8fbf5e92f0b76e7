//! The drives' part of a saved state ([`super::Drives::save`]): the targets, the SO100 jaw's
//! release counters, the pinch's kick flag and the pinch replica's contact cache.
use super::Drives;
use crate::controllers::tgs::CACHED_PATCH_LEN;

impl Drives {
    /// Appends the drives' state to `out`: the targets (position then velocity, per drive),
    /// then, for a robot whose gripper lets go of deep contacts (the SO100's jaw, see
    /// `Drives::release_deep_contacts`), the release counters (per drive, the substeps in a
    /// row its gripper has been sunk deeper than the release depth), which decide the next
    /// substeps' releases, then the pinch's kick flag where the robot can take it, then the
    /// pinch replica's contact cache where it is enabled ([`PinchReplica::save`](crate::controllers::tgs::PinchReplica::save)): with them
    /// a restored state continues bit for bit.
    pub fn save(&self, out: &mut Vec<f64>) {
        self.save_targets(out);
        if self.release_depth.is_some() {
            out.extend(self.deep_substeps.iter().map(|&c| f64::from(c)));
        }
        if self.can_kick {
            out.push(if self.kicking { 1.0 } else { 0.0 });
        }
        if let Some(p) = &self.pinch {
            p.save(out);
        }
    }

    /// Number of values [`Drives::save`] writes.
    pub fn save_len(&self) -> usize {
        self.targets_len() + self.counters_len() + usize::from(self.can_kick) + self.cache_len()
    }

    /// Number of values of the pinch replica's contact cache in a saved state.
    fn cache_len(&self) -> usize {
        self.pinch.as_ref().map_or(0, |p| p.save_len())
    }

    /// Number of release counters [`Drives::save`] writes (0 for a robot without a release
    /// depth).
    fn counters_len(&self) -> usize {
        if self.release_depth.is_some() {
            self.dofs.len()
        } else {
            0
        }
    }

    /// Appends the targets alone (position then velocity, per drive) to `out`.
    pub fn save_targets(&self, out: &mut Vec<f64>) {
        out.extend_from_slice(&self.target_q);
        out.extend_from_slice(&self.target_v);
    }

    /// Number of values [`Drives::save_targets`] writes: also the length of a saved state
    /// from before the release counters were part of it, which [`Drives::load`] takes
    /// (with the counters at zero).
    pub fn targets_len(&self) -> usize {
        2 * self.dofs.len()
    }

    /// Checks the release counters, the kick flag and the pinch replica's contact cache of
    /// `s`, a state of [`Drives::save_len`] (or [`Drives::targets_len`]) values: each counter
    /// must be a whole number from 0 to `u32::MAX`, the flag 0 or 1, the cache's anchor
    /// counts 0, 1 or 2, its broken flags 0 or 1 and its values finite. The error gives the
    /// value's index in `s`, the value and the valid range.
    pub fn check_saved(&self, s: &[f64]) -> Result<(), (usize, f64, String)> {
        let from = self.targets_len();
        let counters = from..from + self.counters_len();
        let kick = counters.end..counters.end + usize::from(self.can_kick);
        for (i, &x) in s.iter().enumerate().skip(from) {
            if kick.contains(&i) {
                if x != 0.0 && x != 1.0 {
                    return Err((i, x, "is not a pinch's kick flag (0 or 1)".to_string()));
                }
            } else if counters.contains(&i) {
                if !(0.0..=f64::from(u32::MAX)).contains(&x) || x.fract() != 0.0 {
                    return Err((
                        i,
                        x,
                        format!(
                            "is not a jaw release count (a whole number of substeps from 0 to {})",
                            u32::MAX
                        ),
                    ));
                }
            } else {
                let k = (i - kick.end) % CACHED_PATCH_LEN;
                if k == 0 && ![0.0, 1.0, 2.0].contains(&x) {
                    return Err((
                        i,
                        x,
                        "is not a cached friction patch's anchor count (0, 1 or 2)".to_string(),
                    ));
                }
                if k == 1 && x != 0.0 && x != 1.0 {
                    return Err((
                        i,
                        x,
                        "is not a cached friction patch's broken flag (0 or 1)".to_string(),
                    ));
                }
                if !x.is_finite() {
                    return Err((i, x, "is not a finite contact-cache value".to_string()));
                }
            }
        }
        Ok(())
    }

    /// Forgets the last substep's contacts (see `Drives::release_deep_contacts`) and the pinch
    /// replica's contact cache: at a reset nothing is sunk into anything yet.
    pub fn forget_contacts(&mut self) {
        self.deep_substeps.fill(0);
        self.kicking = false;
        if let Some(p) = self.pinch.as_deref_mut() {
            p.forget_contacts();
        }
    }

    /// Restores what [`Drives::save`] wrote; a state of [`Drives::targets_len`] values (the
    /// targets alone) restores the release counters at zero and forgets the contact cache.
    /// Counters must have passed [`Drives::check_saved`] (others are clamped into range).
    pub fn load(&mut self, s: &[f64]) {
        self.load_targets(s);
        self.forget_contacts();
        if s.len() >= self.save_len() {
            let from = self.targets_len();
            for (c, &x) in self.deep_substeps.iter_mut().zip(&s[from..]) {
                // In range after check_saved; `as` saturates anything else.
                *c = x as u32;
            }
            let at = from + self.counters_len();
            if self.can_kick {
                self.kicking = s[at] != 0.0;
            }
            let at = at + usize::from(self.can_kick);
            if let Some(p) = self.pinch.as_deref_mut() {
                p.load(&s[at..]);
            }
        }
    }

    /// Restores the targets from what [`Drives::save_targets`] (or [`Drives::save`]) wrote,
    /// leaving the release counters as they are.
    pub fn load_targets(&mut self, s: &[f64]) {
        let n = self.dofs.len();
        self.target_q.copy_from_slice(&s[..n]);
        self.target_v.copy_from_slice(&s[n..2 * n]);
    }
}
