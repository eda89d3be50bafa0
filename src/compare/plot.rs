//! Stage 6 — comparison: figures. In: the two refractive atmospheres (measured, synthetic), the
//! sounding's levels, the fitted layers and the two trace reports. Out: PNG bytes of
//! `profiles.png` (T(h) and dN/dh of both, fitted warming layers shaded, the trapping gradient
//! marked) and `transfer.png` (both transfer curves h(D; α) of every target distance on one
//! panel per distance, target bands shaded).

use plotters::prelude::*;

use super::LayerSummary;
use crate::analysis::TraceReport;
use crate::output::plot::{PLOT_FONT, register_plot_font, rgb8_to_png};
use crate::refractivity::RefractiveAtmosphere;
use crate::sounding::Level;

/// Colour of the measured atmosphere's curves.
const MEASURED: RGBColor = RGBColor(20, 90, 200);
/// Colour of the synthetic atmosphere's curves.
const SYNTHETIC: RGBColor = RGBColor(230, 110, 0);

fn plot_err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// What `profiles.png` shows.
pub struct ProfilesPlot<'a> {
    /// The measured atmosphere.
    pub measured: &'a RefractiveAtmosphere,
    /// The synthetic atmosphere.
    pub synthetic: &'a RefractiveAtmosphere,
    /// The sounding's levels (dots on the temperature panel).
    pub levels: &'a [Level],
    /// Fitted layers; those that warm with height are shaded.
    pub layers: &'a [LayerSummary],
    /// Top of the height axis (m above the measured surface).
    pub top_agl_m: f64,
    /// Figure title.
    pub title: &'a str,
}

/// (height MSL, T °C, dN/dh N/km) of `atm` at 1000 heights from `y0` to `y1`.
fn curve(atm: &RefractiveAtmosphere, y0: f64, y1: f64) -> Vec<(f64, f64, f64)> {
    let steps = 1000;
    (0..=steps)
        .map(|i| {
            let z = y0 + (y1 - y0) * i as f64 / steps as f64;
            let s = atm.sample_at(z);
            (z, s.air.temperature_k - 273.15, s.dn_dh_per_m * 1e9)
        })
        .filter(|(_, t, d)| t.is_finite() && d.is_finite())
        .collect()
}

fn range(values: impl Iterator<Item = f64>, pad: f64) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    if lo.is_finite() && hi.is_finite() {
        (lo - pad, hi + pad)
    } else {
        (-1.0, 1.0)
    }
}

/// Draw `profiles.png`: temperature (left) and dN/dh (right) of both atmospheres against height.
pub fn profiles_png(p: &ProfilesPlot<'_>) -> Result<Vec<u8>, String> {
    register_plot_font()?;
    let (w, h) = (1400u32, 800u32);
    let y0 = p.measured.surface_height_m();
    let y1 = y0 + p.top_agl_m;
    let (cm, cs) = (curve(p.measured, y0, y1), curve(p.synthetic, y0, y1));
    let dots: Vec<(f64, f64)> = p
        .levels
        .iter()
        .filter(|l| l.height_m >= y0 && l.height_m <= y1)
        .map(|l| (l.temperature_k - 273.15, l.height_m))
        .collect();
    let all = || cm.iter().chain(&cs);
    let t = range(all().map(|c| c.1).chain(dots.iter().map(|d| d.0)), 0.5);
    let trap = -1e9 / crate::units::EARTH_RADIUS_M;
    let d = range(all().map(|c| c.2).chain([trap * 1.3, 20.0]), 5.0);
    let mut buffer = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let root = root.titled(p.title, (PLOT_FONT, 22)).map_err(plot_err)?;
        let (left, right) = root.split_horizontally(w / 2);
        let panels = [
            (&left, "temperature (°C)", t, 1usize),
            (&right, "dN/dh (N-units per km)", d, 2usize),
        ];
        for (area, x_desc, (lo, hi), column) in panels {
            let mut chart = ChartBuilder::on(area)
                .margin(12)
                .x_label_area_size(45)
                .y_label_area_size(70)
                .build_cartesian_2d(lo..hi, y0..y1)
                .map_err(plot_err)?;
            chart
                .configure_mesh()
                .x_desc(x_desc)
                .y_desc("height above sea level (m)")
                .y_label_formatter(&|v| format!("{v:.0}"))
                .label_style((PLOT_FONT, 15))
                .light_line_style(RGBColor(235, 235, 235))
                .draw()
                .map_err(plot_err)?;
            shade_layers(&mut chart, p.layers, (lo, hi), (y0, y1))?;
            if column == 2 {
                chart
                    .draw_series(LineSeries::new(
                        [(trap, y0), (trap, y1)],
                        BLACK.mix(0.5).stroke_width(1),
                    ))
                    .map_err(plot_err)?
                    .label("trapping (−157 N/km)")
                    .legend(|(x, y)| PathElement::new([(x, y), (x + 18, y)], BLACK.mix(0.5)));
            }
            let pick = |c: &(f64, f64, f64)| if column == 1 { (c.1, c.0) } else { (c.2, c.0) };
            for (data, colour, label) in
                [(&cm, MEASURED, "measured"), (&cs, SYNTHETIC, "synthetic")]
            {
                chart
                    .draw_series(LineSeries::new(
                        data.iter().map(pick),
                        colour.stroke_width(2),
                    ))
                    .map_err(plot_err)?
                    .label(label)
                    .legend(move |(x, y)| {
                        PathElement::new([(x, y), (x + 18, y)], colour.stroke_width(2))
                    });
            }
            if column == 1 && !dots.is_empty() {
                chart
                    .draw_series(dots.iter().map(|&q| Circle::new(q, 3, BLACK.filled())))
                    .map_err(plot_err)?
                    .label("sounding levels")
                    .legend(|(x, y)| Circle::new((x + 9, y), 3, BLACK.filled()));
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .label_font((PLOT_FONT, 14))
                .position(SeriesLabelPosition::UpperRight)
                .draw()
                .map_err(plot_err)?;
        }
        root.present().map_err(plot_err)?;
    }
    rgb8_to_png(&buffer, w, h)
}

