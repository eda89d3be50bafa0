//! Scene — digital elevation models. In: an SRTM `.hgt` tile or a GeoTIFF heightmap on a
//! geographic (latitude/longitude) grid. Out: a [`Dem`]: heights (m) on a regular lat/lon grid
//! with bilinear sampling and slopes.
//!
//! * **SRTM `.hgt`**: big-endian i16, 1201 × 1201 (3″) or 3601 × 3601 (1″) samples, rows from
//!   north to south, −32768 = void. The tile's name (`N78E015.hgt`) gives the latitude and
//!   longitude of its south-west corner sample; the tile spans one degree, corner samples shared
//!   with the neighbours.
//! * **GeoTIFF**: one band of i8…i32, u8…u32, f32 or f64 samples; `ModelTiepointTag` (33922) and
//!   `ModelPixelScaleTag` (33550) place the grid, `GeoKeyDirectoryTag` (34735) must say it is
//!   geographic (`GTModelTypeGeoKey` = 2); projected or geocentric grids are refused. Raster type
//!   PixelIsArea (the default) puts the tie point on a pixel's corner, PixelIsPoint on its
//!   centre. `GDAL_NODATA` (42113) and NaN samples are voids.
//!
//! Either may come as a zip archive of that one file (SRTM tiles are distributed as
//! `N22W160.hgt.zip`; the member's name then places the tile) or gzip-compressed (`.hgt.gz`).
//! Files are read through [`crate::input::read_limited`] ([`MAX_DEM_BYTES`], also the limit of
//! what an archive may inflate to) and the grid is capped at [`MAX_DEM_SAMPLES`].
//!
//! **Voids** (SRTM's −32768, a GeoTIFF's `GDAL_NODATA` or NaN) stay voids in a [`Dem`];
//! [`Dem::fill_voids`] replaces those it can reach by the harmonic interpolation of the
//! heights around them (what a scene's terrain does unless `fill_voids = false`).

use rayon::prelude::*;
use std::io::Cursor;
use std::path::{Path, PathBuf};

use crate::input::Packing;

use tiff::decoder::{Decoder, DecodingResult, Limits};
use tiff::tags::Tag;

/// Largest elevation-model file read (a 1″ SRTM tile is 26 MB).
pub const MAX_DEM_BYTES: u64 = 512 * 1024 * 1024;
/// Most samples in a grid (a 1″ SRTM tile has 13 M).
pub const MAX_DEM_SAMPLES: usize = 64 * 1024 * 1024;
/// [`Dem::fill_voids`] stops when no filled height changed by more than this in a sweep (m).
pub const VOID_FILL_TOLERANCE_M: f64 = 1e-4;
/// [`Dem::fill_voids`] stops after this many sweeps at the latest.
pub const MAX_VOID_FILL_SWEEPS: usize = 20_000;

/// An elevation model could not be read.
#[derive(Debug, thiserror::Error)]
pub enum DemError {
    /// The file could not be read.
    #[error("cannot read elevation model {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The file's extension is neither `.hgt` nor `.tif`/`.tiff` (nor a `.zip` or `.gz` of one).
    #[error(
        "elevation model {path}: unknown format (expected a .hgt or .tif/.tiff file, or a .zip \
         or .gz of one)"
    )]
    Format {
        /// The file.
        path: PathBuf,
    },
    /// A field of the file is missing or wrong.
    #[error("elevation model {path}: {field}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The field: `file name`, `file size`, a TIFF tag name, `GTModelTypeGeoKey`, …
        field: &'static str,
        /// What is wrong with it.
        message: String,
    },
    /// The TIFF decoder refused the file.
    #[error("elevation model {path}: TIFF: {source}")]
    Tiff {
        /// The file.
        path: PathBuf,
        /// The decoder's error.
        #[source]
        source: tiff::TiffError,
    },
}

/// Heights on a regular latitude/longitude grid (on the scene's sphere).
#[derive(Debug, Clone, PartialEq)]
pub struct Dem {
    /// Rows (north to south).
    pub rows: usize,
    /// Columns (west to east).
    pub cols: usize,
    /// Latitude of row 0's sample centres (°, the northernmost row).
    pub north_lat_deg: f64,
    /// Longitude of column 0's sample centres (°, the westernmost column).
    pub west_lon_deg: f64,
    /// Latitude step from one row to the next, southwards (°, > 0).
    pub lat_step_deg: f64,
    /// Longitude step from one column to the next, eastwards (°, > 0).
    pub lon_step_deg: f64,
    /// Heights (m above the sea), row-major; NaN where void.
    heights_m: Vec<f32>,
}

