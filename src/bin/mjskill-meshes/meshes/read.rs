//! Reading triangle meshes for primitive fitting: binary or ASCII STL and Wavefront OBJ, as
//! plain triangles in the mesh frame, with range checks.

use nalgebra::Vector3;

/// A point in the mesh (link) frame.
pub type Point = Vector3<f64>;

/// Largest `--scale`.
pub const MAX_SCALE: f64 = 1e6;
/// Largest vertex coordinate magnitude, after scaling (m): 1000 km, far beyond any robot part,
/// and small enough that every distance and volume stays finite.
pub const MAX_COORD: f64 = 1e6;

/// Why a mesh could not be read or fitted.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The file is neither a binary STL, an ASCII STL nor an OBJ with faces.
    #[error("{name}: {reason}")]
    Malformed {
        /// File name as given.
        name: String,
        /// What is wrong.
        reason: String,
    },
    /// Nothing left to fit (e.g. the crop box misses the mesh).
    #[error("no mesh points to fit{0}")]
    Empty(String),
    /// A vertex is not finite or out of range, or an argument is out of range.
    #[error("{0}")]
    Invalid(String),
    /// The points lie on a point, a line or a plane: no primitive of positive size fits.
    #[error(
        "the mesh is degenerate: the fitted {kind} has size {size} (its points lie on a point, \
         a line or a plane{crop}); nothing with a positive size can be fitted"
    )]
    Degenerate {
        /// Primitive kind.
        kind: &'static str,
        /// Its size as printed.
        size: String,
        /// Note about the crop box, if any.
        crop: &'static str,
    },
}

/// One triangle of a mesh.
pub type Triangle = [Point; 3];

/// Reads the triangles of a binary STL, an ASCII STL or a Wavefront OBJ file.
pub fn read_triangles(bytes: &[u8], name: &str) -> Result<Vec<Triangle>, MeshError> {
    let bad = |reason: String| MeshError::Malformed {
        name: name.to_string(),
        reason,
    };
    let lower = name.to_ascii_lowercase();
    if lower.ends_with(".obj") {
        return read_obj(bytes).map_err(bad);
    }
    if bytes.len() >= 84 {
        let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
        if n > 0 && n.checked_mul(50).and_then(|b| b.checked_add(84)) == Some(bytes.len()) {
            let tris = read_binary_stl(&bytes[84..], n);
            if let Some(k) = tris.iter().position(|t| t.iter().any(|v| !finite(v))) {
                return Err(bad(format!(
                    "triangle {k} has a non-finite vertex coordinate ({:?})",
                    tris[k].iter().map(|v| [v.x, v.y, v.z]).collect::<Vec<_>>()
                )));
            }
            return Ok(tris);
        }
    }
    if bytes.starts_with(b"solid") {
        return read_ascii_stl(bytes).map_err(bad);
    }
    Err(bad(format!(
        "not a binary STL (size {} does not match a triangle count), not an ASCII STL and not an .obj",
        bytes.len()
    )))
}

fn read_binary_stl(body: &[u8], n: usize) -> Vec<Triangle> {
    let f = |b: &[u8]| f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64;
    (0..n)
        .map(|i| {
            let t = &body[i * 50 + 12..i * 50 + 48];
            let v =
                |k: usize| Point::new(f(&t[k * 12..]), f(&t[k * 12 + 4..]), f(&t[k * 12 + 8..]));
            [v(0), v(1), v(2)]
        })
        .collect()
}

pub(crate) fn finite(v: &Point) -> bool {
    v.iter().all(|x| x.is_finite())
}

fn parse_xyz<'a>(mut it: impl Iterator<Item = &'a str>, line: usize) -> Result<Point, String> {
    let mut c = [0.0f64; 3];
    for x in &mut c {
        let s = it
            .next()
            .ok_or_else(|| format!("line {line}: expected 3 coordinates"))?;
        *x = s
            .parse()
            .map_err(|_| format!("line {line}: {s:?} is not a number"))?;
        if !x.is_finite() {
            return Err(format!("line {line}: coordinate {s:?} is not finite"));
        }
    }
    Ok(Point::from(c))
}

/// Scales every vertex by `scale` (the URDF `<mesh scale>`) and checks the result: `scale`
/// finite, positive and at most [`MAX_SCALE`], every coordinate within ±[`MAX_COORD`].
pub fn scale_triangles(tris: &mut [Triangle], scale: f64) -> Result<(), MeshError> {
    if !(scale.is_finite() && scale > 0.0 && scale <= MAX_SCALE) {
        return Err(MeshError::Invalid(format!(
            "--scale must be a positive number up to {MAX_SCALE:e}, got {scale}"
        )));
    }
    for (k, t) in tris.iter_mut().enumerate() {
        for v in t.iter_mut() {
            *v *= scale;
            if let Some(x) = v.iter().find(|x| !x.is_finite() || x.abs() > MAX_COORD) {
                return Err(MeshError::Invalid(format!(
                    "triangle {k} has a vertex coordinate {x:e} (after scaling by {scale}); \
                     coordinates must lie within ±{MAX_COORD:e} m"
                )));
            }
        }
    }
    Ok(())
}

fn read_ascii_stl(bytes: &[u8]) -> Result<Vec<Triangle>, String> {
    let text =
        std::str::from_utf8(bytes).map_err(|_| "ASCII STL is not valid UTF-8".to_string())?;
    let mut verts = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let mut it = line.split_whitespace();
        if it.next() == Some("vertex") {
            verts.push(parse_xyz(it, i + 1)?);
        }
    }
    if verts.is_empty() || verts.len() % 3 != 0 {
        return Err(format!(
            "ASCII STL has {} vertices, not a positive multiple of 3",
            verts.len()
        ));
    }
    Ok(verts.chunks(3).map(|c| [c[0], c[1], c[2]]).collect())
}

fn read_obj(bytes: &[u8]) -> Result<Vec<Triangle>, String> {
    let text = std::str::from_utf8(bytes).map_err(|_| "OBJ is not valid UTF-8".to_string())?;
    let mut verts = Vec::new();
    let mut tris = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => verts.push(parse_xyz(it, i + 1)?),
            Some("f") => {
                let idx: Vec<usize> = it
                    .map(|s| {
                        let first = s.split('/').next().unwrap_or("");
                        let k: i64 = first
                            .parse()
                            .map_err(|_| format!("line {}: bad face index {s:?}", i + 1))?;
                        let k = if k < 0 { verts.len() as i64 + k } else { k - 1 };
                        usize::try_from(k)
                            .ok()
                            .filter(|&k| k < verts.len())
                            .ok_or_else(|| format!("line {}: face index {s} out of range", i + 1))
                    })
                    .collect::<Result<_, _>>()?;
                if idx.len() < 3 {
                    return Err(format!("line {}: a face needs 3 vertices", i + 1));
                }
                for k in 1..idx.len() - 1 {
                    tris.push([verts[idx[0]], verts[idx[k]], verts[idx[k + 1]]]);
                }
            }
            _ => {}
        }
    }
    if tris.is_empty() {
        return Err("OBJ has no faces".into());
    }
    Ok(tris)
}
