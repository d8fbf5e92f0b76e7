//! Camera images of an env: the task's sensor camera and the robot's mounted cameras
//! (observations in the `rgb`, `depth` and `rgbd` obs modes) and the task's human render
//! camera ([`super::Env::render`]), drawn by one [`Renderer`] into buffers that are reused
//! every step.
use std::sync::Arc;

use crate::mjcf::{GROUP_COLLISION, GROUP_HIDDEN};
use crate::mujoco::render::{RenderError, RenderOptions, Renderer};
use crate::mujoco::{Data, Model, ObjType};
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
    /// Colour, H×W×3 bytes, top row first (None unless the obs mode includes rgb).
    pub rgb: Option<&'a [u8]>,
    /// Depth in metres along the optical axis, H×W×1 (None unless the obs mode includes depth).
    pub depth: Option<&'a [f32]>,
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

/// A robot-mounted camera with its image buffers.
#[derive(Debug)]
pub(crate) struct Mounted {
    pub(crate) name: &'static str,
    pub(crate) size: (usize, usize),
    id: usize,
    pub(crate) rgb: Vec<u8>,
    pub(crate) depth: Vec<f32>,
}

/// The renderer of an env and its image buffers.
pub(crate) struct Vision {
    renderer: Renderer,
    sensor: Cam,
    human: Cam,
    pub(crate) rgb_on: bool,
    pub(crate) depth_on: bool,
    pub(crate) sensor_rgb: Vec<u8>,
    pub(crate) sensor_depth: Vec<f32>,
    pub(crate) mounted: Vec<Mounted>,
    pub(crate) human_rgb: Vec<u8>,
    human_fresh: bool,
}

impl std::fmt::Debug for Vision {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Without the image buffers (hundreds of kilobytes).
        f.debug_struct("Vision")
            .field("renderer", &self.renderer)
            .field("sensor", &self.sensor)
            .field("human", &self.human)
            .field(
                "mounted",
                &self.mounted.iter().map(|m| m.name).collect::<Vec<_>>(),
            )
            .field("rgb_on", &self.rgb_on)
            .field("depth_on", &self.depth_on)
            .finish_non_exhaustive()
    }
}

impl Vision {
    /// A renderer for the task's two cameras and the robot's mounted cameras; `rgb`/`depth`
    /// select the sensor textures (of the task's sensor camera and the mounted ones).
    pub(crate) fn new(
        model: &Arc<Model>,
        cams: (CameraDef, CameraDef),
        mounted: &[MountedCamera],
        rgb: bool,
        depth: bool,
        options: RenderOptions,
    ) -> Result<Vision, RenderError> {
        let resolve = |def: CameraDef| -> Result<Cam, RenderError> {
            let id = model
                .require_id(ObjType::Camera, def.name)
                .map_err(|e| RenderError::Invalid(e.to_string()))?;
            Ok(Cam { def, id })
        };
        let (sensor, human) = (resolve(cams.0)?, resolve(cams.1)?);
        let mounted = mounted
            .iter()
            .map(|c| {
                let id = model
                    .require_id(ObjType::Camera, c.name)
                    .map_err(|e| RenderError::Invalid(e.to_string()))?;
                let (w, h) = c.size;
                Ok(Mounted {
                    name: c.name,
                    size: c.size,
                    id,
                    rgb: vec![0; if rgb { w * h * 3 } else { 0 }],
                    depth: vec![0.0; if depth { w * h } else { 0 }],
                })
            })
            .collect::<Result<Vec<_>, RenderError>>()?;
        let sizes = || {
            [sensor.def.size, human.def.size]
                .into_iter()
                .chain(mounted.iter().map(|m| m.size))
        };
        let w = sizes().map(|s| s.0).max().unwrap_or(1);
        let h = sizes().map(|s| s.1).max().unwrap_or(1);
        let renderer = Renderer::new(model.clone(), (w, h), options)?;
        let (sw, sh) = sensor.def.size;
        let (hw, hh) = human.def.size;
        Ok(Vision {
            renderer,
            rgb_on: rgb,
            depth_on: depth,
            sensor_rgb: vec![0; if rgb { sw * sh * 3 } else { 0 }],
            sensor_depth: vec![0.0; if depth { sw * sh } else { 0 }],
            mounted,
            human_rgb: vec![0; hw * hh * 3],
            sensor,
            human,
            human_fresh: false,
        })
    }

    /// Marks the human frame stale (the state changed).
    pub(crate) fn invalidate(&mut self) {
        self.human_fresh = false;
    }

    /// Renders the sensor camera and the mounted cameras into the observation buffers.
    pub(crate) fn render_sensor(&mut self, data: &mut Data) -> Result<(), RenderError> {
        self.human_fresh = false;
        if !(self.rgb_on || self.depth_on) {
            return Ok(());
        }
        let (rgb_on, depth_on) = (self.rgb_on, self.depth_on);
        self.renderer.render(
            data,
            self.sensor.id,
            self.sensor.def.size,
            sensor_groups(),
            rgb_on.then_some(self.sensor_rgb.as_mut_slice()),
            depth_on.then_some(self.sensor_depth.as_mut_slice()),
        )?;
        for m in self.mounted.iter_mut() {
            self.renderer.render(
                data,
                m.id,
                m.size,
                sensor_groups(),
                rgb_on.then_some(m.rgb.as_mut_slice()),
                depth_on.then_some(m.depth.as_mut_slice()),
            )?;
        }
        Ok(())
    }

    /// Renders the human camera (once per state) and returns its RGB frame.
    pub(crate) fn render_human(&mut self, data: &mut Data) -> Result<&[u8], RenderError> {
        if !self.human_fresh {
            self.renderer.render(
                data,
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
    /// then the mounted cameras); `None` past the last camera. No lookups, no allocation.
    pub(crate) fn sensor_image(&self, k: usize) -> Option<CameraImage<'_>> {
        let (name, size, rgb, depth) = if k == 0 {
            let d = &self.sensor.def;
            (d.name, d.size, &self.sensor_rgb, &self.sensor_depth)
        } else {
            let m = self.mounted.get(k - 1)?;
            (m.name, m.size, &m.rgb, &m.depth)
        };
        Some(CameraImage {
            name,
            width: size.0,
            height: size.1,
            rgb: self.rgb_on.then_some(rgb.as_slice()),
            depth: self.depth_on.then_some(depth.as_slice()),
        })
    }

    /// The sensor camera.
    pub(crate) fn sensor_def(&self) -> &CameraDef {
        &self.sensor.def
    }
}
