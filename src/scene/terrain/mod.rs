//! Scene — terrain. In: the scene's `[terrain]` section (an elevation model file, where the
//! observer stands on it, a palette, optionally an orthophoto). Out: a [`Terrain`]: the decoded
//! [`Dem`], the observer's position and the colour rules the renderer shades terrain hits with.
//!
//! ```toml
//! [terrain]
//! dem = "island.tif"           # SRTM .hgt (named like N78E015.hgt) or a geographic GeoTIFF
//! observer_lat_deg = 78.0      # the camera's position; its heading is camera.heading_deg
//! observer_lon_deg = 15.0
//! snow_line_m = 300.0          # snow at and above this height (default 300)
//! ice_slope_deg = 35.0         # ice on slopes at least this steep, at any height (default 35)
//! rock_rgb = [0.10, 0.09, 0.08]    # linear radiance, 1 = the horizon sky (defaults shown)
//! snow_rgb = [0.85, 0.87, 0.90]
//! ice_rgb = [0.50, 0.64, 0.75]
//! light_azimuth_deg = 180.0    # where the light comes from (clockwise from north, default 180)
//! light_elevation_deg = 30.0   # and how high (default 30)
//! fill_voids = true            # fill the model's voids from the heights around them (default)
//! orthophoto = "island.png"    # optional: ground colours from a georeferenced image
//! orthophoto_bounds_deg = [78.2, 14.5, 78.6, 15.5]  # its S, W, N, E edges (default: the model's)
//! ```
//!
//! The terrain's surface is the sea level of the sphere (`earth.radius_m`); heights at or below
//! 0 m and voids are sea. The camera's `height_m` stays its height above the sea.

pub mod dem;
pub mod ortho;

use std::path::PathBuf;
use std::sync::Arc;

use rayon::prelude::*;
use serde::Serialize;

pub use dem::{Dem, DemError};
pub use ortho::Orthophoto;

/// How terrain is coloured: by height and slope, then lit by one directional light.
///
/// A point is **ice** where its slope is at least `ice_slope_rad`, else **snow** at or above
/// `snow_line_m`, else **rock**. The colour is scaled by `ambient + (1 − ambient)·max(0, n·l)`
/// (n the surface normal, l towards the light), with `ambient` [`Palette::AMBIENT`], and by the
/// sky's brightness.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Palette {
    /// Rock colour (linear RGB, horizon-sky units).
    pub rock_rgb: [f64; 3],
    /// Snow colour.
    pub snow_rgb: [f64; 3],
    /// Ice colour.
    pub ice_rgb: [f64; 3],
    /// Height from which the ground is snow (m).
    pub snow_line_m: f64,
    /// Slope from which the ground is ice (rad).
    pub ice_slope_rad: f64,
    /// Azimuth the light comes from (rad, clockwise from north).
    pub light_azimuth_rad: f64,
    /// Elevation of the light (rad).
    pub light_elevation_rad: f64,
    /// Unit vector (east, north, up) towards the light (from the two angles).
    #[serde(skip)]
    pub light_enu: [f64; 3],
}

impl Palette {
    /// Fraction of the light that reaches surfaces facing away from it (sky light).
    pub const AMBIENT: f64 = 0.35;

    /// The palette's defaults: rock below 300 m, snow above, ice from 35°, light from the south
    /// at 30°.
    pub fn default_palette() -> Self {
        Self {
            rock_rgb: [0.10, 0.09, 0.08],
            snow_rgb: [0.85, 0.87, 0.90],
            ice_rgb: [0.50, 0.64, 0.75],
            snow_line_m: 300.0,
            ice_slope_rad: 35f64.to_radians(),
            light_azimuth_rad: 180f64.to_radians(),
            light_elevation_rad: 30f64.to_radians(),
            light_enu: light_direction(180f64.to_radians(), 30f64.to_radians()),
        }
    }

    /// Unlit colour of ground at `height_m` with slope `slope_rad`.
    pub fn albedo(&self, height_m: f64, slope_rad: f64) -> [f64; 3] {
        if slope_rad >= self.ice_slope_rad {
            self.ice_rgb
        } else if height_m >= self.snow_line_m {
            self.snow_rgb
        } else {
            self.rock_rgb
        }
    }

