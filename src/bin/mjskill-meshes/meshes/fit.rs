//! Collision primitives fitted to mesh data.
//!
//! The robot models in `models/` replace the upstream collision meshes with boxes, capsules,
//! cylinders and spheres. This module derives those primitives: it samples a mesh's surface
//! (read by [`super::read`]), optionally keeps only the part inside a crop box, and fits the
//! smallest enclosing primitive of the requested kind. Boxes are tried in the link frame and
//! in the principal-axis frame; capsule and cylinder axes are tried along the link axes and
//! the principal axis; the smallest volume wins. `mjskill fit-primitives` prints the result
//! as URDF `<collision>` elements.

use nalgebra::{Matrix3, Rotation3, SymmetricEigen, Unit, Vector2, Vector3};
use std::fmt::Write as _;

use super::read::{finite, MeshError, Point, Triangle, MAX_COORD};

/// Most primitives of a decomposition or slabs of a segmentation.
pub const MAX_PARTS: usize = 64;
/// Surface samples [`surface_points`] aims at: the spacing grows beyond [`SAMPLE_SPACING`] as
/// needed to stay within it (but every triangle keeps its corners), so that time and memory
/// stay proportional to the mesh.
pub const MAX_SAMPLES: usize = 400_000;

/// Subdivisions of a triangle's longest edge at `spacing` (1..=200).
fn subdivisions(t: &Triangle, spacing: f64) -> usize {
    let longest = (t[1] - t[0])
        .norm()
        .max((t[2] - t[1]).norm())
        .max((t[0] - t[2]).norm());
    let n = (longest / spacing).ceil();
    if n.is_nan() {
        1
    } else {
        (n.clamp(1.0, 200.0)) as usize
    }
}

/// The spacing [`surface_points`] samples `tris` at: `spacing`, or the smallest multiple of it
/// (growing by 25 % steps) at which the samples number at most `budget`, or at which every
/// triangle is sampled at its corners only.
pub fn sample_spacing(tris: &[Triangle], spacing: f64, budget: usize) -> f64 {
    let count = |s: f64| -> usize {
        tris.iter()
            .map(|t| {
                let n = subdivisions(t, s);
                (n + 1) * (n + 2) / 2
            })
            .sum()
    };
    let mut s = spacing;
    for _ in 0..200 {
        if count(s) <= budget || tris.iter().all(|t| subdivisions(t, s) == 1) {
            break;
        }
        s *= 1.25;
    }
    s
}

/// Samples points on every triangle (corners, edges and interior) no further apart than
/// `spacing` along its edges (at most 200 subdivisions per edge), so that fits of a cropped or
/// cut part cover faces that cross the cut.
pub fn sample_surface(tris: &[Triangle], spacing: f64) -> Vec<Point> {
    let mut out = Vec::new();
    for t in tris {
        let n = subdivisions(t, spacing);
        for i in 0..=n {
            for j in 0..=n - i {
                let (a, b) = (i as f64 / n as f64, j as f64 / n as f64);
                out.push(t[0] * (1.0 - a - b) + t[1] * a + t[2] * b);
            }
        }
    }
    out
}

/// Surface sample spacing used by [`surface_points`] (m).
pub const SAMPLE_SPACING: f64 = 0.003;

/// Volume enclosed by a closed triangle mesh (divergence theorem; absolute value).
pub fn mesh_volume(tris: &[Triangle]) -> f64 {
    (tris
        .iter()
        .map(|t| t[0].dot(&t[1].cross(&t[2])))
        .sum::<f64>()
        / 6.0)
        .abs()
}

/// An axis-aligned crop box in the mesh frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Crop {
    /// Lower corner.
    pub min: Point,
    /// Upper corner.
    pub max: Point,
}

impl Crop {
    /// Whether `p` lies inside (boundary included).
    pub fn contains(&self, p: &Point) -> bool {
        (0..3).all(|k| p[k] >= self.min[k] && p[k] <= self.max[k])
    }
}

