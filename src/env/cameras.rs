//! Camera images of an env: the sensor images of the visual obs modes and the human render
//! (the renderer itself is `render.rs`).
use super::render::{self, CameraImage, PointCloud};
use super::{Env, EnvError};

impl Env {
    /// The sensor camera's colour image of the current state (H×W×3 bytes, top row first),
    /// rewritten in place by every step; `None` unless the obs mode renders colour.
    pub fn sensor_rgb(&self) -> Option<&[u8]> {
        self.vision.as_ref()?.sensor_image(0)?.rgb
    }

    /// The sensor camera's depth image (H×W×1 metres along the optical axis); `None` unless
    /// the obs mode renders depth.
    pub fn sensor_depth(&self) -> Option<&[f32]> {
        self.vision.as_ref()?.sensor_image(0)?.depth
    }

    /// A sensor camera's images by name (ManiSkill's `obs["sensor_data"][name]`): the task's
    /// `env.image("base_camera")` or a robot-mounted camera (Fetch's `"fetch_head"`,
    /// `"fetch_hand"`); `None` for an unknown name or a non-visual obs mode. In the
    /// `pointcloud` mode the images the point cloud is made of are served too.
    pub fn image(&self, camera: &str) -> Option<CameraImage<'_>> {
        let v = self.vision.as_ref()?;
        (0..v.sensor_count())
            .filter_map(|k| v.sensor_image(k))
            .find(|img| img.name == camera)
    }

    /// Sensor image `k` in [`Env::sensor_names`] order; `None` past the last camera or in a
    /// non-visual obs mode. No lookups, no allocation.
    pub fn image_at(&self, k: usize) -> Option<CameraImage<'_>> {
        self.vision.as_ref()?.sensor_image(k)
    }

    /// ManiSkill's fused point cloud of all sensor cameras (obs mode `pointcloud`; else
    /// `None`), rewritten in place by every step. See docs/observations.md for the layout.
    pub fn point_cloud(&self) -> Option<PointCloud<'_>> {
        self.vision.as_ref()?.point_cloud()
    }

    /// ManiSkill's `segmentation_id_map` of this env: `(id, name)` of every robot link and
    /// actor (`table-workspace`, `ground`, the task's actors), background (0) excluded. The
    /// ids are those of the `segmentation` images and of the point cloud.
    pub fn segmentation_id_map(&self) -> Vec<(i16, &str)> {
        self.seg_ids.id_map()
    }

    /// The segmentation id of every geom (0: none), as the renderer labels pixels: of
    /// [`Env::render_model`]'s geoms once the env has a renderer, else of [`Env::model`]'s.
    pub fn geom_segmentation_ids(&self) -> &[i16] {
        match &self.vision {
            Some(v) => v.labels(),
            None => &self.seg_ids.geom_labels,
        }
    }

    /// The model the renderer draws: [`Env::model`] plus the geoms that only draw (visual
    /// meshes, markers), which the physics model leaves out (docs/speed.md). Its bodies,
    /// joints, mocap bodies and cameras are the physics model's. `None` until the env has a
    /// renderer (a visual obs mode, or after the first [`Env::render`]).
    pub fn render_model(&self) -> Option<&std::sync::Arc<crate::mujoco::Model>> {
        self.vision.as_ref().map(|v| v.model())
    }

    /// Buffer and stack bytes of the render model's state (0, 0 without a renderer).
    pub(crate) fn render_data_bytes(&self) -> (usize, usize) {
        self.vision
            .as_ref()
            .map_or((0, 0), |v| v.data().memory_bytes())
    }

    /// Compiles the scene with every geom (see [`Env::render_model`]) and its geoms'
    /// segmentation ids.
    fn compile_render_model(
        &self,
    ) -> Result<(std::sync::Arc<crate::mujoco::Model>, Vec<i16>), EnvError> {
        let scene = self.scene_now()?;
        let model = std::sync::Arc::new(scene.render_model().map_err(EnvError::Robot)?);
        let labels = super::segmentation::SegmentationIds::new(
            &model,
            &self.sim.robot.link_bodies,
            self.sim.task.actor_names(),
        )
        .geom_labels;
        Ok((model, labels))
    }

    /// The physics model the scene compiles to with the task's current shapes, compiled
    /// afresh (a test holds the model edited in place at each reset to it).
    #[cfg(test)]
    pub(crate) fn compile_physics_model(
        &self,
    ) -> Result<std::sync::Arc<crate::mujoco::Model>, EnvError> {
        Ok(self.scene_now()?.model)
    }

    /// The env's scene built and compiled anew, with the task's current shapes.
    fn scene_now(&self) -> Result<crate::robots::TableScene, EnvError> {
        super::registry::build_scene(
            super::registry::env_spec(self.id)?,
            self.sim.spec,
            self.control_mode(),
            self.config.sim,
            self.sim.task.as_ref(),
        )
    }

    /// A renderer of the scene as it is now: the sensor textures of the obs mode (none in a
    /// non-visual mode, which renders only [`Env::render`]'s frames).
    pub(super) fn make_vision(&self) -> Result<render::Vision, EnvError> {
        let (model, labels) = self.compile_render_model()?;
        let visual = self.config.obs_mode.is_visual();
        render::Vision::new(
            &model,
            self.sim.task.cameras(),
            self.sim.spec.cameras,
            match visual {
                true => self.config.obs_mode.textures(),
                false => Default::default(),
            },
            visual && self.config.obs_mode.is_point_cloud(),
            labels,
            self.render_options,
        )
        .map_err(EnvError::from)
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
            self.vision = Some(self.make_vision()?);
        }
        let v = self.vision.as_mut().expect("created above");
        v.render_human(&self.sim.data).map_err(EnvError::from)
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
        if let Some(old) = &self.vision {
            // Build the new renderer first: on error the env keeps the old one.
            let new = render::Vision::new(
                old.model(),
                self.sim.task.cameras(),
                self.sim.spec.cameras,
                self.config.obs_mode.textures(),
                self.config.obs_mode.is_point_cloud(),
                old.labels().to_vec(),
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
