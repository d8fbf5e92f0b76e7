//! `mjskill-meshes`: the mesh-authoring tools behind the robot models (`models/`), a binary of
//! its own behind the `mesh-tools` feature (gltf, meshopt): fitting collision primitives to a
//! mesh (`fit-primitives`) and converting visual meshes into simplified, textured files MuJoCo
//! 2.2 draws (`convert-visuals`), both in [`meshes`].
use std::path::PathBuf;

use clap::{Parser, Subcommand};

mod meshes;

/// The command line's errors, printed with their `Display` text.
type CliError = Box<dyn std::error::Error + Send + Sync>;

#[macro_use]
#[path = "../shared/cli.rs"]
mod cli;
use cli::emit;

/// Value parsers of the numeric flags: each checks the valid range, so that a bad value is an
/// error naming the flag and the range before anything runs.
mod args {
    use crate::cli::ranged;

    /// `fit-primitives --parts` and `--segments`: 1..=[`crate::meshes::MAX_PARTS`].
    pub fn parts(s: &str) -> Result<usize, String> {
        ranged(s, 1, crate::meshes::MAX_PARTS as u64).map(|v| v as usize)
    }

    /// A mesh scale: finite, > 0 and at most [`crate::meshes::MAX_SCALE`].
    pub fn scale(s: &str) -> Result<f64, String> {
        let max = crate::meshes::MAX_SCALE;
        let v: f64 = s.trim().parse().map_err(|_| {
            format!("{s:?} is not a number; valid: a positive number up to {max:e}")
        })?;
        if !(v.is_finite() && v > 0.0) {
            return Err(format!(
                "--scale must be a positive number, got {v} (valid: 0 < scale ≤ {max:e})"
            ));
        }
        if v > max {
            return Err(format!(
                "--scale {v:e} is too large (valid: 0 < scale ≤ {max:e})"
            ));
        }
        Ok(v)
    }

    /// `convert-visuals --max-triangles`: 12..=1000000.
    pub fn max_triangles(s: &str) -> Result<usize, String> {
        ranged(s, 12, 1_000_000).map(|v| v as usize)
    }

    /// `convert-visuals --max-error` (millimetres): a finite number in 0.001..=1000.
    pub fn max_error_mm(s: &str) -> Result<f32, String> {
        let v: f64 = s.trim().parse().map_err(|_| {
            format!("{s:?} is not a number; valid: --max-error in millimetres, 0.001..=1000")
        })?;
        if !(0.001..=1000.0).contains(&v) {
            return Err(format!(
                "{v} is not in 0.001..=1000 (--max-error, millimetres)"
            ));
        }
        Ok(v as f32)
    }

    /// `convert-visuals --texture-size`: 1..=8192.
    pub fn texture_size(s: &str) -> Result<u32, String> {
        ranged(s, 1, 8192).map(|v| v as u32)
    }

    /// `convert-visuals --material NAME=R,G,B,A`: four numbers in 0..=1.
    pub fn named_rgba(s: &str) -> Result<(String, [f32; 4]), String> {
        let (name, rest) = s
            .split_once('=')
            .ok_or_else(|| format!("{s:?} is not NAME=R,G,B,A"))?;
        let v: Vec<f32> = rest
            .split(',')
            .map(|x| {
                x.trim()
                    .parse::<f32>()
                    .ok()
                    .filter(|v| (0.0..=1.0).contains(v))
                    .ok_or_else(|| format!("{x:?} in {s:?} is not a number in 0..=1"))
            })
            .collect::<Result<_, _>>()?;
        if name.is_empty() || v.len() != 4 {
            return Err(format!("{s:?} is not NAME=R,G,B,A (four numbers)"));
        }
        Ok((name.to_string(), [v[0], v[1], v[2], v[3]]))
    }

    #[cfg(test)]
    mod tests {
        use super::*;