/// The kinds of primitive the fitter can produce.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Oriented box.
    Box,
    /// Capsule (cylinder with hemispherical caps).
    Capsule,
    /// Cylinder.
    Cylinder,
    /// Sphere.
    Sphere,
}

impl std::str::FromStr for Kind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "box" => Ok(Kind::Box),
            "capsule" => Ok(Kind::Capsule),
            "cylinder" => Ok(Kind::Cylinder),
            "sphere" => Ok(Kind::Sphere),
            _ => Err(format!(
                "unknown primitive {s:?}; valid: box, capsule, cylinder, sphere"
            )),
        }
    }
}

/// A fitted primitive in the mesh frame.
#[derive(Debug, Clone, PartialEq)]
pub enum Primitive {
    /// Box with centre, orientation and half extents along its own axes.
    Box {
        /// Centre.
        center: Point,
        /// Orientation (columns are the box axes).
        rot: Rotation3<f64>,
        /// Half extents.
        half: Vector3<f64>,
    },
    /// Capsule or cylinder between two points.
    Capsule {
        /// Segment start.
        from: Point,
        /// Segment end.
        to: Point,
        /// Radius.
        radius: f64,
        /// Flat ends (cylinder) instead of hemispheres.
        flat: bool,
    },
    /// Sphere.
    Sphere {
        /// Centre.
        center: Point,
        /// Radius.
        radius: f64,
    },
}

impl Primitive {
    /// Enclosed volume (m³).
    pub fn volume(&self) -> f64 {
        use std::f64::consts::PI;
        match self {
            Primitive::Box { half, .. } => 8.0 * half.x * half.y * half.z,
            Primitive::Capsule {
                from,
                to,
                radius,
                flat,
            } => {
                let cyl = PI * radius * radius * (to - from).norm();
                if *flat {
                    cyl
                } else {
                    cyl + 4.0 / 3.0 * PI * radius.powi(3)
                }
            }
            Primitive::Sphere { radius, .. } => 4.0 / 3.0 * std::f64::consts::PI * radius.powi(3),
        }
    }

    /// Distance by which `p` lies outside the primitive (0 when inside).
    #[cfg(test)]
    pub fn outside_distance(&self, p: &Point) -> f64 {
        match self {
            Primitive::Box { center, rot, half } => {
                let l = rot.inverse() * (p - center);
                let d = Vector3::new(
                    (l.x.abs() - half.x).max(0.0),
                    (l.y.abs() - half.y).max(0.0),
                    (l.z.abs() - half.z).max(0.0),
                );
                d.norm()
            }
            Primitive::Capsule {
                from,
                to,
                radius,
                flat,
            } => {
                let ab = to - from;
                let len2 = ab.norm_squared();
                let t = if len2 > 0.0 {
                    (p - from).dot(&ab) / len2
                } else {
                    0.0
                };
                if *flat {
                    let along = if len2 > 0.0 {
                        ab / len2.sqrt()
                    } else {
                        Vector3::z()
                    };
                    let radial = ((p - from) - along * (p - from).dot(&along)).norm();
                    let axial = (t.clamp(0.0, 1.0) - t).abs() * len2.sqrt();
                    Vector2::new((radial - radius).max(0.0), axial).norm()
                } else {
                    ((p - (from + ab * t.clamp(0.0, 1.0))).norm() - radius).max(0.0)
                }
            }
            Primitive::Sphere { center, radius } => ((p - center).norm() - radius).max(0.0),
        }
    }

