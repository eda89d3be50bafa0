//! Stage 5 (render), the figures of a sweep. In: a sweep's frames (their sun facts, or their
//! transfer curves) and the camera height and Earth radius of its scene. Out: PNG bytes of
//! `sun.png` — above, the sun's apparent elevation band (lowest to highest row showing the sun,
//! along the column through its azimuth) against its true elevation or against time, with the
//! astronomical horizon (0°), the straight-ray sea horizon and the sun's true elevation (the
//! line of no refraction); below, the number of separate strips the sun is seen in — and of
//! `transfer.png`: the transfer curve at a target's distance (apparent elevation against height
//! there) for every observer height of the sweep, over the target's band of heights.

use plotters::prelude::*;

use super::sweep::{SunFacts, TransferSamples};
use crate::output::plot::{PLOT_FONT, register_plot_font, rgb8_to_png};

fn plot_err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

const SUN: RGBColor = RGBColor(230, 110, 0);
const HORIZON: RGBColor = RGBColor(20, 90, 200);

/// What `sun.png` shows: per frame an abscissa, the sun's true elevation and its facts.
#[derive(Debug, Clone)]
pub struct SunSeries {
    /// The abscissa of each frame (true elevation in degrees, or minutes).
    pub x: Vec<f64>,
    /// What the abscissa is.
    pub x_desc: String,
    /// The sun's true elevation in each frame (degrees).
    pub true_deg: Vec<f64>,
    /// The sun in the traced map of each frame.
    pub facts: Vec<SunFacts>,
    /// Camera height (m) for the straight-ray sea horizon.
    pub camera_height_m: f64,
    /// Earth radius (m).
    pub earth_radius_m: f64,
    /// The figure's title.
    pub title: String,
}

