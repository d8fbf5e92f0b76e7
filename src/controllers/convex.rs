//! Convex collision parts and PhysX's contact manifold of a convex part against a box.
//!
//! ManiSkill's grippers collide through convex parts (the SO100's jaws are two and three
//! convex hulls of 8–14 vertices each). PhysX makes at most four contact points per pair of
//! shapes; where two grippers squeeze a cube, where those points lie decides how the pinch
//! kicks the arm within a step (docs/outcome-physics.md, "PhysX's reported velocity from the
//! state alone"). mjskill's MuJoCo model collides through fitted boxes instead; the
//! [`super::tgs`] replica of PhysX's step builds its jaw–cube contacts here, from the parts
//! themselves ([`box_manifold`]), as PhysX does:
//!
//! * the reference face is the face, of the box or of the part, along whose normal the two
//!   overlap least (the separating-axis test over both shapes' face normals);
//! * the incident face is the other shape's face most opposed to it; its polygon, clipped
//!   to the reference face's sides, gives the points, each with its separation along the
//!   reference normal;
//! * points separated by more than [`SPECULATIVE_DISTANCE`] are dropped, and more than four
//!   are reduced as PhysX reduces a manifold: the deepest, the farthest from it, the one
//!   making the largest triangle with those, and the one making the largest quadrilateral.
//!
//! Measured against the contacts PhysX made on 285 held SO100 states, this gives PhysX's
//! four depths per jaw to 0.01 mm.
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// Contact points farther apart than this (m) are not made: a speculative contact that
/// only stops an approach faster than `SPECULATIVE_DISTANCE / dt` (3 m/s at PhysX's
/// sub-step), so dropping the farther ones changes nothing at a gripper's speeds.
pub const SPECULATIVE_DISTANCE: f64 = 0.002;
/// Most points PhysX keeps per manifold.
pub const MAX_MANIFOLD_POINTS: usize = 4;
/// Two hull triangles lie in one face when their normals agree to this cosine and their
/// planes to [`COPLANAR_OFFSET`] m.
const COPLANAR_COS: f64 = 1.0 - 1e-6;
const COPLANAR_OFFSET: f64 = 1e-7;

/// One convex collision part of a link, as stored in `models/<robot>/convex_parts.json`
/// (written by `mjskill-meshes convex-parts` from the upstream collision hulls).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ConvexPartFile {
    /// The link (MuJoCo body) the part moves with; its vertices are in the link frame.
    pub link: String,
    /// Vertices (m, link frame).
    pub vertices: Vec<[f64; 3]>,
    /// The hull's triangles (indices into `vertices`, counter-clockwise seen from outside).
    pub triangles: Vec<[usize; 3]>,
}

/// The parts of one robot's file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ConvexPartsFile {
    /// Where the parts came from (upstream files, the command that converted them).
    pub source: String,
    /// The parts.
    pub parts: Vec<ConvexPartFile>,
}

/// A face of a convex part: outward unit normal, plane offset (`n·x = offset` in the link
/// frame) and its vertices in order around the normal.
#[derive(Debug, Clone, PartialEq)]
pub struct Face {
    /// Outward unit normal (link frame).
    pub normal: Vector3<f64>,
    /// Plane offset.
    pub offset: f64,
    /// Vertex indices, counter-clockwise about `normal`.
    pub vertices: Vec<usize>,
}

/// A convex part ready for collision: vertices and merged faces in the link frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ConvexPart {
    /// The link's name.
    pub link: String,
    /// Vertices (link frame).
    pub vertices: Vec<Vector3<f64>>,
    /// Faces (coplanar triangles merged).
    pub faces: Vec<Face>,
}

/// Why a convex part is unusable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConvexError {
    /// Too few vertices or triangles, an index out of range, a non-finite or huge vertex.
    #[error("convex part of {link:?}: {reason}")]
    Invalid {
        /// The part's link.
        link: String,
        /// What is wrong.
        reason: String,
    },
}

