//! Stage 3 output (`profile` command) — `profile.png`. In: a [`ProfilePlot`] (the atmosphere,
//! its measured levels and layers) and [`PlotOptions`]. Out: PNG bytes of temperature and dn/dh
//! against height, side by side.
//!
//! Left panel: the measured levels as dots, the fitted T(h) as a line, inversion layers shaded.
//! Right panel: dN/dh (N-units per km, i.e. dn/dh·10⁹ m) with the −1/R trapping line and the 0 line
//! (rays curve upward to its right), refractive layers shaded. Heights on the y axis, above mean
//! sea level. Drawn with plotters into an RGB buffer, encoded with `image`.

use plotters::prelude::*;

use super::ReportError;
use crate::profile::InversionLayer;
use crate::refractivity::{RefractiveAtmosphere, RefractiveLayer, RegimeKind};
use crate::sounding::Level;
use crate::units::{EARTH_RADIUS_M, kelvin_to_celsius};

const FONT: &str = crate::output::plot::PLOT_FONT;

fn register_font() -> Result<(), ReportError> {
    crate::output::plot::register_plot_font().map_err(ReportError::Plot)
}

/// What to draw.
#[derive(Debug, Clone, Copy)]
pub struct ProfilePlot<'a> {
    /// The refractive atmosphere (with the fitted air column).
    pub atmosphere: &'a RefractiveAtmosphere,
    /// Measured sounding levels (drawn as dots; may be empty for synthetic atmospheres).
    pub levels: &'a [Level],
    /// Inversion layers (shaded in the temperature panel).
    pub inversions: &'a [InversionLayer],
    /// Refractive layers (shaded in the dn/dh panel).
    pub regimes: &'a [RefractiveLayer],
    /// Title above the panels (station, time …).
    pub title: &'a str,
}

/// Size and height range of the plot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlotOptions {
    /// Image width (pixels).
    pub width_px: u32,
    /// Image height (pixels).
    pub height_px: u32,
    /// Lowest height drawn, above the surface (m).
    pub bottom_agl_m: f64,
    /// Highest height drawn, above the surface (m).
    pub top_agl_m: f64,
}

impl Default for PlotOptions {
    /// 1400 × 900 pixels, the lowest 1.5 km (where mirage layers live).
    fn default() -> Self {
        Self {
            width_px: 1400,
            height_px: 900,
            bottom_agl_m: 0.0,
            top_agl_m: 1_500.0,
        }
    }
}

fn plot_err<E: std::fmt::Display>(e: E) -> ReportError {
    ReportError::Plot(e.to_string())
}

/// (min, max) of the finite values, padded by 5 % (at least `min_pad`).
fn padded_range(values: impl Iterator<Item = f64>, min_pad: f64) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !lo.is_finite() {
        return (-1.0, 1.0);
    }
    let pad = (0.05 * (hi - lo)).max(min_pad);
    (lo - pad, hi + pad)
}

fn regime_colour(kind: RegimeKind) -> RGBColor {
    match kind {
        RegimeKind::Trapping => RGBColor(70, 110, 230),
        RegimeKind::SuperRefraction => RGBColor(120, 190, 250),
        RegimeKind::InferiorMirage => RGBColor(255, 170, 60),
    }
}

