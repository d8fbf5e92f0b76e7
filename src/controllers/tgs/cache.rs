//! PhysX's contact cache for the pinch replica ([`super::PinchReplica`]): which friction
//! anchors a jaw part keeps from one step to the next (`getFrictionPatches`,
//! `correlatePatches` and `growPatches` in PhysX 5.3.1's `DyContactPrepShared.h` and
//! `DyFrictionCorrelation.cpp`), and the cache's place in a saved state.
use nalgebra::Vector3;

use super::{body_pose, PinchReplica};
use crate::mujoco::Data;

/// A jaw part's friction patch kept from the last step (PhysX's contact cache): its
/// anchors, normal (in each body's frame) and whether its friction broke.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CachedPatch {
    /// Anchors kept (0: no patch cached).
    pub anchor_count: usize,
    /// The anchors on body 0 (the jaw) and body 1 (the object), in their frames.
    pub anchor0: [Vector3<f64>; 2],
    /// See `anchor0`.
    pub anchor1: [Vector3<f64>; 2],
    /// The patch normal in body 0's and body 1's frames.
    pub normal0: Vector3<f64>,
    /// See `normal0`.
    pub normal1: Vector3<f64>,
    /// Whether the friction broke (was clamped) in the step's last pass.
    pub broken: bool,
}

/// Values per cached patch in a saved state ([`PinchReplica::save`]).
pub const CACHED_PATCH_LEN: usize = 2 + 4 * 3 + 2 * 3;

/// PhysX's `frictionCorrelationDistance` (SAPIEN keeps PhysX's default): a cached anchor pair
/// that has come apart along the normal by more is dropped.
pub const CORRELATION_DISTANCE: f64 = 0.025;
/// PhysX's `frictionOffsetThreshold` (default): contacts separated by more make no anchors.
pub const FRICTION_OFFSET_THRESHOLD: f64 = 0.04;
/// PhysX's `PXC_SAME_NORMAL`: normals within about 2.5° are the same patch's.
pub const SAME_NORMAL: f64 = 0.999;

impl PinchReplica {
    /// The friction anchors of patch `pi`, as PhysX's `getFrictionPatches`,
    /// `correlatePatches` and `growPatches` choose them: a jaw part's cached patch is kept
    /// if its friction did not break, the bodies have not turned its normal by more than
    /// about 2.5°, no anchor pair has come [`CORRELATION_DISTANCE`] apart along it, the new
    /// contacts share its normal and (with two anchors) the anchors still span a quarter of
    /// the contacts' extent; the anchors missing are the contacts farthest apart.
    pub(super) fn grow_anchors(&mut self, data: &Data, pi: usize) {
        let patch = self.patches[pi];
        let bodies = self.point_bodies[patch.start];
        let (x0, r0) = body_pose(data, bodies.0);
        let (x1, r1) = body_pose(data, bodies.1);
        let normal = self.points[patch.start].normal;
        let mut kept = 0;
        let (mut a0, mut a1) = ([Vector3::zeros(); 2], [Vector3::zeros(); 2]);
        if let Some(c) = self.cache.get(patch.slot) {
            if c.anchor_count > 0 && !c.broken {
                let rel = r0.transpose() * r1;
                let same_normal = c.normal0.dot(&(rel * c.normal1)) > SAME_NORMAL;
                let close = (0..c.anchor_count).all(|a| {
                    let p1 = r0.transpose() * (x1 + r1 * c.anchor1[a] - x0);
                    (c.anchor0[a] - p1).dot(&c.normal0).abs() < CORRELATION_DISTANCE
                });
                if same_normal && close && (r0 * c.normal0).dot(&normal) >= SAME_NORMAL {
                    kept = c.anchor_count;
                    a0 = c.anchor0;
                    a1 = c.anchor1;
                }
            }
        }
        if kept == 2 {
            let (mut lo, mut hi) = (self.points[patch.start].pos, self.points[patch.start].pos);
            for p in &self.points[patch.start..patch.end] {
                lo = lo.inf(&p.pos);
                hi = hi.sup(&p.pos);
            }
            if (a0[0] - a0[1]).norm_squared() * 4.0 < (hi - lo).norm_squared() {
                kept = 0;
            }
        }
        if kept < 2 {
            let mut world = [Vector3::zeros(); 2];
            let mut count = 0;
            if kept == 1 {
                world[0] = x0 + r0 * a0[0];
                count = 1;
            }
            let mut dist = 0.0;
            for p in &self.points[patch.start..patch.end] {
                if p.separation >= FRICTION_OFFSET_THRESHOLD {
                    continue;
                }
                match count {
                    0 => {
                        world[0] = p.pos;
                        count = 1;
                    }
                    1 => {
                        let d = (p.pos - world[0]).norm_squared();
                        if d > 1e-8 {
                            world[1] = p.pos;
                            count = 2;
                            dist = d;
                        }
                    }
                    _ => {
                        let d0 = (p.pos - world[0]).norm_squared();
                        let d1 = (p.pos - world[1]).norm_squared();
                        if d0 > d1 {
                            if d0 > dist {
                                world[1] = p.pos;
                                dist = d0;
                            }
                        } else if d1 > dist {
                            world[0] = p.pos;
                            dist = d1;
                        }
                    }
                }
            }
            for j in kept..count {
                a0[j] = r0.transpose() * (world[j] - x0);
                a1[j] = r1.transpose() * (world[j] - x1);
            }
            kept = count;
        }
        let p = &mut self.patches[pi];
        p.anchor_count = kept;
        p.anchor0 = a0;
        p.anchor1 = a1;
    }