    /// The URDF `<collision>` element for this primitive (capsules and cylinders along local z).
    pub fn to_urdf(&self) -> String {
        let (pos, rot, geom) = match self {
            Primitive::Box { center, rot, half } => (
                *center,
                *rot,
                format!("<box size=\"{}\"/>", fmt3(&(half * 2.0))),
            ),
            Primitive::Capsule {
                from,
                to,
                radius,
                flat,
            } => {
                let axis = to - from;
                let rot = if axis.norm() > 1e-12 {
                    Rotation3::rotation_between(&Vector3::z(), &axis).unwrap_or_else(|| {
                        Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
                    })
                } else {
                    Rotation3::identity()
                };
                let tag = if *flat { "cylinder" } else { "capsule" };
                (
                    (from + to) / 2.0,
                    rot,
                    format!(
                        "<{tag} radius=\"{}\" length=\"{}\"/>",
                        fnum(*radius),
                        fnum(axis.norm())
                    ),
                )
            }
            Primitive::Sphere { center, radius } => (
                *center,
                Rotation3::identity(),
                format!("<sphere radius=\"{}\"/>", fnum(*radius)),
            ),
        };
        let (r, p, y) = rot.euler_angles();
        let mut s = String::new();
        let _ = write!(
            s,
            "<collision><origin xyz=\"{}\" rpy=\"{}\"/><geometry>{geom}</geometry></collision>",
            fmt3(&pos),
            fmt3(&Vector3::new(r, p, y))
        );
        s
    }
}

fn fnum(x: f64) -> String {
    let r = (x * 1e5).round() / 1e5;
    if r == 0.0 {
        "0".into()
    } else {
        format!("{r}")
    }
}

fn fmt3(v: &Vector3<f64>) -> String {
    format!("{} {} {}", fnum(v.x), fnum(v.y), fnum(v.z))
}

/// Principal axes of a point cloud (columns, largest variance first).
pub fn principal_axes(points: &[Point]) -> Matrix3<f64> {
    let n = points.len().max(1) as f64;
    let mean = points.iter().fold(Point::zeros(), |a, p| a + p) / n;
    let cov = points.iter().fold(Matrix3::zeros(), |a, p| {
        let d = p - mean;
        a + d * d.transpose()
    }) / n;
    let eig = SymmetricEigen::new(cov);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let mut m = Matrix3::from_columns(&[
        eig.eigenvectors.column(order[0]).into_owned(),
        eig.eigenvectors.column(order[1]).into_owned(),
        eig.eigenvectors
            .column(order[0])
            .cross(&eig.eigenvectors.column(order[1])),
    ]);
    // Deterministic sign: each axis points to positive along its largest component.
    for k in 0..2 {
        let c = m.column(k).into_owned();
        let big = (0..3)
            .max_by(|&a, &b| c[a].abs().total_cmp(&c[b].abs()))
            .unwrap_or(0);
        if c[big] < 0.0 {
            m.set_column(k, &(-c));
        }
    }
    let third = m.column(0).cross(&m.column(1));
    m.set_column(2, &third);
    m
}