    /// Lit colour of ground at `height_m` with slope `slope_rad` and upward unit normal
    /// `normal_enu`.
    pub fn colour(&self, height_m: f64, slope_rad: f64, normal_enu: [f64; 3]) -> [f64; 3] {
        self.lit(self.albedo(height_m, slope_rad), normal_enu)
    }

    /// `albedo` lit as [`Self::colour`] lights it, on ground with upward unit normal
    /// `normal_enu`.
    #[inline]
    pub fn lit(&self, albedo: [f64; 3], normal_enu: [f64; 3]) -> [f64; 3] {
        let l = self.light_enu;
        let lambert = (normal_enu[0] * l[0] + normal_enu[1] * l[1] + normal_enu[2] * l[2]).max(0.0);
        let light = Self::AMBIENT + (1.0 - Self::AMBIENT) * lambert;
        albedo.map(|c| c * light)
    }

    /// A slope tangent below which every slope is below the ice slope: tan(ice slope − 1e-9
    /// rad) less a relative 1e-12, so that arctan of a smaller tangent is certainly below the
    /// ice slope despite rounding (0 when the ice slope is not in (1e-9, π/2]: the angle is then
    /// always computed). See [`Self::is_ice`].
    pub fn ice_tan_below(&self) -> f64 {
        let s = self.ice_slope_rad;
        if s > 1e-9 && s <= std::f64::consts::FRAC_PI_2 {
            (s - 1e-9).tan() * (1.0 - 1e-12)
        } else {
            0.0
        }
    }

    /// Whether ground whose slope has tangent `tan_slope` is ice (slope ≥ the ice slope, as
    /// [`Self::albedo`] decides it), the arctangent taken only at or above `ice_tan_below`
    /// ([`Self::ice_tan_below`]).
    #[inline]
    pub fn is_ice(&self, tan_slope: f64, ice_tan_below: f64) -> bool {
        tan_slope >= ice_tan_below && tan_slope.atan() >= self.ice_slope_rad
    }
}

/// Unit vector (east, north, up) towards a light at `azimuth_rad` (clockwise from north) and
/// `elevation_rad`.
pub fn light_direction(azimuth_rad: f64, elevation_rad: f64) -> [f64; 3] {
    let (se, ce) = elevation_rad.sin_cos();
    let (sa, ca) = azimuth_rad.sin_cos();
    [ce * sa, ce * ca, se]
}

/// A great circle through the observer: the point at angle δ along it is
/// `start`·cos δ + `tangent`·sin δ (Earth-centred unit vectors).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GreatCircle {
    /// The observer.
    pub start: [f64; 3],
    /// The unit tangent at the observer along the circle's azimuth.
    pub tangent: [f64; 3],
}

impl GreatCircle {
    /// Latitude and longitude (°) of the point at ground distance `distance_m` along the
    /// circle, on a sphere of `radius_m`.
    #[inline]
    pub fn lat_lon_deg(&self, distance_m: f64, radius_m: f64) -> (f64, f64) {
        self.lat_lon_deg_at((distance_m / radius_m).sin_cos())
    }

    /// [`Self::lat_lon_deg`] of the point at the angle δ along the circle whose (sin δ, cos δ)
    /// are `(s, c)`.
    #[inline]
    pub fn lat_lon_deg_at(&self, (s, c): (f64, f64)) -> (f64, f64) {
        let p = [0, 1, 2].map(|k| self.start[k] * c + self.tangent[k] * s);
        (
            p[2].clamp(-1.0, 1.0).asin().to_degrees(),
            p[1].atan2(p[0]).to_degrees(),
        )
    }

    /// The model's fractional (row, column) of the point at `distance_m` along the circle
    /// (`None` off the model), on a sphere of `radius_m`.
    #[inline]
    pub fn grid_at(&self, terrain: &Terrain, distance_m: f64, radius_m: f64) -> Option<(f64, f64)> {
        self.grid_at_angle(terrain, (distance_m / radius_m).sin_cos())
    }

