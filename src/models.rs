//! The robot models shipped in `models/`, embedded into the library at build time by
//! `build.rs` (so the binary needs no files next to it).

include!(concat!(env!("OUT_DIR"), "/models_index.rs"));

/// The bytes of the model file at `path` (relative to `models/`, e.g. `"panda/panda.urdf"`).
pub fn file(path: &str) -> Option<&'static [u8]> {
    FILES.iter().find(|(p, _)| *p == path).map(|(_, b)| *b)
}

/// The model file at `path` as UTF-8 text, with an error naming the file.
pub fn text(path: &str) -> Result<&'static str, String> {
    let bytes =
        file(path).ok_or_else(|| format!("model file {path:?} is not shipped in models/"))?;
    std::str::from_utf8(bytes).map_err(|e| format!("model file {path:?} is not UTF-8: {e}"))
}
