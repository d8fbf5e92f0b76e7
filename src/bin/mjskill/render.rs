//! `mjskill render`: one camera frame of a seeded initial state, written as PNG.
use std::path::Path;

use serde::Serialize;

use crate::CliError;
use mjskill::record::image::write_png;
use mjskill::{make, EnvConfig, ObsMode};

/// The JSON summary of `mjskill render`.
#[derive(Debug, Clone, Serialize)]
pub struct RenderSummary {
    /// Output file.
    pub out: String,
    /// Env id.
    pub env: String,
    /// Robot uid.
    pub robot: String,
    /// Reset seed.
    pub seed: u64,
    /// Camera name.
    pub camera: String,
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
}

/// Resets `env_id` with `seed` and writes the frame of `camera` (the task's human render
/// camera, its sensor camera or a robot-mounted camera, by name) to `out` as PNG.
pub fn run(
    env_id: &str,
    config: EnvConfig,
    seed: u64,
    camera: &str,
    out: &Path,
) -> Result<RenderSummary, CliError> {
    let probe = make(env_id, config.clone())?;
    // The sensor camera, then the robot-mounted ones.
    let (human, sensors) = (probe.cameras().1, probe.sensor_names());
    drop(probe);
    let (rgb, (w, h), robot) = if camera == human.name {
        let mut env = make(env_id, config)?;
        env.reset(Some(seed));
        let frame = env.render()?.to_vec();
        (frame, human.size, env.robot_id().uid())
    } else if sensors.contains(&camera) {
        let config = EnvConfig {
            obs_mode: ObsMode::Rgb,
            ..config
        };
        let mut env = make(env_id, config)?;
        env.reset(Some(seed));
        let img = env
            .image(camera)
            .expect("a sensor camera of the rgb obs mode");
        let frame = img.rgb.expect("rgb obs mode").to_vec();
        (frame, (img.width, img.height), env.robot_id().uid())
    } else {
        let valid: Vec<&str> = std::iter::once(human.name).chain(sensors).collect();
        return Err(format!(
            "unknown camera {camera:?} for {env_id}; valid cameras: {}",
            valid.join(", ")
        )
        .into());
    };
    write_png(out, &rgb, w, h)?;
    Ok(RenderSummary {
        out: out.display().to_string(),
        env: env_id.to_string(),
        robot: robot.to_string(),
        seed,
        camera: camera.to_string(),
        width: w,
        height: h,
    })
}
