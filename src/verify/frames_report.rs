//! Verification, frames report — the frame study's part of `BENCHMARKS.md` and its plot. In: the
//! measured [`FrameTiming`]s and [`SceneSweep`]s with their [`FrameConfig`]. Out: Markdown
//! sections ([`frames_markdown`]) and a log-log plot of time per frame against image error, one
//! line per path ([`frame_time_vs_error_png`]). Nothing here measures; every number comes in.

use std::fmt::Write as _;

use plotters::prelude::*;

use super::accuracy::fmt_tol;
use super::frames::{
    FrameConfig, FrameError, FrameTiming, PathPoint, PixelDiff, SceneSweep, SpectralTiming,
};
use crate::render::RenderOptions;

fn size(s: (u32, u32)) -> String {
    format!("{}×{}", s.0, s.1)
}

fn ms(v: f64) -> String {
    if v >= 100.0 {
        format!("{v:.0}")
    } else {
        format!("{v:.2}")
    }
}

fn changed(d: &PixelDiff) -> String {
    format!("{} ({:.1e})", d.changed, d.changed_fraction())
}

/// The frame-time section: settings, the time per frame of every path, the fan tracer inside
/// the frames.
fn timing_markdown(timings: &[FrameTiming], config: &FrameConfig) -> String {
    let nproc = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut s = String::from("## Frames: time per frame\n\n");
    let _ = writeln!(
        s,
        "* The paper figures' scene files (`data/scenes/`), rendered through the library's render \
         API with 1 sample per pixel on all {nproc} threads at the render default tolerance \
         ({tol:e} m). The time is that of `render_scene` alone: not loading the scene, its \
         atmosphere and cards, not preparing the tracer, not encoding.\n\
         * Fan path and straight rays: the median of {reps} renders. Exact 3-D path (every pixel \
         traced in 3-D): the median of {ereps} render(s); a frame of more than {max} pixels is \
         timed on a proxy, the same view at the smaller size shown, and its time scaled by the \
         ratio of pixel counts (the exact path traces every pixel).\n\
         * Straight rays: the scene with `straight = true` (`render --straight`). A straight-ray \
         scene has only that column.\n",
        tol = RenderOptions::default().tolerance_m,
        reps = config.repetitions,
        ereps = config.exact_repetitions,
        max = config.exact_max_pixels,
    );
    s.push_str(
        "| scene | size | straight rays (ms) | fan (ms) | exact 3-D (ms) | exact / fan |\n\
         |---|---|---:|---:|---:|---:|\n",
    );
    for t in timings {
        let (exact, ratio) = match (&t.exact, t.fan_ms) {
            (Some(e), Some(f)) => {
                let proxy = if e.timed_size == t.size {
                    String::new()
                } else {
                    format!(" (proxy {})", size(e.timed_size))
                };
                (
                    format!("{}{proxy}", ms(e.frame_ms)),
                    format!("{:.0}×", e.frame_ms / f),
                )
            }
            _ => ("–".into(), "–".into()),
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {exact} | {ratio} |",
            t.name,
            size(t.size),
            ms(t.straight_ms),
            t.fan_ms.map_or("–".into(), ms),
        );
    }
    s.push('\n');
    s.push_str(&fan_tracer_markdown(timings));
    s
}

/// The table of the spectral frames against their RGB frames (empty without any).
fn spectral_markdown(timings: &[SpectralTiming], config: &FrameConfig) -> String {
    if timings.is_empty() {
        return String::new();
    }
    let mut s = String::from("\n### Spectral frames\n\n");
    let _ = writeln!(
        s,
        "* Scenes with `[render] spectral_bands`, rendered on the fan path at the render default \
         tolerance with 1 sample per pixel, the median of {reps} renders each. *RGB*: the same \
         scene on the RGB path, `render_scene` alone. *Spectral*: `render_spectral`, which \
         rebuilds the refractive atmosphere and the tracer at each band's wavelength, renders \
         every band and integrates the bands to Rec.709.\n",
        reps = config.repetitions,
    );
    s.push_str(
        "| scene | size | bands | RGB (ms) | spectral (ms) | spectral / RGB |\n\
         |---|---|---:|---:|---:|---:|\n",
    );
    for t in timings {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {:.1}× |",
            t.name,
            size(t.size),
            t.bands,
            ms(t.rgb_ms),
            ms(t.spectral_ms),
            t.spectral_ms / t.rgb_ms,
        );
    }
    s
}