        #[test]
        fn ranges_name_the_valid_values() {
            assert!(parts("65").unwrap_err().contains("1..=64"));
            assert!(scale("1e308").unwrap_err().contains("--scale"));
            assert!(scale("0").unwrap_err().contains("got 0"));
            assert_eq!(max_error_mm("0.5"), Ok(0.5));
            assert!(max_error_mm("0").unwrap_err().contains("0.001..=1000"));
            assert!(max_error_mm("nan").unwrap_err().contains("--max-error"));
            assert!(max_error_mm("x").unwrap_err().contains("not a number"));
        }
    }
}

/// mjskill-meshes: the mesh-authoring tools behind mjskill's robot models.
#[derive(Debug, Parser)]
#[command(name = "mjskill-meshes", version, about, long_about = None)]
struct Cli {
    /// The command to run.
    #[command(subcommand)]
    command: Command,
}

/// The commands.
#[derive(Debug, Subcommand)]
enum Command {
    /// Fit collision primitives to a mesh (binary/ASCII STL or OBJ) and print them as URDF
    /// `<collision>` elements, with their volume and the mesh volume they cover.
    FitPrimitives {
        /// Mesh file.
        #[arg(long)]
        mesh: PathBuf,
        /// Primitive kind: box, capsule, cylinder or sphere; comma-separated to take the smallest.
        #[arg(long, default_value = "box,capsule,cylinder")]
        shape: String,
        /// Decompose greedily into up to this many primitives (1..=64; axis-aligned cuts);
        /// overrides --segments.
        #[arg(long, value_parser = args::parts, allow_hyphen_values = true)]
        parts: Option<usize>,
        /// Split the (cropped) mesh into this many slabs along its principal axis (1..=64).
        #[arg(long, default_value_t = 1, value_parser = args::parts, allow_hyphen_values = true)]
        segments: usize,
        /// Keep only the mesh surface inside this box: "xmin,ymin,zmin,xmax,ymax,zmax" (mesh frame).
        #[arg(long, allow_hyphen_values = true)]
        crop: Option<String>,
        /// Uniform scale applied to the mesh vertices first (the URDF `<mesh scale>`, e.g. 0.001
        /// for meshes in millimetres; positive, up to 1e6); crop boxes are in the scaled frame.
        #[arg(long, default_value_t = 1.0, value_parser = args::scale, allow_hyphen_values = true)]
        scale: f64,
    },
    /// Convert visual meshes (glTF/glb, COLLADA .dae, STL) into simplified OBJ files with
    /// PNG textures that MuJoCo 2.2 draws (docs/rendering.md). Exactly one of --urdf (every
    /// mesh visual of an upstream URDF), --mesh (one mesh, e.g. the table) or --texture (a
    /// PNG re-encoded and downsampled).
    ConvertVisuals(ConvertVisualsArgs),
    /// Write a gripper's convex collision parts (vertices and hull triangles, link frame) as
    /// the JSON file PhysX's step replica reads (`models/<robot>/convex_parts.json`).
    ConvexParts {
        /// LINK=MESH: a convex hull mesh (binary/ASCII STL or OBJ) of LINK's collision, in
        /// the link frame; repeat in the order PhysX solves them (first jaw first).
        #[arg(long = "part", required = true)]
        parts: Vec<String>,
        /// Where the parts came from (stored in the file).
        #[arg(long)]
        source: String,
        /// Output file.
        #[arg(long)]
        out: PathBuf,
    },
}

fn main() {
    let cli = Cli::parse();
    if let Err(e) = run(cli) {
        eprintln!("error: {e}");
        std::process::exit(2);
    }
}

fn run(cli: Cli) -> Result<(), CliError> {
    match cli.command {
        Command::FitPrimitives {
            mesh,
            shape,
            parts,
            segments,
            crop,
            scale,
        } => fit_primitives(&mesh, &shape, parts, segments, crop.as_deref(), scale),
        Command::ConvertVisuals(args) => args.run(),
        Command::ConvexParts { parts, source, out } => convex_parts(&parts, &source, &out),
    }
}

