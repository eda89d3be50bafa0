//! Stage 5 (analysis), the `trace` plot: the ray fan (height against ground distance, vertical
//! scale exaggerated) beside the transfer curves (height at each distance against apparent
//! elevation, with the target bands).
//!
//! In: the atmosphere, the request and its report (a subset of the fan is re-traced with path
//! recording). Out: PNG bytes (plotters draws into an RGB buffer, `image` encodes it).

use plotters::prelude::*;

use super::AnalysisError;
use super::report::{TraceReport, TraceRequest};
use crate::output::plot::PLOT_FONT;
use crate::tracer::{NoHook, RayPoint, RayRecord, StratifiedIndex, Tracer, TracerConfig};

const WIDTH: u32 = 1600;
const HEIGHT: u32 = 700;
/// Rays drawn in the fan panel.
const DRAWN_RAYS: usize = 41;

fn register_font() -> Result<(), AnalysisError> {
    crate::output::plot::register_plot_font().map_err(AnalysisError::Plot)
}

fn plot_err<E: std::fmt::Display>(e: E) -> AnalysisError {
    AnalysisError::Plot(e.to_string())
}

/// Draw the fan and the transfer curves of `report` (traced from `request` through `atmosphere`)
/// as a PNG.
pub fn trace_plot_png(
    atmosphere: &dyn StratifiedIndex,
    request: &TraceRequest,
    report: &TraceReport,
) -> Result<Vec<u8>, AnalysisError> {
    register_font()?;
    let max_d = report.distances_m.last().copied().unwrap_or(30_000.0);
    // Paths of a subset of the fan, out to the farthest distance.
    let cfg = TracerConfig {
        stop_after_last_target: true,
        path_samples_per_step: 4,
        max_step_m: request.tracer.max_step_m.min(max_d / 100.0),
        ..request.tracer.clone()
    };
    let tracer = Tracer::new(atmosphere, cfg)?;
    let elevations = request.elevations_rad();
    let stride = (elevations.len() / DRAWN_RAYS).max(1);
    let mut paths: Vec<Vec<RayPoint>> = Vec::new();
    let mut record = RayRecord::default();
    for &a in elevations.iter().step_by(stride) {
        let mut path = Vec::new();
        tracer.trace_into(
            request.observer_height_m,
            a,
            &[max_d],
            &mut NoHook,
            &mut record,
            Some(&mut path),
        )?;
        paths.push(path);
    }
    let top_h = request
        .target_heights_m
        .iter()
        .copied()
        .fold(request.observer_height_m, f64::max)
        * 3.0;
    let top_h = top_h.max(10.0);

    let mut buffer = vec![0u8; (WIDTH * HEIGHT * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let (left, right) = root.split_horizontally(WIDTH / 2);
        // Fan.
        let mut chart = ChartBuilder::on(&left)
            .caption(
                format!(
                    "Ray fan from {} m (vertical scale exaggerated)",
                    request.observer_height_m
                ),
                (PLOT_FONT, 20),
            )
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(55)
            .build_cartesian_2d(0.0..max_d / 1000.0, 0.0..top_h)
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .x_desc("ground distance (km)")
            .y_desc("height (m)")
            .label_style((PLOT_FONT, 14))
            .draw()
            .map_err(plot_err)?;
        for (i, path) in paths.iter().enumerate() {
            let hue = i as f64 / paths.len().max(1) as f64;
            let colour = HSLColor(0.66 * (1.0 - hue), 0.8, 0.45);
            // plotters clamps out-of-range points to the border: split the path where it leaves.
            let mut segment: Vec<(f64, f64)> = Vec::new();
            for p in path {
                if p.height_m <= top_h && p.distance_m <= max_d {
                    segment.push((p.distance_m / 1000.0, p.height_m));
                } else if !segment.is_empty() {
                    chart
                        .draw_series(LineSeries::new(
                            std::mem::take(&mut segment),
                            colour.stroke_width(1),
                        ))
                        .map_err(plot_err)?;
                }
            }
            if !segment.is_empty() {
                chart
                    .draw_series(LineSeries::new(segment, colour.stroke_width(1)))
                    .map_err(plot_err)?;
            }
        }
        for &d in &report.distances_m {
            for &h in &report.target_heights_m {
                chart
                    .draw_series(LineSeries::new(
                        vec![(d / 1000.0, 0.0), (d / 1000.0, h.min(top_h))],
                        BLACK.stroke_width(3),
                    ))
                    .map_err(plot_err)?;
            }
        }
        // Transfer curves.
        // The fan's span in arcmin; a single ray gets ±1′ around it.
        let (first, last) = (elevations.first().copied(), elevations.last().copied());
        let (amin, amax) = match (first, last) {
            (Some(a), Some(b)) if b > a => (a.to_degrees() * 60.0, b.to_degrees() * 60.0),
            (Some(a), _) => (a.to_degrees() * 60.0 - 1.0, a.to_degrees() * 60.0 + 1.0),
            _ => (-1.0, 1.0),
        };
        let mut chart = ChartBuilder::on(&right)
            .caption("Transfer curves h(D; α)", (PLOT_FONT, 20))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(55)
            .build_cartesian_2d(amin..amax, 0.0..top_h)
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .x_desc("apparent elevation (arcmin)")
            .y_desc("height at distance (m)")
            .label_style((PLOT_FONT, 14))
            .draw()
            .map_err(plot_err)?;
        for &h in &report.target_heights_m {
            chart
                .draw_series(LineSeries::new(
                    vec![(amin, h), (amax, h)],
                    BLACK.mix(0.4).stroke_width(1),
                ))
                .map_err(plot_err)?;
        }
        let n = report.distances_m.len();
        for (j, &d) in report.distances_m.iter().enumerate() {
            let colour = HSLColor(j as f64 / n.max(1) as f64 * 0.8, 0.8, 0.4);
            let mut segment: Vec<(f64, f64)> = Vec::new();
            let mut segments = Vec::new();
            for r in &report.rays {
                match r.heights_m[j] {
                    Some(h) if h <= top_h => segment.push((r.elevation_deg * 60.0, h)),
                    _ => {
                        if !segment.is_empty() {
                            segments.push(std::mem::take(&mut segment));
                        }
                    }
                }
            }
            if !segment.is_empty() {
                segments.push(segment);
            }
            let mut first = true;
            for s in segments {
                let series = chart
                    .draw_series(LineSeries::new(s, colour.stroke_width(2)))
                    .map_err(plot_err)?;
                if first {
                    series
                        .label(format!("D = {} km", d / 1000.0))
                        .legend(move |(x, y)| {
                            PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
                        });
                    first = false;
                }
            }
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font((PLOT_FONT, 14))
            .draw()
            .map_err(plot_err)?;
        root.present().map_err(plot_err)?;
    }
    crate::output::plot::rgb8_to_png(&buffer, WIDTH, HEIGHT).map_err(AnalysisError::Plot)
}
