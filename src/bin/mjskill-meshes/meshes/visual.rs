//! Visual mesh conversion (`mjskill convert-visuals`): upstream visual meshes (glTF, COLLADA,
//! STL; see [`super::formats`]) become files MuJoCo 2.2 draws: one Wavefront OBJ per
//! (mesh, material) with normals and, where the source has a texture, texture coordinates,
//! plus the texture as a (downsampled) PNG.
//!
//! * Vertices are welded by position (and texture coordinate), triangles simplified with
//!   meshoptimizer to a per-mesh budget (texture seams kept), degenerate and repeated
//!   triangles dropped.
//! * Normals are recomputed with a crease angle of [`CREASE_DEG`] (MuJoCo's OBJ loader does
//!   not share vertices between faces, so without normals it could only shade flat). Triangles whose directed edge repeats another's get their own vertices, because
//!   MuJoCo rejects such meshes as "inconsistently oriented".
//! * Material colour factors are linear (glTF, URDF); they are written sRGB-encoded, because
//!   MuJoCo's renderer works in display values. Texture pixels are sRGB already.
//! * Each written mesh is compiled by MuJoCo on the spot; one it rejects (e.g. a flat decal
//!   has no volume) is dropped with a note.
use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use nalgebra::Vector3;

use super::formats::{read_png, read_visual, Image, Part, SourceMesh};
use super::read::{MeshError, MAX_COORD};

/// Default triangle budget of one mesh file (all its materials together).
pub const DEFAULT_MAX_TRIANGLES: usize = 3000;
/// Default largest texture side (pixels).
pub const DEFAULT_TEXTURE_SIZE: u32 = 512;
/// Crease angle for computed normals (degrees): faces meeting at a sharper angle keep their
/// own normals at the shared vertex.
pub const CREASE_DEG: f32 = 35.0;

/// Options of a conversion.
#[derive(Debug, Clone)]
pub struct Options {
    /// Colours (linear RGBA) of materials a URDF names without defining them.
    pub materials: Vec<(String, [f32; 4])>,
    /// Triangle budget per mesh file.
    pub max_triangles: usize,
    /// Largest distance (metres) simplification may move the surface; it overrides the
    /// budget. None: up to 2 % of each mesh's extent (8 % where the budget needs it).
    pub max_error: Option<f32>,
    /// Largest texture side; larger textures are box-filtered down by powers of two.
    pub texture_size: u32,
}

/// One written (mesh, material) part, as a URDF `<visual>` names it.
#[derive(Debug, Clone)]
pub struct WrittenPart {
    /// OBJ file name (relative to the output directory).
    pub obj: String,
    /// sRGB colour.
    pub rgba: [f32; 4],
    /// PNG texture file name (relative to the output directory).
    pub texture: Option<String>,
    /// Triangles before and after simplification.
    pub triangles: (usize, usize),
}