impl Dem {
    /// A grid from its samples (row-major, north row first, NaN = void). `None` if the sizes
    /// disagree, a step is not finite and > 0, or the grid is smaller than 2 × 2.
    pub fn new(
        rows: usize,
        cols: usize,
        (north_lat_deg, west_lon_deg): (f64, f64),
        (lat_step_deg, lon_step_deg): (f64, f64),
        heights_m: Vec<f32>,
    ) -> Option<Self> {
        let step_ok = |s: f64| s.is_finite() && s > 0.0;
        let ok = rows >= 2
            && cols >= 2
            && rows.checked_mul(cols) == Some(heights_m.len())
            && step_ok(lat_step_deg)
            && step_ok(lon_step_deg)
            && north_lat_deg.is_finite()
            && west_lon_deg.is_finite();
        ok.then_some(Self {
            rows,
            cols,
            north_lat_deg,
            west_lon_deg,
            lat_step_deg,
            lon_step_deg,
            heights_m,
        })
    }

    /// Read a `.hgt` or GeoTIFF file (by extension), at most [`MAX_DEM_BYTES`].
    pub fn from_file(path: &Path) -> Result<Self, DemError> {
        let bytes =
            crate::input::read_limited(path, MAX_DEM_BYTES).map_err(|source| DemError::Read {
                path: path.to_path_buf(),
                source,
            })?;
        Self::from_bytes(path, &bytes)
    }

    /// Decode the bytes of a `.hgt` or GeoTIFF file, or of a zip archive or gzip stream holding
    /// one (SRTM tiles are distributed as `N22W160.hgt.zip`); `path` gives the format (its
    /// extension; for an archive its member's, for gzip the name without `.gz`), the SRTM tile's
    /// position (the name of the `.hgt` file itself) and the name in errors.
    pub fn from_bytes(path: &Path, bytes: &[u8]) -> Result<Self, DemError> {
        let ext = extension(path);
        if matches!(ext.as_deref(), Some("zip" | "gz")) {
            let (inflated, packing) =
                crate::input::unpack(bytes.to_vec(), MAX_DEM_BYTES).map_err(|source| {
                    DemError::Read {
                        path: path.to_path_buf(),
                        source,
                    }
                })?;
            let inner = match packing {
                Packing::Zip { member } => PathBuf::from(member),
                // A gzip stream is the file named without its `.gz`.
                _ => PathBuf::from(path.file_stem().unwrap_or_default()),
            };
            return Self::decode(path, &inner, &inflated);
        }
        Self::decode(path, path, bytes)
    }

    /// Decode `bytes` by the extension and name of `inner` (the file itself, or an archive's
    /// member); errors name `path`, and the member when it is not the file.
    fn decode(path: &Path, inner: &Path, bytes: &[u8]) -> Result<Self, DemError> {
        let named = if inner == path {
            path.to_path_buf()
        } else {
            PathBuf::from(format!("{} (member {})", path.display(), inner.display()))
        };
        match extension(inner).as_deref() {
            Some("hgt") => read_hgt(&named, hgt_corner(inner), bytes),
            Some("tif" | "tiff") => read_geotiff(&named, bytes),
            _ => Err(DemError::Format { path: named }),
        }
    }

    /// The stored sample at row `r`, column `c` (NaN = void).
    ///
    /// # Panics
    /// If (`r`, `c`) is outside the grid.
    pub fn sample(&self, r: usize, c: usize) -> f32 {
        self.heights_m[r * self.cols + c]
    }

    /// Latitude and longitude (°) of the sample at row `r`, column `c`.
    pub fn lat_lon_deg(&self, r: usize, c: usize) -> (f64, f64) {
        (
            self.north_lat_deg - r as f64 * self.lat_step_deg,
            self.west_lon_deg + c as f64 * self.lon_step_deg,
        )
    }

    /// The south, north, west and east edges of the sampled area (°, sample centres).
    pub fn bounds_deg(&self) -> (f64, f64, f64, f64) {
        let (south, east) = self.lat_lon_deg(self.rows - 1, self.cols - 1);
        (south, self.north_lat_deg, self.west_lon_deg, east)
    }

