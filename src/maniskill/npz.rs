//! A reader for numpy's `.npz` archives (zip files of `.npy` arrays, stored or deflated), for
//! the camera images ManiSkill rendered (`mjskill compare-images`).
//!
//! Supported `.npy` contents: little-endian `u1`, `i2`, `i4`, `i8`, `f4`, `f8` arrays in C
//! order, and 0-d unicode strings (`<U…`, UTF-32). Anything else is an error naming the dtype.
use std::collections::BTreeMap;
use std::path::Path;

/// Why an archive could not be read.
#[derive(Debug, thiserror::Error)]
pub enum NpzError {
    /// The file could not be read, is not a regular file, or it or its members expand beyond
    /// the size limit ([`crate::files`]).
    #[error(transparent)]
    File(#[from] crate::files::FileError),
    /// Not a zip archive, or one this reader does not handle.
    #[error("{path}: {msg}")]
    Zip {
        /// The file.
        path: String,
        /// What is wrong.
        msg: String,
    },
    /// An array this reader does not handle.
    #[error("{path}: array {name:?}: {msg}")]
    Npy {
        /// The file.
        path: String,
        /// The array.
        name: String,
        /// What is wrong.
        msg: String,
    },
}

/// The values of one array.
#[derive(Debug, Clone, PartialEq)]
pub enum NpyData {
    /// `u1`.
    U8(Vec<u8>),
    /// `i2`.
    I16(Vec<i16>),
    /// `i4`.
    I32(Vec<i32>),
    /// `i8`.
    I64(Vec<i64>),
    /// `f4`.
    F32(Vec<f32>),
    /// `f8`.
    F64(Vec<f64>),
    /// A 0-d unicode string.
    Str(String),
}

/// One array: shape and values (C order).
#[derive(Debug, Clone, PartialEq)]
pub struct NpyArray {
    /// Shape (empty for a scalar).
    pub shape: Vec<usize>,
    /// Values.
    pub data: NpyData,
}

impl NpyArray {
    /// The values as i64 if the array is an integer scalar or has one element.
    pub fn as_i64(&self) -> Option<i64> {
        match &self.data {
            NpyData::I64(v) if v.len() == 1 => Some(v[0]),
            NpyData::I32(v) if v.len() == 1 => Some(v[0] as i64),
            NpyData::I16(v) if v.len() == 1 => Some(v[0] as i64),
            NpyData::U8(v) if v.len() == 1 => Some(v[0] as i64),
            _ => None,
        }
    }
    /// The string of a 0-d unicode array.
    pub fn as_str(&self) -> Option<&str> {
        match &self.data {
            NpyData::Str(s) => Some(s),
            _ => None,
        }
    }
}

fn u16_at(b: &[u8], i: usize) -> Option<usize> {
    Some(u16::from_le_bytes(b.get(i..i + 2)?.try_into().ok()?) as usize)
}

fn u32_at(b: &[u8], i: usize) -> Option<usize> {
    Some(u32::from_le_bytes(b.get(i..i + 4)?.try_into().ok()?) as usize)
}

/// Reads every array of an `.npz` file (a regular file; it and its members decompressed, all
/// together, at most [`crate::files::max_bytes`]).
pub fn read_npz(path: &Path) -> Result<BTreeMap<String, NpyArray>, NpzError> {
    read_npz_limited(path, crate::files::max_bytes())
}

/// [`read_npz`] with the limit `limit` on the file and on its decompressed members together.
pub fn read_npz_limited(path: &Path, limit: u64) -> Result<BTreeMap<String, NpyArray>, NpzError> {
    let p = path.display().to_string();
    let bytes = crate::files::read_limited(path, limit)?;
    parse_npz(&bytes, path, limit).map_err(|e| match e {
        ParseError::Zip(msg) => NpzError::Zip { path: p, msg },
        ParseError::Npy(name, msg) => NpzError::Npy { path: p, name, msg },
        ParseError::File(e) => NpzError::File(e),
    })
}

enum ParseError {
    Zip(String),
    Npy(String, String),
    File(crate::files::FileError),
}

/// Parses an `.npz` archive held in memory (read from `path`); its members, decompressed,
/// may hold `limit` bytes together.
fn parse_npz(b: &[u8], path: &Path, limit: u64) -> Result<BTreeMap<String, NpyArray>, ParseError> {
    let zip = |m: &str| ParseError::Zip(m.to_string());
    // End of central directory: the last "PK\x05\x06" record.
    let eocd = (0..b.len().saturating_sub(21))
        .rev()
        .find(|&i| b[i..].starts_with(b"PK\x05\x06"))
        .ok_or_else(|| zip("not a zip archive (no end of central directory)"))?;
    let entries = u16_at(b, eocd + 10).ok_or_else(|| zip("truncated directory"))?;
    let mut at = u32_at(b, eocd + 16).ok_or_else(|| zip("truncated directory"))?;
    let mut out = BTreeMap::new();
    // What the members may still expand to.
    let mut budget = limit;
    for _ in 0..entries {
        if !b.get(at..).is_some_and(|r| r.starts_with(b"PK\x01\x02")) {
            return Err(zip("bad central directory entry"));
        }
        let field = |o: usize, two: bool| {
            if two {
                u16_at(b, at + o)
            } else {
                u32_at(b, at + o)
            }
            .ok_or_else(|| zip("truncated directory entry"))
        };
        let method = field(10, true)?;
        let csize = field(20, false)?;
        let usize_ = field(24, false)?;
        let (nlen, xlen, clen) = (field(28, true)?, field(30, true)?, field(32, true)?);
        let local = field(42, false)?;
        let name = b
            .get(at + 46..at + 46 + nlen)
            .map(|n| String::from_utf8_lossy(n).into_owned())
            .ok_or_else(|| zip("truncated file name"))?;
        at += 46 + nlen + xlen + clen;
        if csize == u32::MAX as usize || usize_ == u32::MAX as usize {
            return Err(zip("zip64 archives are not supported"));
        }
        let too_large = || {
            ParseError::File(crate::files::FileError::TooLarge {
                path: path.to_path_buf(),
                what: format!(
                    "member {} (with the members before it)",
                    crate::files::short(&name)
                ),
                limit,
            })
        };
        // The declared size is checked before anything is decompressed.
        if usize_ as u64 > budget {
            return Err(too_large());
        }
        let lname = u16_at(b, local + 26).ok_or_else(|| zip("truncated local header"))?;
        let lextra = u16_at(b, local + 28).ok_or_else(|| zip("truncated local header"))?;
        let start = local + 30 + lname + lextra;
        let raw = b
            .get(start..start + csize)
            .ok_or_else(|| zip("truncated member data"))?;
        let data = match method {
            0 => raw.to_vec(),
            8 => crate::files::read_bounded(
                flate2::read::DeflateDecoder::new(raw),
                path,
                &format!("member {}", crate::files::short(&name)),
                budget,
            )
            .map_err(|e| match e {
                crate::files::FileError::Io { reason, .. } => {
                    ParseError::Zip(format!("{name}: bad deflate data: {reason}"))
                }
                _ => too_large(),
            })?,
            m => {
                return Err(ParseError::Zip(format!(
                    "{name}: compression method {m} is not supported (stored or deflate only)"
                )))
            }
        };
        // A member that expands beyond its declared size still counts in full.
        budget = budget
            .checked_sub(data.len() as u64)
            .ok_or_else(too_large)?;
        let key = name.strip_suffix(".npy").unwrap_or(&name).to_string();
        let arr = parse_npy(&data).map_err(|e| ParseError::Npy(key.clone(), e.to_string()))?;
        out.insert(key, arr);
    }
    Ok(out)
}

/// The value of `'key': value` in a `.npy` header dict (up to the next `,` or `}` outside
/// brackets).
fn header_value<'a>(h: &'a str, key: &str) -> Option<&'a str> {
    let i = h.find(&format!("'{key}':"))? + key.len() + 3;
    let rest = h[i..].trim_start();
    let mut depth = 0i32;
    for (k, c) in rest.char_indices() {
        match c {
            '(' | '[' => depth += 1,
            ')' | ']' => depth -= 1,
            ',' | '}' if depth <= 0 => return Some(rest[..k].trim()),
            _ => {}
        }
        if depth < 0 {
            return Some(rest[..k].trim());
        }
    }
    Some(rest.trim())
}

