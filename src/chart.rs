//! `bench --chart FILE.png`: median frame wall time per method, one panel
//! per resolution, one bar per model, on a log scale. Drawn with plotters
//! into memory with a bundled font (no system fonts needed), then written
//! atomically as a PNG.

use std::path::Path;
use std::sync::OnceLock;

use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::bench::BenchReport;
use crate::error::{Error, Result};
use crate::image_io::write_rgb8_png;

/// DejaVu Sans (Bitstream Vera license, `assets/fonts/LICENSE-DejaVu.txt`).
static FONT: &[u8] = include_bytes!("../assets/fonts/DejaVuSans.ttf");
const FAMILY: &str = "sans-serif";

const PALETTE: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

/// Registers the bundled font once per process; every call reports whether
/// that registration worked.
fn register_font() -> Result<()> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED
        .get_or_init(|| plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_ok());
    if ok {
        Ok(())
    } else {
        Err(Error::InvalidArgument(
            "the bundled chart font is invalid".into(),
        ))
    }
}

fn unique<T: PartialEq + Clone>(items: impl Iterator<Item = T>) -> Vec<T> {
    let mut out: Vec<T> = Vec::new();
    for i in items {
        if !out.contains(&i) {
            out.push(i);
        }
    }
    out
}

fn chart_error(e: impl std::fmt::Display) -> Error {
    Error::InvalidArgument(format!("cannot draw the chart: {e}"))
}

/// "812", "4.3k", "0.52": a bar's label.
fn short_ms(ms: f64) -> String {
    if ms >= 10_000.0 {
        format!("{:.0}k", ms / 1000.0)
    } else if ms >= 1000.0 {
        format!("{:.1}k", ms / 1000.0)
    } else if ms >= 10.0 {
        format!("{ms:.0}")
    } else {
        format!("{ms:.2}")
    }
}

/// Draws the chart of `report` and writes it to `path` (.png).
pub fn write_chart(report: &BenchReport, path: &Path) -> Result<()> {
    register_font()?;
    let resolutions = unique(report.cells.iter().map(|c| (c.width, c.height)));
    let methods = unique(report.cells.iter().map(|c| report.label(c)));
    let models = unique(report.cells.iter().map(|c| c.model.clone()));
    if resolutions.is_empty() {
        return Err(Error::InvalidArgument("no cells to chart".into()));
    }
    let (width, panel_height) = (1200u32, 440u32);
    let height = panel_height * resolutions.len() as u32;
    let mut rgb = vec![255u8; (width * height * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(chart_error)?;
        let panels = root.split_evenly((resolutions.len(), 1));
        for (panel, &(w, h)) in panels.iter().zip(&resolutions) {
            let cells: Vec<_> = report
                .cells
                .iter()
                .filter(|c| (c.width, c.height) == (w, h))
                .collect();
            let medians: Vec<f64> = cells
                .iter()
                .map(|c| c.frame_wall_ms.median.max(1e-3))
                .collect();
            let lo = medians.iter().cloned().fold(f64::INFINITY, f64::min) / 2.0;
            // Headroom for the bar labels and the legend.
            let hi = medians.iter().cloned().fold(0.0, f64::max) * 8.0;
            let mut chart = ChartBuilder::on(panel)
                .caption(
                    format!(
                        "{w}×{h}: frame wall time, median of {} runs (ms, log scale) — {}",
                        report.runs, report.device.name
                    ),
                    (FAMILY, 20),
                )
                .margin(12)
                .x_label_area_size(36)
                .y_label_area_size(70)
                .build_cartesian_2d(0.0..methods.len() as f64, (lo..hi).log_scale())
                .map_err(chart_error)?;
            chart
                .configure_mesh()
                .disable_x_mesh()
                .x_labels(0)
                .y_desc("ms")
                .y_label_formatter(&|ms| short_ms(*ms))
                .label_style((FAMILY, 15))
                .draw()
                .map_err(chart_error)?;
            // Method i spans x = i..i + 1: its name below the axis, its
            // bars (one per model, in backend pixels) side by side.
            for (i, method) in methods.iter().enumerate() {
                let (x, y) = chart.backend_coord(&(i as f64 + 0.5, lo));
                let style = TextStyle::from((FAMILY, 15).into_font())
                    .pos(Pos::new(HPos::Center, VPos::Top));
                root.draw(&Text::new(method.clone(), (x, y + 8), style))
                    .map_err(chart_error)?;
            }
            let group = models.len() as f64 + 1.0;
            for cell in &cells {
                let i = methods
                    .iter()
                    .position(|m| *m == report.label(cell))
                    .unwrap_or(0);
                let k = models.iter().position(|m| *m == cell.model).unwrap_or(0);
                let y = cell.frame_wall_ms.median.max(1e-3);
                let (x0, y_top) = chart.backend_coord(&(i as f64, y));
                let (x1, y_base) = chart.backend_coord(&(i as f64 + 1.0, lo));
                let slot = (x1 - x0) as f64 / group;
                let left = x0 + (slot * (k as f64 + 0.5)) as i32;
                let right = x0 + (slot * (k as f64 + 1.5)) as i32 - 1;
                let color = PALETTE[k % PALETTE.len()];
                root.draw(&Rectangle::new(
                    [(left, y_top), (right, y_base)],
                    color.filled(),
                ))
                .map_err(chart_error)?;
                root.draw(&Text::new(
                    short_ms(cell.frame_wall_ms.median),
                    (left, y_top - 16),
                    (FAMILY, 13),
                ))
                .map_err(chart_error)?;
            }
            // Legend: the models, top left of the plot.
            let (lx, ly) = chart.backend_coord(&(0.0, hi));
            for (k, model) in models.iter().enumerate() {
                let y = ly + 8 + 20 * k as i32;
                let color = PALETTE[k % PALETTE.len()];
                root.draw(&Rectangle::new(
                    [(lx + 10, y), (lx + 24, y + 14)],
                    color.filled(),
                ))
                .map_err(chart_error)?;
                root.draw(&Text::new(model.clone(), (lx + 30, y), (FAMILY, 15)))
                    .map_err(chart_error)?;
            }
        }
        root.present().map_err(chart_error)?;
    }
    write_rgb8_png(&rgb, width, height, path)
}