/// Largest vertex coordinate accepted (m).
const MAX_COORD: f64 = 100.0;
/// Most vertices of one part (PhysX's convex hulls have at most 255).
const MAX_VERTICES: usize = 255;

impl ConvexPart {
    /// Checks a stored part and merges its coplanar triangles into faces.
    pub fn new(file: &ConvexPartFile) -> Result<ConvexPart, ConvexError> {
        let bad = |reason: String| ConvexError::Invalid {
            link: file.link.clone(),
            reason,
        };
        let nv = file.vertices.len();
        if !(4..=MAX_VERTICES).contains(&nv) {
            return Err(bad(format!(
                "{nv} vertices; a convex part has 4..={MAX_VERTICES}"
            )));
        }
        if let Some(v) = file
            .vertices
            .iter()
            .find(|v| v.iter().any(|x| !x.is_finite() || x.abs() > MAX_COORD))
        {
            return Err(bad(format!(
                "vertex {v:?} is not finite or beyond {MAX_COORD} m"
            )));
        }
        if file.triangles.len() < 4 || file.triangles.len() > 2 * MAX_VERTICES {
            return Err(bad(format!(
                "{} triangles; a closed hull of {nv} vertices has 4..={}",
                file.triangles.len(),
                2 * MAX_VERTICES
            )));
        }
        if let Some(t) = file.triangles.iter().find(|t| t.iter().any(|&i| i >= nv)) {
            return Err(bad(format!(
                "triangle {t:?} names a vertex beyond the {nv} there are"
            )));
        }
        let vertices: Vec<Vector3<f64>> = file.vertices.iter().map(|v| Vector3::from(*v)).collect();
        let centroid = vertices.iter().sum::<Vector3<f64>>() / nv as f64;
        let mut faces: Vec<Face> = Vec::new();
        for t in &file.triangles {
            let [a, b, c] = t.map(|i| vertices[i]);
            let n = (b - a).cross(&(c - a));
            let len = n.norm();
            if len < 1e-12 {
                continue;
            }
            let mut normal = n / len;
            // Outward, whatever the winding.
            if normal.dot(&(a - centroid)) < 0.0 {
                normal = -normal;
            }
            let offset = normal.dot(&a);
            let face = match faces.iter_mut().find(|f| {
                f.normal.dot(&normal) > COPLANAR_COS && (f.offset - offset).abs() < COPLANAR_OFFSET
            }) {
                Some(f) => f,
                None => {
                    faces.push(Face {
                        normal,
                        offset,
                        vertices: Vec::new(),
                    });
                    faces.last_mut().expect("just pushed")
                }
            };
            for i in *t {
                if !face.vertices.contains(&i) {
                    face.vertices.push(i);
                }
            }
        }
        if faces.len() < 4 {
            return Err(bad(format!(
                "its triangles span {} planes; a convex solid has at least 4",
                faces.len()
            )));
        }
        // Every vertex inside every face's plane: the hull is convex.
        for f in &faces {
            if let Some(v) = vertices.iter().find(|v| f.normal.dot(v) > f.offset + 1e-6) {
                return Err(bad(format!(
                    "vertex {:?} lies outside the face with normal {:?}: not convex",
                    [v.x, v.y, v.z],
                    [f.normal.x, f.normal.y, f.normal.z]
                )));
            }
        }
        for f in &mut faces {
            order_about(&mut f.vertices, &vertices, &f.normal);
        }
        Ok(ConvexPart {
            link: file.link.clone(),
            vertices,
            faces,
        })
    }
}

