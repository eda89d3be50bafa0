//! Scene — terrain orthophoto. In: an image file (PNG, 8-bit sRGB, alpha respected) and the
//! latitudes and longitudes of its edges. Out: an [`Orthophoto`]: the ground's colour (linear,
//! premultiplied RGBA) at a latitude and longitude, which the renderer shades terrain hits with
//! in place of the palette.
//!
//! The image is a plate carrée grid: row 0 along the north edge, column 0 along the west edge,
//! each pixel covering an equal step of latitude and of longitude (as an EPSG:4326 orthophoto
//! or a satellite image resampled to it). Pixels are areas; colours are interpolated bilinearly
//! between pixel centres. Outside the image, and through its transparent pixels, the palette's
//! colour shows.

use std::path::PathBuf;
use std::sync::Arc;

use serde::Serialize;

use crate::scene::card::Texture;

/// A georeferenced image draped over the terrain.
#[derive(Debug, Clone, Serialize)]
pub struct Orthophoto {
    /// The image file.
    pub image_path: PathBuf,
    /// The image's south, west, north and east edges (°).
    pub bounds_deg: [f64; 4],
    /// The decoded image (linear, premultiplied RGBA).
    #[serde(skip)]
    pub texture: Arc<Texture>,
}

impl Orthophoto {
    /// The image's linear, premultiplied RGBA at (`lat_deg`, `lon_deg`) (longitudes taken modulo
    /// 360° onto the image's); transparent outside it.
    #[inline]
    pub fn rgba_at(&self, lat_deg: f64, lon_deg: f64) -> [f32; 4] {
        let [south, west, north, east] = self.bounds_deg;
        let lon = west + (lon_deg - west).rem_euclid(360.0);
        let u = (lon - west) / (east - west);
        let v = (north - lat_deg) / (north - south);
        self.texture.sample(u, v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixels_are_found_at_their_latitude_and_longitude() {
        // 2 × 2 pixels over 10–12° N, 20–24° E: red, green / blue, white.
        let texels = vec![
            [1.0, 0.0, 0.0, 1.0],
            [0.0, 1.0, 0.0, 1.0],
            [0.0, 0.0, 1.0, 1.0],
            [1.0, 1.0, 1.0, 1.0],
        ];
        let photo = Orthophoto {
            image_path: PathBuf::from("p.png"),
            bounds_deg: [10.0, 20.0, 12.0, 24.0],
            texture: Arc::new(Texture {
                width: 2,
                height: 2,
                texels,
            }),
        };
        // Pixel centres: 11.5° N 21° E (red) … 10.5° N 23° E (white); and 360° around.
        assert_eq!(photo.rgba_at(11.5, 21.0), [1.0, 0.0, 0.0, 1.0]);
        assert_eq!(photo.rgba_at(11.5, 23.0), [0.0, 1.0, 0.0, 1.0]);
        assert_eq!(photo.rgba_at(10.5, 21.0 - 360.0), [0.0, 0.0, 1.0, 1.0]);
        assert_eq!(photo.rgba_at(10.5, 23.0), [1.0, 1.0, 1.0, 1.0]);
        // Halfway between red and green.
        assert_eq!(photo.rgba_at(11.5, 22.0), [0.5, 0.5, 0.0, 1.0]);
        // Outside: transparent.
        assert_eq!(photo.rgba_at(12.5, 22.0), [0.0; 4]);
        assert_eq!(photo.rgba_at(11.0, 24.5), [0.0; 4]);
    }
}
