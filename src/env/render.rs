//! Camera images of an env: the task's sensor camera and the robot's mounted cameras
//! (observations in the `rgb`, `depth` and `rgbd` obs modes) and the task's human render
//! camera ([`super::Env::render`]), drawn by one [`Renderer`] into buffers that are reused
//! every step.
use std::sync::Arc;

use super::config::Textures;
use crate::mjcf::{GROUP_COLLISION, GROUP_HIDDEN};
use crate::mujoco::render::{RenderError, RenderOptions, Renderer, Segmentation};
use crate::mujoco::{CameraId, Data, Model, ObjType};
use crate::robots::MountedCamera;
use crate::tasks::CameraDef;

/// One camera image, borrowed from the env (rewritten in place by every step).
#[derive(Debug, Clone, Copy)]
pub struct CameraImage<'a> {
    /// Camera name.
    pub name: &'static str,
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Colour, H×W×3 bytes, top row first (None unless the obs mode renders rgb).
    pub rgb: Option<&'a [u8]>,
    /// Depth in metres along the optical axis, H×W×1 (None unless the obs mode renders depth).
    pub depth: Option<&'a [f32]>,
    /// Depth as ManiSkill gives it: whole millimetres (truncated), int16, 0 where nothing was
    /// drawn, at most 32767 (None unless the obs mode renders depth).
    pub depth_mm: Option<&'a [i16]>,
    /// ManiSkill's segmentation ids (link / actor; 0 = background), H×W×1 (None unless the
    /// obs mode renders segmentation).
    pub segmentation: Option<&'a [i16]>,
}

/// ManiSkill's fused point cloud of all sensor cameras (the `pointcloud` obs mode): every
/// pixel of every camera, cameras in [`super::Env::sensor_names`] order, rows top first.
#[derive(Debug, Clone, Copy)]
pub struct PointCloud<'a> {
    /// Number of points (the sum of the cameras' W·H).
    pub len: usize,
    /// World-frame `[x, y, z, w]` per point: w = 1 where an object was seen; (0, 0, 0, 0)
    /// for the background (segmentation id 0).
    pub xyzw: &'a [f32],
    /// Colour per point, 3 bytes.
    pub rgb: &'a [u8],
    /// Segmentation id per point.
    pub segmentation: &'a [i16],
}

/// ManiSkill's int16 millimetre depth of a depth in metres: truncated toward zero like
/// ManiSkill's `(position * 1000).to(int16)`, 0 for the far plane (nothing drawn), clamped
/// to 32767.
pub fn depth_to_mm(d: f32, far: f32) -> i16 {
    // NaN (never produced) and the far plane read as nothing seen.
    if d.is_nan() || d >= far * 0.999_99 {
        return 0;
    }
    (d * 1000.0).clamp(0.0, i16::MAX as f32) as i16
}

/// Geom groups a sensor camera draws: everything but hidden markers and collision shapes.
pub(crate) fn sensor_groups() -> [bool; 6] {
    let mut g = [true; 6];
    g[GROUP_HIDDEN as usize] = false;
    g[GROUP_COLLISION as usize] = false;
    g
}

/// Geom groups the human camera draws: hidden markers too (ManiSkill shows `_hidden_objects`
/// in human renders), collision shapes not.
pub(crate) fn human_groups() -> [bool; 6] {
    let mut g = [true; 6];
    g[GROUP_COLLISION as usize] = false;
    g
}

#[derive(Debug)]
struct Cam {
    def: CameraDef,
    id: usize,
}

/// A sensor camera: the task's sensor camera or a robot-mounted one.
#[derive(Debug)]
struct SensorCam {
    name: &'static str,
    size: (usize, usize),
    id: usize,
    /// First pixel of the camera in the concatenated buffers.
    at: usize,
    /// Focal length in pixels (square pixels, from the vertical field of view).
    focal: f64,
}

/// The renderer of an env and its image buffers. The sensor cameras' images are
/// concatenated (camera after camera) per texture, so that the point cloud's colour and
/// segmentation are the images themselves.
pub(crate) struct Vision {
    renderer: Renderer,
    /// The render model's state: the physics state copied in before each frame
    /// ([`Vision::sync`]).
    data: Data,
    cams: Vec<SensorCam>,
    human: Cam,
    /// Textures rendered for the sensor cameras.
    pub(crate) tex: Textures,
    point_cloud: bool,
    /// Pixels of all sensor cameras.
    px: usize,
    /// Label (segmentation id) of every model geom.
    labels: Vec<i16>,
    rgb: Vec<u8>,
    depth: Vec<f32>,
    depth_mm: Vec<i16>,
    seg: Vec<i16>,
    xyzw: Vec<f32>,
    far: f32,
    pub(crate) human_rgb: Vec<u8>,
    human_fresh: bool,
}

