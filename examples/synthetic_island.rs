//! Write the synthetic island heightmap of `data/scenes/fig14_island_terrain.toml` as a
//! geographic GeoTIFF: `cargo run --release --example synthetic_island -- OUT.tif`
//! (the committed file is `data/scenes/terrain/island.tif`).
//!
//! The island: a 16 × 10 km massif centred at 78.40° N, 15.00° E (≈ 44.5 km north of the
//! fig14 observer at 78.00° N), a main peak of 900 m and a shoulder of 600 m to the west,
//! ridged by a few sines and cut by a sea cliff on its south side, set in sea (0 m). The grid is
//! 0.0025° in latitude × 0.005° in longitude (278 m × 116 m at 78.4° N), 160 rows × 200 columns,
//! 16-bit integer metres, deflate-compressed, PixelIsArea, GTModelTypeGeoKey = 2 (geographic).

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

fn main() -> anyhow::Result<()> {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "data/scenes/terrain/island.tif".into());
    let km_per_deg = 6_371.0 * PI / 180.0;
    let (lat0, lon0) = (78.4f64, 15.0f64);
    let mut data = Vec::with_capacity((ROWS * COLS) as usize);
    for r in 0..ROWS {
        for c in 0..COLS {
            // Sample centres (PixelIsArea: the tie point is the north-west pixel's corner).
            let lat = NORTH - (r as f64 + 0.5) * DLAT;
            let lon = WEST + (c as f64 + 0.5) * DLON;
            let y = (lat - lat0) * km_per_deg;
            let x = (lon - lon0) * km_per_deg * lat.to_radians().cos();
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
    Ok(())
}