fn linear_to_srgb(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    if x <= 0.0031308 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// Welds exact duplicates, simplifies towards `target` triangles (attribute seams kept by
/// meshoptimizer) and compacts the vertices. With `max_error` (metres), simplification never
/// moves the surface further than that and keeps more triangles than `target` where the
/// bound requires it; without, it may move it by up to 2 % of the mesh's extent, and by up
/// to 8 % (collapsing across texture seams) where the budget cannot be met otherwise.
pub fn simplify(part: &Part, target: usize, max_error: Option<f32>) -> Part {
    #[derive(Clone, Copy, Default)]
    #[repr(C)]
    struct V([f32; 8]);
    let n = part.positions.len();
    // Source normals are not kept: flat-shaded sources split every vertex by normal, which
    // would make every edge a seam that simplification must keep. Normals are recomputed with
    // a crease angle afterwards.
    let verts: Vec<V> = (0..n)
        .map(|i| {
            let p = part.positions[i];
            let nm = [0.0; 3];
            let uv = part.uvs.as_ref().map_or([0.0; 2], |v| v[i]);
            V([p[0], p[1], p[2], nm[0], nm[1], nm[2], uv[0], uv[1]])
        })
        .collect();
    let (unique, remap) = meshopt::generate_vertex_remap(&verts, Some(&part.indices));
    let indices = meshopt::remap_index_buffer(Some(&part.indices), unique, &remap);
    let mut indices = distinct_triangles(&indices);
    let mut verts = meshopt::remap_vertex_buffer(&verts, unique, &remap);
    use meshopt::SimplifyOptions as O;
    let (first, second) = match max_error {
        Some(e) => ((e, O::ErrorAbsolute), (e, O::ErrorAbsolute | O::Permissive)),
        None => ((0.02, O::None), (0.08, O::Permissive)),
    };
    for (error, options) in [first, second] {
        // The second pass only when the first is still over budget (texture seams held it
        // back): it may collapse across seams.
        if indices.len() / 3 > target {
            split_crowded_vertices(&mut indices, &mut verts);
            let positions: Vec<[f32; 3]> = verts.iter().map(|v| [v.0[0], v.0[1], v.0[2]]).collect();
            indices =
                meshopt::simplify_decoder(&indices, &positions, target * 3, error, options, None);
        }
    }
    // Vertex cache optimisation, too, rescans every triangle of a vertex each time it
    // scores it.
    split_crowded_vertices(&mut indices, &mut verts);
    let indices = meshopt::optimize_vertex_cache(&indices, verts.len());
    let mut indices = indices;
    let verts = meshopt::optimize_vertex_fetch(&mut indices, &verts);
    Part {
        material: part.material,
        positions: verts.iter().map(|v| [v.0[0], v.0[1], v.0[2]]).collect(),
        normals: None,
        uvs: part
            .uvs
            .as_ref()
            .map(|_| verts.iter().map(|v| [v.0[6], v.0[7]]).collect()),
        indices,
    }
}

/// `indices` without degenerate triangles (a vertex twice) and without repeats of a
/// triangle (the same three vertices in any order; the first is kept), which [`obj_text`]
/// would drop anyway. A polygon fanned over a few distinct vertices (one OBJ face with
/// 200,000 corners on 8 vertices) becomes at most 56 triangles here instead of hundreds of
/// thousands that simplification and normals would work through.
fn distinct_triangles(indices: &[u32]) -> Vec<u32> {
    let mut seen = std::collections::HashSet::new();
    let mut out = Vec::with_capacity(indices.len());
    for t in indices.chunks_exact(3) {
        let mut sorted = [t[0], t[1], t[2]];
        sorted.sort_unstable();
        if sorted[0] != sorted[1] && sorted[1] != sorted[2] && seen.insert(sorted) {
            out.extend_from_slice(t);
        }
    }
    out
}

/// Most triangles that share one vertex when simplifying and ordering triangles.
/// meshoptimizer classifies each vertex by looking up every edge of its neighbours, and its
/// vertex cache optimisation rescans a vertex's triangles whenever it scores the vertex: both
/// take time quadratic in the triangles at a vertex (the centre of a 200,000-corner polygon
/// fan took minutes).
pub const MAX_TRIANGLES_AT_VERTEX: usize = 256;

/// Gives every further [`MAX_TRIANGLES_AT_VERTEX`] triangles at a vertex their own copy of
/// it (appended to `verts`), so that no vertex has more. The copies share the position, so
/// simplification keeps them in place (a vertex where such copies meet is locked) and the
/// OBJ writes the position once.
fn split_crowded_vertices<T: Copy>(indices: &mut [u32], verts: &mut Vec<T>) {
    let mut seen = vec![0usize; verts.len()];
    let mut copies: HashMap<(u32, usize), u32> = HashMap::new();
    for i in indices.iter_mut() {
        let v = *i;
        let k = seen[v as usize] / MAX_TRIANGLES_AT_VERTEX;
        seen[v as usize] += 1;
        if k > 0 {
            *i = *copies.entry((v, k)).or_insert_with(|| {
                verts.push(verts[v as usize]);
                (verts.len() - 1) as u32
            });
        }
    }
}

fn face_normal(p: &[[f32; 3]], t: &[u32]) -> Vector3<f32> {
    let a = Vector3::from(p[t[0] as usize]);
    let b = Vector3::from(p[t[1] as usize]);
    let c = Vector3::from(p[t[2] as usize]);
    (b - a).cross(&(c - a))
}

/// Most face normals a corner's normal is averaged from: where more faces meet at one
/// position (a polygon fanned from one corner, or a crafted mesh), faces of nearly the same
/// direction are summed into one candidate first, so that the normals take time linear in
/// the triangles.
pub const MAX_NORMAL_CANDIDATES: usize = 256;

/// (unit direction, area-weighted normal) pairs a corner's normal is averaged from.
type Candidates = Vec<(Vector3<f32>, Vector3<f32>)>;

/// The (unit direction, area-weighted normal) candidates a corner at a position where the
/// faces `group` meet averages from: one per face with an area, in order, or, for more than
/// [`MAX_NORMAL_CANDIDATES`] faces, sums of faces whose unit normals fall into the same
/// cell of a grid, the finest (from 2⁻²⁰) that leaves at most that many.
fn normal_candidates(group: &[usize], faces: &[Vector3<f32>]) -> Candidates {
    let own: Vec<(Vector3<f32>, Vector3<f32>)> = group
        .iter()
        .filter_map(|&g| Some((faces[g].try_normalize(0.0)?, faces[g])))
        .collect();
    if own.len() <= MAX_NORMAL_CANDIDATES {
        return own;
    }
    let mut cell = 2f32.powi(-20);
    loop {
        let mut index: HashMap<[i32; 3], usize> = HashMap::new();
        let mut sums: Vec<Vector3<f32>> = Vec::new();
        for (u, n) in &own {
            let key = [u.x, u.y, u.z].map(|x| (x / cell).round() as i32);
            let k = *index.entry(key).or_insert_with(|| {
                sums.push(Vector3::zeros());
                sums.len() - 1
            });
            sums[k] += n;
        }
        // At a cell of 0.5 every unit vector falls into one of 5³ cells, so this ends.
        if sums.len() <= MAX_NORMAL_CANDIDATES {
            return sums
                .into_iter()
                .filter_map(|n| Some((n.try_normalize(0.0)?, n)))
                .collect();
        }
        cell *= 2.0;
    }
}

/// Per-corner normals of triangle list `part`: the source's, or area-weighted averages of
/// the faces at the same position within [`CREASE_DEG`] of the corner's face (see
/// [`MAX_NORMAL_CANDIDATES`] for positions where very many faces meet).
fn corner_normals(part: &Part) -> Vec<[f32; 3]> {
    if let Some(n) = &part.normals {
        return part.indices.iter().map(|&i| n[i as usize]).collect();
    }
    let key = |p: [f32; 3]| (p[0].to_bits(), p[1].to_bits(), p[2].to_bits());
    let mut at: HashMap<(u32, u32, u32), Vec<usize>> = HashMap::new();
    let faces: Vec<Vector3<f32>> = part
        .indices
        .chunks(3)
        .map(|t| face_normal(&part.positions, t))
        .collect();
    for (f, t) in part.indices.chunks(3).enumerate() {
        for &i in t {
            at.entry(key(part.positions[i as usize]))
                .or_default()
                .push(f);
        }
    }
    let candidates: HashMap<(u32, u32, u32), Candidates> = at
        .into_iter()
        .map(|(k, group)| (k, normal_candidates(&group, &faces)))
        .collect();
    let cos = CREASE_DEG.to_radians().cos();
    let mut out = Vec::with_capacity(part.indices.len());
    for (f, t) in part.indices.chunks(3).enumerate() {
        let own = faces[f].try_normalize(0.0).unwrap_or(Vector3::z());
        for &i in t {
            let mut sum = Vector3::zeros();
            for (u, n) in &candidates[&key(part.positions[i as usize])] {
                if u.dot(&own) >= cos {
                    sum += n;
                }
            }
            let n = sum.try_normalize(0.0).unwrap_or(own);
            out.push([n.x, n.y, n.z]);
        }
    }
    out
}

/// The OBJ text of `part` (normals always, texture coordinates if it has them): positions,
/// normals and texture coordinates are each written once and indexed separately.
/// Degenerate and repeated triangles are dropped; a triangle repeating a directed edge of
/// another gets its own copies of its positions (MuJoCo's orientation check works on the
/// position indices). Returns the text and the triangles written.
pub fn obj_text(part: &Part) -> (String, usize) {
    let normals = corner_normals(part);
    let mut text = String::new();
    // Each attribute once, by its printed form (so that rounding merges equal values).
    struct Table {
        index: HashMap<String, u32>,
        lines: String,
        tag: &'static str,
    }
    impl Table {
        fn id(&mut self, printed: String) -> u32 {
            let n = self.index.len() as u32;
            let tag = self.tag;
            *self.index.entry(printed).or_insert_with_key(|k| {
                let _ = writeln!(self.lines, "{tag} {k}");
                n
            })
        }
        fn fresh(&mut self, printed: &str) -> u32 {
            // A copy under a new index (the key gets a unique suffix that is not printed).
            let n = self.index.len() as u32;
            let _ = writeln!(self.lines, "{} {printed}", self.tag);
            self.index.insert(format!("{printed}#{n}"), n);
            n
        }
    }
    let table = |tag| Table {
        index: HashMap::new(),
        lines: String::new(),
        tag,
    };
    let (mut vs, mut vns, mut vts) = (table("v"), table("vn"), table("vt"));
    let mut faces: Vec<[(u32, u32, u32); 3]> = Vec::new();
    let mut seen_tris = std::collections::HashSet::new();
    let mut edges = std::collections::HashSet::new();
    for (f, t) in part.indices.chunks(3).enumerate() {
        if face_normal(&part.positions, t).norm() <= 1e-12 {
            continue;
        }
        let pos = |k: usize| {
            let p = part.positions[t[k] as usize];
            format!("{} {} {}", fmt(p[0]), fmt(p[1]), fmt(p[2]))
        };
        let printed = [pos(0), pos(1), pos(2)];
        if printed[0] == printed[1] || printed[1] == printed[2] || printed[0] == printed[2] {
            continue; // degenerate once rounded
        }
        let mut v = [0u32; 3];
        for k in 0..3 {
            v[k] = vs.id(printed[k].clone());
        }
        let mut sorted = v;
        sorted.sort();
        if !seen_tris.insert(sorted) {
            continue;
        }
        let dir = [(v[0], v[1]), (v[1], v[2]), (v[2], v[0])];
        if dir.iter().any(|e| edges.contains(e)) {
            for k in 0..3 {
                v[k] = vs.fresh(&printed[k]);
            }
        } else {
            edges.extend(dir);
        }
        let mut face = [(0u32, 0u32, 0u32); 3];
        for k in 0..3 {
            let n = normals[3 * f + k];
            let vn = vns.id(format!("{} {} {}", fmt3(n[0]), fmt3(n[1]), fmt3(n[2])));
            let vt = match &part.uvs {
                // OBJ's v grows upwards from the image's bottom row.
                Some(uv) => {
                    let c = uv[t[k] as usize];
                    vts.id(format!("{} {}", fmt4(c[0]), fmt4(1.0 - c[1])))
                }
                None => 0,
            };
            face[k] = (v[k] + 1, vt + 1, vn + 1);
        }
        faces.push(face);
    }
    text.push_str(&vs.lines);
    text.push_str(&vns.lines);
    text.push_str(&vts.lines);
    let textured = part.uvs.is_some();
    for f in &faces {
        let c = |(v, t, n): (u32, u32, u32)| {
            if textured {
                format!("{v}/{t}/{n}")
            } else {
                format!("{v}//{n}")
            }
        };
        let _ = writeln!(text, "f {} {} {}", c(f[0]), c(f[1]), c(f[2]));
    }
    (text, faces.len())
}

fn fmt3(x: f32) -> String {
    trim(format!("{:.3}", x))
}

/// A coordinate in metres to 0.1 mm (well below a pixel of any camera at the table).
fn fmt(x: f32) -> String {
    trim(format!("{:.4}", x))
}

fn fmt4(x: f32) -> String {
    trim(format!("{:.4}", x))
}

fn trim(s: String) -> String {
    let t = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    };
    if t == "-0" {
        "0".into()
    } else {
        t
    }
}