impl std::fmt::Debug for Vision {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Without the image buffers (hundreds of kilobytes).
        f.debug_struct("Vision")
            .field("renderer", &self.renderer)
            .field("cams", &self.cams)
            .field("human", &self.human)
            .field("tex", &self.tex)
            .field("point_cloud", &self.point_cloud)
            .finish_non_exhaustive()
    }
}

fn sized<T: Clone + Default>(on: bool, n: usize) -> Vec<T> {
    vec![T::default(); if on { n } else { 0 }]
}

impl Vision {
    /// A renderer for the task's two cameras and the robot's mounted cameras; `tex` selects
    /// the sensor textures (of the task's sensor camera and the mounted ones), `point_cloud`
    /// adds the fused point cloud (which needs all three). `model` is the render model (every
    /// geom; its bodies, joints and cameras are the physics model's) and `labels` the
    /// segmentation id of each of its geoms.
    pub(crate) fn new(
        model: &Arc<Model>,
        cams: (CameraDef, CameraDef),
        mounted: &[MountedCamera],
        tex: Textures,
        point_cloud: bool,
        labels: Vec<i16>,
        options: RenderOptions,
    ) -> Result<Vision, RenderError> {
        let resolve = |name: &str| -> Result<usize, RenderError> {
            model
                .require_id(ObjType::Camera, name)
                .map_err(|e| RenderError::Invalid(e.to_string()))
        };
        let human = Cam {
            id: resolve(cams.1.name)?,
            def: cams.1,
        };
        let mut px = 0;
        let mut sensors = Vec::with_capacity(1 + mounted.len());
        for (name, size) in std::iter::once((cams.0.name, cams.0.size))
            .chain(mounted.iter().map(|c| (c.name, c.size)))
        {
            let id = resolve(name)?;
            let fovy = model.cam_fovy()[id].to_radians();
            sensors.push(SensorCam {
                name,
                size,
                id,
                at: px,
                focal: 0.5 * size.1 as f64 / (0.5 * fovy).tan(),
            });
            px += size.0 * size.1;
        }
        let sizes = || {
            [human.def.size]
                .into_iter()
                .chain(sensors.iter().map(|c| c.size))
        };
        let w = sizes().map(|s| s.0).max().unwrap_or(1);
        let h = sizes().map(|s| s.1).max().unwrap_or(1);
        let renderer = Renderer::new(model.clone(), (w, h), options)?;
        let data = Data::new(model.clone()).map_err(|e| RenderError::Invalid(e.to_string()))?;
        let (hw, hh) = human.def.size;
        let tex = if point_cloud {
            Textures {
                rgb: true,
                depth: true,
                segmentation: true,
            }
        } else {
            tex
        };
        Ok(Vision {
            renderer,
            data,
            cams: sensors,
            human,
            tex,
            point_cloud,
            px,
            labels,
            rgb: sized(tex.rgb, px * 3),
            depth: sized(tex.depth, px),
            depth_mm: sized(tex.depth, px),
            seg: sized(tex.segmentation, px),
            xyzw: sized(point_cloud, px * 4),
            far: options.clip.1 as f32,
            human_rgb: vec![0; hw * hh * 3],
            human_fresh: false,
        })
    }

    /// The render model (every geom).
    pub(crate) fn model(&self) -> &Arc<Model> {
        self.data.model()
    }

    /// The render model's state (as of the last frame).
    pub(crate) fn data(&self) -> &Data {
        &self.data
    }

    /// The segmentation id of every geom of the render model.
    pub(crate) fn labels(&self) -> &[i16] {
        &self.labels
    }

    /// Marks the human frame stale (the state changed).
    pub(crate) fn invalidate(&mut self) {
        self.human_fresh = false;
    }

    /// Copies the physics state (`physics`, of the physics model) into the render model's
    /// state: joint positions, mocap poses and time, then the poses of bodies, geoms, cameras
    /// and lights. No allocation.
    fn sync(&mut self, physics: &Data) {
        self.data.qpos_mut().copy_from_slice(physics.qpos());
        self.data
            .mocap_pos_mut()
            .copy_from_slice(physics.mocap_pos());
        self.data
            .mocap_quat_mut()
            .copy_from_slice(physics.mocap_quat());
        self.data.set_time(physics.time());
        self.data.update_kinematics();
    }

