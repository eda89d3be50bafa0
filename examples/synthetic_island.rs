//! Write the synthetic island heightmap of `data/scenes/fig14_island_terrain.toml` as a
//! geographic GeoTIFF, and a synthetic orthophoto of it as a PNG:
//! `cargo run --release --example synthetic_island -- [OUT.tif [PHOTO.png]]`
//! (the committed files are `data/scenes/terrain/island.tif` and `island_photo.png`).
//!
//! The island: a 16 × 10 km massif centred at 78.40° N, 15.00° E (≈ 44.5 km north of the
//! fig14 observer at 78.00° N), a main peak of 900 m and a shoulder of 600 m to the west,
//! ridged by a few sines and cut by a sea cliff on its south side, set in sea (0 m). The grid is
//! 0.0025° in latitude × 0.005° in longitude (278 m × 116 m at 78.4° N), 160 rows × 200 columns,
//! 16-bit integer metres, deflate-compressed, PixelIsArea, GTModelTypeGeoKey = 2 (geographic).
//!
//! The orthophoto covers the same area (78.2–78.6° N, 14.5–15.5° E) at twice the model's
//! resolution, 400 × 320 pixels, 8-bit sRGB: what an aerial photograph taken in the light of
//! the scene's palette (from 200° at 25°) might show — sea, green-brown tundra on the low
//! slopes, grey-brown scree, dark rock on slopes of 35° and more, and snow above about 450 m
//! with a ragged edge — computed from the same heights (not a photograph of anything).

use std::f64::consts::PI;

use tiff::encoder::{Compression, DeflateLevel, TiffEncoder, colortype};
use tiff::tags::Tag;

/// Rows, columns, north-west corner and steps (°).
const ROWS: u32 = 160;
const COLS: u32 = 200;
const NORTH: f64 = 78.6;
const WEST: f64 = 14.5;
const DLAT: f64 = 0.0025;
const DLON: f64 = 0.005;

/// Height (m) at a point, from its offsets east and north (km) of the island's centre.
fn height_m(x_km: f64, y_km: f64) -> f64 {
    let bump = |cx: f64, cy: f64, sx: f64, sy: f64, h: f64| {
        h * (-((x_km - cx) / sx).powi(2) - ((y_km - cy) / sy).powi(2)).exp()
    };
    let massif = bump(1.0, 0.5, 4.0, 3.0, 900.0) + bump(-4.5, -0.5, 3.0, 2.5, 600.0);
    let ridges = 1.0
        + 0.12 * (2.0 * PI * (x_km / 2.3 + y_km / 5.1)).sin()
        + 0.08 * (2.0 * PI * (x_km / 1.1 - y_km / 1.7)).sin();
    // The coast: heights fall to the sea where the massif is low, with a cliff on the south.
    let cliff = if y_km < -3.5 { 0.0 } else { 60.0 };
    let h = massif * ridges + cliff * (massif / 150.0).min(1.0) - 40.0;
    h.max(0.0)
}

/// Offsets east and north (km) of the island's centre at (`lat`, `lon`).
fn offsets_km(lat: f64, lon: f64) -> (f64, f64) {
    let km_per_deg = 6_371.0 * PI / 180.0;
    let (lat0, lon0) = (78.4f64, 15.0f64);
    (
        (lon - lon0) * km_per_deg * lat.to_radians().cos(),
        (lat - lat0) * km_per_deg,
    )
}

/// A smooth pseudo-random field in [−1, 1] (a few sines), for ragged colour edges.
fn ripple(x_km: f64, y_km: f64) -> f64 {
    (0.5 * (2.0 * PI * (x_km / 0.9 + y_km / 1.3)).sin()
        + 0.3 * (2.0 * PI * (x_km / 0.37 - y_km / 0.53)).sin()
        + 0.2 * (2.0 * PI * (y_km / 0.23 + x_km / 0.71)).sin())
    .clamp(-1.0, 1.0)
}