    /// Fractional (row, column) of a point, `None` outside the grid.
    #[inline]
    pub fn grid_position(&self, lat_deg: f64, lon_deg: f64) -> Option<(f64, f64)> {
        let r = (self.north_lat_deg - lat_deg) / self.lat_step_deg;
        let c = (lon_deg - self.west_lon_deg) / self.lon_step_deg;
        // Points on the edge stay on the grid despite rounding (a millionth of a step).
        let inside = |x: f64, n: usize| x >= -1e-6 && x <= (n - 1) as f64 + 1e-6;
        let clamp = |x: f64, n: usize| x.clamp(0.0, (n - 1) as f64);
        (inside(r, self.rows) && inside(c, self.cols))
            .then_some((clamp(r, self.rows), clamp(c, self.cols)))
    }

    /// Bilinear height (m) at a point; `None` outside the grid or next to a void.
    #[inline]
    pub fn height_at(&self, lat_deg: f64, lon_deg: f64) -> Option<f64> {
        let (r, c) = self.grid_position(lat_deg, lon_deg)?;
        self.height_at_grid(r, c)
    }

    /// Bilinear height (m) at fractional row `r` and column `c` (on the grid, as
    /// [`Self::grid_position`] gives them); `None` next to a void.
    #[inline]
    pub fn height_at_grid(&self, r: f64, c: f64) -> Option<f64> {
        let h = bilinear(self.rows, self.cols, r, c, |i| f64::from(self.heights_m[i]));
        h.is_finite().then_some(h)
    }

    /// The height's rate of change per grid step southwards (along a column) and eastwards
    /// (along a row) at every sample (m per step), by central differences (one-sided at the
    /// edges and next to voids; NaN for a void or a sample with no known neighbour in a
    /// direction). Row-major like the samples; what [`Self::gradient_at_grid`] interpolates.
    pub fn gradients(&self) -> Vec<[f32; 2]> {
        let (rows, cols) = (self.rows, self.cols);
        let h = |r: usize, c: usize| self.heights_m[r * cols + c];
        let diff = |before: Option<f32>, here: f32, after: Option<f32>| match (
            before.filter(|v| !v.is_nan()),
            after.filter(|v| !v.is_nan()),
        ) {
            (Some(b), Some(a)) => 0.5 * (a - b),
            (Some(b), None) => here - b,
            (None, Some(a)) => a - here,
            (None, None) => f32::NAN,
        };
        (0..rows)
            .into_par_iter()
            .flat_map_iter(|r| (0..cols).map(move |c| (r, c)))
            .map(|(r, c)| {
                let here = h(r, c);
                let south = diff(
                    r.checked_sub(1).map(|r| h(r, c)),
                    here,
                    (r + 1 < rows).then(|| h(r + 1, c)),
                );
                let east = diff(
                    c.checked_sub(1).map(|c| h(r, c)),
                    here,
                    (c + 1 < cols).then(|| h(r, c + 1)),
                );
                [south, east]
            })
            .collect()
    }

    /// Slope (rad from the horizontal) and upward unit normal (east, north, up) at fractional
    /// row `r` and column `c`, from `gradients` ([`Self::gradients`]) interpolated bilinearly,
    /// on a sphere of `radius_m`; `None` where a gradient is unknown.
    pub fn gradient_at_grid(
        &self,
        gradients: &[[f32; 2]],
        r: f64,
        c: f64,
        radius_m: f64,
    ) -> Option<(f64, [f64; 3])> {
        self.tan_slope_at_grid(gradients, r, c, radius_m)
            .map(|(tan_slope, normal)| (tan_slope.atan(), normal))
    }

    /// [`Self::gradient_at_grid`] with the slope's tangent (|∇h|) in place of the slope: the
    /// same arithmetic up to the arctangent, for callers that compare the slope with a
    /// threshold and rarely need the angle itself.
    #[inline]
    pub fn tan_slope_at_grid(
        &self,
        gradients: &[[f32; 2]],
        r: f64,
        c: f64,
        radius_m: f64,
    ) -> Option<(f64, [f64; 3])> {
        let [south, east] = bilinear_pair(self.rows, self.cols, r, c, gradients);
        if !(south.is_finite() && east.is_finite()) {
            return None;
        }
        let m_per_deg = radius_m * std::f64::consts::PI / 180.0;
        let lat = self.north_lat_deg - r * self.lat_step_deg;
        let gy = -south / (self.lat_step_deg * m_per_deg);
        let gx = east / (self.lon_step_deg * m_per_deg * lat.to_radians().cos().max(1e-6));
        let norm = (gx * gx + gy * gy + 1.0).sqrt();
        Some((
            (gx * gx + gy * gy).sqrt(),
            [-gx / norm, -gy / norm, 1.0 / norm],
        ))
    }

