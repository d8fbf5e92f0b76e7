//! Readers of visual meshes with their materials: glTF 2.0 (`.glb`/`.gltf`, through the
//! `gltf` crate), COLLADA (`.dae`, a small `roxmltree` reader of what robot descriptions
//! use: `<triangles>`/`<polylist>` with positions, normals and texture coordinates, node
//! transforms, Phong/Lambert/Blinn diffuse colours or image textures) and STL (no material).
//!
//! Every reader returns a [`SourceMesh`]: parts (one per material) in the mesh file's frame
//! with node transforms and the file's unit already applied.
use std::collections::HashMap;
use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Matrix4, Point3, Vector3};

use super::read::{read_triangles, MeshError};

/// An RGBA image, 8 bits per channel, top row first.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width * height * 4` bytes.
    pub rgba: Vec<u8>,
}

/// A material: a base colour, optionally modulated by a texture.
#[derive(Debug, Clone, PartialEq)]
pub struct Material {
    /// The name in the source file (for messages).
    pub name: String,
    /// Base colour (linear factors as the file gives them).
    pub rgba: [f32; 4],
    /// Base colour texture.
    pub texture: Option<Image>,
}

/// Triangles sharing one material.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Part {
    /// Index into [`SourceMesh::materials`].
    pub material: usize,
    /// Vertex positions (m, in the mesh file frame).
    pub positions: Vec<[f32; 3]>,
    /// Vertex normals, if the file has them.
    pub normals: Option<Vec<[f32; 3]>>,
    /// Texture coordinates (glTF convention: v grows downwards from the image's top row).
    pub uvs: Option<Vec<[f32; 2]>>,
    /// Triangle vertex indices.
    pub indices: Vec<u32>,
}

/// A visual mesh file: materials and the parts drawn with them.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SourceMesh {
    /// Materials.
    pub materials: Vec<Material>,
    /// Parts (several may share a material).
    pub parts: Vec<Part>,
}

impl SourceMesh {
    /// Triangles in all parts.
    pub fn triangles(&self) -> usize {
        self.parts.iter().map(|p| p.indices.len() / 3).sum()
    }

    /// Merges the parts of each material into one part.
    pub fn merge_by_material(self) -> SourceMesh {
        let mut merged: Vec<Part> = Vec::new();
        for p in self.parts {
            let slot = match merged.iter().position(|m| m.material == p.material) {
                Some(k) => k,
                None => {
                    merged.push(Part {
                        material: p.material,
                        normals: p.normals.as_ref().map(|_| Vec::new()),
                        uvs: p.uvs.as_ref().map(|_| Vec::new()),
                        ..Default::default()
                    });
                    merged.len() - 1
                }
            };
            let m = &mut merged[slot];
            let base = m.positions.len() as u32;
            let n = p.positions.len();
            m.positions.extend_from_slice(&p.positions);
            // Attributes only one part has are dropped for the merged part.
            match (&mut m.normals, &p.normals) {
                (Some(a), Some(b)) => a.extend_from_slice(b),
                (a, _) => *a = None,
            }
            match (&mut m.uvs, &p.uvs) {
                (Some(a), Some(b)) => a.extend_from_slice(b),
                (a, _) => *a = None,
            }
            debug_assert!(m
                .normals
                .as_ref()
                .is_none_or(|v| v.len() == m.positions.len()));
            let _ = n;
            m.indices.extend(p.indices.iter().map(|i| i + base));
        }
        SourceMesh {
            materials: self.materials,
            parts: merged,
        }
    }
}

/// Most triangles one visual mesh file may expand to (all its node instances together).
/// Robot visual meshes have at most a few hundred thousand; a file that expands to more (a
/// glTF node shared by many parents, a COLLADA geometry instanced by many nodes) is refused
/// before its vertices are made.
pub const MAX_SOURCE_TRIANGLES: usize = 2_000_000;
/// Most vertices one visual mesh file may expand to (see [`MAX_SOURCE_TRIANGLES`]).
pub const MAX_SOURCE_VERTICES: usize = 3 * MAX_SOURCE_TRIANGLES;
/// Most glTF node instances a file may expand to: a node that is the child of several
/// parents is expanded once per parent, so a small file can describe exponentially many.
pub const MAX_NODE_INSTANCES: usize = 100_000;

