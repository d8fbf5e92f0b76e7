//! Camera images of an env: the sensor images of the visual obs modes and the human render
//! (the renderer itself is `render.rs`).
use super::render::{self, CameraImage};
use super::{Env, EnvError};

impl Env {
    /// The sensor camera's colour image of the current state (H×W×3 bytes, top row first),
    /// rewritten in place by every step; `None` unless the obs mode is `rgb` or `rgbd`.
    pub fn sensor_rgb(&self) -> Option<&[u8]> {
        self.vision
            .as_ref()
            .filter(|v| v.rgb_on)
            .map(|v| v.sensor_rgb.as_slice())
    }

    /// The sensor camera's depth image (H×W×1 metres along the optical axis); `None` unless
    /// the obs mode is `depth` or `rgbd`.
    pub fn sensor_depth(&self) -> Option<&[f32]> {
        self.vision
            .as_ref()
            .filter(|v| v.depth_on)
            .map(|v| v.sensor_depth.as_slice())
    }

    /// A sensor camera's images by name (ManiSkill's `obs["sensor_data"][name]`): the task's
    /// `env.image("base_camera")` or a robot-mounted camera (Fetch's `"fetch_head"`,
    /// `"fetch_hand"`); `None` for an unknown name or a non-visual obs mode.
    pub fn image(&self, camera: &str) -> Option<CameraImage<'_>> {
        let v = self.vision.as_ref()?;
        if !(v.rgb_on || v.depth_on) {
            return None;
        }
        let def = v.sensor_def();
        if def.name == camera {
            return Some(CameraImage {
                name: def.name,
                width: def.size.0,
                height: def.size.1,
                rgb: self.sensor_rgb(),
                depth: self.sensor_depth(),
            });
        }
        let m = v.mounted.iter().find(|m| m.name == camera)?;
        Some(CameraImage {
            name: m.name,
            width: m.size.0,
            height: m.size.1,
            rgb: v.rgb_on.then_some(m.rgb.as_slice()),
            depth: v.depth_on.then_some(m.depth.as_slice()),
        })
    }

    /// Names of the sensor cameras of a visual obs mode, as [`Env::image`] takes them: the
    /// task's sensor camera, then the robot's mounted cameras.
    pub fn sensor_names(&self) -> Vec<&'static str> {
        std::iter::once(self.sim.task.cameras().0.name)
            .chain(self.sim.spec.cameras.iter().map(|c| c.name))
            .collect()
    }

    /// The task's (sensor, human render) cameras.
    pub fn cameras(&self) -> (crate::tasks::CameraDef, crate::tasks::CameraDef) {
        self.sim.task.cameras()
    }

    /// Renders the human camera (ManiSkill's `render_mode="rgb_array"`, 512×512 for the
    /// tabletop tasks) and returns its RGB frame, H×W×3 bytes, top row first. The goal
    /// markers hidden from the sensor are visible here. The first call of an env in a
    /// non-visual obs mode creates its renderer; an error says what to install.
    pub fn render(&mut self) -> Result<&[u8], EnvError> {
        if self.vision.is_none() {
            self.vision = Some(
                render::Vision::new(
                    &self.sim.model,
                    self.sim.task.cameras(),
                    self.sim.spec.cameras,
                    false,
                    false,
                    self.render_options,
                )
                .map_err(EnvError::from)?,
            );
        }
        let v = self.vision.as_mut().expect("created above");
        v.render_human(&mut self.sim.data).map_err(EnvError::from)
    }

    /// Size (width, height) of [`Env::render`]'s frames.
    pub fn render_size(&self) -> (usize, usize) {
        self.sim.task.cameras().1.size
    }

    /// The render quality settings (defaults favour speed).
    pub fn render_options(&self) -> crate::mujoco::render::RenderOptions {
        self.render_options
    }

    /// Changes the render quality (shadows, multisampling, reflections, clip planes); an
    /// existing renderer is rebuilt and the sensor images are redrawn.
    pub fn set_render_options(
        &mut self,
        options: crate::mujoco::render::RenderOptions,
    ) -> Result<(), EnvError> {
        if let Some(old) = self.vision.as_ref() {
            // Build the new renderer first: on error the env keeps the old one.
            let new = render::Vision::new(
                &self.sim.model,
                self.sim.task.cameras(),
                self.sim.spec.cameras,
                old.rgb_on,
                old.depth_on,
                options,
            )
            .map_err(EnvError::from)?;
            self.vision = Some(new);
        }
        self.render_options = options;
        self.render_sensors();
        Ok(())
    }
}