/// Why one `.npy` array does not parse (the message of [`NpzError::Npy`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
enum NpyError {
    /// No `.npy` magic.
    #[error("not a .npy array")]
    NotNpy,
    /// The header is cut short.
    #[error("truncated header")]
    TruncatedHeader,
    /// A format version other than 1 to 3.
    #[error(".npy version {0} is not supported")]
    Version(u8),
    /// The header is not UTF-8.
    #[error("header is not text")]
    HeaderNotText,
    /// A header key is missing.
    #[error("no {0}")]
    Missing(&'static str),
    /// A Fortran-order array.
    #[error("Fortran-order arrays are not supported")]
    FortranOrder,
    /// The shape does not parse.
    #[error("bad shape {0}")]
    BadShape(String),
    /// The shape's product overflows.
    #[error("shape {0} has more values than memory holds")]
    TooManyValues(String),
    /// The data is shorter than the shape says.
    #[error("{n} values of {size} bytes do not fit the data")]
    ShortData {
        /// Values.
        n: usize,
        /// Bytes per value.
        size: usize,
    },
    /// A unicode dtype whose length does not parse.
    #[error("bad dtype {0}")]
    BadDtype(String),
    /// A string longer than the data.
    #[error("{0} characters do not fit the data")]
    ShortString(usize),
    /// A dtype this reader does not handle.
    #[error("dtype {0} is not supported (u1, i2, i4, i8, f4, f8, 0-d unicode)")]
    UnsupportedDtype(String),
}

/// Parses one `.npy` file.
fn parse_npy(b: &[u8]) -> Result<NpyArray, NpyError> {
    if !b.starts_with(b"\x93NUMPY") || b.len() < 10 {
        return Err(NpyError::NotNpy);
    }
    let (hlen, hstart) = match b[6] {
        1 => (u16_at(b, 8).ok_or(NpyError::TruncatedHeader)?, 10),
        2 | 3 => (u32_at(b, 8).ok_or(NpyError::TruncatedHeader)?, 12),
        v => return Err(NpyError::Version(v)),
    };
    let h = std::str::from_utf8(
        b.get(hstart..hstart + hlen)
            .ok_or(NpyError::TruncatedHeader)?,
    )
    .map_err(|_| NpyError::HeaderNotText)?;
    let body = &b[hstart + hlen..];
    let descr = header_value(h, "descr")
        .ok_or(NpyError::Missing("descr"))?
        .trim_matches(|c| c == '\'' || c == '"');
    if header_value(h, "fortran_order") == Some("True") {
        return Err(NpyError::FortranOrder);
    }
    let shape_s = header_value(h, "shape").ok_or(NpyError::Missing("shape"))?;
    let shape: Vec<usize> = shape_s
        .trim_matches(|c| c == '(' || c == ')')
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.parse()
                .map_err(|_| NpyError::BadShape(shape_s.to_string()))
        })
        .collect::<Result<_, NpyError>>()?;
    let n = shape
        .iter()
        .try_fold(1usize, |n, &d| n.checked_mul(d))
        .ok_or_else(|| NpyError::TooManyValues(shape_s.to_string()))?;
    let take = |size: usize| -> Result<&[u8], NpyError> {
        n.checked_mul(size)
            .and_then(|len| body.get(..len))
            .ok_or(NpyError::ShortData { n, size })
    };
    let data = match descr {
        "|u1" | "<u1" => NpyData::U8(take(1)?.to_vec()),
        "<i2" => NpyData::I16(
            take(2)?
                .chunks_exact(2)
                .map(|c| i16::from_le_bytes([c[0], c[1]]))
                .collect(),
        ),
        "<i4" => NpyData::I32(
            take(4)?
                .chunks_exact(4)
                .map(|c| i32::from_le_bytes(c.try_into().expect("4 bytes")))
                .collect(),
        ),
        "<i8" => NpyData::I64(
            take(8)?
                .chunks_exact(8)
                .map(|c| i64::from_le_bytes(c.try_into().expect("8 bytes")))
                .collect(),
        ),
        "<f4" => NpyData::F32(
            take(4)?
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
                .collect(),
        ),
        "<f8" => NpyData::F64(
            take(8)?
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
                .collect(),
        ),
        d if d.starts_with("<U") && shape.is_empty() => {
            let chars: usize = d[2..]
                .parse()
                .map_err(|_| NpyError::BadDtype(d.to_string()))?;
            let raw = chars
                .checked_mul(4)
                .and_then(|len| body.get(..len))
                .ok_or(NpyError::ShortString(chars))?;
            let s: String = raw
                .chunks_exact(4)
                .map(|c| u32::from_le_bytes(c.try_into().expect("4 bytes")))
                .take_while(|&c| c != 0)
                .map(|c| char::from_u32(c).unwrap_or('\u{FFFD}'))
                .collect();
            NpyData::Str(s)
        }
        d => return Err(NpyError::UnsupportedDtype(d.to_string())),
    };
    Ok(NpyArray { shape, data })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stored (uncompressed) zip of the given members.
    fn zip_stored(members: &[(&str, Vec<u8>)]) -> Vec<u8> {
        zip_of(members, false)
    }

    /// A zip of the given members, stored or deflated.
    fn zip_of(members: &[(&str, Vec<u8>)], deflate: bool) -> Vec<u8> {
        let mut out = Vec::new();
        let mut central = Vec::new();
        for (name, plain) in members {
            let data = if deflate {
                let mut e = flate2::write::DeflateEncoder::new(Vec::new(), Default::default());
                std::io::Write::write_all(&mut e, plain).unwrap();
                e.finish().unwrap()
            } else {
                plain.clone()
            };
            let method = if deflate { 8u8 } else { 0 };
            let off = out.len() as u32;
            let crc = 0u32; // not checked by the reader
            let mut local = b"PK\x03\x04".to_vec();
            local.extend_from_slice(&[20, 0, 0, 0, method, 0, 0, 0, 0, 0]);
            local.extend_from_slice(&crc.to_le_bytes());
            local.extend_from_slice(&(data.len() as u32).to_le_bytes());
            local.extend_from_slice(&(plain.len() as u32).to_le_bytes());
            local.extend_from_slice(&(name.len() as u16).to_le_bytes());
            local.extend_from_slice(&0u16.to_le_bytes());
            local.extend_from_slice(name.as_bytes());
            out.extend_from_slice(&local);
            out.extend_from_slice(&data);
            let mut c = b"PK\x01\x02".to_vec();
            c.extend_from_slice(&[20, 0, 20, 0, 0, 0, method, 0, 0, 0, 0, 0]);
            c.extend_from_slice(&crc.to_le_bytes());
            c.extend_from_slice(&(data.len() as u32).to_le_bytes());
            c.extend_from_slice(&(plain.len() as u32).to_le_bytes());
            c.extend_from_slice(&(name.len() as u16).to_le_bytes());
            c.extend_from_slice(&[0; 12]);
            c.extend_from_slice(&off.to_le_bytes());
            c.extend_from_slice(name.as_bytes());
            central.extend_from_slice(&c);
        }
        let cd_off = out.len() as u32;
        out.extend_from_slice(&central);
        out.extend_from_slice(b"PK\x05\x06");
        out.extend_from_slice(&[0, 0, 0, 0]);
        out.extend_from_slice(&(members.len() as u16).to_le_bytes());
        out.extend_from_slice(&(members.len() as u16).to_le_bytes());
        out.extend_from_slice(&(central.len() as u32).to_le_bytes());
        out.extend_from_slice(&cd_off.to_le_bytes());
        out.extend_from_slice(&[0, 0]);
        out
    }

    fn npy(descr: &str, shape: &str, body: &[u8]) -> Vec<u8> {
        let mut h = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
        while (10 + h.len() + 1) % 64 != 0 {
            h.push(' ');
        }
        h.push('\n');
        let mut v = b"\x93NUMPY\x01\x00".to_vec();
        v.extend_from_slice(&(h.len() as u16).to_le_bytes());
        v.extend_from_slice(h.as_bytes());
        v.extend_from_slice(body);
        v
    }

    #[test]
    fn arrays_and_strings_round_trip() {
        let img: Vec<u8> = [-2i16, 300, 7, 0, 1, 2]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let s: Vec<u8> = "hé"
            .chars()
            .flat_map(|c| (c as u32).to_le_bytes())
            .chain([0; 4])
            .collect();
        let z = zip_stored(&[
            ("seg.npy", npy("<i2", "(2, 3, 1)", &img)),
            ("name.npy", npy("<U3", "()", &s)),
            ("step.npy", npy("<i8", "()", &35i64.to_le_bytes())),
        ]);
        let m = parse_npz(&z, Path::new("t.npz"), 1 << 20)
            .ok()
            .expect("parses");
        assert_eq!(m["seg"].shape, [2, 3, 1]);
        assert_eq!(m["seg"].data, NpyData::I16(vec![-2, 300, 7, 0, 1, 2]));
        assert_eq!(m["name"].as_str(), Some("hé"));
        assert_eq!(m["step"].as_i64(), Some(35));
    }

    #[test]
    fn unsupported_dtypes_are_named() {
        let z = zip_stored(&[("x.npy", npy(">i2", "(1,)", &[0, 1]))]);
        match parse_npz(&z, Path::new("t.npz"), 1 << 20) {
            Err(ParseError::Npy(name, msg)) => {
                assert_eq!(name, "x");
                assert!(msg.contains(">i2"), "{msg}");
            }
            _ => panic!("expected an npy error"),
        }
        assert!(matches!(
            parse_npz(b"not a zip", Path::new("t.npz"), 1 << 20),
            Err(ParseError::Zip(_))
        ));
    }

    #[test]
    fn members_are_bounded_by_the_limit_together() {
        let big = npy("|u1", "(4000,)", &[7u8; 4000]);
        let err = |z: &[u8], limit: u64| match parse_npz(z, Path::new("bomb.npz"), limit) {
            Err(ParseError::File(e)) => e.to_string(),
            Ok(_) => panic!("read beyond the limit {limit}"),
            Err(_) => panic!("not a size error"),
        };
        // A deflated member that expands to 4 kB from a few bytes: fine under the limit,
        // refused over it (its declared size first, then what it really expands to).
        let z = zip_of(&[("a.npy", big.clone())], true);
        assert!(z.len() < 400, "{}", z.len());
        assert!(parse_npz(&z, Path::new("bomb.npz"), 5000).is_ok());
        let e = err(&z, 4000);
        assert!(
            e.contains("bomb.npz") && e.contains("limit of 4000 bytes"),
            "{e}"
        );
        let mut lying = z.clone();
        let cd = lying.len() - 22 - 46 - 5; // the central entry's declared size: 1 byte
        lying[cd + 24..cd + 28].copy_from_slice(&1u32.to_le_bytes());
        assert!(err(&lying, 4000).contains("member a.npy"));
        // Three members each under the limit, together over it.
        let z = zip_of(
            &[
                ("a.npy", big.clone()),
                ("b.npy", big.clone()),
                ("c.npy", big),
            ],
            true,
        );
        assert!(parse_npz(&z, Path::new("bomb.npz"), 13_000).is_ok());
        assert!(err(&z, 10_000).contains("member c.npy"));
        // A shape whose size overflows is an error, not a panic.
        let z = zip_stored(&[("x.npy", npy("<f8", "(4294967296, 4294967296)", &[0; 8]))]);
        assert!(matches!(
            parse_npz(&z, Path::new("t.npz"), 1 << 20),
            Err(ParseError::Npy(..))
        ));
    }
}