/// The table of the fan tracer inside the frames.
fn fan_tracer_markdown(timings: &[FrameTiming]) -> String {
    let mut s = String::from(
        "### The fan tracer inside the frames\n\n\
         *Fan rays*: the rays the renderer traced for the frame's elevation fan, counted in one \
         more, untimed render through a wrapper that records every call (its pixels are checked \
         to equal the timed render's). *Tracer time*: the time inside those calls, summed over \
         threads; rays/s and steps/s are per thread inside the tracer. *Steps/ray* (accepted + \
         rejected): every recorded ray re-traced with the planar tracer as the renderer's \
         `CurvedRays` traces it, checked bit for bit against the renderer's ray (– if any \
         differs, or the recorded render's pixels differ from the timed one's).\n\n\
         | scene | size | fan rays | tracer time (ms) | rays/s | steps/ray | steps/s |\n\
         |---|---|---:|---:|---:|---:|---:|\n",
    );
    for t in timings {
        let Some(f) = &t.fan else { continue };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.0} | {} | {} |",
            t.name,
            size(t.size),
            f.fan_rays,
            ms(f.tracer_s * 1e3),
            f.rays_per_s(),
            f.steps_per_ray.map_or("–".into(), |v| format!("{v:.1}")),
            f.steps_per_s().map_or("–".into(), |v| format!("{v:.3e}")),
        );
    }
    s
}

fn rays(p: &PathPoint) -> String {
    format!(
        "{} ({} trapped, {} lost)",
        p.rays, p.trapped_rays, p.lost_rays
    )
}

/// One scene's sweep table.
fn sweep_table(sw: &SceneSweep) -> String {
    let mut s = format!("### {}\n\n", sw.name);
    let (f, e, st) = (&sw.fan_reference, &sw.exact_reference, &sw.straight);
    let _ = writeln!(
        s,
        "{}. Fan reference: {} ms, {} fan rays. Exact reference: {} ms, {} pixel rays; it \
         differs from the fan reference in {} pixels, max Δ {}. Straight rays: {} ms; they \
         differ from the fan reference in {} pixels, max Δ {}.\n",
        size(sw.size),
        ms(f.frame_ms),
        rays(f),
        ms(e.frame_ms),
        rays(e),
        changed(&e.diff),
        e.diff.max_channel,
        ms(st.frame_ms),
        changed(&st.diff),
        st.diff.max_channel,
    );
    s.push_str(
        "| tolerance (m) | fan (ms) | fan rays | fan changed | fan max Δ | exact 3-D (ms) | \
         exact trapped / lost rays | exact changed | exact max Δ |\n\
         |---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for row in &sw.rows {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} / {} | {} | {} |",
            fmt_tol(row.tolerance_m),
            ms(row.fan.frame_ms),
            rays(&row.fan),
            changed(&row.fan.diff),
            row.fan.diff.max_channel,
            ms(row.exact.frame_ms),
            row.exact.trapped_rays,
            row.exact.lost_rays,
            changed(&row.exact.diff),
            row.exact.diff.max_channel,
        );
    }
    s
}

