//! Survey — plots. In: [`SurveyRow`]s and their [`SurveyOptions`]. Out: PNG bytes of
//! `monthly.png` (per observer height, the share of usable soundings of each month showing a
//! superior mirage, an inferior mirage, a Fata Morgana, the Novaya Zemlya effect or a duct),
//! `ducts.png` (the strongest duct's M deficit of every sounding against time) and `dip.png`
//! (histogram of the horizon-dip anomaly against the standard atmosphere, per observer height).

use plotters::prelude::*;

use super::{SurveyOptions, SurveyRow};
use crate::output::plot::{PLOT_FONT, register_plot_font, rgb8_to_png};

fn plot_err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// Line colours, one per phenomenon.
const COLOURS: [RGBColor; 5] = [
    RGBColor(20, 90, 200),
    RGBColor(230, 110, 0),
    RGBColor(40, 160, 60),
    RGBColor(200, 30, 40),
    RGBColor(120, 120, 120),
];

/// A phenomenon of a row at observer height index `k`, any distance.
type Phenomenon = fn(&SurveyRow, usize, usize) -> bool;

fn any_case(r: &SurveyRow, k: usize, n: usize, f: fn(&super::CaseFacts) -> bool) -> bool {
    r.cases.iter().skip(k * n).take(n).any(f)
}

const PHENOMENA: [(&str, Phenomenon); 5] = [
    ("superior mirage", |r, k, n| {
        any_case(r, k, n, |c| c.superior)
    }),
    ("inferior mirage", |r, k, n| {
        any_case(r, k, n, |c| c.inferior)
    }),
    ("Fata Morgana (≥ 3 images)", |r, k, n| {
        any_case(r, k, n, |c| c.images >= 3)
    }),
    ("Novaya Zemlya sun", |r, k, _| {
        r.observers.get(k).is_some_and(|o| o.novaya_zemlya)
    }),
    ("duct (any height)", |r, _, _| r.layers.duct_count > 0),
];

/// Draw `monthly.png`.
pub fn monthly_png(rows: &[SurveyRow], options: &SurveyOptions) -> Result<Vec<u8>, String> {
    register_plot_font()?;
    let panels = options.observer_heights_m.len();
    let (w, h) = (1200u32, 80 + 380 * panels as u32);
    let n = options.distances_m.len();
    let used: Vec<&SurveyRow> = rows.iter().filter(|r| r.unusable.is_none()).collect();
    let mut buffer = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let title = format!(
            "Share of soundings per month with each phenomenon ({} usable of {})",
            used.len(),
            rows.len()
        );
        let root = root.titled(&title, (PLOT_FONT, 22)).map_err(plot_err)?;
        for (k, area) in root.split_evenly((panels, 1)).iter().enumerate() {
            let per_month: Vec<Vec<&SurveyRow>> = (1..=12)
                .map(|m| {
                    used.iter()
                        .copied()
                        .filter(|r| r.month() == Some(m))
                        .collect()
                })
                .collect();
            let caption = format!(
                "observer {} m, target {} m at {}",
                options.observer_heights_m[k],
                options.target_height_m,
                distances_label(&options.distances_m)
            );
            // Each month's label carries its number of soundings: a share of 2 is not one of 200.
            let counts: Vec<usize> = per_month.iter().map(Vec::len).collect();
            let month_label = |v: &f64| {
                let m = v.round() as usize;
                match (MONTHS.get(m.wrapping_sub(1)), counts.get(m.wrapping_sub(1))) {
                    (Some(name), Some(count)) => format!("{name} ({count})"),
                    _ => String::new(),
                }
            };
            let mut chart = ChartBuilder::on(area)
                .caption(caption, (PLOT_FONT, 17))
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(60)
                .build_cartesian_2d(0.5f64..12.5, 0f64..100.0)
                .map_err(plot_err)?;
            chart
                .configure_mesh()
                .x_desc("month (number of usable soundings)")
                .y_desc("soundings (%)")
                .x_labels(12)
                .x_label_formatter(&month_label)
                .label_style((PLOT_FONT, 14))
                .light_line_style(RGBColor(235, 235, 235))
                .draw()
                .map_err(plot_err)?;
            for (p, (label, test)) in PHENOMENA.iter().enumerate() {
                let points: Vec<(f64, f64)> = per_month
                    .iter()
                    .enumerate()
                    .filter(|(_, rs)| !rs.is_empty())
                    .map(|(m, rs)| {
                        let hits = rs.iter().filter(|r| test(r, k, n)).count();
                        ((m + 1) as f64, 100.0 * hits as f64 / rs.len() as f64)
                    })
                    .collect();
                let colour = COLOURS[p];
                // Lines join neighbouring months only: a month without soundings is a gap.
                for run in points.chunk_by(|a, b| b.0 - a.0 == 1.0) {
                    chart
                        .draw_series(LineSeries::new(run.to_vec(), colour.stroke_width(2)))
                        .map_err(plot_err)?;
                }
                chart
                    .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
                    .map_err(plot_err)?
                    .label(*label)
                    .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], colour));
                chart
                    .draw_series(points.iter().map(|&p| Circle::new(p, 4, colour.filled())))
                    .map_err(plot_err)?;
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK.mix(0.3))
                .label_font((PLOT_FONT, 14))
                .position(SeriesLabelPosition::UpperRight)
                .draw()
                .map_err(plot_err)?;
        }
    }
    rgb8_to_png(&buffer, w, h)
}