impl ConvexPart {
    /// A box of half extents `half` placed at `pos` with orientation `rot` (columns: its
    /// axes) in `link`'s frame, as a convex part: the Panda's finger collisions are boxes in
    /// ManiSkill's model too, so PhysX collides exactly these.
    pub fn from_box(
        link: &str,
        half: [f64; 3],
        pos: Vector3<f64>,
        rot: Matrix3<f64>,
    ) -> Result<ConvexPart, ConvexError> {
        let corners = box_corners(&BoxShape {
            center: pos,
            rot,
            half: Vector3::from(half),
        });
        // Two triangles per face; ConvexPart::new orients and merges them.
        let quads = [
            [0, 2, 6, 4],
            [1, 3, 7, 5],
            [0, 1, 5, 4],
            [2, 3, 7, 6],
            [0, 1, 3, 2],
            [4, 5, 7, 6],
        ];
        let triangles = quads
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect();
        ConvexPart::new(&ConvexPartFile {
            link: link.to_string(),
            vertices: corners.iter().map(|v| [v.x, v.y, v.z]).collect(),
            triangles,
        })
    }
}

/// Orders the polygon `idx` counter-clockwise about `normal`.
fn order_about(idx: &mut [usize], vertices: &[Vector3<f64>], normal: &Vector3<f64>) {
    let c = idx.iter().map(|&i| vertices[i]).sum::<Vector3<f64>>() / idx.len() as f64;
    let u = (vertices[idx[0]] - c).normalize();
    let w = normal.cross(&u);
    let angle = |i: usize| {
        let d = vertices[i] - c;
        d.dot(&w).atan2(d.dot(&u))
    };
    idx.sort_by(|&a, &b| angle(a).total_cmp(&angle(b)));
}

/// A box in the world: centre, axes (columns) and half extents.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxShape {
    /// Centre.
    pub center: Vector3<f64>,
    /// Orientation: column k is the box's k-th axis.
    pub rot: Matrix3<f64>,
    /// Half extents along the axes.
    pub half: Vector3<f64>,
}

/// One contact point between a box and a convex part.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactPoint {
    /// World position (on the incident face).
    pub pos: Vector3<f64>,
    /// Unit normal, pointing from the box towards the part.
    pub normal: Vector3<f64>,
    /// Signed separation along the normal (negative: penetration).
    pub separation: f64,
}

/// Scratch buffers of [`box_manifold`], sized once.
#[derive(Debug, Clone, Default)]
pub struct ManifoldScratch {
    world: Vec<Vector3<f64>>,
    poly: Vec<Vector3<f64>>,
    clipped: Vec<Vector3<f64>>,
    points: Vec<ContactPoint>,
}

impl ManifoldScratch {
    /// Buffers for parts of up to `max_vertices` vertices.
    pub fn new(max_vertices: usize) -> ManifoldScratch {
        let n = max_vertices.max(8) * 2 + 8;
        ManifoldScratch {
            world: Vec::with_capacity(max_vertices),
            poly: Vec::with_capacity(n),
            clipped: Vec::with_capacity(n),
            points: Vec::with_capacity(n),
        }
    }
}