    /// Keeps this step's jaw patches for the next (PhysX's contact cache) and forgets the
    /// parts that made none.
    pub(super) fn store_cache(&mut self, data: &Data) {
        for c in &mut self.cache {
            *c = CachedPatch::default();
        }
        for p in &self.patches {
            if p.slot == usize::MAX || p.anchor_count == 0 {
                continue;
            }
            let bodies = self.point_bodies[p.start];
            let (_, r0) = body_pose(data, bodies.0);
            let (_, r1) = body_pose(data, bodies.1);
            let n = self.points[p.start].normal;
            self.cache[p.slot] = CachedPatch {
                anchor_count: p.anchor_count,
                anchor0: p.anchor0,
                anchor1: p.anchor1,
                normal0: r0.transpose() * n,
                normal1: r1.transpose() * n,
                broken: p.broken,
            };
        }
    }

    /// Forgets the contact cache (a reset, a restored state without one).
    pub fn forget_contacts(&mut self) {
        for c in &mut self.cache {
            *c = CachedPatch::default();
        }
    }

    /// Appends the contact cache to `out` ([`CACHED_PATCH_LEN`] values per jaw part).
    pub fn save(&self, out: &mut Vec<f64>) {
        for c in &self.cache {
            out.push(c.anchor_count as f64);
            out.push(if c.broken { 1.0 } else { 0.0 });
            for v in c
                .anchor0
                .iter()
                .chain(&c.anchor1)
                .chain([&c.normal0, &c.normal1])
            {
                out.extend(v.iter());
            }
        }
    }

    /// Values [`PinchReplica::save`] appends.
    pub fn save_len(&self) -> usize {
        self.cache.len() * CACHED_PATCH_LEN
    }

    /// Restores the contact cache from [`PinchReplica::save`]'s values (`save_len` of them,
    /// checked by the caller); an anchor count outside 0..=2 or a non-finite value forgets it.
    pub fn load(&mut self, s: &[f64]) {
        for (c, v) in self.cache.iter_mut().zip(s.chunks_exact(CACHED_PATCH_LEN)) {
            let vec = |k: usize| Vector3::new(v[2 + 3 * k], v[3 + 3 * k], v[4 + 3 * k]);
            let count = v[0];
            *c = if v.iter().all(|x| x.is_finite()) && [0.0, 1.0, 2.0].contains(&count) {
                CachedPatch {
                    anchor_count: count as usize,
                    broken: v[1] != 0.0,
                    anchor0: [vec(0), vec(1)],
                    anchor1: [vec(2), vec(3)],
                    normal0: vec(4),
                    normal1: vec(5),
                }
            } else {
                CachedPatch::default()
            };
        }
    }
}