/// Approximate minimum enclosing ball (Bădoiu–Clarkson iterations from the box centre, then
/// the radius is set to the true maximum distance, so the result always encloses).
fn enclosing_ball<const D: usize>(
    pts: &[nalgebra::SVector<f64, D>],
) -> (nalgebra::SVector<f64, D>, f64) {
    let mut lo = pts[0];
    let mut hi = pts[0];
    for p in pts {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let mut c = (lo + hi) / 2.0;
    for i in 1..=400 {
        let far = pts
            .iter()
            .max_by(|a, b| (*a - c).norm_squared().total_cmp(&(*b - c).norm_squared()))
            .copied()
            .unwrap_or(c);
        c += (far - c) / (i as f64 + 1.0);
    }
    let r = pts.iter().map(|p| (p - c).norm()).fold(0.0, f64::max);
    (c, r)
}

/// Exact minimum enclosing circle (Welzl's incremental algorithm over a fixed shuffle).
fn enclosing_circle(pts: &[Vector2<f64>]) -> (Vector2<f64>, f64) {
    let mut p = pts.to_vec();
    // Deterministic Fisher–Yates shuffle (LCG) for expected linear time.
    let mut state: u64 = 0x9E37_79B9_7F4A_7C15;
    for i in (1..p.len()).rev() {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        p.swap(i, (state >> 33) as usize % (i + 1));
    }
    let eps = 1e-12;
    let inside = |c: &Vector2<f64>, r: f64, q: &Vector2<f64>| (q - c).norm() <= r + eps;
    let mut c = p[0];
    let mut r = 0.0;
    for i in 1..p.len() {
        if inside(&c, r, &p[i]) {
            continue;
        }
        c = p[i];
        r = 0.0;
        for j in 0..i {
            if inside(&c, r, &p[j]) {
                continue;
            }
            c = (p[i] + p[j]) / 2.0;
            r = (p[i] - c).norm();
            for k in 0..j {
                if inside(&c, r, &p[k]) {
                    continue;
                }
                if let Some(cc) = circumcentre(p[i], p[j], p[k]) {
                    c = cc;
                    r = (p[i] - c).norm();
                }
            }
        }
    }
    let r = pts.iter().map(|q| (q - c).norm()).fold(0.0, f64::max);
    (c, r)
}

fn circumcentre(a: Vector2<f64>, b: Vector2<f64>, c: Vector2<f64>) -> Option<Vector2<f64>> {
    let (bx, by) = (b.x - a.x, b.y - a.y);
    let (cx, cy) = (c.x - a.x, c.y - a.y);
    let d = 2.0 * (bx * cy - by * cx);
    if d.abs() < 1e-18 {
        return None;
    }
    let b2 = bx * bx + by * by;
    let c2 = cx * cx + cy * cy;
    Some(Vector2::new(
        a.x + (cy * b2 - by * c2) / d,
        a.y + (bx * c2 - cx * b2) / d,
    ))
}

fn fit_box_in(points: &[Point], rot: Rotation3<f64>) -> Primitive {
    let inv = rot.inverse();
    let mut lo = Vector3::repeat(f64::INFINITY);
    let mut hi = Vector3::repeat(f64::NEG_INFINITY);
    for p in points {
        let l = inv * p;
        lo = lo.inf(&l);
        hi = hi.sup(&l);
    }
    Primitive::Box {
        center: rot * ((lo + hi) / 2.0),
        rot,
        half: (hi - lo) / 2.0,
    }
}

fn fit_capsule_along(points: &[Point], axis: Unit<Vector3<f64>>, flat: bool) -> Primitive {
    let u = if axis.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let u = (u - axis.into_inner() * axis.dot(&u)).normalize();
    let v = axis.cross(&u);
    let planar: Vec<Vector2<f64>> = points
        .iter()
        .map(|p| Vector2::new(p.dot(&u), p.dot(&v)))
        .collect();
    let (c2, radius) = enclosing_circle(&planar);
    let t: Vec<f64> = points.iter().map(|p| p.dot(&axis)).collect();
    let (a, b) = if flat {
        (
            t.iter().copied().fold(f64::INFINITY, f64::min),
            t.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        )
    } else {
        // Shortest segment keeping every point within `radius` of it.
        let mut a = f64::INFINITY;
        let mut b = f64::NEG_INFINITY;
        for (p2, &ti) in planar.iter().zip(&t) {
            let slack = (radius * radius - (p2 - c2).norm_squared()).max(0.0).sqrt();
            a = a.min(ti + slack);
            b = b.max(ti - slack);
        }
        if a > b {
            let m = (a + b) / 2.0;
            (m, m)
        } else {
            (a, b)
        }
    };
    let base = u * c2.x + v * c2.y;
    Primitive::Capsule {
        from: base + axis.into_inner() * a,
        to: base + axis.into_inner() * b,
        radius,
        flat,
    }
}

/// Checks that a fitted primitive has finite, positive sizes (a capsule may have length 0: it
/// is then a sphere).
pub fn check_primitive(p: &Primitive, cropped: bool) -> Result<(), MeshError> {
    let (kind, dims, ok) = match p {
        Primitive::Box { center, half, .. } => (
            "box",
            vec![2.0 * half.x, 2.0 * half.y, 2.0 * half.z],
            finite(center) && half.iter().all(|h| h.is_finite() && *h > 1e-9),
        ),
        Primitive::Capsule {
            from,
            to,
            radius,
            flat,
        } => {
            let len = (to - from).norm();
            (
                if *flat { "cylinder" } else { "capsule" },
                vec![*radius, len],
                finite(from)
                    && finite(to)
                    && radius.is_finite()
                    && *radius > 1e-9
                    && (!flat || len > 1e-9),
            )
        }
        Primitive::Sphere { center, radius } => (
            "sphere",
            vec![*radius],
            finite(center) && radius.is_finite() && *radius > 1e-9,
        ),
    };
    if ok {
        return Ok(());
    }
    Err(MeshError::Degenerate {
        kind,
        size: dims
            .iter()
            .map(|d| format!("{d:e}"))
            .collect::<Vec<_>>()
            .join(" "),
        crop: if cropped { " inside the crop box" } else { "" },
    })
}

/// Fits the smallest enclosing primitive of `kind` to `points`.
pub fn fit(points: &[Point], kind: Kind) -> Result<Primitive, MeshError> {
    if points.is_empty() {
        return Err(MeshError::Empty(String::new()));
    }
    if let Some(p) = points
        .iter()
        .find(|p| !(finite(p) && p.amax() <= MAX_COORD))
    {
        return Err(MeshError::Invalid(format!(
            "point {p:?} is not finite or beyond ±{MAX_COORD:e}"
        )));
    }
    let pca = principal_axes(points);
    let candidates: Vec<Primitive> = match kind {
        Kind::Sphere => {
            let (center, radius) = enclosing_ball(points);
            vec![Primitive::Sphere { center, radius }]
        }
        Kind::Box => vec![
            fit_box_in(points, Rotation3::identity()),
            fit_box_in(points, Rotation3::from_matrix_unchecked(pca)),
        ],
        Kind::Capsule | Kind::Cylinder => {
            let axes = [
                Vector3::x(),
                Vector3::y(),
                Vector3::z(),
                pca.column(0).into_owned(),
            ];
            axes.iter()
                .map(|a| fit_capsule_along(points, Unit::new_normalize(*a), kind == Kind::Cylinder))
                .collect()
        }
    };
    Ok(candidates
        .into_iter()
        .min_by(|a, b| a.volume().total_cmp(&b.volume()))
        .expect("at least one candidate"))
}

/// Fits the smallest of several primitive kinds.
pub fn fit_any(points: &[Point], kinds: &[Kind]) -> Result<Primitive, MeshError> {
    let mut best: Option<Primitive> = None;
    for &k in kinds {
        let p = fit(points, k)?;
        if best.as_ref().is_none_or(|b| p.volume() < b.volume()) {
            best = Some(p);
        }
    }
    best.ok_or_else(|| MeshError::Empty(" (no primitive kind given)".into()))
}

/// A part of a decomposition: its points and their primitive.
type Piece = (Vec<Point>, Primitive);

/// The best axis-aligned cut of one piece: (volume gain, the two sides).
type Split = Option<(f64, [Piece; 2])>;

/// The cut of `pts` (fitted by `prim`) with the plane (x, y or z; 15 positions per axis)
/// that most reduces the total volume, or `None` for fewer than 8 points.
fn best_split(pts: &[Point], prim: &Primitive, kinds: &[Kind]) -> Result<Split, MeshError> {
    if pts.len() < 8 {
        return Ok(None);
    }
    let mut best: Split = None;
    for axis in 0..3 {
        let lo = pts.iter().map(|p| p[axis]).fold(f64::INFINITY, f64::min);
        let hi = pts
            .iter()
            .map(|p| p[axis])
            .fold(f64::NEG_INFINITY, f64::max);
        for k in 1..16 {
            let cut = lo + (hi - lo) * k as f64 / 16.0;
            let (a, b): (Vec<Point>, Vec<Point>) = pts.iter().partition(|p| p[axis] <= cut);
            if a.is_empty() || b.is_empty() {
                continue;
            }
            let (pa, pb) = (fit_any(&a, kinds)?, fit_any(&b, kinds)?);
            // A side whose points lie on a plane cannot be a primitive: not a cut to take.
            if check_primitive(&pa, false).is_err() || check_primitive(&pb, false).is_err() {
                continue;
            }
            let gain = prim.volume() - pa.volume() - pb.volume();
            if best.as_ref().is_none_or(|(g, _)| gain > *g) {
                best = Some((gain, [(a, pa), (b, pb)]));
            }
        }
    }
    Ok(best)
}

/// Greedy decomposition into at most `parts` (1..=[`MAX_PARTS`]) primitives: repeatedly cuts
/// the part whose best axis-aligned cut (x, y or z; 15 positions per axis) most reduces the
/// total volume, and fits each side with the smallest of `kinds`. Every point stays enclosed.
/// Each part's best cut is computed once, so the work grows with the points times the depth
/// of the cuts, not with the square of `parts`.
pub fn decompose(
    points: &[Point],
    kinds: &[Kind],
    parts: usize,
) -> Result<Vec<Primitive>, MeshError> {
    if !(1..=MAX_PARTS).contains(&parts) {
        return Err(MeshError::Invalid(format!(
            "--parts must be in 1..={MAX_PARTS}, got {parts}"
        )));
    }
    let first = fit_any(points, kinds)?;
    let split = best_split(points, &first, kinds)?;
    let mut pieces: Vec<(Piece, Split)> = vec![((points.to_vec(), first), split)];
    while pieces.len() < parts {
        // The first piece with the largest gain, as a scan over every piece's cuts finds it.
        let mut best: Option<(usize, f64)> = None;
        for (i, (_, s)) in pieces.iter().enumerate() {
            if let Some((g, _)) = s {
                if best.is_none_or(|(_, b)| *g > b) {
                    best = Some((i, *g));
                }
            }
        }
        let Some((i, _)) = best.filter(|(_, g)| *g > 0.0) else {
            break;
        };
        let (_, split) = pieces.remove(i);
        let Some((_, [a, b])) = split else { break };
        for piece in [a, b] {
            let s = best_split(&piece.0, &piece.1, kinds)?;
            pieces.push((piece, s));
        }
    }
    Ok(pieces.into_iter().map(|((_, p), _)| p).collect())
}

/// Fits `segments` primitives of `kind`, splitting the points into equal slabs along their
/// principal axis.
pub fn fit_segments(
    points: &[Point],
    kind: Kind,
    segments: usize,
) -> Result<Vec<Primitive>, MeshError> {
    if !(1..=MAX_PARTS).contains(&segments) {
        return Err(MeshError::Invalid(format!(
            "--segments must be in 1..={MAX_PARTS}, got {segments}"
        )));
    }
    if segments == 1 {
        return Ok(vec![fit(points, kind)?]);
    }
    let axis = principal_axes(points).column(0).into_owned();
    let t: Vec<f64> = points.iter().map(|p| p.dot(&axis)).collect();
    let lo = t.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = t.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let step = (hi - lo) / segments as f64;
    (0..segments)
        .map(|k| {
            let (a, b) = (lo + step * k as f64, lo + step * (k + 1) as f64);
            let part: Vec<Point> = points
                .iter()
                .zip(&t)
                .filter(|(_, &ti)| ti >= a && ti <= b)
                .map(|(p, _)| *p)
                .collect();
            fit(&part, kind).map_err(|_| MeshError::Empty(format!(" in segment {k}")))
        })
        .collect()
}

/// Fits one primitive to the part of a mesh inside `crop` (or to the whole mesh).
#[cfg(test)]
pub fn fit_mesh(
    tris: &[Triangle],
    crop: Option<&Crop>,
    kind: Kind,
    segments: usize,
) -> Result<Vec<Primitive>, MeshError> {
    fit_segments(&surface_points(tris, crop)?, kind, segments)
}

/// Surface samples of a mesh, optionally restricted to a crop box: [`SAMPLE_SPACING`] apart,
/// or further apart for meshes that would give more than [`MAX_SAMPLES`] points
/// ([`sample_spacing`]).
pub fn surface_points(tris: &[Triangle], crop: Option<&Crop>) -> Result<Vec<Point>, MeshError> {
    let spacing = sample_spacing(tris, SAMPLE_SPACING, MAX_SAMPLES);
    let pts: Vec<Point> = sample_surface(tris, spacing)
        .into_iter()
        .filter(|p| crop.is_none_or(|c| c.contains(p)))
        .collect();
    if pts.is_empty() {
        return Err(MeshError::Empty(" inside the crop box".into()));
    }
    Ok(pts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::meshes::read::*;

    /// The 12 triangles of an axis-aligned box.
    fn box_tris(lo: Point, hi: Point) -> Vec<Triangle> {
        let c = |i: usize| {
            Point::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            )
        };
        let quads = [
            [0, 1, 3, 2],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 3, 7, 6],
            [0, 2, 6, 4],
            [1, 3, 7, 5],
        ];
        quads
            .iter()
            .flat_map(|q| [[c(q[0]), c(q[1]), c(q[2])], [c(q[0]), c(q[2]), c(q[3])]])
            .collect()
    }

    fn binary_stl(tris: &[Triangle]) -> Vec<u8> {
        let mut b = vec![0u8; 80];
        b.extend((tris.len() as u32).to_le_bytes());
        for t in tris {
            b.extend([0u8; 12]);
            for v in t {
                for k in 0..3 {
                    b.extend((v[k] as f32).to_le_bytes());
                }
            }
            b.extend([0u8; 2]);
        }
        b
    }

    #[test]
    fn binary_ascii_and_obj_read_the_same_triangles() {
        let tris = box_tris(Point::new(-0.1, -0.2, 0.0), Point::new(0.1, 0.2, 0.05));
        let bin = read_triangles(&binary_stl(&tris), "a.stl").unwrap();
        let mut ascii = String::from("solid t\n");
        for t in &tris {
            ascii += "facet normal 0 0 0\nouter loop\n";
            for v in t {
                ascii += &format!("vertex {} {} {}\n", v.x, v.y, v.z);
            }
            ascii += "endloop\nendfacet\n";
        }
        let asc = read_triangles(ascii.as_bytes(), "a.stl").unwrap();
        let obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n";
        let o = read_triangles(obj.as_bytes(), "q.obj").unwrap();
        assert_eq!(bin.len(), 12);
        assert_eq!(asc.len(), 12);
        assert_eq!(o.len(), 2);
        for (a, b) in bin.iter().zip(&asc) {
            for k in 0..3 {
                assert!((a[k] - b[k]).norm() < 1e-7);
            }
        }
    }

    #[test]
    fn malformed_files_are_errors_naming_the_file() {
        let e = read_triangles(b"garbage bytes", "broken.stl")
            .unwrap_err()
            .to_string();
        assert!(e.contains("broken.stl"), "{e}");
        let e = read_triangles(b"solid x\nvertex 1 2\n", "short.stl")
            .unwrap_err()
            .to_string();
        assert!(e.contains("short.stl") && e.contains("line 2"), "{e}");
        let e = read_triangles(b"v 0 0 0\nf 1 2 9\n", "m.obj")
            .unwrap_err()
            .to_string();
        assert!(e.contains("out of range"), "{e}");
    }

    #[test]
    fn box_mesh_gives_back_the_box() {
        let tris = box_tris(Point::new(-0.1, -0.2, 0.0), Point::new(0.1, 0.2, 0.05));
        let p = &fit_mesh(&tris, None, Kind::Box, 1).unwrap()[0];
        assert!((p.volume() - 0.2 * 0.4 * 0.05).abs() < 1e-9, "{p:?}");
        // A consistently wound unit-corner tetrahedron encloses 1/6.
        let (o, x, y, z) = (Point::zeros(), Point::x(), Point::y(), Point::z());
        let tet = [[o, y, x], [o, x, z], [o, z, y], [x, y, z]];
        assert!((mesh_volume(&tet) - 1.0 / 6.0).abs() < 1e-12);
        match p {
            Primitive::Box { center, .. } => {
                assert!((center - Point::new(0.0, 0.0, 0.025)).norm() < 1e-9)
            }
            _ => unreachable!(),
        }
    }

    #[test]
    fn capsule_encloses_every_sample_and_is_tight_for_a_long_bar() {
        let tris = box_tris(Point::new(-0.02, -0.02, -0.3), Point::new(0.02, 0.02, 0.3));
        let pts = sample_surface(&tris, 0.01);
        let p = fit(&pts, Kind::Capsule).unwrap();
        for q in &pts {
            assert!(p.outside_distance(q) < 1e-9);
        }
        match &p {
            Primitive::Capsule {
                from, to, radius, ..
            } => {
                // Enclosing circle of the 4 cm square: radius 0.02·√2.
                assert!((radius - 0.02 * 2f64.sqrt()).abs() < 1e-4, "{radius}");
                assert!((to - from).normalize().z.abs() > 0.999);
                assert!((to - from).norm() <= 0.6 + 1e-9);
            }
            _ => unreachable!(),
        }
        let c = fit(&pts, Kind::Cylinder).unwrap();
        assert!(pts.iter().all(|q| c.outside_distance(q) < 1e-9));
        assert!(c.to_urdf().contains("<cylinder"));
    }

    #[test]
    fn crop_and_segments_split_an_l_shape() {
        let mut tris = box_tris(Point::new(0.0, 0.0, 0.0), Point::new(0.3, 0.05, 0.05));
        tris.extend(box_tris(
            Point::new(0.25, 0.0, 0.0),
            Point::new(0.3, 0.05, 0.4),
        ));
        let whole = fit_mesh(&tris, None, Kind::Box, 1).unwrap()[0].volume();
        let crop = Crop {
            min: Point::new(-1.0, -1.0, -1.0),
            max: Point::new(1.0, 1.0, 0.05),
        };
        let foot = fit_mesh(&tris, Some(&crop), Kind::Box, 1).unwrap()[0].volume();
        assert!((foot - 0.3 * 0.05 * 0.05).abs() < 1e-9);
        assert!(whole > 5.0 * foot);
        let segs = fit_mesh(&tris, None, Kind::Sphere, 3).unwrap();
        assert_eq!(segs.len(), 3);
        let parts = decompose(&surface_points(&tris, None).unwrap(), &[Kind::Box], 2).unwrap();
        assert_eq!(parts.len(), 2);
        let total: f64 = parts.iter().map(|p| p.volume()).sum();
        assert!(total < whole * 0.3, "{total} vs {whole}");
        for q in surface_points(&tris, None).unwrap() {
            assert!(parts.iter().any(|p| p.outside_distance(&q) < 1e-9));
        }
        let miss = Crop {
            min: Point::repeat(5.0),
            max: Point::repeat(6.0),
        };
        assert!(fit_mesh(&tris, Some(&miss), Kind::Box, 1).is_err());
    }

    #[test]
    fn urdf_output_round_trips_through_urdf_rs() {
        let p = Primitive::Capsule {
            from: Point::new(0.0, 0.0, 0.0),
            to: Point::new(0.1, 0.0, 0.0),
            radius: 0.02,
            flat: false,
        };
        let xml = format!(
            "<robot name=\"r\"><link name=\"l\">{}</link></robot>",
            p.to_urdf()
        );
        let robot = urdf_rs::read_from_string(&xml).unwrap();
        let col = &robot.links[0].collision[0];
        // The capsule's z axis is rotated onto +x.
        let rpy = col.origin.rpy;
        let rot = Rotation3::from_euler_angles(rpy[0], rpy[1], rpy[2]);
        assert!((rot * Vector3::z() - Vector3::x()).norm() < 1e-4);
        assert!((col.origin.xyz[0] - 0.05).abs() < 1e-9);
    }
}
