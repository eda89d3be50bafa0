//! Synthetic elevation models written straight from their samples (with the `tiff` encoder and
//! plain big-endian bytes, not the reader under test).

use std::path::Path;

use tiff::encoder::{TiffEncoder, colortype};
use tiff::tags::Tag;

/// A grid to write: `rows` × `cols` heights (north row first), the latitude and longitude of
/// the north-west sample's centre and the steps (°) between samples.
pub struct Grid<'a> {
    pub rows: u32,
    pub cols: u32,
    pub north_lat_deg: f64,
    pub west_lon_deg: f64,
    pub lat_step_deg: f64,
    pub lon_step_deg: f64,
    pub heights_m: &'a [f32],
}

/// Write `grid` as a one-band f32 GeoTIFF (PixelIsArea: the tie point is the north-west pixel's
/// corner, half a step from its centre) with `GTModelTypeGeoKey` = `model_type` (2 =
/// geographic, 1 = projected). `with_tiepoint`: write the ModelTiepointTag.
pub fn write_geotiff(path: &Path, grid: &Grid<'_>, model_type: u16, with_tiepoint: bool) {
    let file = std::fs::File::create(path).unwrap();
    let mut tiff = TiffEncoder::new(std::io::BufWriter::new(file)).unwrap();
    let mut image = tiff
        .new_image::<colortype::Gray32Float>(grid.cols, grid.rows)
        .unwrap();
    let dir = image.encoder();
    let (sx, sy) = (grid.lon_step_deg, grid.lat_step_deg);
    dir.write_tag(Tag::ModelPixelScaleTag, &[sx, sy, 0.0][..])
        .unwrap();
    if with_tiepoint {
        let (west, north) = (grid.west_lon_deg - 0.5 * sx, grid.north_lat_deg + 0.5 * sy);
        dir.write_tag(
            Tag::ModelTiepointTag,
            &[0.0, 0.0, 0.0, west, north, 0.0][..],
        )
        .unwrap();
    }
    let keys: [u16; 12] = [1, 1, 0, 2, 1024, 0, 1, model_type, 1025, 0, 1, 1];
    dir.write_tag(Tag::GeoKeyDirectoryTag, &keys[..]).unwrap();
    image.write_data(grid.heights_m).unwrap();
}

/// Samples of a 1201 × 1201 SRTM tile, row-major from the north: `f(row, col)`.
pub fn hgt_bytes(f: impl Fn(usize, usize) -> i16) -> Vec<u8> {
    let mut bytes = Vec::with_capacity(2 * 1201 * 1201);
    for r in 0..1201 {
        for c in 0..1201 {
            bytes.extend_from_slice(&f(r, c).to_be_bytes());
        }
    }
    bytes
}