/// Halves `img` (2×2 box filter) until its larger side is at most `max`.
pub fn downsample(img: &Image, max: u32) -> Image {
    let mut cur = img.clone();
    while cur.width.max(cur.height) > max && cur.width >= 2 && cur.height >= 2 {
        let (w, h) = (cur.width / 2, cur.height / 2);
        let mut out = vec![0u8; (w * h * 4) as usize];
        for y in 0..h {
            for x in 0..w {
                for c in 0..4 {
                    let at = |xx: u32, yy: u32| {
                        cur.rgba[((yy * cur.width + xx) * 4 + c) as usize] as u32
                    };
                    let s = at(2 * x, 2 * y)
                        + at(2 * x + 1, 2 * y)
                        + at(2 * x, 2 * y + 1)
                        + at(2 * x + 1, 2 * y + 1);
                    out[((y * w + x) * 4 + c) as usize] = ((s + 2) / 4) as u8;
                }
            }
        }
        cur = Image {
            width: w,
            height: h,
            rgba: out,
        };
    }
    cur
}

/// PNG bytes of `img` (RGB when fully opaque).
pub fn png_bytes(img: &Image) -> Result<Vec<u8>, MeshError> {
    let opaque = img.rgba.chunks(4).all(|p| p[3] == 255);
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, img.width, img.height);
        enc.set_color(if opaque {
            png::ColorType::Rgb
        } else {
            png::ColorType::Rgba
        });
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(png::Compression::High);
        let mut w = enc
            .write_header()
            .map_err(|e| MeshError::Invalid(format!("PNG encoding: {e}")))?;
        let data: Vec<u8> = if opaque {
            img.rgba
                .chunks(4)
                .flat_map(|p| [p[0], p[1], p[2]])
                .collect()
        } else {
            img.rgba.clone()
        };
        w.write_image_data(&data)
            .map_err(|e| MeshError::Invalid(format!("PNG encoding: {e}")))?;
    }
    Ok(out)
}