/// Draw `profile.png` and return its bytes.
pub fn profile_png(plot: &ProfilePlot<'_>, options: &PlotOptions) -> Result<Vec<u8>, ReportError> {
    let (w, h) = (options.width_px, options.height_px);
    if !(200..=8000).contains(&w) || !(150..=8000).contains(&h) {
        return Err(ReportError::InvalidOptions(format!(
            "size {w}×{h} px (200–8000 × 150–8000)"
        )));
    }
    let (b, t) = (options.bottom_agl_m, options.top_agl_m);
    if !(b.is_finite() && t.is_finite() && b >= 0.0 && t > b) {
        return Err(ReportError::InvalidOptions(format!(
            "height range {b}–{t} m above the surface"
        )));
    }
    register_font()?;
    let atm = plot.atmosphere;
    let surface = atm.surface_height_m();
    let (y0, y1) = (surface + b, surface + t);
    // Curves: 1500 samples of the exact profile.
    let steps = 1500;
    let curve: Vec<(f64, f64, f64)> = (0..=steps)
        .map(|i| {
            let z = y0 + (y1 - y0) * i as f64 / steps as f64;
            let s = atm.sample_at(z);
            (
                z,
                kelvin_to_celsius(s.air.temperature_k),
                s.dn_dh_per_m * 1e9,
            )
        })
        .filter(|(_, t, d)| t.is_finite() && d.is_finite())
        .collect();
    let dots: Vec<(f64, f64)> = plot
        .levels
        .iter()
        .filter(|l| l.height_m >= y0 && l.height_m <= y1 && l.temperature_k.is_finite())
        .map(|l| (kelvin_to_celsius(l.temperature_k), l.height_m))
        .collect();
    let (t_lo, t_hi) = padded_range(
        curve.iter().map(|c| c.1).chain(dots.iter().map(|d| d.0)),
        0.5,
    );
    let trap = -1e9 / EARTH_RADIUS_M;
    let (d_lo, d_hi) = padded_range(
        curve.iter().map(|c| c.2).chain([trap * 1.3, 0.0, 20.0]),
        5.0,
    );

    let mut buffer = vec![255u8; w as usize * h as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let root = root
            .titled(plot.title, (FONT, 24).into_font())
            .map_err(plot_err)?;
        let (left, right) = root.split_horizontally(w / 2);
        let label_font = (FONT, 16).into_font();

        // Temperature panel.
        let mut chart = ChartBuilder::on(&left)
            .caption("Temperature", (FONT, 20))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(t_lo..t_hi, y0..y1)
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .x_desc("temperature (°C)")
            .y_desc("height above sea level (m)")
            .y_label_formatter(&|v| format!("{v:.0}"))
            .label_style(label_font.clone())
            .axis_desc_style((FONT, 17))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()
            .map_err(plot_err)?;
        let inv_fill = RGBColor(240, 120, 100).mix(0.25).filled();
        let mut first = true;
        for inv in plot.inversions {
            let (lo, hi) = (inv.base_m.max(y0), inv.top_m.min(y1));
            if hi.is_nan() || lo.is_nan() || hi <= lo {
                continue;
            }
            let series = chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(t_lo, lo), (t_hi, hi)],
                    inv_fill,
                )))
                .map_err(plot_err)?;
            if first {
                series
                    .label("inversion")
                    .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 18, y + 6)], inv_fill));
                first = false;
            }
        }
        chart
            .draw_series(LineSeries::new(
                curve.iter().map(|c| (c.1, c.0)),
                RED.stroke_width(2),
            ))
            .map_err(plot_err)?
            .label("fitted T(h)")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], RED.stroke_width(2)));
        if !dots.is_empty() {
            chart
                .draw_series(dots.iter().map(|&p| Circle::new(p, 4, BLACK.filled())))
                .map_err(plot_err)?
                .label("sounding levels")
                .legend(|(x, y)| Circle::new((x + 9, y), 4, BLACK.filled()));
        }
        chart
            .configure_series_labels()
            .label_font(label_font.clone())
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperLeft)
            .draw()
            .map_err(plot_err)?;

        // dn/dh panel.
        let mut chart = ChartBuilder::on(&right)
            .caption("Refractivity gradient", (FONT, 20))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(d_lo..d_hi, y0..y1)
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .x_desc("dN/dh (N-units per km) = dn/dh × 10⁹ m")
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_desc("height above sea level (m)")
            .y_label_formatter(&|v| format!("{v:.0}"))
            .label_style(label_font.clone())
            .axis_desc_style((FONT, 17))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()
            .map_err(plot_err)?;
        let mut labelled = [false; 3];
        for layer in plot.regimes {
            let (lo, hi) = (layer.base_m.max(y0), layer.top_m.min(y1));
            if hi.is_nan() || lo.is_nan() || hi <= lo {
                continue;
            }
            let fill = regime_colour(layer.kind).mix(0.3).filled();
            let series = chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(d_lo, lo), (d_hi, hi)],
                    fill,
                )))
                .map_err(plot_err)?;
            let slot = layer.kind as usize;
            if !labelled[slot] {
                let name = match layer.kind {
                    RegimeKind::Trapping => "trapping layer",
                    RegimeKind::SuperRefraction => "super-refraction",
                    RegimeKind::InferiorMirage => "inferior-mirage layer",
                };
                series
                    .label(name)
                    .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 18, y + 6)], fill));
                labelled[slot] = true;
            }
        }
        chart
            .draw_series(LineSeries::new(
                [(0.0, y0), (0.0, y1)],
                BLACK.stroke_width(1),
            ))
            .map_err(plot_err)?;
        chart
            .draw_series(DashedLineSeries::new(
                [(trap, y0), (trap, y1)],
                8,
                6,
                RGBColor(0, 90, 200).stroke_width(2),
            ))
            .map_err(plot_err)?
            .label("−1/R (trapping, −157 N/km)")
            .legend(|(x, y)| {
                PathElement::new(
                    vec![(x, y), (x + 18, y)],
                    RGBColor(0, 90, 200).stroke_width(2),
                )
            });
        chart
            .draw_series(LineSeries::new(
                curve.iter().map(|c| (c.2, c.0)),
                RGBColor(20, 20, 20).stroke_width(2),
            ))
            .map_err(plot_err)?
            .label("dN/dh")
            .legend(|(x, y)| {
                PathElement::new(
                    vec![(x, y), (x + 18, y)],
                    RGBColor(20, 20, 20).stroke_width(2),
                )
            });
        chart
            .configure_series_labels()
            .label_font(label_font)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperLeft)
            .draw()
            .map_err(plot_err)?;
        root.present().map_err(plot_err)?;
    }
    crate::output::plot::rgb8_to_png(&buffer, w, h).map_err(ReportError::Encode)
}
