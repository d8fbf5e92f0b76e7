//! mjskill's camera images against ManiSkill's, state by state (`mjskill compare-images`).
//!
//! A reference state is one `.npz` file of ManiSkill's rendering (the layout of the shared
//! reference images: per sensor camera `<cam>_rgb` H×W×3 u8, `<cam>_depth` H×W×1 i16
//! millimetres, `<cam>_segmentation` H×W×1 i16 ids; `state_json`, the state dict that was
//! rendered; `control_mode`, `seed`, `step`). Its directory is named `<env id>__<robot>`.
//! mjskill loads the state dict into an env of the same id, robot and control mode in the
//! `rgb+depth+segmentation` obs mode and scores each camera:
//!
//! * **segmentation**: the IoU of every id present in either image (background 0 included),
//!   their mean, and the pixel accuracy (share of pixels with equal ids);
//! * **depth**: the median absolute difference in millimetres over pixels where both images
//!   saw something (depth > 0);
//! * **rgb**: the mean absolute difference over all pixels and channels (0–255).
//!
//! [`panel`] draws the side-by-side picture: top row mjskill | ManiSkill | |difference| in
//! colour, bottom row the same for segmentation (ids in ManiSkill's own false colours;
//! mismatching pixels red).
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Serialize;

use super::npz::{read_npz, NpyData};
use crate::env::{make, Env, EnvError};
use crate::env::{CameraImage, EnvConfig, ObsMode, StateDict};

/// One camera of a reference state.
#[derive(Debug, Clone, PartialEq)]
pub struct RefCamera {
    /// Camera name (`base_camera`, `fetch_head`, ...).
    pub name: String,
    /// Width.
    pub width: usize,
    /// Height.
    pub height: usize,
    /// Colour, H×W×3.
    pub rgb: Vec<u8>,
    /// Depth in millimetres (0: nothing), H×W.
    pub depth_mm: Vec<i16>,
    /// Segmentation ids, H×W.
    pub segmentation: Vec<i16>,
}

/// One reference state: what ManiSkill rendered for a state dict.
#[derive(Debug, Clone)]
pub struct RefImageState {
    /// Env id.
    pub env_id: String,
    /// Robot uid.
    pub robot: String,
    /// The file's stem (`<source>_<control mode>_<seed>_<step>`).
    pub name: String,
    /// Control mode of the recording.
    pub control_mode: String,
    /// The state dict that was rendered.
    pub state: serde_json::Value,
    /// The episode's seed, from the file's stem (`<source>_<control mode>_<seed>_<step>`):
    /// a task whose shapes change every episode (PegInsertionSide-v1) is reset with it before
    /// the state dict, which holds poses but not shapes, is loaded.
    pub seed: Option<u64>,
    /// The cameras, sorted by name.
    pub cameras: Vec<RefCamera>,
}