fn write(path: &Path, bytes: &[u8]) -> Result<(), MeshError> {
    std::fs::write(path, bytes)
        .map_err(|e| MeshError::Invalid(format!("cannot write {}: {e}", path.display())))
}

/// Whether MuJoCo 2.2 compiles `obj` as a mesh geom (visual-only, density 0); the error text
/// otherwise.
fn mujoco_accepts(obj: &str) -> Result<(), String> {
    let mjcf = mjskill::Mjcf {
        xml: "<mujoco><asset><mesh name=\"m\" file=\"m.obj\"/></asset><worldbody><body>\
              <geom type=\"mesh\" mesh=\"m\" density=\"0\" contype=\"0\" conaffinity=\"0\"/>\
              <geom type=\"sphere\" size=\"0.01\"/></body></worldbody></mujoco>"
            .into(),
        assets: vec![("m.obj".into(), obj.as_bytes().to_vec())],
    };
    mjcf.compile().map(|_| ()).map_err(|e| e.to_string())
}

/// Converts one visual mesh file: every material part simplified, written as
/// `<stem>_<k>.obj` into `out_dir` (textures as `<stem>_<k>.png`). `rgba` colours an STL;
/// `override_rgba` (a URDF `<material>` colour, which SAPIEN applies to every part of the
/// visual) replaces the file's colours; `scale` is baked into the vertices. Notes go to
/// `notes`.
pub fn convert_mesh(
    src: &Path,
    scale: [f32; 3],
    override_rgba: Option<[f32; 4]>,
    out_dir: &Path,
    stem: &str,
    opts: &Options,
    notes: &mut Vec<String>,
) -> Result<Vec<WrittenPart>, MeshError> {
    let default_rgba = override_rgba.unwrap_or([1.0, 1.0, 1.0, 1.0]);
    let mut mesh: SourceMesh = read_visual(src, default_rgba)?.merge_by_material();
    if let Some(c) = override_rgba {
        for m in &mut mesh.materials {
            m.rgba = c;
            m.texture = None;
        }
        for p in &mut mesh.parts {
            p.uvs = None;
        }
        // One colour: one part.
        for p in &mut mesh.parts {
            p.material = 0;
        }
        mesh = mesh.merge_by_material();
    }
    for p in &mut mesh.parts {
        for v in &mut p.positions {
            for k in 0..3 {
                v[k] *= scale[k];
            }
        }
        if scale.iter().any(|s| *s < 0.0) {
            for t in p.indices.chunks_mut(3) {
                t.swap(1, 2);
            }
        }
    }
    for (k, p) in mesh.parts.iter().enumerate() {
        check_vertices(src, k, p, scale)?;
    }
    let total = mesh.triangles().max(1);
    let mut out = Vec::new();
    for (k, p) in mesh.parts.iter().enumerate() {
        let tris = p.indices.len() / 3;
        let budget = ((opts.max_triangles as f64 * tris as f64 / total as f64).ceil() as usize)
            .max(12)
            .min(tris);
        let simple = simplify(p, budget, opts.max_error);
        let (obj, written) = obj_text(&simple);
        let name = format!("{stem}_{k}");
        if written < 2 {
            notes.push(format!(
                "{}: part {k} ({}) has no drawable triangles left; dropped",
                src.display(),
                mesh.materials[p.material].name
            ));
            continue;
        }
        if let Err(e) = mujoco_accepts(&obj) {
            notes.push(format!(
                "{}: part {k} ({}, {written} triangles) dropped: {e}",
                src.display(),
                mesh.materials[p.material].name
            ));
            continue;
        }
        write(&out_dir.join(format!("{name}.obj")), obj.as_bytes())?;
        let mat = &mesh.materials[p.material];
        let texture = match (&mat.texture, &simple.uvs) {
            (Some(img), Some(_)) => {
                let file = format!("{name}.png");
                write(
                    &out_dir.join(&file),
                    &png_bytes(&downsample(img, opts.texture_size))?,
                )?;
                Some(file)
            }
            _ => None,
        };
        let c = mat.rgba;
        out.push(WrittenPart {
            obj: format!("{name}.obj"),
            rgba: [
                linear_to_srgb(c[0]),
                linear_to_srgb(c[1]),
                linear_to_srgb(c[2]),
                c[3],
            ],
            texture,
            triangles: (tris, written),
        });
    }
    Ok(out)
}

