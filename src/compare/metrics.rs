//! Stage 6 — comparison: image metrics. In: two films of one scene (measured and synthetic
//! atmosphere) and the PNG exposure. Out: [`ImageMetrics`] (RMSE, SSIM, changed pixels) on the
//! 8-bit images a user looks at, and the labelled side-by-side figure measured | synthetic |
//! difference.
//!
//! SSIM is `image-compare`'s (8 × 8 windows, Wang et al.'s constants, on luma); the RMSE and the
//! difference image are one line of arithmetic each and are computed here.

use serde::Serialize;

use crate::output::png::{encode_rgb8, film_to_srgb8};
use crate::render::Film;

/// Why two films could not be compared.
#[derive(Debug, thiserror::Error)]
pub enum CompareError {
    /// The films differ in size.
    #[error("the images differ in size: {0}×{1} and {2}×{3} pixels")]
    Size(u32, u32, u32, u32),
    /// A film's pixel count is not width × height.
    #[error("a {0}×{1} film holds {2} pixels")]
    Malformed(u32, u32, usize),
    /// SSIM could not be computed.
    #[error("SSIM: {0}")]
    Ssim(String),
    /// The labels could not be drawn.
    #[error("cannot label the side-by-side figure: {0}")]
    Label(String),
    /// The figure could not be encoded.
    #[error("cannot encode the side-by-side figure")]
    Encode(#[from] image::ImageError),
}

/// How different two renders look (8-bit sRGB luma, values on a 0–1 scale).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ImageMetrics {
    /// Root-mean-square luma difference (0 = identical, 1 = black against white).
    pub rmse: f64,
    /// Mean structural similarity (1 = identical).
    pub ssim: f64,
    /// Fraction of pixels whose luma differs by more than 2/255.
    pub changed_fraction: f64,
}

/// Rec. 709 luma of 8-bit sRGB pixels (the gray image SSIM is computed on).
fn luma(rgb: &[u8]) -> Vec<u8> {
    rgb.chunks_exact(3)
        .map(|p| {
            let y = 0.2126 * p[0] as f64 + 0.7152 * p[1] as f64 + 0.0722 * p[2] as f64;
            y.round().clamp(0.0, 255.0) as u8
        })
        .collect()
}

fn check(a: &Film, b: &Film) -> Result<(), CompareError> {
    for f in [a, b] {
        if f.pixels.len() != f.width as usize * f.height as usize {
            return Err(CompareError::Malformed(f.width, f.height, f.pixels.len()));
        }
    }
    if (a.width, a.height) != (b.width, b.height) {
        return Err(CompareError::Size(a.width, a.height, b.width, b.height));
    }
    Ok(())
}

/// RMSE, SSIM and changed fraction of `b` against `a`, both tone-mapped with `exposure`.
pub fn image_metrics(a: &Film, b: &Film, exposure: f64) -> Result<ImageMetrics, CompareError> {
    check(a, b)?;
    let (ya, yb) = (
        luma(&film_to_srgb8(a, exposure)),
        luma(&film_to_srgb8(b, exposure)),
    );
    let n = ya.len().max(1) as f64;
    let (mut sum_sq, mut changed) = (0.0, 0usize);
    for (&p, &q) in ya.iter().zip(&yb) {
        let d = (p as f64 - q as f64) / 255.0;
        sum_sq += d * d;
        changed += usize::from(p.abs_diff(q) > 2);
    }
    let gray = |y: Vec<u8>| image::GrayImage::from_raw(a.width, a.height, y);
    let (ga, gb) = match (gray(ya), gray(yb)) {
        (Some(ga), Some(gb)) => (ga, gb),
        _ => return Err(CompareError::Malformed(a.width, a.height, a.pixels.len())),
    };
    let ssim =
        image_compare::gray_similarity_structure(&image_compare::Algorithm::MSSIMSimple, &ga, &gb)
            .map_err(|e| CompareError::Ssim(e.to_string()))?
            .score;
    Ok(ImageMetrics {
        rmse: (sum_sq / n).sqrt(),
        ssim,
        changed_fraction: changed as f64 / n,
    })
}

/// Gap between the panels of the side-by-side figure (pixels).
const GAP_PX: u32 = 6;
/// Height of the label strip above the panels (pixels).
const LABEL_PX: u32 = 22;
/// The difference panel shows |Δ| amplified by this factor.
pub const DIFFERENCE_GAIN: f64 = 4.0;