    /// [`Self::grid_at`] the angle δ along the circle whose (sin δ, cos δ) are `angle`.
    #[inline]
    pub fn grid_at_angle(&self, terrain: &Terrain, angle: (f64, f64)) -> Option<(f64, f64)> {
        let (lat, lon) = self.lat_lon_deg_at(angle);
        terrain.dem.grid_position(lat, terrain.wrap_lon(lon))
    }
}

/// Terrain in a scene: an elevation model, the observer on it, and its palette.
#[derive(Debug, Clone, Serialize)]
pub struct Terrain {
    /// The elevation model file.
    pub dem_path: PathBuf,
    /// Observer (camera) latitude (°).
    pub observer_lat_deg: f64,
    /// Observer (camera) longitude (°).
    pub observer_lon_deg: f64,
    /// How hits are coloured.
    #[serde(flatten)]
    pub palette: Palette,
    /// Whether the model's voids were filled (`fill_voids`, default true; see
    /// [`Dem::fill_voids`]); unfilled voids are no ground.
    pub fill_voids: bool,
    /// How many void samples were filled.
    #[serde(skip)]
    pub voids_filled: usize,
    /// Ground colours from a georeferenced image, where it covers the ground (else the
    /// palette's).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub orthophoto: Option<Orthophoto>,
    /// Highest terrain height in the model (m; 0 if it is all sea).
    pub max_height_m: f64,
    /// The decoded model.
    #[serde(skip)]
    pub dem: Arc<Dem>,
    /// The model's height gradients per sample ([`Dem::gradients`]), for slopes and normals.
    #[serde(skip)]
    pub gradients: Arc<Vec<[f32; 2]>>,
}

impl Terrain {
    /// Terrain from a decoded model (the file is named for errors and the scene's record), its
    /// voids filled first if `fill_voids`.
    pub fn new(
        dem_path: PathBuf,
        mut dem: Dem,
        (observer_lat_deg, observer_lon_deg): (f64, f64),
        palette: Palette,
        fill_voids: bool,
    ) -> Self {
        let voids_filled = if fill_voids { dem.fill_voids() } else { 0 };
        let mut max_height_m = 0.0f64;
        for r in 0..dem.rows {
            for c in 0..dem.cols {
                let h = dem.sample(r, c) as f64;
                if h.is_finite() {
                    max_height_m = max_height_m.max(h);
                }
            }
        }
        let gradients = Arc::new(dem.gradients());
        Self {
            dem_path,
            observer_lat_deg,
            observer_lon_deg,
            palette,
            fill_voids,
            voids_filled,
            orthophoto: None,
            max_height_m,
            dem: Arc::new(dem),
            gradients,
        }
    }

    /// The same terrain coloured by `orthophoto` where it covers the ground.
    pub fn with_orthophoto(mut self, orthophoto: Orthophoto) -> Self {
        self.orthophoto = Some(orthophoto);
        self
    }

    /// The cells around the model's samples: its sample centres widened by half a step on each
    /// side, as south, west, north and east edges (°) — an orthophoto's default bounds.
    pub fn model_area_deg(&self) -> [f64; 4] {
        let (south, north, west, east) = self.dem.bounds_deg();
        let (dlat, dlon) = (0.5 * self.dem.lat_step_deg, 0.5 * self.dem.lon_step_deg);
        [south - dlat, west - dlon, north + dlat, east + dlon]
    }

    /// Latitude and longitude (°) of the point at ground distance `distance_m` along
    /// `azimuth_rad` (clockwise from north) from the observer, on a sphere of `radius_m`
    /// (the great circle through the observer in that direction).
    #[inline]
    pub fn destination_deg(&self, azimuth_rad: f64, distance_m: f64, radius_m: f64) -> (f64, f64) {
        let (p1, l1) = (
            self.observer_lat_deg.to_radians(),
            self.observer_lon_deg.to_radians(),
        );
        let delta = distance_m / radius_m;
        let (sd, cd) = delta.sin_cos();
        let (sp, cp) = p1.sin_cos();
        let sp2 = (sp * cd + cp * sd * azimuth_rad.cos()).clamp(-1.0, 1.0);
        let p2 = sp2.asin();
        let l2 = l1 + (azimuth_rad.sin() * sd * cp).atan2(cd - sp * sp2);
        (p2.to_degrees(), l2.to_degrees())
    }