    /// Renders the sensor cameras of the physics state `physics` into the observation
    /// buffers (and the point cloud). Allocates nothing after the first call.
    pub(crate) fn render_sensor(&mut self, physics: &Data) -> Result<(), RenderError> {
        self.human_fresh = false;
        if !self.tex.any() {
            return Ok(());
        }
        self.sync(physics);
        let data = &mut self.data;
        let t = self.tex;
        for c in &self.cams {
            let (w, h) = c.size;
            let r = c.at..c.at + w * h;
            let seg = t.segmentation.then(|| Segmentation {
                labels: &self.labels,
                out: &mut self.seg[r.clone()],
            });
            self.renderer.render_frame(
                data,
                c.id,
                c.size,
                sensor_groups(),
                t.rgb.then(|| &mut self.rgb[3 * r.start..3 * r.end]),
                t.depth.then(|| &mut self.depth[r.clone()]),
                seg,
            )?;
            if t.depth {
                for (mm, d) in self.depth_mm[r.clone()].iter_mut().zip(&self.depth[r]) {
                    *mm = depth_to_mm(*d, self.far);
                }
            }
            if self.point_cloud {
                fuse_points(c, data, &self.depth, &self.seg, &mut self.xyzw);
            }
        }
        Ok(())
    }

    /// Renders the human camera of the physics state `physics` (once per state) and returns
    /// its RGB frame.
    pub(crate) fn render_human(&mut self, physics: &Data) -> Result<&[u8], RenderError> {
        if !self.human_fresh {
            self.sync(physics);
            self.renderer.render(
                &mut self.data,
                self.human.id,
                self.human.def.size,
                human_groups(),
                Some(&mut self.human_rgb),
                None,
            )?;
            self.human_fresh = true;
        }
        Ok(&self.human_rgb)
    }

    /// Sensor image `k` in [`super::Env::sensor_names`] order (0: the task's sensor camera,
    /// then the mounted cameras); `None` past the last camera or when no texture is rendered.
    /// No lookups, no allocation.
    pub(crate) fn sensor_image(&self, k: usize) -> Option<CameraImage<'_>> {
        let c = self.cams.get(k)?;
        if !self.tex.any() {
            return None;
        }
        let (w, h) = c.size;
        let r = c.at..c.at + w * h;
        let t = self.tex;
        Some(CameraImage {
            name: c.name,
            width: w,
            height: h,
            rgb: t.rgb.then(|| &self.rgb[3 * r.start..3 * r.end]),
            depth: t.depth.then(|| &self.depth[r.clone()]),
            depth_mm: t.depth.then(|| &self.depth_mm[r.clone()]),
            segmentation: t.segmentation.then(|| &self.seg[r]),
        })
    }

    /// The fused point cloud (`pointcloud` obs mode only).
    pub(crate) fn point_cloud(&self) -> Option<PointCloud<'_>> {
        self.point_cloud.then(|| PointCloud {
            len: self.px,
            xyzw: &self.xyzw,
            rgb: &self.rgb,
            segmentation: &self.seg,
        })
    }

    /// The concatenated buffers of all sensor cameras: colour, depth (metres), segmentation,
    /// point cloud (each empty unless rendered).
    pub(crate) fn buffers(&self) -> (&[u8], &[f32], &[i16], &[f32]) {
        (&self.rgb, &self.depth, &self.seg, &self.xyzw)
    }

    /// Number of sensor cameras.
    pub(crate) fn sensor_count(&self) -> usize {
        self.cams.len()
    }
}

/// Writes camera `c`'s points (world frame, ManiSkill's `xyzw`) from its depth and
/// segmentation into `xyzw` (indexed like the concatenated images).
fn fuse_points(c: &SensorCam, data: &Data, depth: &[f32], seg: &[i16], xyzw: &mut [f32]) {
    let (w, h) = c.size;
    let cam = CameraId::from_index(c.id);
    let p = data.camera_pos(cam);
    // Row-major; columns are the camera's right, up and backward axes (OpenGL camera frame).
    let m = data.camera_mat(cam);
    let (cx, cy, f) = (0.5 * w as f64, 0.5 * h as f64, c.focal);
    for v in 0..h {
        let y = (cy - (v as f64 + 0.5)) / f;
        for u in 0..w {
            let i = c.at + v * w + u;
            let out = &mut xyzw[4 * i..4 * i + 4];
            if seg[i] == 0 {
                out.fill(0.0);
                continue;
            }
            let d = depth[i] as f64;
            let x = (u as f64 + 0.5 - cx) / f;
            // Camera frame (x right, y up, z backward): (x·d, y·d, −d).
            let q = [x * d, y * d, -d];
            for k in 0..3 {
                out[k] =
                    (m[3 * k] * q[0] + m[3 * k + 1] * q[1] + m[3 * k + 2] * q[2] + p[k]) as f32;
            }
            out[3] = 1.0;
        }
    }
}