/// Errors when `triangles` or `vertices` read so far exceed [`MAX_SOURCE_TRIANGLES`] or
/// [`MAX_SOURCE_VERTICES`].
fn check_budget(name: &str, triangles: usize, vertices: usize) -> Result<(), MeshError> {
    if triangles > MAX_SOURCE_TRIANGLES || vertices > MAX_SOURCE_VERTICES {
        return Err(malformed(
            name,
            format!(
                "the mesh expands to more than {MAX_SOURCE_TRIANGLES} triangles or \
                 {MAX_SOURCE_VERTICES} vertices (every instance counted), the most a visual \
                 mesh may have"
            ),
        ));
    }
    Ok(())
}

fn malformed(name: &str, reason: impl Into<String>) -> MeshError {
    MeshError::Malformed {
        name: name.to_string(),
        reason: reason.into(),
    }
}

/// Reads a visual mesh file by its extension: `.glb`/`.gltf`, `.dae` or `.stl`/`.obj` (one
/// part, with material `rgba`). Textures of COLLADA files are read relative to the file.
pub fn read_visual(path: &Path, rgba: [f32; 4]) -> Result<SourceMesh, MeshError> {
    let name = path.display().to_string();
    let bytes = mjskill::files::read(path).map_err(|e| malformed(&name, e.reason()))?;
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    match ext.as_str() {
        "glb" | "gltf" => read_gltf(&bytes, &name),
        "dae" => read_dae(&bytes, &name, path.parent().unwrap_or(Path::new("."))),
        "stl" | "obj" => {
            let tris = read_triangles(&bytes, &name)?;
            check_budget(&name, tris.len(), 3 * tris.len())?;
            let mut part = Part::default();
            for t in tris {
                for v in t {
                    part.indices.push(part.positions.len() as u32);
                    part.positions.push([v.x as f32, v.y as f32, v.z as f32]);
                }
            }
            Ok(SourceMesh {
                materials: vec![Material {
                    name: "urdf".into(),
                    rgba,
                    texture: None,
                }],
                parts: vec![part],
            })
        }
        other => Err(malformed(
            &name,
            format!("unknown mesh extension {other:?}; valid: glb, gltf, dae, stl, obj"),
        )),
    }
}

fn image_from_gltf(d: &gltf::image::Data) -> Image {
    use gltf::image::Format;
    let px = (d.width * d.height) as usize;
    let mut rgba = Vec::with_capacity(px * 4);
    let ch = match d.format {
        Format::R8 => 1,
        Format::R8G8 => 2,
        Format::R8G8B8 => 3,
        Format::R8G8B8A8 => 4,
        // 16-bit and float formats: take the high byte of each 16-bit channel.
        Format::R16 => 1,
        Format::R16G16 => 2,
        Format::R16G16B16 => 3,
        Format::R16G16B16A16 => 4,
        Format::R32G32B32FLOAT => 3,
        Format::R32G32B32A32FLOAT => 4,
    };
    let bytes_per = d.pixels.len() / (px * ch).max(1);
    for i in 0..px {
        let c = |k: usize| -> u8 {
            let off = (i * ch + k) * bytes_per;
            match bytes_per {
                1 => d.pixels[off],
                2 => d.pixels[off + 1],
                _ => {
                    let f = f32::from_le_bytes([
                        d.pixels[off],
                        d.pixels[off + 1],
                        d.pixels[off + 2],
                        d.pixels[off + 3],
                    ]);
                    (f.clamp(0.0, 1.0) * 255.0).round() as u8
                }
            }
        };
        let (r, g, b, a) = match ch {
            1 => (c(0), c(0), c(0), 255),
            2 => (c(0), c(0), c(0), c(1)),
            3 => (c(0), c(1), c(2), 255),
            _ => (c(0), c(1), c(2), c(3)),
        };
        rgba.extend_from_slice(&[r, g, b, a]);
    }
    Image {
        width: d.width,
        height: d.height,
        rgba,
    }
}

