//! PNG encoding of rendered frames (the `png` crate).

/// Encodes an RGB image (H×W×3 bytes, top row first) as PNG into `out` (cleared first).
pub fn encode_png(
    rgb: &[u8],
    width: usize,
    height: usize,
    out: &mut Vec<u8>,
) -> Result<(), String> {
    if rgb.len() != width * height * 3 {
        return Err(format!(
            "image buffer has {} bytes, a {width}x{height} RGB image needs {}",
            rgb.len(),
            width * height * 3
        ));
    }
    out.clear();
    let mut enc = png::Encoder::new(&mut *out, width as u32, height as u32);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_compression(png::Compression::Fast);
    let mut w = enc.write_header().map_err(|e| e.to_string())?;
    w.write_image_data(rgb).map_err(|e| e.to_string())?;
    w.finish().map_err(|e| e.to_string())
}

/// Writes an RGB image as a PNG file.
pub fn write_png(
    path: &std::path::Path,
    rgb: &[u8],
    width: usize,
    height: usize,
) -> Result<(), String> {
    let mut buf = Vec::new();
    encode_png(rgb, width, height, &mut buf)?;
    std::fs::write(path, &buf).map_err(|e| format!("cannot write {}: {e}", path.display()))
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
            .contains("5x3"));
    }
}
