//! How close mjskill's sensor images look to ManiSkill's (docs/rendering.md): for each
//! ManiSkill frame `<env>__<robot>/<...>.npz` (from ManiSkill's own renderer, with the state
//! dict it was rendered at), loads that state into mjskill with `set_state_dict`, renders
//! `base_camera` (128×128) and prints the mean absolute RGB difference (0–255) per file, per
//! (env, robot) pair and overall.
//!
//! ```text
//! cargo run --release --example rgb_diff -- [DIR_OR_NPZ ...] [--save OUT_DIR]
//! ```
//! DIR defaults to `/work/shared/reference/maniskill/images`; `--save` writes each pair of
//! images side by side (ManiSkill left, mjskill right) as PNG.
use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};

use mjskill::{make, EnvConfig, ObsMode, StateDict};

type Error = Box<dyn std::error::Error>;

/// The members of a zip archive (stored or deflated), by name.
fn unzip(bytes: &[u8]) -> Result<BTreeMap<String, Vec<u8>>, Error> {
    let u16_at = |o: usize| u16::from_le_bytes([bytes[o], bytes[o + 1]]) as usize;
    let u32_at = |o: usize| {
        u32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]) as usize
    };
    // End of central directory record: the last "PK\x05\x06".
    let eocd = (0..bytes.len().saturating_sub(21))
        .rev()
        .find(|&i| bytes[i..i + 4] == [0x50, 0x4b, 0x05, 0x06])
        .ok_or("not a zip file (no end of central directory)")?;
    let (count, mut at) = (u16_at(eocd + 10), u32_at(eocd + 16));
    let mut out = BTreeMap::new();
    for _ in 0..count {
        if bytes[at..at + 4] != [0x50, 0x4b, 0x01, 0x02] {
            return Err("bad zip central directory entry".into());
        }
        let method = u16_at(at + 10);
        let csize = u32_at(at + 20);
        let (nlen, xlen, clen) = (u16_at(at + 28), u16_at(at + 30), u16_at(at + 32));
        let local = u32_at(at + 42);
        let name = String::from_utf8_lossy(&bytes[at + 46..at + 46 + nlen]).to_string();
        at += 46 + nlen + xlen + clen;
        let data_at = local + 30 + u16_at(local + 26) + u16_at(local + 28);
        let raw = &bytes[data_at..data_at + csize];
        let data = match method {
            0 => raw.to_vec(),
            8 => {
                let mut v = Vec::new();
                flate2::read::DeflateDecoder::new(raw).read_to_end(&mut v)?;
                v
            }
            m => {
                return Err(format!("zip member {name}: compression method {m} unsupported").into())
            }
        };
        out.insert(name, data);
    }
    Ok(out)
}

/// An .npy array: (dtype descr, shape, raw little-endian data).
fn npy(bytes: &[u8]) -> Result<(String, Vec<usize>, &[u8]), Error> {
    if !bytes.starts_with(b"\x93NUMPY") {
        return Err("not an .npy array".into());
    }
    let (hlen, start) = if bytes[6] == 1 {
        (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10)
    } else {
        (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        )
    };
    let header = std::str::from_utf8(&bytes[start..start + hlen])?;
    let field = |key: &str| -> Option<String> {
        let i = header.find(&format!("'{key}':"))? + key.len() + 3;
        let rest = header[i..].trim_start();
        let end = if rest.starts_with('(') {
            rest.find(')')? + 1
        } else {
            rest.find(',')?
        };
        Some(rest[..end].trim().trim_matches('\'').to_string())
    };
    let descr = field("descr").ok_or("npy header without descr")?;
    let shape: Vec<usize> = field("shape")
        .ok_or("npy header without shape")?
        .trim_matches(|c| c == '(' || c == ')')
        .split(',')
        .filter_map(|s| s.trim().parse().ok())
        .collect();
    Ok((descr, shape, &bytes[start + hlen..]))
}