    /// Slope (rad from the horizontal) and the upward unit normal (east, north, up) at a point,
    /// by central differences of [`Self::height_at`] one grid step apart on a sphere of
    /// `radius_m`; `None` where a height is missing.
    pub fn slope_at(&self, lat_deg: f64, lon_deg: f64, radius_m: f64) -> Option<(f64, [f64; 3])> {
        let (dlat, dlon) = (self.lat_step_deg, self.lon_step_deg);
        let h = |la: f64, lo: f64| {
            self.height_at(la, lo)
                .or_else(|| self.height_at(lat_deg, lon_deg))
        };
        let north = h(lat_deg + dlat, lon_deg)? - h(lat_deg - dlat, lon_deg)?;
        let east = h(lat_deg, lon_deg + dlon)? - h(lat_deg, lon_deg - dlon)?;
        let m_per_deg = radius_m * std::f64::consts::PI / 180.0;
        let gy = north / (2.0 * dlat * m_per_deg);
        let gx = east / (2.0 * dlon * m_per_deg * lat_deg.to_radians().cos().max(1e-6));
        let norm = (gx * gx + gy * gy + 1.0).sqrt();
        Some((
            (gx * gx + gy * gy).sqrt().atan(),
            [-gx / norm, -gy / norm, 1.0 / norm],
        ))
    }

    /// Fill the voids that known samples surround or border with the harmonic interpolation of
    /// those samples: each filled height is the mean of its four neighbours (those on the grid),
    /// so a void inside a plane is filled with the plane, and no filled height lies outside the
    /// range of the known heights around its void. Solved by successive over-relaxation from a
    /// breadth-first first guess, to [`VOID_FILL_TOLERANCE_M`] (at most
    /// [`MAX_VOID_FILL_SWEEPS`] sweeps, in a fixed order: the result does not depend on the
    /// thread count). A void region touching no known sample stays void. Returns how many
    /// samples were filled.
    pub fn fill_voids(&mut self) -> usize {
        let (first_guess, layers) = self.void_first_guess();
        let filled: Vec<usize> = first_guess.iter().map(|&(i, _)| i).collect();
        let mut z: Vec<f64> = self.heights_m.iter().map(|&h| f64::from(h)).collect();
        for &(i, v) in &first_guess {
            z[i] = v;
        }
        // Over-relaxation factor for a region `layers` samples deep (the optimum for a square
        // of twice that side).
        let extent = (2 * layers + 2) as f64;
        let omega = 2.0 / (1.0 + (std::f64::consts::PI / extent).sin());
        for _ in 0..MAX_VOID_FILL_SWEEPS {
            let mut largest = 0.0f64;
            for &i in &filled {
                let mean = self.neighbour_mean(&z, i);
                let change = omega * (mean - z[i]);
                z[i] += change;
                largest = largest.max(change.abs());
            }
            if largest < VOID_FILL_TOLERANCE_M {
                break;
            }
        }
        for &i in &filled {
            self.heights_m[i] = z[i] as f32;
        }
        filled.len()
    }

    /// The mean of the on-grid four neighbours of sample `i` in `z`.
    #[inline]
    fn neighbour_mean(&self, z: &[f64], i: usize) -> f64 {
        let (r, c) = (i / self.cols, i % self.cols);
        let mut sum = 0.0;
        let mut n = 0.0;
        for (dr, dc) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
            let (rr, cc) = (r as i64 + dr, c as i64 + dc);
            if rr >= 0 && cc >= 0 && (rr as usize) < self.rows && (cc as usize) < self.cols {
                sum += z[rr as usize * self.cols + cc as usize];
                n += 1.0;
            }
        }
        sum / n
    }

    /// Every void sample a known one can be reached from, with a first guess (the mean of its
    /// neighbours reached in earlier layers of a breadth-first search from the known samples),
    /// in the order reached; and the number of layers.
    fn void_first_guess(&self) -> (Vec<(usize, f64)>, usize) {
        let mut value: Vec<f64> = self.heights_m.iter().map(|&h| f64::from(h)).collect();
        let mut reached: Vec<bool> = value.iter().map(|v| !v.is_nan()).collect();
        let mut pending: Vec<usize> = (0..value.len()).filter(|&i| !reached[i]).collect();
        let mut out = Vec::new();
        let mut layers = 0;
        loop {
            let layer: Vec<(usize, f64)> = pending
                .iter()
                .filter_map(|&i| {
                    let (r, c) = (i / self.cols, i % self.cols);
                    let near = [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)]
                        .into_iter()
                        .filter_map(|(dr, dc)| {
                            let (rr, cc) = (r as i64 + dr, c as i64 + dc);
                            let inside = rr >= 0
                                && cc >= 0
                                && (rr as usize) < self.rows
                                && (cc as usize) < self.cols;
                            let j = inside.then(|| rr as usize * self.cols + cc as usize)?;
                            reached[j].then_some(value[j])
                        });
                    let (sum, count) = near.fold((0.0, 0.0), |(s, k), v| (s + v, k + 1.0));
                    (count > 0.0).then(|| (i, sum / count))
                })
                .collect();
            if layer.is_empty() {
                return (out, layers);
            }
            layers += 1;
            for &(i, v) in &layer {
                reached[i] = true;
                value[i] = v;
            }
            pending.retain(|&i| !reached[i]);
            out.extend(layer);
        }
    }

    /// The finest grid spacing (m) on a sphere of `radius_m` (the east–west spacing shrinks with
    /// the cosine of the latitude; taken at the grid's most poleward row).
    pub fn spacing_m(&self, radius_m: f64) -> f64 {
        let (south, north, _, _) = self.bounds_deg();
        let polemost = south.abs().max(north.abs()).min(89.9);
        let m_per_deg = radius_m * std::f64::consts::PI / 180.0;
        (self.lat_step_deg * m_per_deg)
            .min(self.lon_step_deg * m_per_deg * polemost.to_radians().cos())
    }
}

