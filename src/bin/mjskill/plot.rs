//! Error-curve plots of `mjskill fidelity --plot` (plotters, PNG).
use std::path::Path;

use plotters::prelude::*;

use mjskill::maniskill::fidelity::{FileFidelity, StepError};

/// Font file the plots' text uses (Debian's `fonts-dejavu-core`, installed by `.ci/setup`).
pub const FONT_FILE: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

fn register_font() -> Result<(), String> {
    static FONT: std::sync::OnceLock<Result<(), String>> = std::sync::OnceLock::new();
    FONT.get_or_init(|| {
        let bytes = std::fs::read(FONT_FILE).map_err(|e| {
            format!("--plot needs the DejaVu font {FONT_FILE} (Debian: fonts-dejavu-core): {e}")
        })?;
        // plotters keeps registered fonts for the life of the process.
        let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
        plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
            .map_err(|_| format!("{FONT_FILE} is not a usable TrueType font"))
    })
    .clone()
}

/// Draws the mean (over episodes) joint, TCP and object errors against the step, one panel
/// each, log-scaled, to a PNG.
pub fn error_curves(report: &FileFidelity, path: &Path) -> Result<(), String> {
    register_font()?;
    let steps = report
        .episodes
        .iter()
        .map(|e| e.per_step.len())
        .max()
        .unwrap_or(0);
    if steps == 0 {
        return Err("nothing to plot: no steps were replayed".into());
    }
    type Metric = fn(&StepError) -> f64;
    let metrics: [(&str, Metric); 3] = [
        ("joint error (rad or m)", |e| e.joint),
        ("TCP position error (m)", |e| e.tcp_pos),
        ("object position error (m)", |e| e.obj_pos),
    ];
    let err = |e: &dyn std::fmt::Display| format!("cannot draw {}: {e}", path.display());
    let root = BitMapBackend::new(path, (900, 900)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let title = format!(
        "{} / {}: mean over {} episodes (sim_freq {})",
        report.env_id,
        report.robot,
        report.episodes.len(),
        report.sim.sim_freq
    );
    let root = root
        .titled(&title, ("sans-serif", 20))
        .map_err(|e| err(&e))?;
    for (area, (name, f)) in root.split_evenly((3, 1)).iter().zip(metrics) {
        let mean: Vec<(u32, f64)> = (0..steps)
            .filter_map(|i| {
                let v: Vec<f64> = report
                    .episodes
                    .iter()
                    .filter_map(|e| e.per_step.get(i).map(f))
                    .collect();
                (!v.is_empty()).then(|| (i as u32 + 1, v.iter().sum::<f64>() / v.len() as f64))
            })
            .collect();
        let hi = mean.iter().map(|p| p.1).fold(1e-9, f64::max) * 2.0;
        let mut chart = ChartBuilder::on(area)
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(60)
            .caption(name, ("sans-serif", 16))
            .build_cartesian_2d(1u32..steps as u32, (1e-7f64..hi).log_scale())
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc("step")
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .draw()
            .map_err(|e| err(&e))?;
        chart
            .draw_series(LineSeries::new(
                mean.into_iter().map(|(t, v)| (t, v.max(1e-7))),
                &BLUE,
            ))
            .map_err(|e| err(&e))?;
    }
    root.present().map_err(|e| err(&e))
}