/// The frame study's sections of `BENCHMARKS.md` (`##` headings): time per frame (with the
/// spectral scenes' cost against RGB), then image error against tolerance with the plot at
/// `plot_rel` (relative to the file).
pub fn frames_markdown(
    timings: &[FrameTiming],
    spectral: &[SpectralTiming],
    sweeps: &[SceneSweep],
    config: &FrameConfig,
    plot_rel: &str,
) -> String {
    let mut s = timing_markdown(timings, config);
    s.push_str(&spectral_markdown(spectral, config));
    let _ = writeln!(
        s,
        "\n## Frames: image error against tolerance\n\n\
         * Each curved-ray paper scene at {sz}, 1 sample per pixel, rendered at every tolerance \
         on the fan path and on the exact 3-D path, against a render of the same path at \
         {rt:e} m, the tightest tolerance `ghostship render` accepts (the ray study's 1e-7 m is \
         outside its range), with the renderer's own step budget.\n\
         * *Trapped* rays oscillate in a duct for ever (proved by Bouguer's invariant) and \
         *lost* rays were cut short (step budget, non-finite field); neither reaches the sea or \
         the sky, and both are shaded as the horizon-sky fallback. Trapped rays are physics; a \
         reference with lost rays is wrong where they are, and the rows below compare with it \
         all the same. The exact path traces one ray per pixel.\n\
         * Image error on the 8-bit sRGB pixels of the PNG output (exposure {exp}): **changed** \
         — pixels of which any channel differs (count, and fraction of the frame); **max Δ** — \
         the largest difference of one channel (of 255).\n\
         * Time: `render_scene` alone, all threads; fan path the median of {reps} renders, exact \
         path of {ereps}.\n\n\
         ![frame time against image error]({plot_rel})\n\n\
         The plot: for each tolerance, the mean time per frame over the {n} curved scenes \
         against the fraction of their pixels (all {n} frames together) that change; one line \
         per path, points labelled by tolerance (m); straight rays as one point, their pixels \
         against the fan reference. A sweep in which no pixel changes is drawn on the dotted \
         floor line.\n",
        sz = size(config.sweep_size),
        rt = config.reference_tolerance_m,
        exp = config.exposure,
        reps = config.repetitions,
        ereps = config.exact_repetitions,
        n = sweeps.len(),
    );
    for sw in sweeps {
        s.push_str(&sweep_table(sw));
        s.push('\n');
    }
    s
}

/// One point of the plot: mean frame time (ms), fraction of pixels changed, over all sweeps.
fn mean_point(points: &[&PathPoint]) -> (f64, f64) {
    let n = points.len().max(1) as f64;
    let t = points.iter().map(|p| p.frame_ms).sum::<f64>() / n;
    let d = points
        .iter()
        .fold(PixelDiff::default(), |acc, p| acc.combined(p.diff));
    (t, d.changed_fraction())
}

/// The plot's lines: per tolerance (mean ms, changed fraction, tolerance), fan then exact; and
/// the straight-ray point.
type Lines = (Vec<(f64, f64, f64)>, Vec<(f64, f64, f64)>, (f64, f64));

fn plot_lines(sweeps: &[SceneSweep], config: &FrameConfig) -> Lines {
    let line = |pick: fn(&super::frames::SweepRow) -> &PathPoint| {
        (0..config.tolerances_m.len())
            .filter_map(|i| {
                let pts: Vec<&PathPoint> = sweeps
                    .iter()
                    .filter_map(|s| s.rows.get(i).map(pick))
                    .collect();
                (!pts.is_empty()).then(|| {
                    let (t, f) = mean_point(&pts);
                    (t, f, config.tolerances_m[i])
                })
            })
            .collect::<Vec<_>>()
    };
    let straight: Vec<&PathPoint> = sweeps.iter().map(|s| &s.straight).collect();
    (line(|r| &r.fan), line(|r| &r.exact), mean_point(&straight))
}

fn plot_err<E: std::fmt::Display>(e: E) -> FrameError {
    FrameError::Plot(e.to_string())
}