/// Errors naming `src` when part `k` (scaled by `scale`) has a non-finite position, normal
/// or texture coordinate, or a position beyond ±[`MAX_COORD`] m: an OBJ with `v NaN NaN NaN`
/// would draw nothing, or garbage.
fn check_vertices(src: &Path, k: usize, p: &Part, scale: [f32; 3]) -> Result<(), MeshError> {
    let bad = |what: &str, i: usize, v: &[f32]| MeshError::Malformed {
        name: src.display().to_string(),
        reason: format!(
            "part {k} vertex {i} has {what} {v:?} (after scaling by {scale:?}); positions \
             must be finite and within ±{MAX_COORD:e} m, normals and texture coordinates finite"
        ),
    };
    let far = |v: &[f32]| {
        v.iter()
            .any(|x| !x.is_finite() || f64::from(x.abs()) > MAX_COORD)
    };
    if let Some((i, v)) = p.positions.iter().enumerate().find(|(_, v)| far(&v[..])) {
        return Err(bad("the position", i, v));
    }
    let not_finite = |v: &[f32]| v.iter().any(|x| !x.is_finite());
    if let Some(n) = &p.normals {
        if let Some((i, v)) = n.iter().enumerate().find(|(_, v)| not_finite(&v[..])) {
            return Err(bad("the normal", i, v));
        }
    }
    if let Some(uv) = &p.uvs {
        if let Some((i, v)) = uv.iter().enumerate().find(|(_, v)| not_finite(&v[..])) {
            return Err(bad("the texture coordinate", i, v));
        }
    }
    Ok(())
}