/// Bilinear interpolation at fractional row `r`, column `c` (within the grid) of the values
/// `at(index)` of a `rows` × `cols` row-major grid.
#[inline]
fn bilinear(rows: usize, cols: usize, r: f64, c: f64, at: impl Fn(usize) -> f64) -> f64 {
    let (r0, c0) = ((r as usize).min(rows - 2), (c as usize).min(cols - 2));
    let (tr, tc) = (r - r0 as f64, c - c0 as f64);
    let i = r0 * cols + c0;
    let top = at(i) + (at(i + 1) - at(i)) * tc;
    let bottom = at(i + cols) + (at(i + cols + 1) - at(i + cols)) * tc;
    top + (bottom - top) * tr
}

/// [`bilinear`] of both components of `values` (the same arithmetic per component, one
/// lookup of the cell).
#[inline]
fn bilinear_pair(rows: usize, cols: usize, r: f64, c: f64, values: &[[f32; 2]]) -> [f64; 2] {
    let (r0, c0) = ((r as usize).min(rows - 2), (c as usize).min(cols - 2));
    let (tr, tc) = (r - r0 as f64, c - c0 as f64);
    let i = r0 * cols + c0;
    let (top, bottom) = (&values[i..i + 2], &values[i + cols..i + cols + 2]);
    [0, 1].map(|k| {
        let at = |v: &[[f32; 2]], j: usize| f64::from(v[j][k]);
        let top = at(top, 0) + (at(top, 1) - at(top, 0)) * tc;
        let bottom = at(bottom, 0) + (at(bottom, 1) - at(bottom, 0)) * tc;
        top + (bottom - top) * tr
    })
}

fn invalid(path: &Path, field: &'static str, message: String) -> DemError {
    DemError::Invalid {
        path: path.to_path_buf(),
        field,
        message,
    }
}

/// South-west corner (lat, lon) from an SRTM tile name such as `N78E015` or `s03w061`.
fn hgt_corner(path: &Path) -> Option<(f64, f64)> {
    let stem = path.file_stem()?.to_str()?.to_ascii_uppercase();
    let b = stem.as_bytes();
    if b.len() != 7 {
        return None;
    }
    let sign = |c: u8, pos: u8, neg: u8| match c {
        _ if c == pos => Some(1.0),
        _ if c == neg => Some(-1.0),
        _ => None,
    };
    let lat = sign(b[0], b'N', b'S')? * stem.get(1..3)?.parse::<u8>().ok()? as f64;
    let lon = sign(b[3], b'E', b'W')? * stem.get(4..7)?.parse::<u16>().ok()? as f64;
    ((-90.0..=89.0).contains(&lat) && (-180.0..=179.0).contains(&lon)).then_some((lat, lon))
}

/// The lower-case extension of `path`.
fn extension(path: &Path) -> Option<String> {
    path.extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
}