const MONTHS: [&str; 12] = [
    "Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec",
];

fn distances_label(distances_m: &[f64]) -> String {
    let km: Vec<String> = distances_m
        .iter()
        .map(|d| format!("{}", d / 1000.0))
        .collect();
    format!("{} km", km.join(", "))
}

/// Days since 1970-01-01 (with the hour as a fraction) of `"YYYY-MM-DD HH"`.
fn days_since_epoch(time: &str) -> Option<f64> {
    let num = |a: usize, b: usize| time.get(a..b)?.parse::<i64>().ok();
    let (y, m, d) = (num(0, 4)?, num(5, 7)?, num(8, 10)?);
    let hour = num(11, 13).unwrap_or(0);
    // Civil date to days (H. Hinnant's algorithm).
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let doy = (153 * ((m + 9) % 12) + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    Some((era * 146_097 + doe - 719_468) as f64 + hour as f64 / 24.0)
}

/// Draw `ducts.png`: the strongest duct's M deficit (0 without a duct) of every usable sounding
/// with a known time, against time (years).
pub fn ducts_png(rows: &[SurveyRow]) -> Result<Vec<u8>, String> {
    register_plot_font()?;
    let points: Vec<(f64, f64, bool)> = rows
        .iter()
        .filter(|r| r.unusable.is_none())
        .filter_map(|r| {
            let t = 1970.0 + days_since_epoch(r.time_utc.as_deref()?)? / 365.2425;
            let m = r.layers.strongest_duct.map_or(0.0, |d| d.2);
            Some((t, m, r.layers.surface_duct))
        })
        .collect();
    let (w, h) = (1200u32, 500u32);
    let (t0, t1) = span(points.iter().map(|p| p.0), 0.05);
    let top = points.iter().map(|p| p.1).fold(1.0f64, f64::max) * 1.1;
    let mut buffer = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!(
                    "Strongest duct of each sounding ({} soundings)",
                    points.len()
                ),
                (PLOT_FONT, 20),
            )
            .margin(14)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(t0..t1, 0f64..top)
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .x_desc("year")
            .y_desc("duct strength ΔM (M-units)")
            // Decimals by span, so that ticks a fraction of a year apart read apart.
            .x_label_formatter(&|v| match t1 - t0 {
                s if s > 20.0 => format!("{v:.0}"),
                s if s > 2.0 => format!("{v:.1}"),
                _ => format!("{v:.2}"),
            })
            .label_style((PLOT_FONT, 14))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()
            .map_err(plot_err)?;
        for (surface, colour, label) in [
            (true, COLOURS[3], "surface-based duct"),
            (false, COLOURS[0], "elevated duct (or none: 0)"),
        ] {
            chart
                .draw_series(
                    points
                        .iter()
                        .filter(|p| p.2 == surface)
                        .map(|&(t, m, _)| Circle::new((t, m), 4, colour.filled())),
                )
                .map_err(plot_err)?
                .label(label)
                .legend(move |(x, y)| Circle::new((x + 8, y), 4, colour.filled()));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.3))
            .label_font((PLOT_FONT, 14))
            .draw()
            .map_err(plot_err)?;
    }
    rgb8_to_png(&buffer, w, h)
}