type Chart<'a, 'b> = ChartContext<
    'a,
    BitMapBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// Shade the fitted layers that warm with height (inversions of the synthetic atmosphere).
fn shade_layers(
    chart: &mut Chart<'_, '_>,
    layers: &[LayerSummary],
    (lo, hi): (f64, f64),
    (y0, y1): (f64, f64),
) -> Result<(), String> {
    let fill = RGBColor(240, 120, 100).mix(0.22).filled();
    let mut first = true;
    for l in layers.iter().filter(|l| l.delta_t_k > 0.0) {
        let (b, t) = (l.base_m.max(y0), l.top_m.min(y1));
        if t <= b {
            continue;
        }
        let series = chart
            .draw_series(std::iter::once(Rectangle::new([(lo, b), (hi, t)], fill)))
            .map_err(plot_err)?;
        if first {
            series
                .label("fitted warming layer")
                .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 18, y + 6)], fill));
            first = false;
        }
    }
    Ok(())
}

/// Largest number of distance panels in `transfer.png`.
const MAX_PANELS: usize = 4;

/// Draw `transfer.png`: for each target distance (up to four), the height reached at that
/// distance against apparent elevation through both atmospheres, the targets' bands shaded.
/// Both reports must come from the same request (same fan, distances and targets); `targets`
/// are the (distance m, height m) pairs whose bands are shaded at their distance.
pub fn transfer_png(
    measured: &TraceReport,
    synthetic: &TraceReport,
    targets: &[(f64, f64)],
) -> Result<Vec<u8>, String> {
    register_plot_font()?;
    let distances: Vec<(usize, f64)> = measured
        .distances_m
        .iter()
        .copied()
        .enumerate()
        .take(MAX_PANELS)
        .collect();
    let (w, h) = (560 * distances.len().max(1) as u32, 620u32);
    let top = measured
        .target_heights_m
        .iter()
        .fold(measured.observer_height_m, |a, &b| a.max(b))
        * 3.0;
    let top = top.max(10.0);
    let elevations: Vec<f64> = measured
        .rays
        .iter()
        .map(|r| r.elevation_deg * 60.0)
        .collect();
    let (amin, amax) = match (elevations.first(), elevations.last()) {
        (Some(&a), Some(&b)) if b > a => (a, b),
        (Some(&a), _) => (a - 1.0, a + 1.0),
        _ => (-1.0, 1.0),
    };
    let mut buffer = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let root = root
            .titled(
                &format!(
                    "Transfer curves from {} m: measured (blue) and synthetic (orange)",
                    measured.observer_height_m
                ),
                (PLOT_FONT, 20),
            )
            .map_err(plot_err)?;
        let areas = root.split_evenly((1, distances.len().max(1)));
        for ((j, d), area) in distances.iter().zip(areas.iter()) {
            let mut chart = ChartBuilder::on(area)
                .caption(format!("D = {:.1} km", d / 1000.0), (PLOT_FONT, 17))
                .margin(10)
                .x_label_area_size(40)
                .y_label_area_size(55)
                .build_cartesian_2d(amin..amax, 0.0..top)
                .map_err(plot_err)?;
            chart
                .configure_mesh()
                .x_desc("apparent elevation (arcmin)")
                .y_desc("height at distance (m)")
                .label_style((PLOT_FONT, 13))
                .draw()
                .map_err(plot_err)?;
            for &(_, th) in targets.iter().filter(|t| t.0 == *d) {
                let band = RGBColor(120, 120, 120).mix(0.15).filled();
                chart
                    .draw_series(std::iter::once(Rectangle::new(
                        [(amin, 0.0), (amax, th.min(top))],
                        band,
                    )))
                    .map_err(plot_err)?;
            }
            for (report, colour) in [(measured, MEASURED), (synthetic, SYNTHETIC)] {
                for segment in segments(report, *j, top) {
                    chart
                        .draw_series(LineSeries::new(segment, colour.stroke_width(2)))
                        .map_err(plot_err)?;
                }
            }
        }
        root.present().map_err(plot_err)?;
    }
    rgb8_to_png(&buffer, w, h)
}

/// The transfer curve at distance index `j`, split where rays do not reach it or leave the plot.
fn segments(report: &TraceReport, j: usize, top: f64) -> Vec<Vec<(f64, f64)>> {
    let mut out = Vec::new();
    let mut segment = Vec::new();
    for r in &report.rays {
        match r.heights_m.get(j).copied().flatten() {
            Some(h) if h <= top => segment.push((r.elevation_deg * 60.0, h)),
            _ if !segment.is_empty() => out.push(std::mem::take(&mut segment)),
            _ => {}
        }
    }
    if !segment.is_empty() {
        out.push(segment);
    }
    out
}