/// The log-log plot of time per frame against the fraction of pixels changed (see
/// [`frames_markdown`]): PNG bytes, `width × height` pixels.
pub fn frame_time_vs_error_png(
    sweeps: &[SceneSweep],
    config: &FrameConfig,
    width: u32,
    height: u32,
) -> Result<Vec<u8>, FrameError> {
    crate::output::plot::register_plot_font().map_err(FrameError::Plot)?;
    let font = crate::output::plot::PLOT_FONT;
    let (fan, exact, straight) = plot_lines(sweeps, config);
    let pixels: usize = sweeps.iter().map(|s| s.straight.diff.pixels).sum();
    let floor = 0.5 / pixels.max(1) as f64;
    let all: Vec<(f64, f64)> = fan
        .iter()
        .chain(&exact)
        .map(|p| (p.0, p.1))
        .chain([straight])
        .collect();
    let (mut x0, mut x1, mut y1) = (f64::INFINITY, 0.0f64, floor);
    for &(x, y) in &all {
        if x.is_finite() && x > 0.0 {
            x0 = x0.min(x);
            x1 = x1.max(x);
        }
        y1 = y1.max(y);
    }
    if !x0.is_finite() {
        (x0, x1) = (1.0, 10.0);
    }
    let (x0, x1, y0, y1) = (x0 / 2.0, x1 * 2.0, floor / 2.0, (y1 * 2.0).min(2.0));
    let clamp = move |y: f64| y.max(floor);

    let mut buffer = vec![255u8; width as usize * height as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let title = format!(
            "Time per frame against image error ({}, 1 spp, {} curved paper scenes)",
            size(config.sweep_size),
            sweeps.len()
        );
        let mut chart = ChartBuilder::on(&root)
            .caption(title, (font, 24))
            .margin(20)
            .x_label_area_size(50)
            .y_label_area_size(90)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .x_desc("mean time per frame (ms, render only, all threads)")
            .y_desc(format!(
                "pixels changed vs the {:e} m render (fraction)",
                config.reference_tolerance_m
            ))
            .x_label_formatter(&|v| {
                let s = format!("{v:.3}");
                s.trim_end_matches('0').trim_end_matches('.').to_string()
            })
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .label_style((font, 16))
            .axis_desc_style((font, 18))
            .draw()
            .map_err(plot_err)?;
        let grey = RGBColor(120, 120, 120);
        chart
            .draw_series(DashedLineSeries::new(
                [(x0, floor), (x1, floor)],
                4,
                6,
                grey.stroke_width(1),
            ))
            .map_err(plot_err)?
            .label("no pixel changed (drawn here)")
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], grey.stroke_width(1))
            });
        let paths = [
            ("fan path", RGBColor(31, 119, 180), &fan),
            ("exact 3-D path", RGBColor(220, 20, 60), &exact),
        ];
        for (label, colour, pts) in paths {
            let line: Vec<(f64, f64)> = pts.iter().map(|p| (p.0, clamp(p.1))).collect();
            chart
                .draw_series(LineSeries::new(line, colour.stroke_width(2)))
                .map_err(plot_err)?
                .label(label)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(3))
                });
            // Labels alternate above and below the line, so neighbours do not overlap.
            chart
                .draw_series(pts.iter().enumerate().map(|(i, &(x, y, t))| {
                    let dy = if i % 2 == 0 { -16 } else { 4 };
                    EmptyElement::at((x, clamp(y)))
                        + Circle::new((0, 0), 4, colour.filled())
                        + Text::new(fmt_tol(t), (7, dy), (font, 13).into_font())
                }))
                .map_err(plot_err)?;
        }
        let green = RGBColor(34, 139, 34);
        chart
            .draw_series([straight].iter().map(|&(x, y)| {
                EmptyElement::at((x, clamp(y)))
                    + Rectangle::new([(-5, -5), (5, 5)], green.filled())
                    + Text::new("straight rays", (8, -16), (font, 13).into_font())
            }))
            .map_err(plot_err)?
            .label("straight rays (no tolerance)")
            .legend(move |(x, y)| {
                Rectangle::new([(x + 4, y - 5), (x + 14, y + 5)], green.filled())
            });
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font((font, 14))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(plot_err)?;
        root.present().map_err(plot_err)?;
    }
    crate::output::plot::rgb8_to_png(&buffer, width, height).map_err(FrameError::Plot)
}