/// Why a comparison could not run.
#[derive(Debug, thiserror::Error)]
pub enum CompareError {
    /// The archive could not be read.
    #[error(transparent)]
    Npz(#[from] super::npz::NpzError),
    /// The archive lacks something or holds something unexpected.
    #[error("{path}: {msg}")]
    Bad {
        /// The file.
        path: String,
        /// What is wrong.
        msg: String,
    },
    /// The env could not be made or the state not loaded.
    #[error("{what}: {source}")]
    Env {
        /// Which state.
        what: String,
        /// The env's error.
        source: EnvError,
    },
    /// A directory could not be listed or a panel not written.
    #[error("{0}")]
    Io(String),
}

/// `(env id, robot)` of a reference directory named `<env id>__<robot>`.
pub fn pair_of(dir: &Path) -> Option<(String, String)> {
    let name = dir.file_name()?.to_str()?;
    let (env, robot) = name.split_once("__")?;
    Some((env.to_string(), robot.to_string()))
}

impl RefImageState {
    /// Reads one reference state; the env and robot come from the parent directory's name.
    pub fn open(path: &Path) -> Result<RefImageState, CompareError> {
        let p = path.display().to_string();
        let bad = |msg: String| CompareError::Bad {
            path: p.clone(),
            msg,
        };
        let (env_id, robot) = path
            .parent()
            .and_then(pair_of)
            .ok_or_else(|| bad("the directory is not named <env id>__<robot>".into()))?;
        let arrays = read_npz(path)?;
        let text = |k: &str| {
            arrays
                .get(k)
                .and_then(|a| a.as_str())
                .map(str::to_string)
                .ok_or_else(|| bad(format!("no string {k:?}")))
        };
        let state: serde_json::Value = serde_json::from_str(&text("state_json")?)
            .map_err(|e| bad(format!("state_json is not JSON: {e}")))?;
        let control_mode = text("control_mode")?;
        let mut cameras = Vec::new();
        for (key, arr) in &arrays {
            let Some(cam) = key.strip_suffix("_segmentation") else {
                continue;
            };
            let get = |suffix: &str| {
                arrays
                    .get(&format!("{cam}_{suffix}"))
                    .ok_or_else(|| bad(format!("camera {cam} has no {suffix}")))
            };
            let (rgb, depth) = (get("rgb")?, get("depth")?);
            let (h, w) = match arr.shape[..] {
                [h, w, 1] => (h, w),
                _ => return Err(bad(format!("{key} has shape {:?}, not H×W×1", arr.shape))),
            };
            let (NpyData::U8(rgb_v), NpyData::I16(depth_v), NpyData::I16(seg_v)) =
                (&rgb.data, &depth.data, &arr.data)
            else {
                return Err(bad(format!(
                    "camera {cam}: expected rgb u8, depth i16, segmentation i16"
                )));
            };
            if rgb.shape != [h, w, 3] || depth.shape != [h, w, 1] {
                return Err(bad(format!("camera {cam}: image shapes differ")));
            }
            cameras.push(RefCamera {
                name: cam.to_string(),
                width: w,
                height: h,
                rgb: rgb_v.clone(),
                depth_mm: depth_v.clone(),
                segmentation: seg_v.clone(),
            });
        }
        if cameras.is_empty() {
            return Err(bad("no <camera>_segmentation arrays".into()));
        }
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let seed = name.rsplit('_').nth(1).and_then(|s| s.parse().ok());
        Ok(RefImageState {
            env_id,
            robot,
            name,
            seed,
            control_mode,
            state,
            cameras,
        })
    }
}

/// The scores of one camera of one state.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CameraScore {
    /// Camera name.
    pub camera: String,
    /// Mean IoU over the ids present in either image (background included).
    pub seg_miou: f64,
    /// Share of pixels whose ids agree.
    pub seg_pixel_accuracy: f64,
    /// `(id, IoU)` of every id present in either image.
    pub seg_iou: Vec<(i16, f64)>,
    /// Median absolute depth difference (mm) over pixels both images saw.
    pub depth_median_mm: f64,
    /// Share of pixels where exactly one image saw something.
    pub depth_coverage_mismatch: f64,
    /// Mean absolute colour difference (0–255).
    pub rgb_mae: f64,
}

/// Scores mjskill's image `mj` of a camera against ManiSkill's `r`. `None` when `mj` lacks
/// a texture or the sizes differ.
pub fn score(mj: &CameraImage, r: &RefCamera) -> Option<CameraScore> {
    if (mj.width, mj.height) != (r.width, r.height) {
        return None;
    }
    let (rgb, depth, seg) = (mj.rgb?, mj.depth_mm?, mj.segmentation?);
    let n = r.width * r.height;
    // IoU per id: intersection and union counts.
    let mut counts: BTreeMap<i16, (usize, usize, usize)> = BTreeMap::new();
    let mut equal = 0usize;
    for (&a, &b) in seg.iter().zip(&r.segmentation) {
        if a == b {
            equal += 1;
            counts.entry(a).or_default().0 += 1;
        }
        counts.entry(a).or_default().1 += 1;
        counts.entry(b).or_default().2 += 1;
    }
    let seg_iou: Vec<(i16, f64)> = counts
        .iter()
        .map(|(&id, &(i, a, b))| (id, i as f64 / (a + b - i) as f64))
        .collect();
    let seg_miou = seg_iou.iter().map(|(_, v)| v).sum::<f64>() / seg_iou.len().max(1) as f64;
    let mut diffs: Vec<i32> = Vec::with_capacity(n);
    let mut mismatch = 0usize;
    for (&a, &b) in depth.iter().zip(&r.depth_mm) {
        match (a > 0, b > 0) {
            (true, true) => diffs.push((a as i32 - b as i32).abs()),
            (false, false) => {}
            _ => mismatch += 1,
        }
    }
    let depth_median_mm = median(&mut diffs);
    let rgb_mae = rgb
        .iter()
        .zip(&r.rgb)
        .map(|(&a, &b)| (a as i32 - b as i32).unsigned_abs() as u64)
        .sum::<u64>() as f64
        / (3 * n).max(1) as f64;
    Some(CameraScore {
        camera: r.name.clone(),
        seg_miou,
        seg_pixel_accuracy: equal as f64 / n.max(1) as f64,
        seg_iou,
        depth_median_mm,
        depth_coverage_mismatch: mismatch as f64 / n.max(1) as f64,
        rgb_mae,
    })
}