    /// The great circle leaving the observer along `azimuth_rad` (clockwise from north), for
    /// many points along it ([`GreatCircle::grid_at`]): the same points as
    /// [`Self::destination_deg`], with one sine and cosine per point instead of four.
    pub fn great_circle(&self, azimuth_rad: f64) -> GreatCircle {
        let (sp, cp) = self.observer_lat_deg.to_radians().sin_cos();
        let (sl, cl) = self.observer_lon_deg.to_radians().sin_cos();
        let (sa, ca) = azimuth_rad.sin_cos();
        // Earth-centred unit vectors: the observer, and north and east there.
        let up = [cp * cl, cp * sl, sp];
        let north = [-sp * cl, -sp * sl, cp];
        let east = [-sl, cl, 0.0];
        GreatCircle {
            start: up,
            tangent: [0, 1, 2].map(|k| ca * north[k] + sa * east[k]),
        }
    }

    /// Ground distance (m) from the observer to a point, on a sphere of `radius_m` (haversine).
    pub fn distance_to_m(&self, lat_deg: f64, lon_deg: f64, radius_m: f64) -> f64 {
        let (p1, p2) = (self.observer_lat_deg.to_radians(), lat_deg.to_radians());
        let dp = p2 - p1;
        let dl = (lon_deg - self.observer_lon_deg).to_radians();
        let a = (0.5 * dp).sin().powi(2) + p1.cos() * p2.cos() * (0.5 * dl).sin().powi(2);
        2.0 * radius_m * a.sqrt().min(1.0).asin()
    }

    /// Height (m) of the terrain at ground distance `distance_m` along `azimuth_rad`; `None` for
    /// sea (≤ 0 m), voids and points off the model.
    #[inline]
    pub fn height_along(&self, azimuth_rad: f64, distance_m: f64, radius_m: f64) -> Option<f64> {
        let (r, c) = self.grid_along(azimuth_rad, distance_m, radius_m)?;
        self.dem.height_at_grid(r, c).filter(|&h| h > 0.0)
    }

    /// The model's fractional (row, column) of the point at ground distance `distance_m` along
    /// `azimuth_rad`; `None` off the model.
    #[inline]
    pub fn grid_along(
        &self,
        azimuth_rad: f64,
        distance_m: f64,
        radius_m: f64,
    ) -> Option<(f64, f64)> {
        let (lat, lon) = self.destination_deg(azimuth_rad, distance_m, radius_m);
        self.dem.grid_position(lat, self.wrap_lon(lon))
    }

    /// Slope (rad) and upward unit normal (east, north, up) of the ground at the model's
    /// fractional row `r` and column `c`, on a sphere of `radius_m`: the gradients
    /// ([`Dem::gradients`]) interpolated bilinearly; flat where unknown.
    #[inline]
    pub fn slope_at_grid(&self, r: f64, c: f64, radius_m: f64) -> (f64, [f64; 3]) {
        self.dem
            .gradient_at_grid(&self.gradients, r, c, radius_m)
            .unwrap_or((0.0, [0.0, 0.0, 1.0]))
    }

    /// `lon_deg` shifted by whole turns to the model's longitudes when that puts it on the model.
    #[inline]
    pub fn wrap_lon(&self, lon_deg: f64) -> f64 {
        let (_, _, west, _) = self.dem.bounds_deg();
        if lon_deg < west {
            lon_deg + 360.0 * ((west - lon_deg) / 360.0).ceil()
        } else if lon_deg > west + 360.0 {
            lon_deg - 360.0 * ((lon_deg - west) / 360.0).floor()
        } else {
            lon_deg
        }
    }