/// Reads a glTF 2.0 file (binary or embedded): every mesh primitive of the default scene,
/// transformed by its node's world transform, with its material's base colour and texture.
pub fn read_gltf(bytes: &[u8], name: &str) -> Result<SourceMesh, MeshError> {
    let (doc, buffers, images) =
        gltf::import_slice(bytes).map_err(|e| malformed(name, format!("glTF: {e}")))?;
    let mut out = SourceMesh::default();
    let mut material_index: HashMap<Option<usize>, usize> = HashMap::new();
    let scene = doc
        .default_scene()
        .or_else(|| doc.scenes().next())
        .ok_or_else(|| malformed(name, "glTF file has no scene"))?;
    // Depth first; `on_path[i]`: node i is an ancestor of the nodes on the stack above its
    // `Leave`, so meeting it again as a child is a cycle. A node shared by several parents
    // (a DAG) is expanded once per parent, which [`MAX_NODE_INSTANCES`] bounds.
    enum Visit<'a> {
        Enter(gltf::Node<'a>, Matrix4<f32>),
        Leave(usize),
    }
    let mut on_path = vec![false; doc.nodes().count()];
    let mut stack: Vec<Visit> = scene
        .nodes()
        .map(|n| Visit::Enter(n, Matrix4::identity()))
        .collect();
    let (mut instances, mut triangles, mut vertices) = (0usize, 0usize, 0usize);
    while let Some(visit) = stack.pop() {
        let (node, parent) = match visit {
            Visit::Enter(node, parent) => (node, parent),
            Visit::Leave(i) => {
                on_path[i] = false;
                continue;
            }
        };
        instances += 1;
        if instances > MAX_NODE_INSTANCES {
            return Err(malformed(
                name,
                format!(
                    "glTF nodes expand to more than {MAX_NODE_INSTANCES} node instances \
                     (children shared by several parents are expanded once per parent)"
                ),
            ));
        }
        on_path[node.index()] = true;
        stack.push(Visit::Leave(node.index()));
        let local = Matrix4::from(node.transform().matrix());
        let world = parent * local;
        for child in node.children() {
            if on_path[child.index()] {
                return Err(malformed(
                    name,
                    format!(
                        "glTF node {} ({:?}) is its own ancestor (a cycle in the node graph, \
                         reached from node {})",
                        child.index(),
                        child.name().unwrap_or(""),
                        node.index()
                    ),
                ));
            }
            stack.push(Visit::Enter(child, world));
        }
        let Some(mesh) = node.mesh() else { continue };
        let normal_m: Matrix3<f32> = world
            .fixed_view::<3, 3>(0, 0)
            .into_owned()
            .try_inverse()
            .unwrap_or_else(Matrix3::identity)
            .transpose();
        for prim in mesh.primitives() {
            if prim.mode() != gltf::mesh::Mode::Triangles {
                continue;
            }
            let reader = prim.reader(|b| Some(&buffers[b.index()]));
            let Some(pos) = reader.read_positions() else {
                continue;
            };
            // Checked before anything is read: instances multiply the file's own sizes.
            vertices += pos.len();
            triangles += prim.indices().map_or(pos.len(), |a| a.count()) / 3;
            check_budget(name, triangles, vertices)?;
            let positions: Vec<[f32; 3]> = pos
                .map(|p| {
                    let q = world.transform_point(&Point3::from(p));
                    [q.x, q.y, q.z]
                })
                .collect();
            let normals = reader.read_normals().map(|it| {
                it.map(|n| {
                    let m = (normal_m * Vector3::from(n))
                        .try_normalize(1e-12)
                        .unwrap_or(Vector3::z());
                    [m.x, m.y, m.z]
                })
                .collect::<Vec<_>>()
            });
            let mat = prim.material();
            let tex = mat.pbr_metallic_roughness().base_color_texture();
            let uvs = match &tex {
                Some(t) => reader
                    .read_tex_coords(t.tex_coord())
                    .map(|c| c.into_f32().collect::<Vec<_>>()),
                None => None,
            };
            let indices: Vec<u32> = match reader.read_indices() {
                Some(i) => i.into_u32().collect(),
                None => (0..positions.len() as u32).collect(),
            };
            if indices.iter().any(|&i| i as usize >= positions.len()) {
                return Err(malformed(name, "glTF index out of range"));
            }
            let key = mat.index();
            let material = match material_index.get(&key) {
                Some(&k) => k,
                None => {
                    let texture = match (&tex, &uvs) {
                        (Some(t), Some(_)) => {
                            let src = t.texture().source().index();
                            let img = images.get(src).ok_or_else(|| {
                                malformed(name, format!("glTF image {src} missing"))
                            })?;
                            Some(image_from_gltf(img))
                        }
                        _ => None,
                    };
                    out.materials.push(Material {
                        name: mat.name().unwrap_or("glTF material").to_string(),
                        rgba: mat.pbr_metallic_roughness().base_color_factor(),
                        texture,
                    });
                    material_index.insert(key, out.materials.len() - 1);
                    out.materials.len() - 1
                }
            };
            let textured = out.materials[material].texture.is_some();
            out.parts.push(Part {
                material,
                positions,
                normals,
                uvs: if textured { uvs } else { None },
                indices,
            });
        }
    }
    if out.parts.is_empty() {
        return Err(malformed(name, "glTF file has no triangle meshes"));
    }
    Ok(out)
}