/// The orthophoto's linear colour at offsets (`x`, `y`) km from the island's centre.
fn photo_rgb(x: f64, y: f64) -> [f64; 3] {
    let h = height_m(x, y);
    if h <= 0.0 {
        return [0.015, 0.03, 0.045];
    }
    // Slope and hillshade from central differences over 20 m.
    let e = 0.02;
    let gx = (height_m(x + e, y) - height_m(x - e, y)) / (2000.0 * e);
    let gy = (height_m(x, y + e) - height_m(x, y - e)) / (2000.0 * e);
    let norm = (gx * gx + gy * gy + 1.0).sqrt();
    let normal = [-gx / norm, -gy / norm, 1.0 / norm];
    let (az, el) = (200f64.to_radians(), 25f64.to_radians());
    let light = [el.cos() * az.sin(), el.cos() * az.cos(), el.sin()];
    let lambert = (normal[0] * light[0] + normal[1] * light[1] + normal[2] * light[2]).max(0.0);
    let shade = 0.35 + 0.65 * lambert;
    let slope_deg = (gx * gx + gy * gy).sqrt().atan().to_degrees();
    let n = ripple(x, y);
    let albedo = if slope_deg >= 35.0 {
        [0.05, 0.048, 0.045]
    } else if h >= 450.0 + 120.0 * n {
        [0.80, 0.82, 0.86]
    } else if h >= 150.0 + 60.0 * n {
        [0.13, 0.12, 0.105]
    } else {
        [0.07 + 0.02 * n, 0.09 + 0.02 * n, 0.04]
    };
    albedo.map(|c| c * shade)
}

/// The sRGB encoding of a linear value in [0, 1], as 8 bits.
fn srgb8(v: f64) -> u8 {
    let v = v.clamp(0.0, 1.0);
    let e = if v <= 0.0031308 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (e * 255.0).round() as u8
}

/// Write the orthophoto (see the module docs) to `out`.
fn write_photo(out: &str) -> anyhow::Result<()> {
    let (width, height) = (2 * COLS, 2 * ROWS);
    let image = image::RgbImage::from_fn(width, height, |c, r| {
        let lat = NORTH - (r as f64 + 0.5) * DLAT / 2.0;
        let lon = WEST + (c as f64 + 0.5) * DLON / 2.0;
        let (x, y) = offsets_km(lat, lon);
        image::Rgb(photo_rgb(x, y).map(srgb8))
    });
    image.save(out)?;
    println!("wrote {out} ({width} × {height})");
    Ok(())
}

fn main() -> anyhow::Result<()> {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "data/scenes/terrain/island.tif".into());
    let photo = std::env::args()
        .nth(2)
        .unwrap_or_else(|| "data/scenes/terrain/island_photo.png".into());
    let mut data = Vec::with_capacity((ROWS * COLS) as usize);
    for r in 0..ROWS {
        for c in 0..COLS {
            // Sample centres (PixelIsArea: the tie point is the north-west pixel's corner).
            let lat = NORTH - (r as f64 + 0.5) * DLAT;
            let lon = WEST + (c as f64 + 0.5) * DLON;
            let (x, y) = offsets_km(lat, lon);
            data.push(height_m(x, y).round() as i16);
        }
    }
    let file = std::fs::File::create(&out)?;
    let mut tiff = TiffEncoder::new(std::io::BufWriter::new(file))?
        .with_compression(Compression::Deflate(DeflateLevel::Best));
    let mut image = tiff.new_image::<colortype::GrayI16>(COLS, ROWS)?;
    let dir = image.encoder();
    dir.write_tag(Tag::ModelPixelScaleTag, &[DLON, DLAT, 0.0][..])?;
    dir.write_tag(
        Tag::ModelTiepointTag,
        &[0.0, 0.0, 0.0, WEST, NORTH, 0.0][..],
    )?;
    // Version 1.1.0, 3 keys: model type geographic, raster PixelIsArea, WGS 84.
    let keys: [u16; 16] = [1, 1, 0, 3, 1024, 0, 1, 2, 1025, 0, 1, 1, 2048, 0, 1, 4326];
    dir.write_tag(Tag::GeoKeyDirectoryTag, &keys[..])?;
    image.write_data(&data)?;
    println!("wrote {out} ({COLS} × {ROWS})");
    write_photo(&photo)
}