/// Decode an SRTM `.hgt` tile whose name (like `N78E015.hgt`) gave its south-west `corner`.
fn read_hgt(path: &Path, corner: Option<(f64, f64)>, bytes: &[u8]) -> Result<Dem, DemError> {
    let (lat, lon) = corner.ok_or_else(|| {
        invalid(
            path,
            "file name",
            "an SRTM tile must be named like N78E015.hgt (latitude and longitude of its \
             south-west corner)"
                .into(),
        )
    })?;
    let n = match bytes.len() {
        l if l == 2 * 1201 * 1201 => 1201,
        l if l == 2 * 3601 * 3601 => 3601,
        l => {
            return Err(invalid(
                path,
                "file size",
                format!(
                    "{l} bytes; an SRTM tile has 1201 × 1201 (2884802 bytes) or 3601 × 3601 \
                     (25934402 bytes) big-endian 16-bit samples (truncated or not a .hgt file?)"
                ),
            ));
        }
    };
    let heights: Vec<f32> = bytes
        .chunks_exact(2)
        .map(|b| match i16::from_be_bytes([b[0], b[1]]) {
            -32768 => f32::NAN,
            v => v as f32,
        })
        .collect();
    let step = 1.0 / (n - 1) as f64;
    Dem::new(n, n, (lat + 1.0, lon), (step, step), heights)
        .ok_or_else(|| invalid(path, "grid", "inconsistent grid".into()))
}

/// GeoTIFF keys this reader uses.
const GT_MODEL_TYPE: u16 = 1024;
const GT_RASTER_TYPE: u16 = 1025;
const MODEL_TYPE_GEOGRAPHIC: u16 = 2;
const RASTER_PIXEL_IS_POINT: u16 = 2;

/// (model type, raster type) from a GeoKeyDirectoryTag's values.
fn geo_keys(path: &Path, dir: &[u16]) -> Result<(Option<u16>, Option<u16>), DemError> {
    if dir.len() < 4 || dir.len() < 4 + 4 * dir[3] as usize {
        return Err(invalid(
            path,
            "GeoKeyDirectoryTag",
            format!("{} values do not hold its header and keys", dir.len()),
        ));
    }
    let mut model = None;
    let mut raster = None;
    for key in dir[4..4 + 4 * dir[3] as usize].chunks_exact(4) {
        // Key id, location (0: the value is in place), count, value.
        if key[1] != 0 {
            continue;
        }
        match key[0] {
            GT_MODEL_TYPE => model = Some(key[3]),
            GT_RASTER_TYPE => raster = Some(key[3]),
            _ => {}
        }
    }
    Ok((model, raster))
}

/// One band of samples as f32 (any integer or float sample type).
fn samples_f32(path: &Path, image: DecodingResult) -> Result<Vec<f32>, DemError> {
    Ok(match image {
        DecodingResult::U8(v) => v.into_iter().map(f32::from).collect(),
        DecodingResult::I8(v) => v.into_iter().map(f32::from).collect(),
        DecodingResult::U16(v) => v.into_iter().map(f32::from).collect(),
        DecodingResult::I16(v) => v.into_iter().map(f32::from).collect(),
        DecodingResult::U32(v) => v.into_iter().map(|x| x as f32).collect(),
        DecodingResult::I32(v) => v.into_iter().map(|x| x as f32).collect(),
        DecodingResult::F32(v) => v,
        DecodingResult::F64(v) => v.into_iter().map(|x| x as f32).collect(),
        _ => {
            return Err(invalid(
                path,
                "SampleFormat",
                "samples must be 8–32-bit integers or 32/64-bit floats".into(),
            ));
        }
    })
}

