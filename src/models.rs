//! The robot models shipped in `models/`, embedded into the library at build time by
//! `build.rs` (so the binary needs no files next to it).

include!(concat!(env!("OUT_DIR"), "/models_index.rs"));

/// The bytes of the model file at `path` (relative to `models/`, e.g. `"panda/panda.urdf"`).
pub fn file(path: &str) -> Option<&'static [u8]> {
    FILES.iter().find(|(p, _)| *p == path).map(|(_, b)| *b)
}

/// The bytes of the file a model file at `base` (relative to `models/`) names as `file`
/// (relative to `base`'s directory, e.g. a URDF's `"visual/link0_0.obj"`).
pub fn file_near(base: &str, file: &str) -> Option<&'static [u8]> {
    match base.rsplit_once('/') {
        Some((dir, _)) => self::file(&format!("{dir}/{file}")),
        None => self::file(file),
    }
}

/// Why a model file cannot be read: the error names the file.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ModelFileError {
    /// No such file in `models/`.
    #[error("model file {0:?} is not shipped in models/")]
    NotShipped(String),
    /// The file is not UTF-8 text.
    #[error("model file {path:?} is not UTF-8: {source}")]
    NotUtf8 {
        /// The file.
        path: String,
        /// The decoding error.
        source: std::str::Utf8Error,
    },
}

/// The model file at `path` as UTF-8 text, with an error naming the file.
pub fn text(path: &str) -> Result<&'static str, ModelFileError> {
    let bytes = file(path).ok_or_else(|| ModelFileError::NotShipped(path.to_string()))?;
    std::str::from_utf8(bytes).map_err(|source| ModelFileError::NotUtf8 {
        path: path.to_string(),
        source,
    })
}