fn span(values: impl Iterator<Item = f64>, pad: f64) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    if !(lo.is_finite() && hi.is_finite()) {
        return (0.0, 1.0);
    }
    let pad = pad.max((hi - lo) * 0.05);
    (lo - pad, hi + pad)
}

/// Draw `dip.png`: per observer height, a histogram of the horizon dip minus the standard
/// atmosphere's (deg; positive: the horizon lies lower than normal).
pub fn dip_png(rows: &[SurveyRow], options: &SurveyOptions) -> Result<Vec<u8>, String> {
    register_plot_font()?;
    let panels = options.observer_heights_m.len();
    let (w, h) = (1000u32, 60 + 340 * panels as u32);
    let mut buffer = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let root = root
            .titled(
                "Horizon dip minus the standard atmosphere's",
                (PLOT_FONT, 22),
            )
            .map_err(plot_err)?;
        for (k, area) in root.split_evenly((panels, 1)).iter().enumerate() {
            let values: Vec<f64> = rows
                .iter()
                .filter_map(|r| r.observers.get(k)?.dip_anomaly_deg)
                .collect();
            draw_histogram(area, &values, options.observer_heights_m[k])?;
        }
    }
    rgb8_to_png(&buffer, w, h)
}

fn draw_histogram<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    values: &[f64],
    observer_height_m: f64,
) -> Result<(), String> {
    let (lo, hi) = span(values.iter().copied(), 0.01);
    let bins = 30usize;
    let width = (hi - lo) / bins as f64;
    let mut counts = vec![0u32; bins];
    for v in values {
        counts[(((v - lo) / width) as usize).min(bins - 1)] += 1;
    }
    let top = counts.iter().copied().max().unwrap_or(0).max(1) as f64 * 1.15;
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!(
                "observer {observer_height_m} m ({} soundings)",
                values.len()
            ),
            (PLOT_FONT, 17),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(55)
        .build_cartesian_2d(lo..hi, 0f64..top)
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .x_desc("dip anomaly (deg; > 0: horizon lower than in the standard atmosphere)")
        .y_desc("soundings")
        .y_label_formatter(&|v| {
            if v.fract() == 0.0 {
                format!("{v:.0}")
            } else {
                String::new()
            }
        })
        .x_label_formatter(&|v| format!("{v:.3}"))
        .label_style((PLOT_FONT, 14))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(plot_err)?;
    chart
        .draw_series(counts.iter().enumerate().map(|(i, &c)| {
            let x0 = lo + i as f64 * width;
            Rectangle::new(
                [(x0, 0.0), (x0 + width, c as f64)],
                COLOURS[0].mix(0.7).filled(),
            )
        }))
        .map_err(plot_err)?;
    chart
        .draw_series(LineSeries::new(
            [(0.0, 0.0), (0.0, top)],
            BLACK.mix(0.6).stroke_width(1),
        ))
        .map_err(plot_err)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::days_since_epoch;

    #[test]
    fn civil_days_match_known_dates() {
        assert_eq!(days_since_epoch("1970-01-01 00"), Some(0.0));
        assert_eq!(days_since_epoch("2000-03-01 12"), Some(11_017.5));
        assert_eq!(days_since_epoch("2024-02-29 00"), Some(19_782.0));
    }
}