/// The median of `v` (NaN when empty); sorts `v`.
fn median(v: &mut [i32]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_unstable();
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m] as f64
    } else {
        (v[m - 1] as f64 + v[m] as f64) / 2.0
    }
}

/// ManiSkill's false colour of a segmentation id (`camera_observations_to_images`:
/// `id × (11, 61, 127)` as bytes).
pub fn seg_colour(id: i16) -> [u8; 3] {
    let id = id as i64;
    [(id * 11) as u8, (id * 61) as u8, (id * 127) as u8]
}

/// The side-by-side panel of one camera (see the module docs): 3 W × 2 H pixels, RGB.
/// `None` when `mj` lacks colour or segmentation or the sizes differ.
pub fn panel(mj: &CameraImage, r: &RefCamera) -> Option<(Vec<u8>, usize, usize)> {
    if (mj.width, mj.height) != (r.width, r.height) {
        return None;
    }
    let (rgb, seg) = (mj.rgb?, mj.segmentation?);
    let (w, h) = (r.width, r.height);
    let (pw, ph) = (3 * w, 2 * h);
    let mut out = vec![0u8; pw * ph * 3];
    let mut put = |col: usize, row: usize, x: usize, y: usize, c: [u8; 3]| {
        let i = 3 * ((row * h + y) * pw + col * w + x);
        out[i..i + 3].copy_from_slice(&c);
    };
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let a = [rgb[3 * i], rgb[3 * i + 1], rgb[3 * i + 2]];
            let b = [r.rgb[3 * i], r.rgb[3 * i + 1], r.rgb[3 * i + 2]];
            put(0, 0, x, y, a);
            put(1, 0, x, y, b);
            let d = |k: usize| (2 * (a[k] as i32 - b[k] as i32).unsigned_abs()).min(255) as u8;
            put(2, 0, x, y, [d(0), d(1), d(2)]);
            let (sa, sb) = (seg[i], r.segmentation[i]);
            put(0, 1, x, y, seg_colour(sa));
            put(1, 1, x, y, seg_colour(sb));
            let m = if sa == sb {
                seg_colour(sb).map(|c| c / 3)
            } else {
                [255, 0, 0]
            };
            put(2, 1, x, y, m);
        }
    }
    Some((out, pw, ph))
}

/// The scores of one state.
#[derive(Debug, Clone, Serialize)]
pub struct StateScore {
    /// `<env id>__<robot>`.
    pub pair: String,
    /// The file's stem.
    pub state: String,
    /// Per camera.
    pub cameras: Vec<CameraScore>,
}

/// Compares reference states with mjskill's images; keeps one env per (pair, control mode).
#[derive(Debug, Default)]
pub struct Comparer {
    envs: BTreeMap<(String, String, String), Env>,
    /// Where to write the panels (`<pair>__<state>.png`); none when unset.
    pub panels: Option<PathBuf>,
}

impl Comparer {
    /// A comparer writing its panels to `panels` (none if `None`).
    pub fn new(panels: Option<PathBuf>) -> Comparer {
        Comparer {
            envs: BTreeMap::new(),
            panels,
        }
    }

