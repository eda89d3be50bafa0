//! Output — PNG exporter. In: a [`Film`] (linear radiance) and an exposure. Out: the bytes of an
//! 8-bit sRGB PNG.
//!
//! Each linear pixel is multiplied by `exposure`; a colour brighter than white (its largest channel
//! above 1 — in practice only the sun) is scaled down as a whole so that channel is 1, which keeps
//! its hue (a low, reddened sun stays orange instead of clipping to white channel by channel); the
//! channels are then clamped to [0, 1], encoded with the
//! sRGB transfer function (IEC 61966-2-1: 12.92·L below 0.0031308, else 1.055·L^(1/2.4) − 0.055)
//! and quantised as ⌊255·V + 0.5⌋. Film unit 1.0 is the white horizon sky, so the default exposure
//! [`DEFAULT_EXPOSURE`] = 0.85 shows the horizon sky a little below white and leaves headroom
//! before the sun clips. Alpha is dropped (the film is opaque).

use image::ImageEncoder;

use crate::render::Film;

/// Default exposure for PNG output (linear multiplier).
pub const DEFAULT_EXPOSURE: f64 = 0.85;

/// The sRGB opto-electronic transfer function: linear [0, 1] → encoded [0, 1].
#[inline]
pub fn linear_to_srgb(l: f64) -> f64 {
    if l <= 0.003_130_8 {
        12.92 * l
    } else {
        1.055 * l.powf(1.0 / 2.4) - 0.055
    }
}

/// Linear value (before exposure) → 8-bit sRGB code; NaN maps to 0.
#[inline]
pub fn encode_channel(linear: f64, exposure: f64) -> u8 {
    let l = linear * exposure;
    let l = if l.is_nan() { 0.0 } else { l.clamp(0.0, 1.0) };
    (linear_to_srgb(l) * 255.0 + 0.5).floor() as u8
}

/// Apply `exposure` to a linear RGB colour and, if its largest channel then exceeds 1, scale the
/// whole colour down so that channel is exactly 1 (hue-preserving highlight compression).
/// Non-finite or negative channels count as 0.
#[inline]
pub fn desaturate_highlight(rgb: [f64; 3], exposure: f64) -> [f64; 3] {
    let c = rgb.map(|v| {
        let v = v * exposure;
        if v.is_finite() && v > 0.0 { v } else { 0.0 }
    });
    let max = c[0].max(c[1]).max(c[2]);
    if max > 1.0 { c.map(|v| v / max) } else { c }
}

/// Encode `film` as an 8-bit sRGB PNG (bytes) with the given `exposure`.
///
/// A film whose pixel count is not width × height (its fields are public) is an error, not a
/// panic.
pub fn encode_png(film: &Film, exposure: f64) -> Result<Vec<u8>, image::ImageError> {
    if film.pixels.len() != film.width as usize * film.height as usize {
        return Err(image::ImageError::Parameter(
            image::error::ParameterError::from_kind(
                image::error::ParameterErrorKind::DimensionMismatch,
            ),
        ));
    }
    let mut rgb = Vec::with_capacity(film.pixels.len() * 3);
    for p in &film.pixels {
        for c in desaturate_highlight([p[0], p[1], p[2]].map(f64::from), exposure) {
            rgb.push(encode_channel(c, 1.0));
        }
    }
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out).write_image(
        &rgb,
        film.width,
        film.height,
        image::ExtendedColorType::Rgb8,
    )?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_transfer_matches_the_standard() {
        // crates.md §1.5: 0.625 linear is 207 in 8-bit sRGB (a plain scale would give 159).
        assert_eq!(encode_channel(0.625, 1.0), 207);
        assert_eq!(encode_channel(0.0, 1.0), 0);
        assert_eq!(encode_channel(1.0, 1.0), 255);
        assert_eq!(encode_channel(7.0, 1.0), 255);
        assert_eq!(encode_channel(f64::NAN, 1.0), 0);
        // 18 % grey → 118 (sRGB of 0.18 is 0.4614).
        assert_eq!(encode_channel(0.18, 1.0), 118);
        // Linear segment: 0.002 → 12.92·0.002·255 = 6.59 → 7.
        assert_eq!(encode_channel(0.002, 1.0), 7);
    }

    #[test]
    fn highlights_keep_their_hue() {
        // Below white: untouched (only the exposure applies).
        assert_eq!(
            desaturate_highlight([0.5, 0.25, 0.1], 1.0),
            [0.5, 0.25, 0.1]
        );
        assert_eq!(desaturate_highlight([0.5, 0.25, 0.1], 2.0), [1.0, 0.5, 0.2]);
        // A bright orange sun keeps its channel ratios instead of clipping to white.
        let c = desaturate_highlight([400.0, 100.0, 4.0], 1.0);
        assert_eq!(c, [1.0, 0.25, 0.01]);
        assert_eq!(
            desaturate_highlight([f64::NAN, -1.0, 2.0], 1.0),
            [0.0, 0.0, 1.0]
        );
    }
}