fn f3(v: &[f64; 3]) -> String {
    v.iter()
        .map(|x| trim(format!("{x:.6}")))
        .collect::<Vec<_>>()
        .join(" ")
}

/// URDF `<visual>` elements for `parts` at `origin` (xyz, rpy), file names prefixed by
/// `prefix` (the output directory relative to the URDF, e.g. `"visual/"`).
pub fn visual_elements(
    parts: &[WrittenPart],
    xyz: &[f64; 3],
    rpy: &[f64; 3],
    prefix: &str,
) -> Vec<String> {
    parts
        .iter()
        .map(|p| {
            let c = p.rgba.map(|x| trim(format!("{x:.4}"))).join(" ");
            let tex = p
                .texture
                .as_ref()
                .map(|t| format!("<texture filename=\"{prefix}{t}\"/>"))
                .unwrap_or_default();
            let stem = p.obj.trim_end_matches(".obj");
            format!(
                "<visual><origin xyz=\"{}\" rpy=\"{}\"/><geometry><mesh filename=\"{prefix}{}\"/></geometry>\
                 <material name=\"{stem}\"><color rgba=\"{c}\"/>{tex}</material></visual>",
                f3(xyz),
                f3(rpy),
                p.obj
            )
        })
        .collect()
}

/// A text file (URDF, MJCF) by the rule of every input file ([`mjskill::files`]).
fn read_text(path: &Path) -> Result<String, MeshError> {
    let bytes = mjskill::files::read(path).map_err(|e| MeshError::Invalid(e.to_string()))?;
    String::from_utf8(bytes)
        .map_err(|_| MeshError::Invalid(format!("cannot read {}: not UTF-8 text", path.display())))
}