    /// Loads `s`'s state dict into an env of its id, robot and control mode (obs mode
    /// `rgb+depth+segmentation`), renders, scores every camera and writes the panel.
    pub fn compare(&mut self, s: &RefImageState) -> Result<StateScore, CompareError> {
        let pair = format!("{}__{}", s.env_id, s.robot);
        let what = format!("{pair}/{}", s.name);
        let env_err = |source| CompareError::Env {
            what: what.clone(),
            source,
        };
        let key = (s.env_id.clone(), s.robot.clone(), s.control_mode.clone());
        if !self.envs.contains_key(&key) {
            let cfg = EnvConfig {
                robot: Some(s.robot.clone()),
                control_mode: Some(s.control_mode.clone()),
                obs_mode: ObsMode::RgbDepthSegmentation,
                ..EnvConfig::default()
            };
            let env = make(&s.env_id, cfg).map_err(env_err)?;
            self.envs.insert(key.clone(), env);
        }
        let env = self.envs.get_mut(&key).expect("inserted above");
        if env.reconfigures() {
            let seed = s.seed.ok_or_else(|| CompareError::Bad {
                path: what.clone(),
                msg: "the file's name holds no seed, which this task's shapes need".into(),
            })?;
            env.reset(Some(seed));
        }
        let sd = StateDict::from_json(&s.state).map_err(|e| CompareError::Bad {
            path: what.clone(),
            msg: format!("state_json: {e}"),
        })?;
        env.set_state_dict(&sd).map_err(env_err)?;
        let mut cameras = Vec::new();
        let mut panels = Vec::new();
        for r in &s.cameras {
            let img = env.image(&r.name).ok_or_else(|| CompareError::Bad {
                path: what.clone(),
                msg: format!(
                    "mjskill has no sensor camera {:?} (it has {})",
                    r.name,
                    env.sensor_names().join(", ")
                ),
            })?;
            let sc = score(&img, r).ok_or_else(|| CompareError::Bad {
                path: what.clone(),
                msg: format!(
                    "camera {}: mjskill renders {}x{}, ManiSkill {}x{}",
                    r.name, img.width, img.height, r.width, r.height
                ),
            })?;
            cameras.push(sc);
            if self.panels.is_some() {
                panels.extend(panel(&img, r));
            }
        }
        if let Some(dir) = &self.panels {
            // Cameras stacked vertically, padded to the widest.
            let pw = panels.iter().map(|p| p.1).max().unwrap_or(0);
            let ph: usize = panels.iter().map(|p| p.2).sum();
            let mut out = vec![0u8; pw * ph * 3];
            let mut y0 = 0;
            for (img, w, h) in &panels {
                for y in 0..*h {
                    let dst = 3 * ((y0 + y) * pw);
                    out[dst..dst + 3 * w].copy_from_slice(&img[3 * y * w..3 * (y + 1) * w]);
                }
                y0 += h;
            }
            let path = dir.join(format!("{pair}__{}.png", s.name));
            crate::record::image::write_png(&path, &out, pw, ph)
                .map_err(|e| CompareError::Io(e.to_string()))?;
        }
        Ok(StateScore {
            pair,
            state: s.name.clone(),
            cameras,
        })
    }
}

/// The reference states under `root`: every `<env>__<robot>/*.npz`, sorted; `pairs` (if not
/// empty) keeps only those directories.
pub fn list_states(root: &Path, pairs: &[String]) -> Result<Vec<PathBuf>, CompareError> {
    let io = |p: &Path, e: std::io::Error| CompareError::Io(format!("{}: {e}", p.display()));
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(root)
        .map_err(|e| io(root, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir() && pair_of(p).is_some())
        .collect();
    dirs.sort();
    let names: Vec<String> = dirs
        .iter()
        .filter_map(|d| d.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
    for p in pairs {
        if !names.contains(p) {
            return Err(CompareError::Io(format!(
                "no reference directory {p:?} under {}; valid: {}",
                root.display(),
                names.join(", ")
            )));
        }
    }
    let mut out = Vec::new();
    for d in dirs {
        let name = d
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if !pairs.is_empty() && !pairs.contains(&name) {
            continue;
        }
        let mut files: Vec<PathBuf> = std::fs::read_dir(&d)
            .map_err(|e| io(&d, e))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "npz"))
            .collect();
        files.sort();
        out.extend(files);
    }
    Ok(out)
}