/// Draw `sun.png` of `series`.
pub fn sun_sweep_png(series: &SunSeries) -> Result<Vec<u8>, String> {
    register_plot_font()?;
    let (w, h) = (1200u32, 900u32);
    let (camera_height_m, earth_radius_m) = (series.camera_height_m, series.earth_radius_m);
    let xs = &series.x;
    let bands: Vec<(f64, f64, f64)> = series
        .facts
        .iter()
        .zip(xs)
        .filter_map(|(f, &t)| {
            let low = f.apparent_low_rad?.to_degrees();
            let high = f.apparent_high_rad?.to_degrees();
            Some((t, low, high))
        })
        .collect();
    let dip_deg = -(earth_radius_m / (earth_radius_m + camera_height_m))
        .acos()
        .to_degrees();
    let (x0, x1) = span(xs.iter().copied(), 0.02 * span_width(xs));
    let (y0, y1) = span(
        bands
            .iter()
            .flat_map(|&(_, l, h)| [l, h])
            .chain([0.0, dip_deg])
            .chain(series.true_deg.iter().copied()),
        0.1,
    );
    let max_strips = series
        .facts
        .iter()
        .map(|f| f.strips)
        .max()
        .unwrap_or(0)
        .max(1);
    let mut buffer = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let root = root
            .titled(&series.title, (PLOT_FONT, 22))
            .map_err(plot_err)?;
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
            .x_desc(series.x_desc.as_str())
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
        let true_line: Vec<(f64, f64)> = xs
            .iter()
            .copied()
            .zip(series.true_deg.iter().copied())
            .collect();
        chart
            .draw_series(LineSeries::new(
                true_line,
                RGBColor(150, 150, 150).stroke_width(1),
            ))
            .map_err(plot_err)?
            .label("the sun's true elevation (no refraction)")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 18, y)], RGBColor(150, 150, 150)));
        let step = if xs.len() > 1 {
            (x1 - x0) / xs.len() as f64 * 0.35
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
            .position(SeriesLabelPosition::LowerMiddle)
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
            .x_desc(series.x_desc.as_str())
            .y_desc("strips")
            .y_labels(max_strips + 2)
            .y_label_formatter(&|v| format!("{v:.0}"))
            .label_style((PLOT_FONT, 14))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()
            .map_err(plot_err)?;
        let points: Vec<(f64, f64)> = series
            .facts
            .iter()
            .zip(xs)
            .map(|(f, &t)| (t, f.strips as f64))
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

/// The width of the range of `values` (0 when empty or a single value).
fn span_width(values: &[f64]) -> f64 {
    let (lo, hi) = values
        .iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    if hi > lo { hi - lo } else { 0.0 }
}

/// Colour of curve `i` of `n`: from blue (the first) through green to red (the last).
fn curve_colour(i: usize, n: usize) -> RGBColor {
    let t = if n > 1 {
        i as f64 / (n - 1) as f64
    } else {
        0.0
    };
    let hue = (1.0 - t) * 0.66;
    let HSLColor(h, s, l) = HSLColor(hue, 0.85, 0.45);
    let c = HSLColor(h, s, l).to_rgba();
    RGBColor(c.0, c.1, c.2)
}

/// Most curves `transfer.png` draws (each labelled).
pub const MAX_TRANSFER_CURVES: usize = 8;

/// Indices of the curves drawn of `n`: all when at most [`MAX_TRANSFER_CURVES`], else that many
/// evenly spread from the first to the last.
fn shown_curves(n: usize) -> Vec<usize> {
    if n <= MAX_TRANSFER_CURVES {
        return (0..n).collect();
    }
    let k = MAX_TRANSFER_CURVES - 1;
    (0..=k).map(|j| (j * (n - 1) + k / 2) / k).collect()
}

/// Draw `transfer.png`: for each of `curves` (one per observer height, in sweep order; at most
/// [`MAX_TRANSFER_CURVES`] of them, evenly spread, first and last included) the
/// apparent elevation of the rays against their height at the curve's distance, over heights
/// from the surface to three times the target's top (`target_m`: its base and top, shaded).
pub fn transfer_png(
    curves: &[&TransferSamples],
    target_m: (f64, f64),
    title: &str,
) -> Result<Vec<u8>, String> {
    register_plot_font()?;
    let (w, h) = (1200u32, 800u32);
    let x1 = (3.0 * target_m.1).max(10.0);
    let (x0, x1) = (0.0, x1);
    let inside = |v: Option<f64>| v.filter(|h| (x0..=x1).contains(h));
    let (y0, y1) = span(
        curves
            .iter()
            .flat_map(|c| c.elevations_rad.iter().zip(&c.heights_m))
            .filter(|(_, h)| inside(**h).is_some())
            .map(|(a, _)| a.to_degrees()),
        0.01,
    );
    let mut buffer = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let root = root.titled(title, (PLOT_FONT, 20)).map_err(plot_err)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                "apparent elevation of the rays against their height at the target's distance \
                 (several heights at one elevation: folds, several images)",
                (PLOT_FONT, 15),
            )
            .margin(14)
            .x_label_area_size(44)
            .y_label_area_size(76)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .x_desc("height of the ray at the target's distance (m above the surface)")
            .y_desc("apparent elevation at the observer (deg)")
            .label_style((PLOT_FONT, 14))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()
            .map_err(plot_err)?;
        chart
            .draw_series([Rectangle::new(
                [(target_m.0, y0), (target_m.1, y1)],
                RGBColor(255, 200, 120).mix(0.35).filled(),
            )])
            .map_err(plot_err)?
            .label("the target's heights")
            .legend(|(x, y)| {
                Rectangle::new(
                    [(x, y - 5), (x + 18, y + 5)],
                    RGBColor(255, 200, 120).filled(),
                )
            });
        let shown = shown_curves(curves.len());
        let n = shown.len();
        for (i, curve) in shown.iter().map(|&k| curves[k]).enumerate() {
            let colour = curve_colour(i, n);
            // Break the line where a ray ends before the distance or leaves the plotted heights.
            let mut segments: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
            for (a, hm) in curve.elevations_rad.iter().zip(&curve.heights_m) {
                match inside(*hm) {
                    Some(hm) => segments
                        .last_mut()
                        .map_or((), |s| s.push((hm, a.to_degrees()))),
                    None if segments.last().is_some_and(|s| !s.is_empty()) => {
                        segments.push(Vec::new())
                    }
                    None => {}
                }
            }
            let segments: Vec<Vec<(f64, f64)>> =
                segments.into_iter().filter(|s| s.len() > 1).collect();
            if segments.is_empty() {
                chart
                    .draw_series(LineSeries::new(Vec::new(), colour.stroke_width(2)))
                    .map_err(plot_err)?
                    .label(format!(
                        "observer at {} m: no ray passes here in the frame",
                        curve.camera_height_m
                    ))
                    .legend(move |(x, y)| {
                        PathElement::new([(x, y), (x + 18, y)], colour.stroke_width(2))
                    });
            }
            let mut first = true;
            for segment in segments {
                let series = chart
                    .draw_series(LineSeries::new(segment, colour.stroke_width(2)))
                    .map_err(plot_err)?;
                if first {
                    series
                        .label(format!("observer at {} m", curve.camera_height_m))
                        .legend(move |(x, y)| {
                            PathElement::new([(x, y), (x + 18, y)], colour.stroke_width(2))
                        });
                }
                first = false;
            }
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.3))
            .label_font((PLOT_FONT, 14))
            .position(SeriesLabelPosition::UpperLeft)
            .draw()
            .map_err(plot_err)?;
    }
    rgb8_to_png(&buffer, w, h)
}