/// Decode a GeoTIFF heightmap on a geographic grid.
fn read_geotiff(path: &Path, bytes: &[u8]) -> Result<Dem, DemError> {
    let tiff_err = |source| DemError::Tiff {
        path: path.to_path_buf(),
        source,
    };
    let mut limits = Limits::default();
    limits.decoding_buffer_size = MAX_DEM_SAMPLES * 8;
    let mut dec = Decoder::new(Cursor::new(bytes))
        .map_err(tiff_err)?
        .with_limits(limits);
    let (w, h) = dec.dimensions().map_err(tiff_err)?;
    let (cols, rows) = (w as usize, h as usize);
    if rows.saturating_mul(cols) > MAX_DEM_SAMPLES || rows < 2 || cols < 2 {
        return Err(invalid(
            path,
            "ImageWidth/ImageLength",
            format!("{cols} × {rows}: a heightmap needs 2…{MAX_DEM_SAMPLES} samples, ≥ 2 a side"),
        ));
    }
    match dec.colortype().map_err(tiff_err)? {
        tiff::ColorType::Gray(_) => {}
        other => {
            return Err(invalid(
                path,
                "SamplesPerPixel",
                format!("a heightmap has one band, got {other:?}"),
            ));
        }
    }
    let f64_tag = |dec: &mut Decoder<_>, tag: Tag, name: &'static str, n: usize| {
        let v = dec
            .find_tag(tag)
            .map_err(tiff_err)?
            .ok_or_else(|| invalid(path, name, "missing (the grid is not georeferenced)".into()))?
            .into_f64_vec()
            .map_err(tiff_err)?;
        if v.len() < n || v.iter().any(|x| !x.is_finite()) {
            return Err(invalid(
                path,
                name,
                format!("needs {n} finite numbers, got {v:?}"),
            ));
        }
        Ok(v)
    };
    let keys = dec
        .find_tag(Tag::GeoKeyDirectoryTag)
        .map_err(tiff_err)?
        .ok_or_else(|| {
            invalid(
                path,
                "GeoKeyDirectoryTag",
                "missing: cannot tell a geographic grid from a projected one".into(),
            )
        })?
        .into_u16_vec()
        .map_err(tiff_err)?;
    let (model, raster) = geo_keys(path, &keys)?;
    if model != Some(MODEL_TYPE_GEOGRAPHIC) {
        let what = match model {
            Some(1) => "1 (projected: eastings and northings)".to_string(),
            Some(3) => "3 (geocentric)".to_string(),
            Some(m) => m.to_string(),
            None => "absent".to_string(),
        };
        return Err(invalid(
            path,
            "GTModelTypeGeoKey",
            format!(
                "{what}; only geographic (latitude/longitude) grids are supported: reproject \
                 the heightmap to EPSG:4326 first"
            ),
        ));
    }
    let tie = f64_tag(&mut dec, Tag::ModelTiepointTag, "ModelTiepointTag", 6)?;
    let scale = f64_tag(&mut dec, Tag::ModelPixelScaleTag, "ModelPixelScaleTag", 2)?;
    let nodata = match dec.find_tag(Tag::GdalNodata).map_err(tiff_err)? {
        Some(v) => {
            let s = v.into_string().map_err(tiff_err)?;
            let s = s.trim_matches(|c: char| c == '\0' || c.is_whitespace());
            Some(
                s.parse::<f64>()
                    .map_err(|_| invalid(path, "GDAL_NODATA", format!("{s:?} is not a number")))?,
            )
        }
        None => None,
    };
    let mut heights = samples_f32(path, dec.read_image().map_err(tiff_err)?)?;
    if heights.len() != rows * cols {
        return Err(invalid(
            path,
            "SamplesPerPixel",
            format!("{} samples for {cols} × {rows}", heights.len()),
        ));
    }
    if let Some(nd) = nodata {
        for v in &mut heights {
            if (*v as f64 - nd).abs() <= 1e-6 * nd.abs().max(1.0) {
                *v = f32::NAN;
            }
        }
    }
    // Raster (I, J) ↦ (lon X, lat Y); with PixelIsArea the tie point is a pixel's corner.
    let centre = if raster == Some(RASTER_PIXEL_IS_POINT) {
        0.0
    } else {
        0.5
    };
    let (i, j, x, y) = (tie[0], tie[1], tie[3], tie[4]);
    let (sx, sy) = (scale[0], scale[1]);
    let west = x + (centre - i) * sx;
    let north = y - (centre - j) * sy;
    let (south, east) = (
        north - (rows - 1) as f64 * sy,
        west + (cols - 1) as f64 * sx,
    );
    if !(sx > 0.0 && sy > 0.0) || north > 90.0 || south < -90.0 || west < -540.0 || east > 540.0 {
        return Err(invalid(
            path,
            "ModelPixelScaleTag",
            format!(
                "scale ({sx}, {sy})° from the tie point ({x}, {y}) gives latitudes \
                 {south}…{north}°, longitudes {west}…{east}°: not a geographic grid"
            ),
        ));
    }
    Dem::new(rows, cols, (north, west), (sy, sx), heights)
        .ok_or_else(|| invalid(path, "grid", "inconsistent grid".into()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tile_names_give_the_south_west_corner() {
        let c = |s: &str| hgt_corner(Path::new(s));
        assert_eq!(c("N78E015.hgt"), Some((78.0, 15.0)));
        assert_eq!(c("dir/s03w061.HGT"), Some((-3.0, -61.0)));
        assert_eq!(c("N78E15.hgt"), None);
        assert_eq!(c("X78E015.hgt"), None);
        assert_eq!(c("N95E015.hgt"), None);
    }

    #[test]
    fn voids_inside_a_plane_are_filled_with_the_plane() {
        // h = 3·row − 2·col + 100 on 40 × 50, a 12 × 9 void block and a lone void inside.
        let plane = |r: usize, c: usize| 3.0 * r as f32 - 2.0 * c as f32 + 100.0;
        let mut h: Vec<f32> = (0..2000).map(|k| plane(k / 50, k % 50)).collect();
        let holes: Vec<usize> = (10..22)
            .flat_map(|r| (20..29).map(move |c| r * 50 + c))
            .chain([35 * 50 + 7])
            .collect();
        for &i in &holes {
            h[i] = f32::NAN;
        }
        let mut dem = Dem::new(40, 50, (1.0, 0.0), (0.01, 0.01), h).unwrap();
        assert_eq!(dem.fill_voids(), holes.len());
        for &i in &holes {
            let (r, c) = (i / 50, i % 50);
            assert!((dem.sample(r, c) - plane(r, c)).abs() < 1e-2, "({r}, {c})");
        }
    }

    #[test]
    fn voids_at_an_edge_are_filled_within_their_surroundings_and_unreachable_ones_stay() {
        // A void strip along the north edge of a bumpy grid: filled, between the lowest and
        // highest known height. A grid of voids only: nothing to fill from.
        let mut h: Vec<f32> = (0..400).map(|k| ((k * 37) % 23) as f32).collect();
        for v in &mut h[..60] {
            *v = f32::NAN;
        }
        let mut dem = Dem::new(20, 20, (1.0, 0.0), (0.01, 0.01), h).unwrap();
        assert_eq!(dem.fill_voids(), 60);
        for c in 0..20 {
            for r in 0..3 {
                let v = dem.sample(r, c);
                assert!((0.0..=22.0).contains(&v), "({r}, {c}): {v}");
            }
        }
        let mut empty = Dem::new(3, 3, (1.0, 0.0), (0.1, 0.1), vec![f32::NAN; 9]).unwrap();
        assert_eq!(empty.fill_voids(), 0);
        assert!(empty.sample(1, 1).is_nan());
    }

    #[test]
    fn bilinear_height_and_slope_of_a_plane() {
        // h = 10·row + 2·col on a 3 × 4 grid.
        let h: Vec<f32> = (0..12)
            .map(|k| (10 * (k / 4) + 2 * (k % 4)) as f32)
            .collect();
        let dem = Dem::new(3, 4, (1.0, 0.0), (0.5, 0.25), h).unwrap();
        let v = dem.height_at(0.75, 0.125).unwrap();
        assert!((v - (10.0 * 0.5 + 2.0 * 0.5)).abs() < 1e-9, "{v}");
        assert_eq!(dem.height_at(1.01, 0.1), None);
        assert!(dem.slope_at(0.5, 0.375, 6.371e6).is_some());
    }

    #[test]
    fn gradients_in_parallel_are_row_major_and_interpolated_as_each_component_alone() {
        // A bumpy 7 × 9 grid with a void: every sample's central (one-sided next to the void
        // and at the edges) differences, in row-major order.
        let (rows, cols) = (7, 9);
        let mut h: Vec<f32> = (0..rows * cols)
            .map(|k| ((k * 37) % 23) as f32 * 1.5)
            .collect();
        h[3 * cols + 4] = f32::NAN;
        let dem = Dem::new(rows, cols, (1.0, 0.0), (0.01, 0.01), h.clone()).unwrap();
        let g = dem.gradients();
        let at = |r: usize, c: usize| h[r * cols + c];
        assert_eq!(
            g[cols + 1],
            [0.5 * (at(2, 1) - at(0, 1)), 0.5 * (at(1, 2) - at(1, 0))]
        );
        assert_eq!(g[2 * cols + 4][0], at(2, 4) - at(1, 4));
        assert_eq!(g[3 * cols + 5][1], at(3, 6) - at(3, 5));
        assert_eq!(g[cols - 1][1], at(0, cols - 1) - at(0, cols - 2));
        assert_eq!(g[(rows - 1) * cols][0], at(rows - 1, 0) - at(rows - 2, 0));
        // The pair interpolation is each component's own, bit for bit.
        for (r, c) in [(0.0, 0.0), (0.3, 7.9), (5.999, 2.5), (6.0, 8.0), (2.7, 4.2)] {
            let pair = bilinear_pair(rows, cols, r, c, &g);
            for (k, v) in pair.into_iter().enumerate() {
                let alone = bilinear(rows, cols, r, c, |i| f64::from(g[i][k]));
                assert_eq!(v.to_bits(), alone.to_bits(), "({r}, {c}) {k}");
            }
        }
    }
}