/// Largest side of a PNG texture read (pixels, as its header declares it).
pub const MAX_TEXTURE_SIDE: u32 = 16_384;
/// Most pixels of a PNG texture read, as its header declares them: 8192 × 8192 (256 MiB as
/// RGBA). The header is checked before anything is decoded, so a file declaring more (or a
/// small file that would decompress to more) is refused without allocating it.
pub const MAX_TEXTURE_PIXELS: u64 = 8192 * 8192;

/// Reads a PNG file into RGBA. Its declared size must be within [`MAX_TEXTURE_SIDE`] a side
/// and [`MAX_TEXTURE_PIXELS`] in all.
pub fn read_png(path: &Path) -> Result<Image, MeshError> {
    read_png_within(path, MAX_TEXTURE_SIDE, MAX_TEXTURE_PIXELS)
}

/// [`read_png`] with the limits given.
fn read_png_within(path: &Path, max_side: u32, max_pixels: u64) -> Result<Image, MeshError> {
    let name = path.display().to_string();
    let file = mjskill::files::open_regular(path).map_err(|e| malformed(&name, e.reason()))?;
    // The decoder's own allocations (row buffers, metadata) stay within a few rows of the
    // largest accepted image; the output buffer is sized from the checked header.
    let limits = png::Limits { bytes: 64 << 20 };
    let mut dec = png::Decoder::new_with_limits(std::io::BufReader::new(file), limits);
    let header = dec
        .read_header_info()
        .map_err(|e| malformed(&name, format!("PNG: {e}")))?;
    let (w, h) = (header.width, header.height);
    if w > max_side || h > max_side || u64::from(w) * u64::from(h) > max_pixels {
        return Err(malformed(
            &name,
            format!(
                "PNG declares {w} x {h} pixels; textures may have at most {max_side} pixels a \
                 side and {max_pixels} pixels in all"
            ),
        ));
    }
    dec.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = dec
        .read_info()
        .map_err(|e| malformed(&name, format!("PNG: {e}")))?;
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| malformed(&name, "PNG too large"))?;
    let mut buf = vec![0; size];
    let info = reader
        .next_frame(&mut buf)
        .map_err(|e| malformed(&name, format!("PNG: {e}")))?;
    let px = (info.width * info.height) as usize;
    let ch = info.color_type.samples();
    let mut rgba = Vec::with_capacity(px * 4);
    for i in 0..px {
        let p = &buf[i * ch..i * ch + ch];
        let (r, g, b, a) = match ch {
            1 => (p[0], p[0], p[0], 255),
            2 => (p[0], p[0], p[0], p[1]),
            3 => (p[0], p[1], p[2], 255),
            _ => (p[0], p[1], p[2], p[3]),
        };
        rgba.extend_from_slice(&[r, g, b, a]);
    }
    Ok(Image {
        width: info.width,
        height: info.height,
        rgba,
    })
}

fn child<'a, 'i>(n: roxmltree::Node<'a, 'i>, tag: &str) -> Option<roxmltree::Node<'a, 'i>> {
    n.children().find(|c| c.tag_name().name() == tag)
}

fn floats(text: &str) -> Vec<f32> {
    text.split_whitespace()
        .filter_map(|s| s.parse().ok())
        .collect()
}

fn ints(text: &str) -> Vec<usize> {
    text.split_whitespace()
        .filter_map(|s| s.parse().ok())
        .collect()
}

/// A COLLADA `<source>`: flat floats with a stride.
struct DaeSource {
    data: Vec<f32>,
    stride: usize,
}

/// The parts of a COLLADA document that `read_dae` looks things up in.
struct Dae<'a, 'i> {
    /// Elements by `id`.
    by_id: HashMap<&'a str, roxmltree::Node<'a, 'i>>,
    /// The file's directory (texture images are relative to it).
    dir: &'a Path,
}

/// `#id` → `id`.
fn id_of(url: &str) -> String {
    url.trim_start_matches('#').to_string()
}

/// The named input sources of a primitive list: (semantic, source id, offset), the
/// `VERTEX` input expanded into its `<vertices>` inputs, and the index stride.
type PrimInputs = (Vec<(String, String, usize)>, usize);