    /// The nearest and farthest ground distances (m) of land (height > 0) in the model from the
    /// observer, on a sphere of `radius_m`, with the grid spacing (m) used to find them; `None`
    /// if the model holds no land.
    pub fn land_distance_range_m(&self, radius_m: f64) -> Option<(f64, f64)> {
        let dem = &self.dem;
        // At most ~1M samples visited; the range is widened by the stride's diagonal.
        let stride = ((dem.rows * dem.cols) as f64 / 1.0e6)
            .sqrt()
            .ceil()
            .max(1.0) as usize;
        // Rows of cells in parallel (the minimum and maximum do not depend on the order).
        let (lo, hi) = (0..dem.rows)
            .into_par_iter()
            .step_by(stride)
            .map(|r| {
                let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
                for c in (0..dem.cols).step_by(stride) {
                    let rr = (r + stride).min(dem.rows);
                    let cc = (c + stride).min(dem.cols);
                    let land = (r..rr).any(|i| (c..cc).any(|j| dem.sample(i, j) > 0.0));
                    if !land {
                        continue;
                    }
                    let (lat, lon) = dem.lat_lon_deg(r, c);
                    let d = self.distance_to_m(lat, lon, radius_m);
                    lo = lo.min(d);
                    hi = hi.max(d);
                }
                (lo, hi)
            })
            .reduce(
                || (f64::INFINITY, 0.0f64),
                |a, b| (a.0.min(b.0), a.1.max(b.1)),
            );
        if !lo.is_finite() {
            return None;
        }
        let m_per_deg = radius_m * std::f64::consts::PI / 180.0;
        let pad = 1.5 * stride as f64 * m_per_deg * dem.lat_step_deg.max(dem.lon_step_deg);
        Some(((lo - pad).max(0.0), hi + pad))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn is_ice_decides_as_the_slope_angle_does() {
        let mut palette = Palette::default_palette();
        for ice_deg in [0.0, 1e-9, 5.0, 20.0, 35.0, 60.0, 89.9, 90.0, 95.0] {
            palette.ice_slope_rad = f64::to_radians(ice_deg);
            let below = palette.ice_tan_below();
            let t = palette.ice_slope_rad.tan().abs();
            // Tangents around the threshold (a few ulps and relative steps each side), spread
            // over [0, 1e20], and the extremes.
            let mut tangents = vec![0.0, 1e-300, f64::MAX, 1e16, 1.633e16, 1e20];
            tangents.extend((0..2000).map(|k| 10f64.powf(-6.0 + 26.0 * k as f64 / 2000.0)));
            for rel in [1e-15, 1e-12, 1e-10, 1e-9, 1e-6, 1e-3] {
                tangents.extend([t * (1.0 - rel), t * (1.0 + rel)]);
            }
            for ulps in 0..64u64 {
                tangents.extend([
                    f64::from_bits(t.to_bits() - ulps),
                    f64::from_bits(t.to_bits() + ulps),
                ]);
            }
            for &x in &tangents {
                assert_eq!(
                    palette.is_ice(x, below),
                    x.atan() >= palette.ice_slope_rad,
                    "ice slope {ice_deg}°, tangent {x:e}"
                );
            }
        }
    }

    #[test]
    fn great_circle_points_are_the_destinations() {
        let dem = Dem::new(2, 2, (80.0, 10.0), (1.0, 1.0), vec![0.0; 4]).unwrap();
        let t = Terrain::new(
            PathBuf::from("x.tif"),
            dem,
            (78.3, 15.2),
            Palette::default_palette(),
            false,
        );
        let r = 6.371e6;
        for az in [0.0f64, 0.7, 2.0, 3.1, -1.2] {
            let gc = t.great_circle(az);
            for d in [0.0, 1_000.0, 45_000.0, 700_000.0] {
                let (a, b) = gc.lat_lon_deg(d, r);
                let (c, e) = t.destination_deg(az, d, r);
                let dl = (b - e + 540.0).rem_euclid(360.0) - 180.0;
                assert!(
                    (a - c).abs() < 1e-9 && dl.abs() < 1e-9,
                    "{az} {d}: {a},{b} vs {c},{e}"
                );
            }
        }
    }
}