/// The PNG figure `a | b | difference` under a strip of labels (`labels`, one per panel): the
/// two renders tone-mapped with `exposure` and, right, the per-channel |b − a| ×
/// [`DIFFERENCE_GAIN`] on black, white gaps between the panels.
pub fn side_by_side_png(
    a: &Film,
    b: &Film,
    exposure: f64,
    labels: [&str; 3],
) -> Result<Vec<u8>, CompareError> {
    check(a, b)?;
    let (w, h) = (a.width, a.height);
    let (ra, rb) = (film_to_srgb8(a, exposure), film_to_srgb8(b, exposure));
    let diff: Vec<u8> = ra
        .iter()
        .zip(&rb)
        .map(|(&p, &q)| (p.abs_diff(q) as f64 * DIFFERENCE_GAIN).min(255.0) as u8)
        .collect();
    let total_w = 3 * w + 2 * GAP_PX;
    let total_h = h + LABEL_PX;
    let mut out = vec![255u8; (total_w * total_h * 3) as usize];
    for (panel, rgb) in [&ra, &rb, &diff].into_iter().enumerate() {
        let x0 = panel as u32 * (w + GAP_PX);
        for y in 0..h {
            let src = (y * w * 3) as usize..((y + 1) * w * 3) as usize;
            let dst = (((y + LABEL_PX) * total_w + x0) * 3) as usize;
            out[dst..dst + src.len()].copy_from_slice(&rgb[src]);
        }
    }
    draw_labels(&mut out, (total_w, total_h), w + GAP_PX, labels)?;
    Ok(encode_rgb8(&out, total_w, total_h)?)
}

/// Write `labels` into the strip above each panel (`pitch` pixels apart).
fn draw_labels(
    buffer: &mut [u8],
    size: (u32, u32),
    pitch: u32,
    labels: [&str; 3],
) -> Result<(), CompareError> {
    use plotters::prelude::*;
    let err = |e: String| CompareError::Label(e);
    crate::output::plot::register_plot_font().map_err(err)?;
    let root = BitMapBackend::with_buffer(buffer, size).into_drawing_area();
    let style = (crate::output::plot::PLOT_FONT, 15)
        .into_font()
        .color(&BLACK);
    for (i, label) in labels.iter().enumerate() {
        let x = (i as u32 * pitch + 4) as i32;
        root.draw(&Text::new(label.to_string(), (x, 3), style.clone()))
            .map_err(|e| err(e.to_string()))?;
    }
    root.present().map_err(|e| err(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::RenderStats;

    fn film(w: u32, h: u32, f: impl Fn(u32, u32) -> f32) -> Film {
        let mut pixels = Vec::new();
        for y in 0..h {
            for x in 0..w {
                let v = f(x, y);
                pixels.push([v, v, v, 1.0]);
            }
        }
        Film {
            width: w,
            height: h,
            pixels,
            stats: RenderStats::default(),
        }
    }

    #[test]
    fn identical_films_are_identical() {
        let a = film(32, 16, |x, y| (x + y) as f32 / 48.0);
        let m = image_metrics(&a, &a, 1.0).unwrap();
        assert_eq!((m.rmse, m.changed_fraction), (0.0, 0.0));
        assert!((m.ssim - 1.0).abs() < 1e-12, "{}", m.ssim);
    }

    #[test]
    fn black_against_white_is_the_largest_difference() {
        let (a, b) = (film(16, 16, |_, _| 0.0), film(16, 16, |_, _| 1.0));
        let m = image_metrics(&a, &b, 1.0).unwrap();
        assert!((m.rmse - 1.0).abs() < 1e-12, "{}", m.rmse);
        assert_eq!(m.changed_fraction, 1.0);
        assert!(m.ssim < 0.01, "{}", m.ssim);
    }

    #[test]
    fn half_changed_image() {
        // The lower half turns from black to white: RMSE √½, half the pixels changed.
        let a = film(16, 16, |_, _| 0.0);
        let b = film(16, 16, |_, y| if y >= 8 { 1.0 } else { 0.0 });
        let m = image_metrics(&a, &b, 1.0).unwrap();
        assert!((m.rmse - 0.5f64.sqrt()).abs() < 1e-12, "{}", m.rmse);
        assert_eq!(m.changed_fraction, 0.5);
    }

    #[test]
    fn sizes_must_match() {
        let (a, b) = (film(16, 16, |_, _| 0.0), film(16, 8, |_, _| 0.0));
        assert!(matches!(
            image_metrics(&a, &b, 1.0),
            Err(CompareError::Size(16, 16, 16, 8))
        ));
        assert!(side_by_side_png(&a, &b, 1.0, ["a", "b", "c"]).is_err());
    }

    #[test]
    fn side_by_side_has_three_panels() {
        let (a, b) = (film(10, 4, |_, _| 0.0), film(10, 4, |_, _| 1.0));
        let png = side_by_side_png(&a, &b, 1.0, ["", "", ""]).unwrap();
        let img = image::load_from_memory(&png).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (3 * 10 + 2 * GAP_PX, 4 + LABEL_PX));
        let y = LABEL_PX;
        assert_eq!(img.get_pixel(0, y).0, [0, 0, 0]);
        assert_eq!(img.get_pixel(10 + GAP_PX, y).0, [255, 255, 255]);
        // Difference panel: 255 × gain, clipped.
        assert_eq!(img.get_pixel(2 * (10 + GAP_PX), y).0, [255, 255, 255]);
        assert_eq!(img.get_pixel(10, y).0, [255, 255, 255], "gap is white");
        assert_eq!(
            img.get_pixel(0, 0).0,
            [255, 255, 255],
            "label strip is white"
        );
    }
}
