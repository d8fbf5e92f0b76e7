//! How a [`VecEnv`](super::VecEnv)'s camera images cross threads: each env's images travel
//! as one block of atomic cells (colour bytes packed four per cell, segmentation ids two per
//! cell, depth and point coordinates as f32 bits), laid out by [`ImageLayout`].

use std::sync::atomic::{AtomicU32, Ordering};

use crate::env::config::Textures;
use crate::env::Env;

/// Where one sensor camera's images live inside an env's image block.
#[derive(Debug, Clone)]
pub(super) struct CamSlot {
    pub(super) name: &'static str,
    pub(super) size: (usize, usize),
    /// First pixel of the camera within the env's block (cameras are concatenated).
    pub(super) at: usize,
}

/// Image layout of one env (identical for all envs of a VecEnv); empty for non-visual modes.
/// Every texture of an env travels as one block: colour bytes packed four per cell,
/// segmentation ids two per cell, depth and point coordinates as f32 bits.
#[derive(Debug, Clone, Default)]
pub(super) struct ImageLayout {
    pub(super) cams: Vec<CamSlot>,
    pub(super) tex: Textures,
    pub(super) point_cloud: bool,
    /// Pixels per env (all cameras).
    pub(super) px: usize,
    /// rgb cells per env (`3·px` bytes rounded up to whole cells).
    pub(super) rgb_cells: usize,
    /// segmentation cells per env (`2·px` bytes rounded up).
    pub(super) seg_cells: usize,
    /// depth values per env.
    pub(super) depth_len: usize,
    /// point-cloud values per env (`4·px`).
    pub(super) xyzw_len: usize,
    /// The far clip plane (the depth of nothing), for the millimetre depth.
    pub(super) far: f32,
}

impl ImageLayout {
    /// Bytes one env takes in a VecEnv's buffers: `values` f32s (observation and action)
    /// and its images, each held twice (the shared cells and the unpacked copy).
    pub(super) fn buffer_bytes(&self, values: usize) -> u64 {
        let cells = values + self.rgb_cells + self.depth_len + self.seg_cells + self.xyzw_len;
        // Depth also as millimetres, segmentation ids unpacked to one i16 per pixel.
        (8 * cells + 2 * self.depth_len + 2 * self.px) as u64
    }

    /// The layout of `env`'s sensor images (empty unless its obs mode renders).
    pub(super) fn of(env: &Env) -> ImageLayout {
        let mut l = ImageLayout::default();
        let Some(v) = env.vision.as_ref().filter(|v| v.tex.any()) else {
            return l;
        };
        l.tex = v.tex;
        l.point_cloud = env.point_cloud().is_some();
        l.far = env.render_options().clip.1 as f32;
        let mut k = 0;
        while let Some(img) = v.sensor_image(k) {
            l.cams.push(CamSlot {
                name: img.name,
                size: (img.width, img.height),
                at: l.px,
            });
            l.px += img.width * img.height;
            k += 1;
        }
        if l.tex.rgb {
            l.rgb_cells = (3 * l.px).div_ceil(4);
        }
        if l.tex.segmentation {
            l.seg_cells = (2 * l.px).div_ceil(4);
        }
        if l.tex.depth {
            l.depth_len = l.px;
        }
        if l.point_cloud {
            l.xyzw_len = 4 * l.px;
        }
        l
    }
}

/// Packs int16 values two per cell (little-endian; an odd last value is zero-padded).
pub(super) fn pack_i16(cells: &[AtomicU32], values: &[i16]) {
    for (cell, c) in cells.iter().zip(values.chunks(2)) {
        let hi = c.get(1).copied().unwrap_or(0) as u16 as u32;
        cell.store(c[0] as u16 as u32 | hi << 16, Ordering::Relaxed);
    }
}

/// Unpacks cells written by [`pack_i16`] into `dst`.
pub(super) fn unpack_i16(dst: &mut [i16], cells: &[AtomicU32]) {
    for (d, cell) in dst.chunks_mut(2).zip(cells) {
        let v = cell.load(Ordering::Relaxed);
        d[0] = v as u16 as i16;
        if let Some(x) = d.get_mut(1) {
            *x = (v >> 16) as u16 as i16;
        }
    }
}

/// Stores f32 values as bits.
pub(super) fn store_f32(cells: &[AtomicU32], values: &[f32]) {
    for (cell, v) in cells.iter().zip(values) {
        cell.store(v.to_bits(), Ordering::Relaxed);
    }
}

/// Packs `bytes` four per cell (little-endian; a short last chunk is zero-padded).
pub(super) fn pack_bytes(cells: &[AtomicU32], bytes: &[u8]) {
    let chunks = bytes.chunks_exact(4);
    let rest = chunks.remainder();
    let n = chunks.len();
    for (cell, c) in cells.iter().zip(chunks) {
        cell.store(
            u32::from_le_bytes([c[0], c[1], c[2], c[3]]),
            Ordering::Relaxed,
        );
    }
    if !rest.is_empty() {
        let mut b = [0u8; 4];
        b[..rest.len()].copy_from_slice(rest);
        cells[n].store(u32::from_le_bytes(b), Ordering::Relaxed);
    }
}

/// Unpacks cells written by [`pack_bytes`] into `dst` (4 bytes per cell; `dst` holds whole
/// cells, so padding bytes land in it too).
pub(super) fn unpack_bytes(dst: &mut [u8], cells: &[AtomicU32]) {
    for (d, cell) in dst.chunks_exact_mut(4).zip(cells) {
        d.copy_from_slice(&cell.load(Ordering::Relaxed).to_le_bytes());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_survive_packing_with_a_partial_last_cell() {
        // Two cameras of 7 and 5 bytes: 2 + 2 cells, the second camera starts at cell 2.
        let cells: Vec<AtomicU32> = (0..4).map(|_| AtomicU32::new(u32::MAX)).collect();
        let (a, b) = ([1u8, 2, 3, 4, 5, 6, 7], [8u8, 9, 10, 11, 12]);
        pack_bytes(&cells[0..], &a);
        pack_bytes(&cells[2..], &b);
        let mut out = [0xAAu8; 16];
        unpack_bytes(&mut out, &cells);
        assert_eq!(&out[..7], &a);
        assert_eq!(out[7], 0, "padding is zeroed");
        assert_eq!(&out[8..13], &b);
        assert_eq!(&out[13..], &[0, 0, 0]);
    }
}
