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
//!
//! Speed: the 8-bit codes come from a table of the 255 exact thresholds of [`encode_channel`]
//! (the same codes, without a `powf` per channel), rows are converted in parallel, and the PNG is
//! compressed with the `png` crate's fast deflate ([`PNG_COMPRESSION`], [`PNG_FILTER`]). The
//! bytes depend only on the film, never on the thread count.

use std::sync::OnceLock;

use image::ImageEncoder;
use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use rayon::prelude::*;

use crate::render::Film;

/// Deflate setting of film PNGs: `png`'s fast (fdeflate) encoder.
pub const PNG_COMPRESSION: CompressionType = CompressionType::Fast;

/// Row filter of film PNGs.
pub const PNG_FILTER: FilterType = FilterType::Adaptive;

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

/// Cells of the coarse index into [`Srgb8Table::thresholds`] over linear [0, 1]. The code
/// climbs at most 12.92 · 255 ≈ 3 295 per unit of linear value (the steepest part of the curve,
/// its linear toe), so a cell 1/4 096 wide holds at most one threshold (checked when the table is
/// built).
const TABLE_CELLS: usize = 4096;

/// [`encode_channel`]`(l, 1)` for l in [0, 1] without evaluating the sRGB curve: the code is the
/// number of thresholds at or below l (the code is monotone in l), found from a coarse index
/// and one comparison.
struct Srgb8Table {
    /// `thresholds[k]`: the smallest l ∈ [0, 1] with code ≥ k (k = 1…255); `thresholds[0]` = 0
    /// and `thresholds[256]` = ∞ (no code above 255).
    thresholds: [f64; 257],
    /// Code at the start of each of the [`TABLE_CELLS`] cells, `cell[i] = code(i / TABLE_CELLS)`.
    cell: [u8; TABLE_CELLS],
}