/// Reads each LINK=MESH hull, merges its repeated vertices and writes the parts file.
fn convex_parts(parts: &[String], source: &str, out: &std::path::Path) -> Result<(), CliError> {
    use mjskill::convex::{ConvexPart, ConvexPartFile, ConvexPartsFile};
    let mut file = ConvexPartsFile {
        source: source.to_string(),
        parts: Vec::with_capacity(parts.len()),
    };
    for p in parts {
        let (link, mesh) = p
            .split_once('=')
            .ok_or_else(|| format!("--part {p:?}: expected LINK=MESH"))?;
        let bytes = mjskill::files::read(std::path::Path::new(mesh)).map_err(|e| e.to_string())?;
        let tris = meshes::read_triangles(&bytes, mesh)?;
        let mut vertices: Vec<[f64; 3]> = Vec::new();
        let mut triangles = Vec::with_capacity(tris.len());
        for t in &tris {
            let mut idx = [0usize; 3];
            for (k, v) in t.iter().enumerate() {
                let v = [v.x, v.y, v.z];
                idx[k] = match vertices
                    .iter()
                    .position(|u| u.iter().zip(&v).all(|(a, b)| (a - b).abs() < 1e-9))
                {
                    Some(i) => i,
                    None => {
                        vertices.push(v);
                        vertices.len() - 1
                    }
                };
            }
            triangles.push(idx);
        }
        let part = ConvexPartFile {
            link: link.to_string(),
            vertices,
            triangles,
        };
        let checked = ConvexPart::new(&part).map_err(|e| format!("{mesh}: {e}"))?;
        out!(
            "{link}: {} vertices, {} faces ({mesh})",
            checked.vertices.len(),
            checked.faces.len()
        );
        file.parts.push(part);
    }
    let text = serde_json::to_string_pretty(&file).map_err(|e| e.to_string())?;
    std::fs::write(out, text + "\n").map_err(|e| format!("{}: {e}", out.display()))?;
    Ok(())
}

/// The arguments of `mjskill convert-visuals`.
#[derive(Debug, clap::Args)]
struct ConvertVisualsArgs {
    /// Upstream URDF whose mesh visuals to convert (paths relative to it).
    #[arg(long, conflicts_with_all = ["mesh", "texture"])]
    urdf: Option<PathBuf>,
    /// With --urdf: the model URDF whose links' `<visual>` elements are replaced by the
    /// converted ones (its directory must contain --out-dir). Without it they are printed.
    #[arg(long, requires = "urdf")]
    into: Option<PathBuf>,
    /// One mesh file to convert; writes <out-dir>/<name>.urdf, a one-link URDF with its
    /// visuals.
    #[arg(long, conflicts_with = "texture")]
    mesh: Option<PathBuf>,
    /// With --mesh: uniform scale baked into the vertices (positive, up to 1e6).
    #[arg(long, default_value_t = 1.0, value_parser = args::scale, allow_hyphen_values = true)]
    scale: f64,
    /// A PNG texture to re-encode as <out-dir>/<name>.png.
    #[arg(long)]
    texture: Option<PathBuf>,
    /// Output directory (created if missing).
    #[arg(long)]
    out_dir: PathBuf,
    /// File stem for --mesh and --texture.
    #[arg(long, default_value = "visual")]
    name: String,
    /// Triangle budget per mesh file (12..=1000000).
    #[arg(long, default_value_t = meshes::visual::DEFAULT_MAX_TRIANGLES, value_parser = args::max_triangles, allow_hyphen_values = true)]
    max_triangles: usize,
    /// Largest distance in millimetres that simplification may move a mesh's surface
    /// (0.001..=1000); meshes keep more triangles than --max-triangles where this needs it.
    /// Default: up to 2 % of each mesh's extent (8 % where the budget needs it).
    #[arg(long, value_parser = args::max_error_mm, allow_hyphen_values = true)]
    max_error: Option<f32>,
    /// Colour of a material the URDF names without defining it, as NAME=R,G,B,A (linear,
    /// 0..=1; repeatable), e.g. trossen_black=0.02,0.02,0.02,1.
    #[arg(long = "material", value_parser = args::named_rgba)]
    materials: Vec<(String, [f32; 4])>,
    /// Largest texture side in pixels (1..=8192; halved until it fits).
    #[arg(long, default_value_t = meshes::visual::DEFAULT_TEXTURE_SIZE, value_parser = args::texture_size, allow_hyphen_values = true)]
    texture_size: u32,
}