/// Converts every mesh `<visual>` of the URDF at `src` (paths relative to it) into
/// `out_dir`; returns per link its new `<visual>` elements, with file names prefixed by
/// `prefix`. Primitive visuals are kept as they are, with their colour. Prints a line per
/// mesh to `log`.
pub fn convert_urdf(
    src: &Path,
    out_dir: &Path,
    prefix: &str,
    opts: &Options,
    log: &mut Vec<String>,
) -> Result<Vec<(String, Vec<String>)>, MeshError> {
    let name = src.display().to_string();
    let text = read_text(src)?;
    let robot = urdf_rs::read_from_string(&text).map_err(|e| MeshError::Malformed {
        name: name.clone(),
        reason: e.to_string(),
    })?;
    let mut global: HashMap<String, [f32; 4]> = robot
        .materials
        .iter()
        .filter_map(|m| Some((m.name.clone(), m.color.as_ref()?.rgba.map(|x| x as f32))))
        .collect();
    for (n, c) in &opts.materials {
        global.entry(n.clone()).or_insert(*c);
    }
    let dir = src.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(out_dir)
        .map_err(|e| MeshError::Invalid(format!("cannot create {}: {e}", out_dir.display())))?;
    // Each link's meshes are written as `<link>_<visual>_<part>.obj`: a second link of the
    // same name would overwrite the first one's.
    let mut names = std::collections::HashSet::new();
    if let Some(link) = robot.links.iter().find(|l| !names.insert(l.name.as_str())) {
        return Err(MeshError::Malformed {
            name,
            reason: format!(
                "link {:?} is defined twice; link names must be unique",
                link.name
            ),
        });
    }
    let mut out = Vec::new();
    let mut done: HashMap<(PathBuf, String), Vec<WrittenPart>> = HashMap::new();
    for link in &robot.links {
        let mut elements = Vec::new();
        for (k, v) in link.visual.iter().enumerate() {
            let rgba = v.material.as_ref().and_then(|m| {
                m.color
                    .as_ref()
                    .map(|c| c.rgba.map(|x| x as f32))
                    .or_else(|| global.get(&m.name).copied())
            });
            let xyz = *v.origin.xyz;
            let rpy = *v.origin.rpy;
            match &v.geometry {
                urdf_rs::Geometry::Mesh { filename, scale } => {
                    let s = scale.map(|s| s.map(|x| x as f32)).unwrap_or([1.0; 3]);
                    let path = dir.join(filename.trim_start_matches("package://"));
                    let key = (path.clone(), format!("{s:?}{rgba:?}"));
                    let parts = match done.get(&key) {
                        Some(p) => p.clone(),
                        None => {
                            let stem = format!("{}_{k}", link.name);
                            let mut notes = Vec::new();
                            let p = convert_mesh(&path, s, rgba, out_dir, &stem, opts, &mut notes)?;
                            let before: usize = p.iter().map(|p| p.triangles.0).sum();
                            let after: usize = p.iter().map(|p| p.triangles.1).sum();
                            log.push(format!(
                                "{} -> {stem}_*.obj: {} parts, {before} -> {after} triangles",
                                filename,
                                p.len()
                            ));
                            log.extend(notes);
                            done.insert(key, p.clone());
                            p
                        }
                    };
                    elements.extend(visual_elements(&parts, &xyz, &rpy, prefix));
                }
                g => {
                    let geom = match g {
                        urdf_rs::Geometry::Box { size } => format!("<box size=\"{}\"/>", f3(size)),
                        urdf_rs::Geometry::Cylinder { radius, length } => {
                            format!("<cylinder radius=\"{radius}\" length=\"{length}\"/>")
                        }
                        urdf_rs::Geometry::Capsule { radius, length } => {
                            format!("<capsule radius=\"{radius}\" length=\"{length}\"/>")
                        }
                        urdf_rs::Geometry::Sphere { radius } => {
                            format!("<sphere radius=\"{radius}\"/>")
                        }
                        urdf_rs::Geometry::Mesh { .. } => unreachable!("handled above"),
                    };
                    let c = rgba.unwrap_or([1.0; 4]);
                    let c = [
                        linear_to_srgb(c[0]),
                        linear_to_srgb(c[1]),
                        linear_to_srgb(c[2]),
                        c[3],
                    ]
                    .map(|x| trim(format!("{x:.4}")))
                    .join(" ");
                    elements.push(format!(
                        "<visual><origin xyz=\"{}\" rpy=\"{}\"/><geometry>{geom}</geometry>\
                         <material name=\"{}_{k}\"><color rgba=\"{c}\"/></material></visual>",
                        f3(&xyz),
                        f3(&rpy),
                        link.name
                    ));
                }
            }
        }
        if !elements.is_empty() {
            out.push((link.name.clone(), elements));
        }
    }
    Ok(out)
}

/// Replaces the `<visual>` elements of each link named in `visuals` in the URDF text
/// `model` with the given ones (other links are left alone). Errors name a link the model
/// lacks.
pub fn splice_visuals(model: &str, visuals: &[(String, Vec<String>)]) -> Result<String, String> {
    let mut text = model.to_string();
    for (link, elements) in visuals {
        let open = format!("<link name=\"{link}\"");
        let start = text
            .find(&open)
            .ok_or_else(|| format!("the model URDF has no link {link:?}"))?;
        let tag_end = start + text[start..].find('>').ok_or("unterminated <link>")?;
        let self_closing = text[..tag_end].ends_with('/');
        let indent = {
            let line_start = text[..start].rfind('\n').map_or(0, |i| i + 1);
            text[line_start..start].to_string()
        };
        let inner_indent = format!("{indent}  ");
        let new_lines: String = elements
            .iter()
            .map(|e| format!("\n{inner_indent}{e}"))
            .collect();
        if self_closing {
            let replacement = format!(
                "{}>{new_lines}\n{indent}</link>",
                &text[start..tag_end - 1].trim_end()
            );
            text.replace_range(start..tag_end + 1, &replacement);
            continue;
        }
        let close = tag_end
            + text[tag_end..]
                .find("</link>")
                .ok_or_else(|| format!("link {link:?} has no </link>"))?;
        // Remove the existing visuals (each with the line it sits on when alone there).
        let mut body = text[tag_end + 1..close].to_string();
        while let Some(a) = body.find("<visual") {
            let b = a
                + body[a..]
                    .find("</visual>")
                    .ok_or_else(|| format!("link {link:?}: unterminated <visual>"))?
                + "</visual>".len();
            let line_a = body[..a].rfind('\n').unwrap_or(a);
            let only_ws = body[line_a..a].trim().is_empty();
            let from = if only_ws { line_a } else { a };
            body.replace_range(from..b, "");
        }
        text.replace_range(tag_end + 1..close, &format!("{new_lines}{body}"));
    }
    Ok(text)
}