/// Reads a COLLADA file: the geometries instanced by the visual scene's nodes, with their
/// transforms, the `<unit>` scale and the bound materials (diffuse colour or texture image,
/// read relative to `dir`). The `<up_axis>` is ignored, as ManiSkill's renderer ignores it.
pub fn read_dae(bytes: &[u8], name: &str, dir: &Path) -> Result<SourceMesh, MeshError> {
    let text = std::str::from_utf8(bytes).map_err(|_| malformed(name, "not UTF-8"))?;
    let doc = roxmltree::Document::parse(text).map_err(|e| malformed(name, format!("XML: {e}")))?;
    let root = doc.root_element();
    let dae = Dae {
        by_id: root
            .descendants()
            .filter_map(|n| n.attribute("id").map(|id| (id, n)))
            .collect(),
        dir,
    };
    let unit = root
        .descendants()
        .find(|n| n.tag_name().name() == "unit")
        .and_then(|n| n.attribute("meter"))
        .and_then(|m| m.parse::<f32>().ok())
        .unwrap_or(1.0);
    // The `<up_axis>` is ignored, as SAPIEN (ManiSkill's renderer, assimp with
    // `IMPORT_COLLADA_IGNORE_UP_DIRECTION`) ignores it: the vertices are taken in the link
    // frame as written. Robotiq's outer knuckle says `Y_UP`; turning it to Z up put the
    // knuckle where ManiSkill draws none (segmentation IoU 0).
    let top = Matrix4::new_scaling(unit);
    let mut out = SourceMesh::default();
    // (triangles, vertices) made so far, for [`check_budget`].
    let mut expanded = (0usize, 0usize);
    let mut mat_slots: HashMap<String, usize> = HashMap::new();
    let mut textures: HashMap<PathBuf, Image> = HashMap::new();
    let scene = root
        .descendants()
        .find(|n| n.tag_name().name() == "visual_scene")
        .ok_or_else(|| malformed(name, "no <visual_scene>"))?;
    let mut stack: Vec<(roxmltree::Node, Matrix4<f32>)> = scene
        .children()
        .filter(|n| n.tag_name().name() == "node")
        .map(|n| (n, top))
        .collect();
    while let Some((node, parent)) = stack.pop() {
        let m = node_transform(node, parent);
        for c in node.children().filter(|c| c.tag_name().name() == "node") {
            stack.push((c, m));
        }
        for inst in node
            .children()
            .filter(|c| c.tag_name().name() == "instance_geometry")
        {
            let Some(geom) = inst
                .attribute("url")
                .and_then(|u| dae.by_id.get(id_of(u).as_str()))
            else {
                continue;
            };
            // symbol → material id
            let bind: HashMap<&str, String> = inst
                .descendants()
                .filter(|n| n.tag_name().name() == "instance_material")
                .filter_map(|n| Some((n.attribute("symbol")?, id_of(n.attribute("target")?))))
                .collect();
            let Some(mesh) = child(*geom, "mesh") else {
                continue;
            };
            let (sources, vertices_inputs) = mesh_sources(mesh);
            for prims in mesh
                .children()
                .filter(|c| matches!(c.tag_name().name(), "triangles" | "polylist" | "polygons"))
            {
                let symbol = prims.attribute("material").unwrap_or("");
                let mat_id = bind
                    .get(symbol)
                    .cloned()
                    .unwrap_or_else(|| symbol.to_string());
                let inputs = prim_inputs(prims, &vertices_inputs);
                let Some((_, pos_src, pos_off)) = inputs.0.iter().find(|(s, _, _)| s == "POSITION")
                else {
                    continue;
                };
                let pos = sources
                    .get(pos_src)
                    .ok_or_else(|| malformed(name, format!("missing source {pos_src}")))?;
                let (mat_name, rgba, tex_path) = dae.material(&mat_id);
                let texture = match &tex_path {
                    Some(path) if uv_source(&inputs, &sources) => {
                        if !textures.contains_key(path) {
                            textures.insert(path.clone(), read_png(path)?);
                        }
                        Some(path.clone())
                    }
                    _ => None,
                };
                let slot_key = format!(
                    "{mat_id}|{}",
                    texture
                        .as_ref()
                        .map(|p| p.display().to_string())
                        .unwrap_or_default()
                );
                let material = *mat_slots.entry(slot_key).or_insert_with(|| {
                    out.materials.push(Material {
                        name: mat_name,
                        rgba: if texture.is_some() { [1.0; 4] } else { rgba },
                        texture: texture.as_ref().map(|p| textures[p].clone()),
                    });
                    out.materials.len() - 1
                });
                let position = (pos, *pos_off);
                let part = fan_part(
                    prims,
                    &inputs,
                    position,
                    &sources,
                    &m,
                    material,
                    texture.is_some(),
                    name,
                    &mut expanded,
                )?;
                if !part.indices.is_empty() {
                    out.parts.push(part);
                }
            }
        }
    }
    if out.parts.is_empty() {
        return Err(malformed(
            name,
            "COLLADA file has no triangles in its visual scene",
        ));
    }
    Ok(out)
}