/// The contact manifold of `part` (posed by the link's world position `pos` and rotation
/// `rot`) against `bx`: at most [`MAX_MANIFOLD_POINTS`] points separated by at most
/// `max_separation` ([`SPECULATIVE_DISTANCE`] as PhysX), appended to `out` (which is not
/// cleared). Returns how many were added.
pub fn box_manifold(
    part: &ConvexPart,
    pos: &Vector3<f64>,
    rot: &Matrix3<f64>,
    bx: &BoxShape,
    max_separation: f64,
    scratch: &mut ManifoldScratch,
    out: &mut Vec<ContactPoint>,
) -> usize {
    let s = scratch;
    s.world.clear();
    s.world.extend(part.vertices.iter().map(|v| pos + rot * v));
    let corners = box_corners(bx);
    // The separating-axis test over both shapes' face normals: the axis of largest
    // separation (least overlap) is the reference.
    let mut best_sep = f64::NEG_INFINITY;
    let mut best: Option<(bool, usize, f64)> = None; // (box face?, index, sign)
    for k in 0..3 {
        let axis = bx.rot.column(k).into_owned();
        for sign in [1.0, -1.0] {
            let n = axis * sign;
            let sep = s
                .world
                .iter()
                .map(|v| n.dot(&(v - bx.center)))
                .fold(f64::INFINITY, f64::min)
                - bx.half[k];
            if sep > best_sep {
                best_sep = sep;
                best = Some((true, k, sign));
            }
        }
    }
    for (fi, f) in part.faces.iter().enumerate() {
        let m = rot * f.normal;
        let d = m.dot(&(pos + rot * (f.normal * f.offset)));
        let sep = corners
            .iter()
            .map(|c| m.dot(c))
            .fold(f64::INFINITY, f64::min)
            - d;
        if sep > best_sep {
            best_sep = sep;
            best = Some((false, fi, 1.0));
        }
    }
    let Some((box_ref, index, sign)) = best else {
        return 0;
    };
    if best_sep > max_separation {
        return 0;
    }
    s.points.clear();
    if box_ref {
        // Reference: the box face `sign · axis[index]`; incident: the part's face most
        // opposed to it, clipped to the face's rectangle.
        let n = bx.rot.column(index).into_owned() * sign;
        let incident = part
            .faces
            .iter()
            .min_by(|a, b| {
                (rot * a.normal)
                    .dot(&n)
                    .total_cmp(&(rot * b.normal).dot(&n))
            })
            .expect("a part has faces");
        s.poly.clear();
        s.poly.extend(incident.vertices.iter().map(|&i| s.world[i]));
        for j in 0..3 {
            if j == index {
                continue;
            }
            let a = bx.rot.column(j).into_owned();
            let off = a.dot(&bx.center);
            clip(&mut s.poly, &mut s.clipped, &a, off + bx.half[j]);
            clip(&mut s.poly, &mut s.clipped, &(-a), -(off - bx.half[j]));
        }
        for p in &s.poly {
            let sep = n.dot(&(p - bx.center)) - bx.half[index];
            if sep <= max_separation {
                s.points.push(ContactPoint {
                    pos: *p,
                    normal: n,
                    separation: sep,
                });
            }
        }
    } else {
        // Reference: the part's face; incident: the box face most opposed to it, clipped to
        // the part face's polygon.
        let f = &part.faces[index];
        let m = rot * f.normal;
        let d = m.dot(&(pos + rot * (f.normal * f.offset)));
        let (k, sgn) = (0..3)
            .flat_map(|k| [(k, 1.0), (k, -1.0)])
            .min_by(|a, b| {
                (bx.rot.column(a.0) * a.1)
                    .dot(&m)
                    .total_cmp(&(bx.rot.column(b.0) * b.1).dot(&m))
            })
            .expect("six faces");
        box_face(bx, k, sgn, &mut s.poly);
        let nv = f.vertices.len();
        for e in 0..nv {
            let a = s.world[f.vertices[e]];
            let b = s.world[f.vertices[(e + 1) % nv]];
            let side = (b - a).cross(&m);
            let len = side.norm();
            if len < 1e-12 {
                continue;
            }
            let side = side / len;
            clip(&mut s.poly, &mut s.clipped, &side, side.dot(&a));
        }
        for p in &s.poly {
            let sep = m.dot(p) - d;
            if sep <= max_separation {
                s.points.push(ContactPoint {
                    pos: *p,
                    normal: -m,
                    separation: sep,
                });
            }
        }
    }
    let added = reduce(&mut s.points);
    out.extend_from_slice(&s.points[..added]);
    added
}