impl ConvertVisualsArgs {
    /// Converts exactly one source (`--urdf`, `--mesh` or `--texture`) into `--out-dir`.
    fn run(self) -> Result<(), CliError> {
        let ConvertVisualsArgs {
            urdf,
            into,
            mesh,
            scale,
            texture,
            out_dir,
            name,
            max_triangles,
            max_error,
            materials,
            texture_size,
        } = self;
        let opts = meshes::visual::Options {
            materials,
            max_triangles,
            max_error: max_error.map(|e| e / 1000.0),
            texture_size,
        };
        let source = match (urdf, mesh, texture) {
            (Some(u), None, None) => meshes::visual::Source::Urdf { urdf: u, into },
            (None, Some(m), None) => meshes::visual::Source::Mesh { mesh: m, scale },
            (None, None, Some(t)) => meshes::visual::Source::Texture(t),
            _ => {
                return Err(
                    "convert-visuals needs exactly one of --urdf, --mesh or --texture".into(),
                )
            }
        };
        for line in meshes::visual::run(source, &out_dir, &name, opts)? {
            out!("{line}");
        }
        Ok(())
    }
}

fn fit_primitives(
    mesh: &std::path::Path,
    shape: &str,
    parts: Option<usize>,
    segments: usize,
    crop: Option<&str>,
    scale: f64,
) -> Result<(), CliError> {
    use crate::meshes as mesh_fit;
    let kinds: Vec<mesh_fit::Kind> = shape
        .split(',')
        .map(|s| s.trim().parse())
        .collect::<Result<_, _>>()?;
    let crop = match crop {
        None => None,
        Some(s) => {
            let v: Vec<f64> = s
                .split(',')
                .map(|x| {
                    x.trim()
                        .parse::<f64>()
                        .ok()
                        .filter(|v| v.is_finite())
                        .ok_or_else(|| format!("--crop: {x:?} is not a finite number"))
                })
                .collect::<Result<_, _>>()?;
            if v.len() != 6 {
                return Err(format!(
                    "--crop needs 6 numbers xmin,ymin,zmin,xmax,ymax,zmax, got {}",
                    v.len()
                )
                .into());
            }
            if (0..3).any(|k| v[k] > v[k + 3]) {
                return Err(format!("--crop {s}: each minimum must not exceed its maximum").into());
            }
            Some(mesh_fit::Crop {
                min: [v[0], v[1], v[2]].into(),
                max: [v[3], v[4], v[5]].into(),
            })
        }
    };
    let bytes = mjskill::files::read(mesh).map_err(|e| e.to_string())?;
    let mut tris = mesh_fit::read_triangles(&bytes, &mesh.display().to_string())?;
    mesh_fit::scale_triangles(&mut tris, scale)?;
    let pts = mesh_fit::surface_points(&tris, crop.as_ref())?;
    let prims = match parts {
        Some(n) => mesh_fit::decompose(&pts, &kinds, n),
        None if segments > 1 && kinds.len() == 1 => {
            mesh_fit::fit_segments(&pts, kinds[0], segments)
        }
        None if segments > 1 => return Err("--segments needs a single --shape".into()),
        None => mesh_fit::fit_any(&pts, &kinds).map(|p| vec![p]),
    }?;
    for p in &prims {
        mesh_fit::check_primitive(p, crop.is_some())?;
    }
    let total: f64 = prims.iter().map(|p| p.volume()).sum();
    for p in &prims {
        out!("{}", p.to_urdf());
    }
    out!(
        "<!-- primitives volume {total:.3e} m^3, mesh volume {:.3e} m^3 -->",
        mesh_fit::mesh_volume(&tris)
    );
    Ok(())
}
