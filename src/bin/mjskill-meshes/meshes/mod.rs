//! Mesh tools of the `mjskill` binary, side by side: reading meshes ([`read`]), fitting
//! collision primitives to them ([`fit`], `mjskill fit-primitives`), and converting visual
//! meshes into simplified, textured files MuJoCo 2.2 draws ([`visual`], with the glTF and
//! COLLADA readers in [`formats`]; `mjskill convert-visuals`).
pub mod fit;
pub mod formats;
pub mod read;
pub mod visual;

pub use fit::*;
pub use read::*;
