//! Scene — textured cards (ships, ice cliffs, calibration boards). In: a card image (PNG, sRGB,
//! with alpha) and its placement. Out: linear, premultiplied RGBA seen at a point of the card.
//!
//! A card is a vertical surface at constant ground distance D from the observer: a section of the
//! vertical cylinder of ground radius D around the observer, centred on an azimuth. A ray hits it
//! where its height at distance D lies in `[base, base + height]` and its azimuth is within half
//! the card's width: the horizontal coordinate on the card is the azimuth offset × R·sin(D/R)
//! (the radius of the circle of ground distance D on the sphere; ≈ D). A flat card of width W
//! would differ from this cylinder by its sagitta W²/(8D): 4.8 cm for a 100 m ship at 26 km,
//! 12.5 cm for 100 m at 10 km — far below a pixel at any sensible field of view.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::Serialize;

/// The sRGB electro-optical transfer function: 8-bit-encoded value in [0, 1] → linear.
#[inline]
pub fn srgb_to_linear(v: f64) -> f64 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// A card image decoded to linear, premultiplied RGBA f32 (row 0 at the top).
#[derive(Debug, Clone, PartialEq)]
pub struct Texture {
    /// Width (pixels).
    pub width: u32,
    /// Height (pixels).
    pub height: u32,
    /// Premultiplied linear RGBA, row-major, row 0 at the top.
    pub texels: Vec<[f32; 4]>,
}

/// A card image could not be read.
#[derive(Debug, thiserror::Error)]
#[error("cannot read card image {path}: {source}")]
pub struct TextureError {
    /// The image file.
    pub path: PathBuf,
    /// Why.
    #[source]
    pub source: image::ImageError,
}

impl Texture {
    /// Decode an 8-bit sRGB image (any format the `image` crate was built with: PNG) from bytes.
    pub fn from_image_bytes(bytes: &[u8]) -> Result<Self, image::ImageError> {
        let img = image::load_from_memory(bytes)?.to_rgba8();
        let lut: Vec<f32> = (0..256)
            .map(|v| srgb_to_linear(v as f64 / 255.0) as f32)
            .collect();
        let texels = img
            .pixels()
            .map(|p| {
                let a = p[3] as f32 / 255.0;
                [
                    lut[p[0] as usize] * a,
                    lut[p[1] as usize] * a,
                    lut[p[2] as usize] * a,
                    a,
                ]
            })
            .collect();
        Ok(Self {
            width: img.width(),
            height: img.height(),
            texels,
        })
    }

    /// Read and decode an image file.
    pub fn from_file(path: &Path) -> Result<Self, TextureError> {
        Self::from_file_with_digest(path).map(|(texture, _)| texture)
    }

    /// Read and decode an image file, with the sha256 of the bytes that were decoded.
    pub fn from_file_with_digest(path: &Path) -> Result<(Self, [u8; 32]), TextureError> {
        use sha2::{Digest, Sha256};
        let wrap = |source| TextureError {
            path: path.to_path_buf(),
            source,
        };
        let bytes = crate::input::read_limited(path, crate::input::MAX_IMAGE_BYTES)
            .map_err(|e| wrap(image::ImageError::IoError(e)))?;
        let texture = Self::from_image_bytes(&bytes).map_err(wrap)?;
        Ok((texture, Sha256::digest(&bytes).into()))
    }

    /// Bilinear sample at texture coordinates (`u`, `v`) in [0, 1] (v = 0 at the top edge);
    /// transparent outside, and everywhere for an empty texture or one whose texel count is not
    /// width × height (the fields are public).
    #[inline]
    pub fn sample(&self, u: f64, v: f64) -> [f32; 4] {
        let (w, h) = (self.width as usize, self.height as usize);
        if !(0.0..=1.0).contains(&u)
            || !(0.0..=1.0).contains(&v)
            || self.texels.is_empty()
            || self.texels.len() != w * h
        {
            return [0.0; 4];
        }
        let x = (u * w as f64 - 0.5).clamp(0.0, (w - 1) as f64);
        let y = (v * h as f64 - 0.5).clamp(0.0, (h - 1) as f64);
        // x, y ≥ 0, so truncation is the floor; through i32 because u64 ↔ f64 conversions are
        // slow on baseline x86-64 (textures are far smaller than 2³¹ texels a side).
        let (xi, yi) = (x as i32, y as i32);
        let (fx, fy) = ((x - xi as f64) as f32, (y - yi as f64) as f32);
        let (x0, y0) = (xi as usize, yi as usize);
        let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
        let t = |xx: usize, yy: usize| self.texels[yy * w + xx];
        let (a, b, c, d) = (t(x0, y0), t(x1, y0), t(x0, y1), t(x1, y1));
        let mut out = [0.0f32; 4];
        for i in 0..4 {
            let top = a[i] + (b[i] - a[i]) * fx;
            let bottom = c[i] + (d[i] - c[i]) * fx;
            out[i] = top + (bottom - top) * fy;
        }
        out
    }
}

/// A placed card.
#[derive(Debug, Clone, Serialize)]
pub struct Card {
    /// The image file (resolved path).
    pub image_path: PathBuf,
    /// Ground distance from the observer (m).
    pub distance_m: f64,
    /// Azimuth of the card's centre (rad, clockwise from north).
    pub azimuth_rad: f64,
    /// Width along the circle of constant distance (m).
    pub width_m: f64,
    /// Height (m).
    pub height_m: f64,
    /// Height of the card's bottom edge above the surface (m).
    pub base_m: f64,
    /// The decoded image.
    #[serde(skip)]
    pub texture: Arc<Texture>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_decoding_matches_the_standard() {
        // IEC 61966-2-1: 0.04045 ↔ 0.0031308; 0.5 → 0.21404.
        assert!((srgb_to_linear(0.04045) - 0.0031308).abs() < 1e-6);
        assert!((srgb_to_linear(0.5) - 0.214_041).abs() < 1e-5);
        assert_eq!(srgb_to_linear(1.0), 1.0);
    }

    #[test]
    fn bilinear_sampling_is_premultiplied_and_transparent_outside() {
        let tex = Texture {
            width: 2,
            height: 1,
            texels: vec![[1.0, 0.0, 0.0, 1.0], [0.0; 4]],
        };
        assert_eq!(tex.sample(0.25, 0.5), [1.0, 0.0, 0.0, 1.0]);
        assert_eq!(tex.sample(0.5, 0.5), [0.5, 0.0, 0.0, 0.5]);
        assert_eq!(tex.sample(1.5, 0.5), [0.0; 4]);
        assert_eq!(tex.sample(0.5, -0.1), [0.0; 4]);
    }

    #[test]
    fn inconsistent_texture_is_transparent_not_a_panic() {
        // 2×2 declared, one texel given: sampling the bottom-right used to index out of bounds.
        let tex = Texture {
            width: 2,
            height: 2,
            texels: vec![[1.0; 4]],
        };
        assert_eq!(tex.sample(0.9, 0.9), [0.0; 4]);
    }
}
