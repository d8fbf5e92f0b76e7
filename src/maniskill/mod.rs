//! Interoperation with ManiSkill 3's own data: reference trajectories recorded from
//! ManiSkill ([`reference`](mod@reference)), the step-by-step comparison of mjskill against them
//! ([`fidelity`]), the outcome agreement of fixed action sequences ([`outcome`]), and
//! mjskill's camera images against ManiSkill's ([`images`], reading numpy archives with
//! [`npz`]).
pub mod fidelity;
pub mod images;
pub mod npz;
pub mod outcome;
pub mod reference;

/// The bytes of a file, gunzipped when it starts with gzip's magic number (reference and
/// outcome files are stored as `.json.gz` or plain `.json`).
fn read_maybe_gzip(path: &std::path::Path) -> std::io::Result<Vec<u8>> {
    use std::io::Read;
    let raw = std::fs::read(path)?;
    if !raw.starts_with(&[0x1f, 0x8b]) {
        return Ok(raw);
    }
    let mut s = Vec::new();
    flate2::read::GzDecoder::new(raw.as_slice()).read_to_end(&mut s)?;
    Ok(s)
}
