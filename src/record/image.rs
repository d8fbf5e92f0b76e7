//! PNG encoding of rendered frames (the `png` crate).

/// Why an image could not be encoded or written.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    /// The buffer length does not match the size.
    #[error("image buffer has {got} bytes, a {width}x{height} RGB image needs {need}")]
    BufferLength {
        /// Bytes given.
        got: usize,
        /// Width.
        width: usize,
        /// Height.
        height: usize,
        /// Bytes needed.
        need: usize,
    },
    /// The size overflows.
    #[error("a {0}x{1} RGB image is too large (the size overflows)")]
    Overflow(usize, usize),
    /// A side beyond PNG's limit.
    #[error("a {0}x{1} image is too large for PNG (at most {max} pixels a side)", max = u32::MAX)]
    TooLarge(usize, usize),
    /// A zero side.
    #[error("a {0}x{1} image is empty")]
    Empty(usize, usize),
    /// The PNG encoder failed.
    #[error(transparent)]
    Encode(#[from] png::EncodingError),
    /// The file could not be written.
    #[error("cannot write {}: {source}", .path.display())]
    Write {
        /// The file.
        path: std::path::PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}

/// Encodes an RGB image (H×W×3 bytes, top row first) as PNG into `out` (cleared first).
pub fn encode_png(
    rgb: &[u8],
    width: usize,
    height: usize,
    out: &mut Vec<u8>,
) -> Result<(), ImageError> {
    let need = width.checked_mul(height).and_then(|n| n.checked_mul(3));
    if need != Some(rgb.len()) {
        return Err(match need {
            Some(need) => ImageError::BufferLength {
                got: rgb.len(),
                width,
                height,
                need,
            },
            None => ImageError::Overflow(width, height),
        });
    }
    let (Ok(w), Ok(h)) = (u32::try_from(width), u32::try_from(height)) else {
        return Err(ImageError::TooLarge(width, height));
    };
    if w == 0 || h == 0 {
        return Err(ImageError::Empty(width, height));
    }
    out.clear();
    let mut enc = png::Encoder::new(&mut *out, w, h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_compression(png::Compression::Fast);
    let mut w = enc.write_header()?;
    w.write_image_data(rgb)?;
    Ok(w.finish()?)
}

/// Writes an RGB image as a PNG file.
pub fn write_png(
    path: &std::path::Path,
    rgb: &[u8],
    width: usize,
    height: usize,
) -> Result<(), ImageError> {
    let mut buf = Vec::new();
    encode_png(rgb, width, height, &mut buf)?;
    std::fs::write(path, &buf).map_err(|source| ImageError::Write {
        path: path.to_path_buf(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_roundtrip() {
        let (w, h) = (5, 3);
        let rgb: Vec<u8> = (0..w * h * 3).map(|i| (i * 7) as u8).collect();
        let mut buf = Vec::new();
        encode_png(&rgb, w, h, &mut buf).unwrap();
        let dec = png::Decoder::new(std::io::Cursor::new(&buf));
        let mut r = dec.read_info().unwrap();
        let mut out = vec![0; r.output_buffer_size().unwrap()];
        let info = r.next_frame(&mut out).unwrap();
        assert_eq!((info.width, info.height), (w as u32, h as u32));
        assert_eq!(&out[..info.buffer_size()], &rgb[..]);
        assert!(encode_png(&rgb[1..], w, h, &mut buf)
            .unwrap_err()
            .to_string()
            .contains("5x3"));
        // A size whose byte count overflows is an error, not a wrapped size that passes.
        let huge = usize::MAX / 2 + 1;
        let e = encode_png(&[], huge, 2, &mut buf).unwrap_err().to_string();
        assert!(e.contains("overflows"), "{e}");
        // 2^63 × 2 × 3 wraps to 0 bytes in unchecked arithmetic: the empty buffer would pass.
        assert_eq!(huge.wrapping_mul(2).wrapping_mul(3), 0);
        assert!(encode_png(&[], 0, 0, &mut buf)
            .unwrap_err()
            .to_string()
            .contains("empty"));
    }
}
