//! Stage 5 (render), the sun sweep's figure. In: a sun sweep's [`SunFrame`]s and the camera
//! height and Earth radius of its scene. Out: PNG bytes of `sun.png`: above, the sun's apparent
//! elevation band (lowest to highest row showing the sun, along the column through its azimuth)
//! against its true elevation, with the astronomical horizon (0°), the straight-ray sea horizon
//! and the line of no refraction; below, the number of separate strips the sun is seen in.

use plotters::prelude::*;

use super::sweep::SunFrame;
use crate::output::plot::{PLOT_FONT, register_plot_font, rgb8_to_png};

fn plot_err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

const SUN: RGBColor = RGBColor(230, 110, 0);
const HORIZON: RGBColor = RGBColor(20, 90, 200);

/// Draw `sun.png` for `frames` seen from `camera_height_m` over a sphere of `earth_radius_m`.
pub fn sun_sweep_png(
    frames: &[SunFrame],
    camera_height_m: f64,
    earth_radius_m: f64,
    title: &str,
) -> Result<Vec<u8>, String> {
    register_plot_font()?;
    let (w, h) = (1200u32, 900u32);
    let true_deg: Vec<f64> = frames
        .iter()
        .map(|f| f.sun_elevation_rad.to_degrees())
        .collect();
    let bands: Vec<(f64, f64, f64)> = frames
        .iter()
        .zip(&true_deg)
        .filter_map(|(f, &t)| {
            let low = f.facts.apparent_low_rad?.to_degrees();
            let high = f.facts.apparent_high_rad?.to_degrees();
            Some((t, low, high))
        })
        .collect();
    let dip_deg = -(earth_radius_m / (earth_radius_m + camera_height_m))
        .acos()
        .to_degrees();
    let (x0, x1) = span(true_deg.iter().copied(), 0.05);
    let (y0, y1) = span(
        bands
            .iter()
            .flat_map(|&(_, l, h)| [l, h])
            .chain([0.0, dip_deg, x0, x1]),
        0.1,
    );
    let max_strips = frames
        .iter()
        .map(|f| f.facts.strips)
        .max()
        .unwrap_or(0)
        .max(1);
    let mut buffer = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let root = root.titled(title, (PLOT_FONT, 22)).map_err(plot_err)?;
        let (upper, lower) = root.split_vertically(580);
        let mut chart = ChartBuilder::on(&upper)
            .caption(
                "apparent elevation of the sun (band: lowest to highest row of the frame showing it)",
                (PLOT_FONT, 17),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .x_desc("true elevation of the sun's centre (deg)")
            .y_desc("apparent elevation (deg)")
            .label_style((PLOT_FONT, 14))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()
            .map_err(plot_err)?;
        let line = |y: f64| vec![(x0, y), (x1, y)];
        chart
            .draw_series(LineSeries::new(line(0.0), BLACK.stroke_width(1)))
            .map_err(plot_err)?
            .label("astronomical horizon (0°)")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 18, y)], BLACK));
        chart
            .draw_series(LineSeries::new(line(dip_deg), HORIZON.stroke_width(2)))
            .map_err(plot_err)?
            .label(format!(
                "straight-ray sea horizon ({dip_deg:.3}°, eye at {camera_height_m} m)"
            ))
            .legend(|(x, y)| PathElement::new([(x, y), (x + 18, y)], HORIZON.stroke_width(2)));
        chart
            .draw_series(LineSeries::new(
                vec![(x0, x0), (x1, x1)],
                RGBColor(150, 150, 150).stroke_width(1),
            ))
            .map_err(plot_err)?
            .label("no refraction (apparent = true)")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 18, y)], RGBColor(150, 150, 150)));
        let step = if true_deg.len() > 1 {
            (x1 - x0) / true_deg.len() as f64 * 0.35
        } else {
            0.01
        };
        chart
            .draw_series(bands.iter().map(|&(t, l, h)| {
                Rectangle::new([(t - step, l), (t + step, h)], SUN.mix(0.8).filled())
            }))
            .map_err(plot_err)?
            .label("the sun (apparent band)")
            .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 18, y + 5)], SUN.filled()));
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.3))
            .label_font((PLOT_FONT, 14))
            .position(SeriesLabelPosition::UpperLeft)
            .draw()
            .map_err(plot_err)?;
        let mut strips = ChartBuilder::on(&lower)
            .caption(
                "number of separate strips the sun is seen in",
                (PLOT_FONT, 17),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, 0f64..(max_strips as f64 + 0.5))
            .map_err(plot_err)?;
        strips
            .configure_mesh()
            .x_desc("true elevation of the sun's centre (deg)")
            .y_desc("strips")
            .y_labels(max_strips + 2)
            .y_label_formatter(&|v| format!("{v:.0}"))
            .label_style((PLOT_FONT, 14))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()
            .map_err(plot_err)?;
        let points: Vec<(f64, f64)> = frames
            .iter()
            .zip(&true_deg)
            .map(|(f, &t)| (t, f.facts.strips as f64))
            .collect();
        strips
            .draw_series(LineSeries::new(points.clone(), SUN.stroke_width(2)))
            .map_err(plot_err)?;
        strips
            .draw_series(points.iter().map(|&p| Circle::new(p, 3, SUN.filled())))
            .map_err(plot_err)?;
    }
    rgb8_to_png(&buffer, w, h)
}

/// The range of `values` widened by `pad` on each side ((-1, 1) when empty).
fn span(values: impl Iterator<Item = f64>, pad: f64) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if lo.is_finite() && hi > lo {
        (lo - pad, hi + pad)
    } else if lo.is_finite() {
        (lo - 1.0, lo + 1.0)
    } else {
        (-1.0, 1.0)
    }
}