/// The contact of `part` (posed by its link's world position `pos` and rotation `rot`)
/// with a sphere of `radius` centred at `center`, as PhysX makes a sphere's contact with a
/// convex: one point, on the part's surface where it comes closest to the centre, with the
/// normal from the sphere towards the part. Appended to `out` when separated by at most
/// `max_separation`; returns how many points were added (0 or 1).
pub fn sphere_manifold(
    part: &ConvexPart,
    pos: &Vector3<f64>,
    rot: &Matrix3<f64>,
    center: &Vector3<f64>,
    radius: f64,
    max_separation: f64,
    out: &mut Vec<ContactPoint>,
) -> usize {
    // In the link frame.
    let c = rot.transpose() * (center - pos);
    let (mut deepest, mut deepest_d) = (0, f64::NEG_INFINITY);
    for (i, f) in part.faces.iter().enumerate() {
        let d = f.normal.dot(&c) - f.offset;
        if d > deepest_d {
            deepest_d = d;
            deepest = i;
        }
    }
    let (closest, normal, dist) = if deepest_d <= 0.0 {
        // The centre is inside: out through the face it is nearest.
        let f = &part.faces[deepest];
        (c - f.normal * deepest_d, -f.normal, deepest_d)
    } else {
        // Outside: the nearest point over the faces it is in front of (inside the face's
        // polygon, or on one of its edges).
        let mut best = (c, f64::INFINITY);
        for f in &part.faces {
            let d = f.normal.dot(&c) - f.offset;
            if d <= 0.0 {
                continue;
            }
            let on_plane = c - f.normal * d;
            let nv = f.vertices.len();
            let inside = (0..nv).all(|e| {
                let a = part.vertices[f.vertices[e]];
                let b = part.vertices[f.vertices[(e + 1) % nv]];
                (b - a).cross(&(on_plane - a)).dot(&f.normal) >= 0.0
            });
            if inside {
                if d < best.1 {
                    best = (on_plane, d);
                }
                continue;
            }
            for e in 0..nv {
                let a = part.vertices[f.vertices[e]];
                let b = part.vertices[f.vertices[(e + 1) % nv]];
                let ab = b - a;
                let t = ((c - a).dot(&ab) / ab.norm_squared().max(1e-300)).clamp(0.0, 1.0);
                let q = a + ab * t;
                let d = (c - q).norm();
                if d < best.1 {
                    best = (q, d);
                }
            }
        }
        let (q, d) = best;
        let normal = if d > 1e-12 { (q - c) / d } else { Vector3::z() };
        (q, normal, d)
    };
    let separation = dist - radius;
    if separation > max_separation {
        return 0;
    }
    out.push(ContactPoint {
        pos: pos + rot * closest,
        normal: rot * normal,
        separation,
    });
    1
}

/// The box's eight corners.
fn box_corners(bx: &BoxShape) -> [Vector3<f64>; 8] {
    let mut c = [Vector3::zeros(); 8];
    for (i, x) in c.iter_mut().enumerate() {
        let s = Vector3::new(
            if i & 1 == 0 { -1.0 } else { 1.0 },
            if i & 2 == 0 { -1.0 } else { 1.0 },
            if i & 4 == 0 { -1.0 } else { 1.0 },
        );
        *x = bx.center + bx.rot * s.component_mul(&bx.half);
    }
    c
}

/// The four corners of the box face with outward normal `sign · axis[k]`, in order.
fn box_face(bx: &BoxShape, k: usize, sign: f64, out: &mut Vec<Vector3<f64>>) {
    let (i, j) = ((k + 1) % 3, (k + 2) % 3);
    let c = bx.center + bx.rot.column(k) * (sign * bx.half[k]);
    let (u, v) = (bx.rot.column(i) * bx.half[i], bx.rot.column(j) * bx.half[j]);
    out.clear();
    out.extend([c - u - v, c + u - v, c + u + v, c - u + v]);
}

/// Clips the polygon `poly` to the half-space `n·x ≤ off` (Sutherland–Hodgman).
fn clip(poly: &mut Vec<Vector3<f64>>, tmp: &mut Vec<Vector3<f64>>, n: &Vector3<f64>, off: f64) {
    tmp.clear();
    let len = poly.len();
    for i in 0..len {
        let (a, b) = (poly[i], poly[(i + 1) % len]);
        let (da, db) = (n.dot(&a) - off, n.dot(&b) - off);
        if da <= 0.0 {
            tmp.push(a);
        }
        if (da < 0.0 && db > 0.0) || (da > 0.0 && db < 0.0) {
            tmp.push(a + (b - a) * (da / (da - db)));
        }
    }
    std::mem::swap(poly, tmp);
}