impl Dae<'_, '_> {
    /// Material id → (name, colour, texture image file).
    fn material(&self, mat_id: &str) -> (String, [f32; 4], Option<PathBuf>) {
        let mut rgba = [0.8, 0.8, 0.8, 1.0];
        let mut texture = None;
        let Some(mat) = self.by_id.get(mat_id) else {
            return (mat_id.to_string(), rgba, None);
        };
        let name = mat.attribute("name").unwrap_or(mat_id).to_string();
        let effect = child(*mat, "instance_effect")
            .and_then(|e| e.attribute("url"))
            .and_then(|u| self.by_id.get(id_of(u).as_str()).copied());
        if let Some(effect) = effect {
            let diffuse = effect
                .descendants()
                .find(|n| n.tag_name().name() == "diffuse");
            if let Some(d) = diffuse {
                if let Some(c) = child(d, "color").and_then(|c| c.text()) {
                    let v = floats(c);
                    if v.len() >= 3 {
                        rgba = [v[0], v[1], v[2], v.get(3).copied().unwrap_or(1.0)];
                    }
                }
                if let Some(t) = child(d, "texture").and_then(|t| t.attribute("texture")) {
                    texture = self.texture_file(effect, t);
                    rgba = [1.0, 1.0, 1.0, 1.0];
                }
            }
        }
        (name, rgba, texture)
    }

    /// The image file of an effect's `<texture texture="...">`: sampler newparam → surface
    /// newparam → image, or an image id directly.
    fn texture_file(&self, effect: roxmltree::Node, t: &str) -> Option<PathBuf> {
        let param = |sid: &str| {
            effect
                .descendants()
                .find(|n| n.tag_name().name() == "newparam" && n.attribute("sid") == Some(sid))
        };
        let mut image_id = t.to_string();
        if let Some(src) = param(t).and_then(|sampler| text_of(sampler, "source")) {
            if let Some(init) = param(src.trim()).and_then(|surface| text_of(surface, "init_from"))
            {
                image_id = init.trim().to_string();
            }
        }
        self.by_id
            .get(image_id.as_str())
            .and_then(|img| text_of(*img, "init_from"))
            .map(|f| self.dir.join(f.trim().trim_start_matches("file://")))
    }
}

/// The text of `n`'s first descendant `<tag>`.
fn text_of<'a>(n: roxmltree::Node<'a, '_>, tag: &str) -> Option<&'a str> {
    n.descendants()
        .find(|c| c.tag_name().name() == tag)
        .and_then(|c| c.text())
}

/// A node's transform: `parent` times its `<matrix>`, `<translate>`, `<scale>` and `<rotate>`
/// elements in order.
fn node_transform(node: roxmltree::Node, parent: Matrix4<f32>) -> Matrix4<f32> {
    let mut m = parent;
    for t in node.children().filter(|c| c.is_element()) {
        let v = floats(t.text().unwrap_or(""));
        match t.tag_name().name() {
            "matrix" if v.len() == 16 => m *= Matrix4::from_row_slice(&v),
            "translate" if v.len() == 3 => {
                m *= Matrix4::new_translation(&Vector3::new(v[0], v[1], v[2]))
            }
            "scale" if v.len() == 3 => {
                m *= Matrix4::new_nonuniform_scaling(&Vector3::new(v[0], v[1], v[2]))
            }
            "rotate" if v.len() == 4 => {
                let axis = nalgebra::Unit::new_normalize(Vector3::new(v[0], v[1], v[2]));
                m *= Matrix4::from_axis_angle(&axis, v[3].to_radians())
            }
            _ => {}
        }
    }
    m
}

/// A `<mesh>`'s float sources by id, and each `<vertices id>`'s inputs (its POSITION and
/// possibly NORMAL sources) as (semantic, source id).
#[allow(clippy::type_complexity)]
fn mesh_sources(
    mesh: roxmltree::Node,
) -> (
    HashMap<String, DaeSource>,
    HashMap<String, Vec<(String, String)>>,
) {
    let mut sources: HashMap<String, DaeSource> = HashMap::new();
    for s in mesh.children().filter(|c| c.tag_name().name() == "source") {
        let Some(id) = s.attribute("id") else {
            continue;
        };
        let data = child(s, "float_array")
            .and_then(|a| a.text())
            .map(floats)
            .unwrap_or_default();
        let stride = s
            .descendants()
            .find(|n| n.tag_name().name() == "accessor")
            .and_then(|a| a.attribute("stride"))
            .and_then(|s| s.parse().ok())
            .unwrap_or(3);
        sources.insert(id.to_string(), DaeSource { data, stride });
    }
    let mut vertices_inputs: HashMap<String, Vec<(String, String)>> = HashMap::new();
    for v in mesh
        .children()
        .filter(|c| c.tag_name().name() == "vertices")
    {
        let ins = v
            .children()
            .filter(|c| c.tag_name().name() == "input")
            .filter_map(|i| {
                Some((
                    i.attribute("semantic")?.to_string(),
                    id_of(i.attribute("source")?),
                ))
            })
            .collect();
        vertices_inputs.insert(v.attribute("id").unwrap_or("").to_string(), ins);
    }
    (sources, vertices_inputs)
}