/// Re-encodes a PNG texture, downsampled to at most `size` pixels a side.
pub fn convert_texture(src: &Path, dst: &Path, size: u32) -> Result<(u32, u32), MeshError> {
    let img = downsample(&read_png(src)?, size);
    write(dst, &png_bytes(&img)?)?;
    Ok((img.width, img.height))
}

/// What `mjskill convert-visuals` converts.
#[derive(Debug, Clone)]
pub enum Source {
    /// Every mesh visual of an upstream URDF, optionally spliced into a model URDF.
    Urdf {
        /// The upstream URDF.
        urdf: PathBuf,
        /// The model URDF to rewrite.
        into: Option<PathBuf>,
    },
    /// One mesh with a uniform scale.
    Mesh {
        /// The mesh file.
        mesh: PathBuf,
        /// Scale baked into the vertices.
        scale: f64,
    },
    /// A PNG texture.
    Texture(PathBuf),
}

/// Runs a conversion into `out_dir`; returns the lines to print (a summary per mesh, and the
/// `<visual>` elements when they are not spliced into a model).
pub fn run(
    source: Source,
    out_dir: &Path,
    name: &str,
    opts: Options,
) -> Result<Vec<String>, MeshError> {
    std::fs::create_dir_all(out_dir)
        .map_err(|e| MeshError::Invalid(format!("cannot create {}: {e}", out_dir.display())))?;
    let mut log = Vec::new();
    match source {
        Source::Urdf { urdf, into } => {
            let prefix = match &into {
                Some(model) => {
                    let base = model
                        .parent()
                        .filter(|p| !p.as_os_str().is_empty())
                        .unwrap_or(Path::new("."));
                    let canon = |p: &Path| {
                        p.canonicalize().map_err(|e| {
                            MeshError::Invalid(format!("cannot resolve {}: {e}", p.display()))
                        })
                    };
                    let rel = canon(out_dir)?
                        .strip_prefix(canon(base)?)
                        .map(|r| r.to_path_buf())
                        .map_err(|_| {
                            MeshError::Invalid(format!(
                                "--out-dir {} is not inside the directory of --into {}",
                                out_dir.display(),
                                model.display()
                            ))
                        })?;
                    let rel = rel.to_string_lossy().replace('\\', "/");
                    if rel.is_empty() {
                        String::new()
                    } else {
                        format!("{rel}/")
                    }
                }
                None => String::new(),
            };
            let visuals = convert_urdf(&urdf, out_dir, &prefix, &opts, &mut log)?;
            match into {
                Some(model) => {
                    let text = read_text(&model)?;
                    let new = splice_visuals(&text, &visuals)
                        .map_err(|e| MeshError::Invalid(format!("{}: {e}", model.display())))?;
                    write(&model, new.as_bytes())?;
                    log.push(format!(
                        "rewrote the visuals of {} links in {}",
                        visuals.len(),
                        model.display()
                    ));
                }
                None => {
                    for (link, elements) in &visuals {
                        log.push(format!("<!-- link {link} -->"));
                        log.extend(elements.iter().cloned());
                    }
                }
            }
        }
        Source::Mesh { mesh, scale } => {
            let s = scale as f32;
            let mut notes = Vec::new();
            let parts = convert_mesh(&mesh, [s; 3], None, out_dir, name, &opts, &mut notes)?;
            let before: usize = parts.iter().map(|p| p.triangles.0).sum();
            let after: usize = parts.iter().map(|p| p.triangles.1).sum();
            log.push(format!(
                "{} -> {name}_*.obj: {} parts, {before} -> {after} triangles",
                mesh.display(),
                parts.len()
            ));
            log.extend(notes);
            let visuals = visual_elements(&parts, &[0.0; 3], &[0.0; 3], "");
            let mut urdf = format!("<?xml version=\"1.0\"?>\n<!-- {name}: converted by mjskill convert-visuals from {} at scale {scale} -->\n<robot name=\"{name}\">\n  <link name=\"{name}\">\n",
                mesh.file_name().map(|f| f.to_string_lossy().to_string()).unwrap_or_default());
            for v in visuals {
                urdf.push_str(&format!("    {v}\n"));
            }
            urdf.push_str("  </link>\n</robot>\n");
            let path = out_dir.join(format!("{name}.urdf"));
            write(&path, urdf.as_bytes())?;
            log.push(format!("wrote {}", path.display()));
        }
        Source::Texture(png) => {
            let dst = out_dir.join(format!("{name}.png"));
            let (w, h) = convert_texture(&png, &dst, opts.texture_size)?;
            log.push(format!("{} -> {} ({w}x{h})", png.display(), dst.display()));
        }
    }
    Ok(log)
}

#[cfg(test)]
#[path = "visual_tests.rs"]
mod tests;