/// Reduces `pts` in place to at most four points, as PhysX reduces a manifold, and returns
/// how many are kept (at the front).
fn reduce(pts: &mut [ContactPoint]) -> usize {
    let n = pts.len();
    if n <= MAX_MANIFOLD_POINTS {
        return n;
    }
    let argmax = |pts: &[ContactPoint], from: usize, key: &dyn Fn(&ContactPoint) -> f64| {
        (from..pts.len())
            .max_by(|&a, &b| key(&pts[a]).total_cmp(&key(&pts[b])))
            .expect("non-empty")
    };
    // The deepest.
    let i = argmax(pts, 0, &|p| -p.separation);
    pts.swap(0, i);
    let a = pts[0].pos;
    // The farthest from it.
    let i = argmax(pts, 1, &|p| (p.pos - a).norm_squared());
    pts.swap(1, i);
    let b = pts[1].pos;
    // The largest triangle with those.
    let i = argmax(pts, 2, &|p| (b - a).cross(&(p.pos - a)).norm_squared());
    pts.swap(2, i);
    let c = pts[2].pos;
    // The largest quadrilateral: the point farthest outside the triangle's edges.
    let normal = (b - a).cross(&(c - a));
    let outside = |p: &ContactPoint| {
        [(a, b), (b, c), (c, a)]
            .iter()
            .map(|(u, v)| (v - u).cross(&(p.pos - u)).dot(&normal).min(0.0).abs())
            .sum::<f64>()
    };
    let i = argmax(pts, 3, &outside);
    pts.swap(3, i);
    MAX_MANIFOLD_POINTS
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sphere_touches_a_box_part_at_its_nearest_point() {
        let part = ConvexPart::from_box(
            "finger",
            [0.01, 0.02, 0.03],
            Vector3::new(0.1, 0.0, 0.0),
            Matrix3::identity(),
        )
        .unwrap();
        assert_eq!(part.faces.len(), 6);
        let (pos, rot) = (Vector3::zeros(), Matrix3::identity());
        let mut out = Vec::new();
        // Over the +x face, 1 mm into it.
        let c = Vector3::new(0.11 + 0.019, 0.005, 0.0);
        assert_eq!(
            sphere_manifold(&part, &pos, &rot, &c, 0.02, 0.002, &mut out),
            1
        );
        let p = out[0];
        assert!((p.separation + 0.001).abs() < 1e-12, "{p:?}");
        assert!((p.normal - Vector3::new(-1.0, 0.0, 0.0)).norm() < 1e-12);
        assert!((p.pos - Vector3::new(0.11, 0.005, 0.0)).norm() < 1e-12);
        // Off the +x+y edge, 1 mm clear: the nearest point is on the edge.
        out.clear();
        let dir = Vector3::new(1.0, 1.0, 0.0).normalize();
        let edge = Vector3::new(0.11, 0.02, 0.01);
        let c = edge + dir * 0.021;
        assert_eq!(
            sphere_manifold(&part, &pos, &rot, &c, 0.02, 0.002, &mut out),
            1
        );
        assert!((out[0].separation - 0.001).abs() < 1e-12);
        assert!((out[0].pos - edge).norm() < 1e-12);
        assert!((out[0].normal + dir).norm() < 1e-12);
        // Beyond the reach: none.
        out.clear();
        let c = Vector3::new(0.11 + 0.023, 0.0, 0.0);
        assert_eq!(
            sphere_manifold(&part, &pos, &rot, &c, 0.02, 0.002, &mut out),
            0
        );
        // The centre inside the part: out through the nearest face (−z here).
        let c = Vector3::new(0.1, 0.0, -0.025);
        assert_eq!(
            sphere_manifold(&part, &pos, &rot, &c, 0.02, 0.002, &mut out),
            1
        );
        assert!((out[0].separation - (-0.005 - 0.02)).abs() < 1e-12);
        assert!((out[0].normal - Vector3::new(0.0, 0.0, 1.0)).norm() < 1e-12);
    }

    #[test]
    fn a_posed_box_part_follows_its_link() {
        // The link turned a quarter about z and moved: the part's +x face now faces +y.
        let part = ConvexPart::from_box(
            "finger",
            [0.01, 0.01, 0.01],
            Vector3::zeros(),
            Matrix3::identity(),
        )
        .unwrap();
        let rot = Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
        let pos = Vector3::new(0.0, 0.0, 0.5);
        let c = Vector3::new(0.0, 0.0295, 0.5);
        let mut out = Vec::new();
        assert_eq!(
            sphere_manifold(&part, &pos, &rot, &c, 0.02, 0.002, &mut out),
            1
        );
        assert!((out[0].separation + 0.0005).abs() < 1e-12);
        assert!((out[0].normal - Vector3::new(0.0, -1.0, 0.0)).norm() < 1e-12);
        assert!(ConvexPart::from_box(
            "x",
            [0.0, 0.01, 0.01],
            Vector3::zeros(),
            Matrix3::identity()
        )
        .is_err());
    }

    /// A unit-free cube part of half size `h` centred at the link origin.
    fn cube_part(h: f64) -> ConvexPart {
        // Two triangles per face (ConvexPart::new merges them and makes the normals outward).
        ConvexPart::from_box("test", [h, h, h], Vector3::zeros(), Matrix3::identity())
            .expect("valid cube")
    }

    fn unit_box() -> BoxShape {
        BoxShape {
            center: Vector3::zeros(),
            rot: Matrix3::identity(),
            half: Vector3::new(0.02, 0.02, 0.02),
        }
    }

    #[test]
    fn coplanar_triangles_merge_into_faces() {
        let p = cube_part(0.01);
        assert_eq!(p.faces.len(), 6);
        assert!(p.faces.iter().all(|f| f.vertices.len() == 4));
        for f in &p.faces {
            assert!((f.offset - 0.01).abs() < 1e-12, "{f:?}");
        }
    }

    #[test]
    fn a_face_pressed_into_the_box_gives_its_four_corners_at_the_depth() {
        let part = cube_part(0.005);
        let bx = unit_box();
        // The part's −x face sunk 1 mm into the box's +x face, centred on it.
        let pos = Vector3::new(0.02 + 0.005 - 0.001, 0.0, 0.0);
        let mut out = Vec::new();
        let mut s = ManifoldScratch::new(8);
        let n = box_manifold(
            &part,
            &pos,
            &Matrix3::identity(),
            &bx,
            SPECULATIVE_DISTANCE,
            &mut s,
            &mut out,
        );
        assert_eq!(n, 4);
        for c in &out {
            assert!((c.separation + 0.001).abs() < 1e-12, "{c:?}");
            assert!((c.normal - Vector3::x()).norm() < 1e-12);
            assert!((c.pos.x - 0.019).abs() < 1e-12);
        }
    }

    #[test]
    fn an_overhanging_face_is_clipped_to_the_box_face() {
        let part = cube_part(0.01);
        let bx = unit_box();
        // Sunk 0.5 mm into +x, shifted so that half of it overhangs the box's +y edge.
        let pos = Vector3::new(0.02 + 0.01 - 0.0005, 0.02, 0.0);
        let mut out = Vec::new();
        let mut s = ManifoldScratch::new(8);
        box_manifold(
            &part,
            &pos,
            &Matrix3::identity(),
            &bx,
            SPECULATIVE_DISTANCE,
            &mut s,
            &mut out,
        );
        assert_eq!(out.len(), 4);
        assert!(out
            .iter()
            .all(|c| c.pos.y <= 0.02 + 1e-12 && c.pos.y >= 0.01 - 1e-12));
        assert!(out.iter().all(|c| (c.separation + 0.0005).abs() < 1e-12));
    }

    #[test]
    fn far_apart_shapes_make_no_contact() {
        let part = cube_part(0.01);
        let pos = Vector3::new(0.02 + 0.01 + 0.003, 0.0, 0.0);
        let mut out = Vec::new();
        let mut s = ManifoldScratch::new(8);
        let n = box_manifold(
            &part,
            &pos,
            &Matrix3::identity(),
            &unit_box(),
            SPECULATIVE_DISTANCE,
            &mut s,
            &mut out,
        );
        assert_eq!(n, 0);
        // Within the speculative distance: points with a positive separation.
        let pos = Vector3::new(0.02 + 0.01 + 0.001, 0.0, 0.0);
        box_manifold(
            &part,
            &pos,
            &Matrix3::identity(),
            &unit_box(),
            SPECULATIVE_DISTANCE,
            &mut s,
            &mut out,
        );
        assert!(!out.is_empty() && out.iter().all(|c| (c.separation - 0.001).abs() < 1e-12));
        // A larger reach takes the farther part too.
        let pos = Vector3::new(0.02 + 0.01 + 0.003, 0.0, 0.0);
        out.clear();
        let n = box_manifold(
            &part,
            &pos,
            &Matrix3::identity(),
            &unit_box(),
            0.004,
            &mut s,
            &mut out,
        );
        assert_eq!(n, 4);
    }

    #[test]
    fn a_tilted_part_keeps_the_deepest_point_first() {
        let part = cube_part(0.01);
        let rot = *nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), 0.3).matrix();
        let pos = Vector3::new(0.02 + 0.01, 0.0, 0.0);
        let mut out = Vec::new();
        let mut s = ManifoldScratch::new(8);
        box_manifold(
            &part,
            &pos,
            &rot,
            &unit_box(),
            SPECULATIVE_DISTANCE,
            &mut s,
            &mut out,
        );
        assert!(!out.is_empty() && out.len() <= MAX_MANIFOLD_POINTS);
        let deepest = out
            .iter()
            .map(|c| c.separation)
            .fold(f64::INFINITY, f64::min);
        assert!(deepest < 0.0);
    }

    #[test]
    fn reduction_keeps_four_spread_points() {
        let mk = |x: f64, y: f64, s: f64| ContactPoint {
            pos: Vector3::new(x, y, 0.0),
            normal: Vector3::z(),
            separation: s,
        };
        let mut pts = vec![
            mk(0.0, 0.0, -0.001),
            mk(0.5, 0.5, -0.0005),
            mk(1.0, 0.0, -0.0002),
            mk(1.0, 1.0, -0.0002),
            mk(0.0, 1.0, -0.0002),
            mk(0.5, 0.4, -0.0002),
        ];
        assert_eq!(reduce(&mut pts), 4);
        assert_eq!(pts[0].pos, Vector3::new(0.0, 0.0, 0.0));
        assert_eq!(pts[1].pos, Vector3::new(1.0, 1.0, 0.0));
        let kept: Vec<_> = pts[..4].iter().map(|p| (p.pos.x, p.pos.y)).collect();
        assert!(
            kept.contains(&(1.0, 0.0)) && kept.contains(&(0.0, 1.0)),
            "{kept:?}"
        );
    }

    #[test]
    fn malformed_parts_are_refused_with_the_reason() {
        let mut f = ConvexPartFile {
            link: "jaw".into(),
            vertices: vec![[0.0; 3]; 3],
            triangles: vec![[0, 1, 2]; 4],
        };
        assert!(ConvexPart::new(&f)
            .unwrap_err()
            .to_string()
            .contains("3 vertices"));
        f.vertices = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [f64::NAN, 0.0, 0.0],
        ];
        assert!(ConvexPart::new(&f)
            .unwrap_err()
            .to_string()
            .contains("not finite"));
        f.vertices[3] = [0.0, 0.0, 1.0];
        f.triangles = vec![[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 9]];
        assert!(ConvexPart::new(&f)
            .unwrap_err()
            .to_string()
            .contains("beyond the 4"));
    }
}