impl Srgb8Table {
    fn get() -> &'static Srgb8Table {
        static TABLE: OnceLock<Srgb8Table> = OnceLock::new();
        TABLE.get_or_init(Srgb8Table::build)
    }

    fn build() -> Srgb8Table {
        let code = |l: f64| encode_channel(l, 1.0);
        let mut thresholds = [f64::INFINITY; 257];
        thresholds[0] = 0.0;
        for (k, t) in thresholds.iter_mut().enumerate().take(256).skip(1) {
            // Bisection on the bit patterns of non-negative doubles (ordered like the values):
            // lo has code < k, hi has code ≥ k.
            let (mut lo, mut hi) = (0u64, 1.0f64.to_bits());
            while hi - lo > 1 {
                let mid = lo + (hi - lo) / 2;
                if (code(f64::from_bits(mid)) as usize) < k {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            *t = f64::from_bits(hi);
        }
        let mut cell = [0u8; TABLE_CELLS];
        for (i, c) in cell.iter_mut().enumerate() {
            *c = code(i as f64 / TABLE_CELLS as f64);
            // One comparison must reach every code of the cell.
            let end = (i + 1) as f64 / TABLE_CELLS as f64;
            assert!(
                thresholds.get(*c as usize + 2).is_none_or(|&t| t >= end),
                "sRGB table: cell {i} holds two thresholds"
            );
        }
        Srgb8Table { thresholds, cell }
    }

    /// The 8-bit code of a linear value already clamped to [0, 1].
    #[inline]
    fn code(&self, l: f64) -> u8 {
        // l · 4096 is exact, so the cell starts at or below l and its code is a lower bound.
        let c = self.cell[((l * TABLE_CELLS as f64) as usize).min(TABLE_CELLS - 1)];
        c + u8::from(l >= self.thresholds[c as usize + 1])
    }
}

/// The 8-bit codes of one linear pixel: [`encode_channel`]`(·, 1)` of
/// [`desaturate_highlight`]`(rgb, exposure)`, with the (rare) highlight scaling off the hot path.
#[inline]
fn pixel_codes(table: &Srgb8Table, rgb: [f32; 3], exposure: f64) -> [u8; 3] {
    // Exactly desaturate_highlight's arithmetic: non-finite or non-positive channels count as 0.
    let c = rgb.map(|v| {
        let v = f64::from(v) * exposure;
        if v > 0.0 && v < f64::INFINITY { v } else { 0.0 }
    });
    if c[0] > 1.0 || c[1] > 1.0 || c[2] > 1.0 {
        return highlight_codes(table, c);
    }
    c.map(|v| table.code(v))
}

/// [`pixel_codes`] of a colour brighter than white: scaled so its largest channel is 1.
#[cold]
#[inline(never)]
fn highlight_codes(table: &Srgb8Table, c: [f64; 3]) -> [u8; 3] {
    let max = c[0].max(c[1]).max(c[2]);
    c.map(|v| table.code((v / max).clamp(0.0, 1.0)))
}

/// The film's 8-bit sRGB pixels (RGB, row-major), exactly as [`encode_channel`] of
/// [`desaturate_highlight`] gives them; blocks of pixels are converted in parallel.
pub fn film_to_srgb8(film: &Film, exposure: f64) -> Vec<u8> {
    let table = Srgb8Table::get();
    let mut rgb = vec![0u8; film.pixels.len() * 3];
    // Blocks of 16 384 pixels: enough work per task, many tasks for the threads.
    const BLOCK: usize = 1 << 14;
    rgb.par_chunks_mut(BLOCK * 3)
        .zip(film.pixels.par_chunks(BLOCK))
        .for_each(|(out, pixels)| {
            // Neighbouring pixels are often the same colour (sky and sea rows): reuse the codes.
            // (The start value, three NaNs, is right too: NaN channels are code 0.)
            let mut last_rgb = [f32::NAN; 3].map(f32::to_bits);
            let mut last_codes = [0u8; 3];
            for (o, p) in out.chunks_exact_mut(3).zip(pixels) {
                let rgb = [p[0], p[1], p[2]];
                let bits = rgb.map(f32::to_bits);
                if bits != last_rgb {
                    last_codes = pixel_codes(table, rgb, exposure);
                    last_rgb = bits;
                }
                o.copy_from_slice(&last_codes);
            }
        });
    rgb
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
    let rgb = film_to_srgb8(film, exposure);
    encode_rgb8(&rgb, film.width, film.height)
}

/// Encode 8-bit RGB pixels (row-major) as PNG with [`PNG_COMPRESSION`] and [`PNG_FILTER`].
pub fn encode_rgb8(rgb: &[u8], width: u32, height: u32) -> Result<Vec<u8>, image::ImageError> {
    // A fast-deflated frame is about a byte per pixel or less; reserve that much.
    let mut out = Vec::with_capacity(rgb.len() / 3);
    PngEncoder::new_with_quality(&mut out, PNG_COMPRESSION, PNG_FILTER).write_image(
        rgb,
        width,
        height,
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
    fn the_threshold_table_gives_exactly_encode_channel() {
        let table = Srgb8Table::get();
        let check = |l: f64| {
            assert_eq!(table.code(l), encode_channel(l, 1.0), "l = {l:e}");
        };
        // Around every threshold, to ±200 ulps.
        for &t in &table.thresholds[1..256] {
            let bits = t.to_bits();
            for d in 0..=200u64 {
                check(f64::from_bits(bits + d));
                if bits >= d {
                    check(f64::from_bits(bits - d));
                }
            }
        }
        // Evenly spaced and random values over [0, 1], and the ends.
        for i in 0..=1_000_000u32 {
            check(f64::from(i) / 1e6);
        }
        let mut state = 0x853c_49e6_748f_ea9bu64;
        for _ in 0..1_000_000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let l = f64::from_bits(state % 1.0f64.to_bits());
            check(l);
        }
        for l in [
            0.0,
            f64::MIN_POSITIVE,
            0.003_130_8,
            0.5,
            1.0 - f64::EPSILON,
            1.0,
        ] {
            check(l);
        }
    }

    #[test]
    fn fast_conversion_matches_the_definition_at_any_thread_count() {
        let mut state = 0xdead_beef_cafe_f00du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let specials = [f32::NAN, f32::INFINITY, -1.0, 0.0, 1.2, 400.0, 1e-6];
        let mut pixels: Vec<[f32; 4]> = (0..70_001)
            .map(|i| {
                if i % 97 == 0 {
                    [specials[i % 7], specials[(i / 7) % 7], next() * 3.0, 1.0]
                } else {
                    [next(), next() * 1.5, next() * 0.2, 1.0]
                }
            })
            .collect();
        // Runs of equal pixels (the converter reuses a neighbour's codes), and a NaN pixel first.
        for i in (0..pixels.len()).filter(|i| i % 5 != 0) {
            if i % 3 != 0 {
                pixels[i] = pixels[i - 1];
            }
        }
        pixels[0] = [f32::NAN, f32::NAN, f32::NAN, 1.0];
        pixels[1] = [0.5, f32::NAN, 2.0, 1.0];
        let film = Film {
            width: 70_001,
            height: 1,
            pixels,
            stats: Default::default(),
        };
        for exposure in [0.85, 1.0, 3.0] {
            let want: Vec<u8> = film
                .pixels
                .iter()
                .flat_map(|p| {
                    desaturate_highlight([p[0], p[1], p[2]].map(f64::from), exposure)
                        .map(|c| encode_channel(c, 1.0))
                })
                .collect();
            for threads in [1, 2, 3] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let got = pool.install(|| film_to_srgb8(&film, exposure));
                assert!(got == want, "exposure {exposure}, {threads} threads");
            }
        }
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