/// Means over a set of state scores (every camera of every state counts once).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Summary {
    /// States.
    pub states: usize,
    /// Camera images.
    pub images: usize,
    /// Mean of the per-image mean IoU.
    pub seg_miou: f64,
    /// Lowest per-image mean IoU.
    pub seg_miou_min: f64,
    /// Mean pixel accuracy.
    pub seg_pixel_accuracy: f64,
    /// Median over images of the per-image median depth error (mm).
    pub depth_median_mm: f64,
    /// Largest per-image median depth error (mm).
    pub depth_median_mm_max: f64,
    /// Mean of the per-image mean absolute colour difference.
    pub rgb_mae: f64,
}

impl Summary {
    /// Summarises `scores`.
    pub fn of<'a>(scores: impl IntoIterator<Item = &'a StateScore>) -> Summary {
        let mut states = 0;
        let mut cams: Vec<&CameraScore> = Vec::new();
        for s in scores {
            states += 1;
            cams.extend(&s.cameras);
        }
        let n = cams.len().max(1) as f64;
        let mean = |f: &dyn Fn(&CameraScore) -> f64| cams.iter().map(|c| f(c)).sum::<f64>() / n;
        let mut depth: Vec<f64> = cams
            .iter()
            .map(|c| c.depth_median_mm)
            .filter(|d| d.is_finite())
            .collect();
        depth.sort_by(f64::total_cmp);
        let depth_median_mm = match depth.len() {
            0 => f64::NAN,
            k if k % 2 == 1 => depth[k / 2],
            k => (depth[k / 2 - 1] + depth[k / 2]) / 2.0,
        };
        Summary {
            states,
            images: cams.len(),
            seg_miou: mean(&|c| c.seg_miou),
            seg_miou_min: cams
                .iter()
                .map(|c| c.seg_miou)
                .fold(f64::INFINITY, f64::min),
            seg_pixel_accuracy: mean(&|c| c.seg_pixel_accuracy),
            depth_median_mm,
            depth_median_mm_max: depth.last().copied().unwrap_or(f64::NAN),
            rgb_mae: mean(&|c| c.rgb_mae),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(seg: Vec<i16>, depth: Vec<i16>, rgb: Vec<u8>) -> RefCamera {
        RefCamera {
            name: "c".into(),
            width: 2,
            height: 2,
            rgb,
            depth_mm: depth,
            segmentation: seg,
        }
    }

    #[test]
    fn scores_count_iou_depth_and_colour() {
        let r = cam(vec![0, 1, 1, 2], vec![0, 500, 510, 700], vec![10; 12]);
        let (seg, depth, rgb) = ([0i16, 1, 2, 2], [0i16, 502, 0, 703], [13u8; 12]);
        let img = CameraImage {
            name: "c",
            width: 2,
            height: 2,
            rgb: Some(&rgb),
            depth: None,
            depth_mm: Some(&depth),
            segmentation: Some(&seg),
        };
        let s = score(&img, &r).unwrap();
        // id 0: 1/1; id 1: 1/2; id 2: 1/2.
        assert_eq!(s.seg_iou, [(0, 1.0), (1, 0.5), (2, 0.5)]);
        assert!((s.seg_miou - 2.0 / 3.0).abs() < 1e-12);
        assert_eq!(s.seg_pixel_accuracy, 0.75);
        // Both saw: pixels 1 (2 mm) and 3 (3 mm); pixel 2 only ManiSkill.
        assert_eq!(s.depth_median_mm, 2.5);
        assert_eq!(s.depth_coverage_mismatch, 0.25);
        assert_eq!(s.rgb_mae, 3.0);
        let (p, w, h) = panel(&img, &r).unwrap();
        assert_eq!((w, h, p.len()), (6, 4, 6 * 4 * 3));
        // Bottom-right block, pixel (1, 0): ids 1 vs 1 agree, pixel (0, 1): 2 vs 1 is red.
        let at = |x: usize, y: usize| &p[3 * (y * w + x)..3 * (y * w + x) + 3];
        assert_eq!(at(4 + 1, 2), seg_colour(1).map(|c| c / 3));
        assert_eq!(at(4, 3), [255, 0, 0]);
    }

    #[test]
    fn pairs_come_from_directory_names() {
        assert_eq!(
            pair_of(Path::new("/x/PickCube-v1__xarm6_robotiq")),
            Some(("PickCube-v1".into(), "xarm6_robotiq".into()))
        );
        assert_eq!(pair_of(Path::new("/x/images")), None);
    }
}