/// A numpy unicode scalar (`<U…`, UTF-32LE) as a string.
fn npy_str(bytes: &[u8]) -> Result<String, Error> {
    let (descr, _, data) = npy(bytes)?;
    if !descr.starts_with("<U") {
        return Err(format!("expected a unicode scalar, got dtype {descr}").into());
    }
    Ok(data
        .chunks(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .take_while(|&c| c != 0)
        .filter_map(char::from_u32)
        .collect())
}

struct Frame {
    env: String,
    robot: String,
    control_mode: String,
    state: StateDict,
    rgb: Vec<u8>,
    size: (usize, usize),
}

fn load(path: &Path) -> Result<Frame, Error> {
    let pair = path
        .parent()
        .and_then(|p| p.file_name())
        .and_then(|n| n.to_str())
        .ok_or("no <env>__<robot> directory")?;
    let (env, robot) = pair
        .split_once("__")
        .ok_or_else(|| format!("directory {pair:?} is not <env>__<robot>"))?;
    let z = unzip(&std::fs::read(path)?)?;
    let get = |k: &str| {
        z.get(k)
            .ok_or_else(|| format!("{} lacks {k}", path.display()))
    };
    let state_json = npy_str(get("state_json.npy")?)?;
    let control_mode = npy_str(get("control_mode.npy")?)?;
    let (descr, shape, data) = npy(get("base_camera_rgb.npy")?)?;
    if descr != "|u1" || shape.len() != 3 || shape[2] != 3 {
        return Err(format!("base_camera_rgb: dtype {descr} shape {shape:?}").into());
    }
    let state = StateDict::from_json(&serde_json::from_str(&state_json)?)?;
    Ok(Frame {
        env: env.into(),
        robot: robot.into(),
        control_mode,
        state,
        rgb: data[..shape[0] * shape[1] * 3].to_vec(),
        size: (shape[1], shape[0]),
    })
}

fn mad(a: &[u8], b: &[u8]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (*x as f64 - *y as f64).abs())
        .sum::<f64>()
        / a.len() as f64
}

fn collect(p: &Path, out: &mut Vec<PathBuf>) {
    if p.is_dir() {
        if let Ok(rd) = std::fs::read_dir(p) {
            let mut v: Vec<_> = rd.flatten().map(|e| e.path()).collect();
            v.sort();
            for q in v {
                collect(&q, out);
            }
        }
    } else if p.extension().is_some_and(|e| e == "npz") {
        out.push(p.to_path_buf());
    }
}

fn main() -> Result<(), Error> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let save = match args.iter().position(|a| a == "--save") {
        Some(i) => {
            let d = args.get(i + 1).ok_or("--save needs a directory")?.clone();
            args.drain(i..i + 2);
            std::fs::create_dir_all(&d)?;
            Some(PathBuf::from(d))
        }
        None => None,
    };
    if args.is_empty() {
        args.push("/work/shared/reference/maniskill/images".into());
    }
    let mut files = Vec::new();
    for a in &args {
        collect(Path::new(a), &mut files);
    }
    let mut per_pair: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    for f in &files {
        let fr = load(f).map_err(|e| format!("{}: {e}", f.display()))?;
        let config = EnvConfig {
            robot: Some(fr.robot.clone()),
            control_mode: Some(fr.control_mode.clone()),
            obs_mode: ObsMode::Rgb,
            ..Default::default()
        };
        let mut env = make(&fr.env, config)?;
        env.reset(Some(0));
        env.set_state_dict(&fr.state)?;
        let img = env.image("base_camera").ok_or("no base_camera")?;
        let ours = img.rgb.ok_or("no rgb")?;
        if (img.width, img.height) != fr.size {
            return Err(format!(
                "size {:?} vs ManiSkill's {:?}",
                (img.width, img.height),
                fr.size
            )
            .into());
        }
        let d = mad(ours, &fr.rgb);
        println!("{:.2}\t{}", d, f.display());
        if let Some(dir) = &save {
            let (w, h) = fr.size;
            let mut side = vec![0u8; w * 2 * h * 3];
            for y in 0..h {
                side[y * w * 6..y * w * 6 + w * 3]
                    .copy_from_slice(&fr.rgb[y * w * 3..(y + 1) * w * 3]);
                side[y * w * 6 + w * 3..(y + 1) * w * 6]
                    .copy_from_slice(&ours[y * w * 3..(y + 1) * w * 3]);
            }
            let name = format!(
                "{}__{}.png",
                f.parent()
                    .and_then(|p| p.file_name())
                    .and_then(|n| n.to_str())
                    .unwrap_or("x"),
                f.file_stem().and_then(|n| n.to_str()).unwrap_or("x")
            );
            mjskill::record::image::write_png(&dir.join(name), &side, w * 2, h)?;
        }
        per_pair
            .entry(format!("{}__{}", fr.env, fr.robot))
            .or_default()
            .push(d);
    }
    let mut all = Vec::new();
    println!("pair\tframes\tmean_abs_rgb_diff");
    for (pair, v) in &per_pair {
        println!(
            "{pair}\t{}\t{:.2}",
            v.len(),
            v.iter().sum::<f64>() / v.len() as f64
        );
        all.extend(v);
    }
    if !all.is_empty() {
        println!(
            "all\t{}\t{:.2}",
            all.len(),
            all.iter().sum::<f64>() / all.len() as f64
        );
    }
    Ok(())
}