/// The inputs of a primitive list (texture coordinates of set 0 only).
fn prim_inputs(
    prims: roxmltree::Node,
    vertices_inputs: &HashMap<String, Vec<(String, String)>>,
) -> PrimInputs {
    let mut inputs: Vec<(String, String, usize)> = Vec::new();
    let mut stride = 0;
    for i in prims.children().filter(|c| c.tag_name().name() == "input") {
        let off: usize = i
            .attribute("offset")
            .and_then(|o| o.parse().ok())
            .unwrap_or(0);
        stride = stride.max(off + 1);
        let sem = i.attribute("semantic").unwrap_or("");
        let src = id_of(i.attribute("source").unwrap_or(""));
        if sem == "TEXCOORD" && i.attribute("set").is_some_and(|s| s != "0") {
            continue;
        }
        if sem == "VERTEX" {
            for (s2, src2) in vertices_inputs.get(&src).cloned().unwrap_or_default() {
                inputs.push((s2, src2, off));
            }
        } else {
            inputs.push((sem.to_string(), src, off));
        }
    }
    (inputs, stride)
}

/// Whether the primitive list's first `TEXCOORD` input names an existing source.
fn uv_source(inputs: &PrimInputs, sources: &HashMap<String, DaeSource>) -> bool {
    let first = inputs.0.iter().find(|(s, _, _)| s == "TEXCOORD");
    first.is_some_and(|(_, s, _)| sources.contains_key(s))
}

/// A primitive list's polygons (positions from `pos` at index offset `pos_off`),
/// fan-triangulated and transformed by `m` into one part of `material` (with normals when the list has them, with texture coordinates when
/// `textured`).
#[allow(clippy::too_many_arguments)]
fn fan_part(
    prims: roxmltree::Node,
    (inputs, stride): &PrimInputs,
    (pos, pos_off): (&DaeSource, usize),
    sources: &HashMap<String, DaeSource>,
    m: &Matrix4<f32>,
    material: usize,
    textured: bool,
    name: &str,
    expanded: &mut (usize, usize),
) -> Result<Part, MeshError> {
    let stride = *stride;
    let find = |sem: &str| inputs.iter().find(|(s, _, _)| s == sem);
    let nrm = find("NORMAL").and_then(|(_, s, o)| Some((sources.get(s)?, *o)));
    let uv = find("TEXCOORD").and_then(|(_, s, o)| Some((sources.get(s)?, *o)));
    let normal_m: Matrix3<f32> = m
        .fixed_view::<3, 3>(0, 0)
        .into_owned()
        .try_inverse()
        .unwrap_or_else(Matrix3::identity)
        .transpose();
    // Polygons of a polylist: fan-triangulated.
    let p: Vec<usize> = prims
        .children()
        .filter(|c| c.tag_name().name() == "p")
        .flat_map(|c| ints(c.text().unwrap_or("")))
        .collect();
    let counts: Vec<usize> = match child(prims, "vcount") {
        Some(vc) => ints(vc.text().unwrap_or("")),
        None => vec![3; p.len() / (3 * stride.max(1))],
    };
    let mut part = Part {
        material,
        normals: nrm.map(|_| Vec::new()),
        uvs: if textured { Some(Vec::new()) } else { None },
        ..Default::default()
    };
    let get = |s: &DaeSource, k: usize, n: usize| -> Option<Vec<f32>> {
        let a = k * s.stride;
        s.data.get(a..a + n).map(|v| v.to_vec())
    };
    let mut cursor = 0usize;
    for &n in &counts {
        if n < 3 || cursor.saturating_add(n).saturating_mul(stride) > p.len() {
            cursor = cursor.saturating_add(n);
            continue;
        }
        // Checked before the polygon's vertices are made: many nodes may instance one large
        // geometry.
        expanded.0 += n - 2;
        expanded.1 += n;
        check_budget(name, expanded.0, expanded.1)?;
        let base = part.positions.len() as u32;
        for v in 0..n {
            let at = (cursor + v) * stride;
            let q = get(pos, p[at + pos_off], 3)
                .ok_or_else(|| malformed(name, "position index out of range"))?;
            let w = m.transform_point(&Point3::new(q[0], q[1], q[2]));
            part.positions.push([w.x, w.y, w.z]);
            if let (Some(list), Some((s, o))) = (part.normals.as_mut(), nrm) {
                let q = get(s, p[at + o], 3).unwrap_or(vec![0.0, 0.0, 1.0]);
                let w = normal_m * Vector3::new(q[0], q[1], q[2]);
                let w = w.try_normalize(1e-12).unwrap_or(Vector3::z());
                list.push([w.x, w.y, w.z]);
            }
            if let (Some(list), Some((s, o))) = (part.uvs.as_mut(), uv) {
                let q = get(s, p[at + o], 2).unwrap_or(vec![0.0, 0.0]);
                // COLLADA's v grows upwards; store glTF's (downwards).
                list.push([q[0], 1.0 - q[1]]);
            }
        }
        for k in 1..n as u32 - 1 {
            part.indices.extend([base, base + k, base + k + 1]);
        }
        cursor += n;
    }
    Ok(part)
}

#[cfg(test)]
mod tests {
    use super::*;

    const DAE: &str = r##"<?xml version="1.0"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit meter="0.001"/><up_axis>Z_UP</up_axis></asset>
  <library_effects>
    <effect id="red-fx"><profile_COMMON><technique sid="c"><phong>
      <diffuse><color>1 0 0 1</color></diffuse></phong></technique></profile_COMMON></effect>
  </library_effects>
  <library_materials><material id="red" name="red"><instance_effect url="#red-fx"/></material></library_materials>
  <library_geometries><geometry id="g"><mesh>
    <source id="pos"><float_array id="pa" count="12">0 0 0 1000 0 0 0 1000 0 0 0 1000</float_array>
      <technique_common><accessor source="#pa" count="4" stride="3"/></technique_common></source>
    <vertices id="v"><input semantic="POSITION" source="#pos"/></vertices>
    <polylist material="m" count="2"><input semantic="VERTEX" source="#v" offset="0"/>
      <vcount>3 4</vcount><p>0 1 2 0 1 3 2</p></polylist>
  </mesh></geometry></library_geometries>
  <library_visual_scenes><visual_scene id="s"><node id="n"><translate>0 0 1000</translate>
    <instance_geometry url="#g"><bind_material><technique_common>
      <instance_material symbol="m" target="#red"/></technique_common></bind_material></instance_geometry>
  </node></visual_scene></library_visual_scenes>
</COLLADA>"##;

    #[test]
    fn collada_polylist_units_transforms_and_colour() {
        let m = read_dae(DAE.as_bytes(), "t.dae", Path::new(".")).unwrap();
        assert_eq!(m.materials.len(), 1);
        assert_eq!(m.materials[0].rgba, [1.0, 0.0, 0.0, 1.0]);
        // A triangle and a fan-triangulated quad.
        assert_eq!(m.triangles(), 3);
        let p = &m.parts[0].positions;
        // Millimetres → metres, translated 1 m up.
        assert_eq!(p[0], [0.0, 0.0, 1.0]);
        assert_eq!(p[1], [1.0, 0.0, 1.0]);
        assert_eq!(p[5], [0.0, 0.0, 2.0]);
    }

    #[test]
    fn collada_up_axis_is_ignored_as_by_maniskills_renderer() {
        let y_up = DAE.replace("Z_UP", "Y_UP");
        let m = read_dae(y_up.as_bytes(), "t.dae", Path::new(".")).unwrap();
        let p = &m.parts[0].positions;
        // The same vertices as the Z_UP file: not turned from Y up to Z up.
        assert_eq!(p[0], [0.0, 0.0, 1.0]);
        assert_eq!(p[1], [1.0, 0.0, 1.0]);
        assert_eq!(p[5], [0.0, 0.0, 2.0]);
    }

    #[test]
    fn unknown_extension_names_the_valid_ones() {
        let dir = std::env::temp_dir().join(format!("mjskill-fmt-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("x.ply");
        std::fs::write(&f, b"ply").unwrap();
        let e = read_visual(&f, [1.0; 4]).unwrap_err().to_string();
        assert!(
            e.contains("ply") && e.contains("glb, gltf, dae, stl, obj"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
