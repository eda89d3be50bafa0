//! Scene — the pinhole camera. In: camera parameters (height, heading, pitch, field of view,
//! resolution). Out: for a point on the film, the viewing direction as (azimuth, apparent
//! elevation) in the observer's local frame (east, north, up).
//!
//! With a spherically symmetric atmosphere the ray depends only on its apparent elevation; the
//! azimuth only selects where on the cards (and relative to the sun) it lands.

use serde::Serialize;

/// A pinhole camera at `height_m` above the surface. Film coordinates: x to the right in
/// `[0, width]`, y down in `[0, height]`; pixel (i, j) covers `[i, i+1] × [j, j+1]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Camera {
    /// Height of the camera above the surface (m).
    pub height_m: f64,
    /// Azimuth of the optical axis (rad, clockwise from north).
    pub heading_rad: f64,
    /// Elevation of the optical axis (rad, positive up).
    pub pitch_rad: f64,
    /// Horizontal field of view (rad).
    pub hfov_rad: f64,
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// Samples per pixel (a square number n²: n×n stratified jitter).
    pub samples_per_pixel: u32,
}

/// The camera's orthonormal basis in east–north–up coordinates, and its focal length in pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraFrame {
    forward: [f64; 3],
    right: [f64; 3],
    up: [f64; 3],
    /// Focal length in pixels: (width / 2) / tan(hfov / 2).
    pub focal_px: f64,
    half_w: f64,
    half_h: f64,
}

/// How much smaller than the centre pixel [`Camera::min_pixel_angle_rad`] may make a pixel.
pub const MAX_PIXEL_SHRINK: f64 = 16.0;

impl Camera {
    /// The camera's frame (basis and focal length).
    pub fn frame(&self) -> CameraFrame {
        let (sh, ch) = self.heading_rad.sin_cos();
        let (sp, cp) = self.pitch_rad.sin_cos();
        CameraFrame {
            forward: [sh * cp, ch * cp, sp],
            right: [ch, -sh, 0.0],
            up: [-sh * sp, -ch * sp, cp],
            focal_px: 0.5 * self.width as f64 / (0.5 * self.hfov_rad).tan(),
            half_w: 0.5 * self.width as f64,
            half_h: 0.5 * self.height as f64,
        }
    }

    /// Angular size of one pixel at the image centre (rad): 1 / focal length in pixels. Pixels
    /// away from the centre subtend less.
    pub fn pixel_angle_rad(&self) -> f64 {
        1.0 / self.frame().focal_px
    }

    /// The smallest angle any pixel of the frame subtends (rad): a pinhole pixel at angle θ from
    /// the optical axis spans cos²θ / f radially, so the frame's corners set it. Floored at
    /// 1/[`MAX_PIXEL_SHRINK`] of the centre pixel, so an extreme wide angle cannot make the
    /// elevation fan explode; below that floor (diagonal field of view above ≈ 151°) the fan's
    /// stated sub-pixel bound holds only in the central part of the frame.
    pub fn min_pixel_angle_rad(&self) -> f64 {
        let frame = self.frame();
        let half_diagonal_px = frame.half_w.hypot(frame.half_h);
        let cos_corner = (half_diagonal_px / frame.focal_px).atan().cos();
        (cos_corner * cos_corner).max(1.0 / MAX_PIXEL_SHRINK) / frame.focal_px
    }
}

/// Largest |x| for which [`small_atan`] is used (elevations within ±7.1°, where mirage frames
/// live); beyond it, the library `atan2`.
const SMALL_ATAN_MAX: f64 = 0.125;

/// atan(x) for |x| ≤ [`SMALL_ATAN_MAX`] from its Maclaurin series x − x³/3 + x⁵/5 − …, nine
/// terms: the first omitted term is below x·2⁻⁵⁴/19, under half an ulp, so this agrees with
/// the library function to rounding (a unit test checks 2 ulp). Written by hand because it
/// is several times cheaper than a general `atan2` and the renderer takes one per sample.
#[inline]
fn small_atan(x: f64) -> f64 {
    // cₖ = (−1)ᵏ / (2k + 1), k = 0..8, in z = x², evaluated by Estrin's scheme (pairs, then
    // powers z², z⁴): a short dependency chain instead of Horner's sixteen dependent steps.
    const C: [f64; 9] = [
        1.0,
        -1.0 / 3.0,
        1.0 / 5.0,
        -1.0 / 7.0,
        1.0 / 9.0,
        -1.0 / 11.0,
        1.0 / 13.0,
        -1.0 / 15.0,
        1.0 / 17.0,
    ];
    let z = x * x;
    let z2 = z * z;
    let z4 = z2 * z2;
    let p01 = C[0] + C[1] * z;
    let p23 = C[2] + C[3] * z;
    let p45 = C[4] + C[5] * z;
    let p67 = C[6] + C[7] * z;
    let p03 = p01 + p23 * z2;
    let p47 = p45 + p67 * z2;
    let p = p03 + (p47 + C[8] * z4) * z4;
    x * p
}

/// The azimuth offsets from the heading of the pixel centres of one camera's film, row by row
/// as first asked for ([`CameraFrame::row_azimuth_offsets`]): shared by the frames of a sweep
/// that share the camera, each row is worked out once for all of them.
#[derive(Debug)]
pub struct FilmAzimuths {
    frame: CameraFrame,
    width: usize,
    rows: Vec<std::sync::OnceLock<Box<[f64]>>>,
}

impl FilmAzimuths {
    /// For a film `width` × `height` pixels seen through `frame`.
    pub fn new(frame: CameraFrame, width: u32, height: u32) -> Self {
        FilmAzimuths {
            frame,
            width: width as usize,
            rows: (0..height).map(|_| std::sync::OnceLock::new()).collect(),
        }
    }

    /// The camera frame they are of.
    pub fn frame(&self) -> &CameraFrame {
        &self.frame
    }

    /// The offsets (rad) of row `y`'s pixel centres, one per column.
    ///
    /// # Panics
    /// If `y` is not a row of the film.
    pub fn row(&self, y: u32) -> &[f64] {
        self.rows[y as usize].get_or_init(|| {
            let mut offsets = Vec::with_capacity(self.width);
            self.frame
                .row_azimuth_offsets(y as f64 + 0.5, 0..self.width, &mut offsets);
            offsets.into_boxed_slice()
        })
    }
}

/// One sample's viewing direction in the camera's own terms: its apparent elevation, and what
/// its azimuth needs (computed only when a card or the sun may be met).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewDirection {
    /// Apparent elevation (rad).
    pub elevation_rad: f64,
    /// Film x offset from the centre in focal lengths (the direction's component along the
    /// camera's horizontal right axis).
    u: f64,
    /// The direction's horizontal component along the heading: cos pitch − v·sin pitch.
    a: f64,
}

impl ViewDirection {
    /// Azimuth relative to the camera heading (rad, clockwise, in (−π, π]): atan2(u, a), by the
    /// short series when |u/a| ≤ 0.125 (every frame narrower than ±7°).
    #[inline]
    pub fn azimuth_offset_rad(&self) -> f64 {
        if self.a > 0.0 && self.u.abs() <= SMALL_ATAN_MAX * self.a {
            small_atan(self.u / self.a)
        } else {
            self.u.atan2(self.a)
        }
    }
}

/// How far (rad) [`CameraFrame::row_elevation_range`] widens its bounds: thousands of times the
/// rounding of an elevation (below 1e-15 rad), and far below a pixel's height at any film size.
pub const ROW_ELEVATION_PAD_RAD: f64 = 1e-12;

/// Elevation (rad) of a direction with vertical component `dz` and horizontal length
/// `horizontal` (> 0 or a zenith/nadir direction).
#[inline]
fn elevation_from(dz: f64, horizontal: f64) -> f64 {
    let t = dz / horizontal;
    if t.abs() <= SMALL_ATAN_MAX {
        small_atan(t)
    } else {
        dz.atan2(horizontal)
    }
}

impl CameraFrame {
    /// Direction through film point (`x`, `y`) (pixels, y down) as (azimuth, elevation) in
    /// radians; the azimuth is clockwise from north, in (−π, π].
    #[inline]
    pub fn direction(&self, x: f64, y: f64) -> (f64, f64) {
        let d = self.direction_vector(x, y);
        (Self::azimuth_of(d), Self::elevation_of(d))
    }

    /// Unnormalised direction vector (east, north, up) through film point (`x`, `y`) (pixels,
    /// y down); its length is √(1 + u² + v²) with u, v the film offsets in focal lengths. The
    /// renderer takes the elevation of every sample but the azimuth only when it needs it.
    #[inline]
    pub fn direction_vector(&self, x: f64, y: f64) -> [f64; 3] {
        let u = (x - self.half_w) / self.focal_px;
        let v = (self.half_h - y) / self.focal_px;
        [
            self.forward[0] + u * self.right[0] + v * self.up[0],
            self.forward[1] + u * self.right[1] + v * self.up[1],
            self.forward[2] + u * self.right[2] + v * self.up[2],
        ]
    }

    /// The view direction through film point (`x`, `y`) (pixels, y down). Its elevation is
    /// atan(d_z / |d_h|) with d_z = sin pitch + v·cos pitch and |d_h|² = a² + u² (u, v the film
    /// offsets in focal lengths, a = cos pitch − v·sin pitch): the same direction as
    /// [`Self::direction_vector`], written so that a row shares everything but u.
    #[inline]
    pub fn view_direction(&self, x: f64, y: f64) -> ViewDirection {
        let (dz, a) = self.row_terms(y);
        let u = (x - self.half_w) / self.focal_px;
        let horizontal = (a * a + u * u).sqrt();
        ViewDirection {
            elevation_rad: elevation_from(dz, horizontal),
            u,
            a,
        }
    }

    /// The direction through film point (`x`, `y`) with its elevation taken as `elevation_rad`
    /// (a row shaded at one elevation: only the azimuth comes from the film point).
    #[inline]
    pub fn view_direction_at_elevation(&self, x: f64, y: f64, elevation_rad: f64) -> ViewDirection {
        let (_, a) = self.row_terms(y);
        ViewDirection {
            elevation_rad,
            u: (x - self.half_w) / self.focal_px,
            a,
        }
    }

    /// Bounds (rad) on the elevations of the view directions through the pixel centres of row
    /// `y` of a film `width` pixels wide ([`Self::row_view_directions`], [`Self::view_direction`]):
    /// along a row the elevation depends on the column only through its distance from the
    /// film's centre, and monotonically (its tangent is a fixed height over a horizontal length
    /// that grows with that distance), so it is bounded by the elevations of the columns
    /// nearest to and farthest from the centre, here widened by [`ROW_ELEVATION_PAD_RAD`] on
    /// either side for rounding. (−∞, +∞) when one of those is not finite.
    pub fn row_elevation_range(&self, y: u32, width: u32) -> (f64, f64) {
        let Some(last) = width.checked_sub(1) else {
            return (f64::INFINITY, f64::NEG_INFINITY);
        };
        // The column nearest the centre (of two as near, the other mirrors it), and both ends.
        let near = (self.half_w - 0.5).floor().clamp(0.0, f64::from(last)) as u32;
        let columns = [0, last, near];
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for x in columns {
            let e = self
                .view_direction(f64::from(x) + 0.5, f64::from(y) + 0.5)
                .elevation_rad;
            if !e.is_finite() {
                return (f64::NEG_INFINITY, f64::INFINITY);
            }
            (lo, hi) = (lo.min(e), hi.max(e));
        }
        (lo - ROW_ELEVATION_PAD_RAD, hi + ROW_ELEVATION_PAD_RAD)
    }

    /// The view directions through the pixel centres of row `y` (integer row index, so the film
    /// y coordinate is `y + 0.5`) into `out`: the same values as [`Self::view_direction`], with
    /// the square roots and the arctangent series in loops the compiler can vectorise.
    pub fn row_view_directions(&self, y: u32, width: u32, out: &mut Vec<ViewDirection>) {
        let (dz, a) = self.row_terms(y as f64 + 0.5);
        out.clear();
        out.extend((0..width).map(|x| {
            let u = (x as f64 + 0.5 - self.half_w) / self.focal_px;
            ViewDirection {
                elevation_rad: dz / (a * a + u * u).sqrt(),
                u,
                a,
            }
        }));
        if out.iter().all(|d| d.elevation_rad.abs() <= SMALL_ATAN_MAX) {
            for d in out.iter_mut() {
                d.elevation_rad = small_atan(d.elevation_rad);
            }
        } else {
            for d in out.iter_mut() {
                d.elevation_rad = elevation_from(dz, (a * a + d.u * d.u).sqrt());
            }
        }
    }

    /// The azimuth offsets from the heading ([`ViewDirection::azimuth_offset_rad`]) of the
    /// directions through the pixel centres of `columns` on film row `y` (pixels, y down),
    /// into `out`: the same values as [`Self::view_direction_at_elevation`] gives them (they do
    /// not depend on the elevation), the row's shared terms worked out once.
    pub fn row_azimuth_offsets(&self, y: f64, columns: std::ops::Range<usize>, out: &mut Vec<f64>) {
        let (_, a) = self.row_terms(y);
        out.clear();
        out.extend(columns.map(|x| (x as f64 + 0.5 - self.half_w) / self.focal_px));
        if a > 0.0 && out.iter().all(|u| u.abs() <= SMALL_ATAN_MAX * a) {
            for u in out.iter_mut() {
                *u = small_atan(*u / a);
            }
        } else {
            for u in out.iter_mut() {
                *u = ViewDirection {
                    elevation_rad: 0.0,
                    u: *u,
                    a,
                }
                .azimuth_offset_rad();
            }
        }
    }

    /// For film row `y`: the vertical component d_z and the along-heading horizontal component a
    /// of the direction vector (both shared by the whole row).
    #[inline]
    fn row_terms(&self, y: f64) -> (f64, f64) {
        let v = (self.half_h - y) / self.focal_px;
        // forward = (…, sin pitch), up = (…, cos pitch).
        (
            self.forward[2] + v * self.up[2],
            self.up[2] - v * self.forward[2],
        )
    }

    /// Elevation (rad) of direction vector `d` (any length).
    #[inline]
    pub fn elevation_of(d: [f64; 3]) -> f64 {
        // The components are O(1) (|d|² = 1 + u² + v²), so the plain square root cannot
        // overflow; it is several times cheaper than `hypot`.
        let horizontal = (d[0] * d[0] + d[1] * d[1]).sqrt();
        let x = d[2] / horizontal;
        if x.abs() <= SMALL_ATAN_MAX {
            small_atan(x)
        } else {
            d[2].atan2(horizontal)
        }
    }

    /// Azimuth (rad, clockwise from north, in (−π, π]) of direction vector `d` (any length).
    #[inline]
    pub fn azimuth_of(d: [f64; 3]) -> f64 {
        d[0].atan2(d[1])
    }

    /// Film point (x, y) (pixels, y down) where direction `d` (east, north, up) projects, or
    /// `None` if it points behind the camera.
    pub fn project(&self, d: [f64; 3]) -> Option<(f64, f64)> {
        let dot = |a: [f64; 3]| a[0] * d[0] + a[1] * d[1] + a[2] * d[2];
        let z = dot(self.forward);
        if z <= 0.0 {
            return None;
        }
        Some((
            self.half_w + self.focal_px * dot(self.right) / z,
            self.half_h - self.focal_px * dot(self.up) / z,
        ))
    }

    /// Film x range (pixels) of the directions whose azimuth, relative to the heading, lies in
    /// [`lo`, `hi`] (rad), over the film rows y in [`y0`, `y1`]: a direction's azimuth offset is
    /// atan2(u, a) with u its film x offset in focal lengths and a = cos pitch − v sin pitch
    /// (v its film y offset), so it grows with x along a row. `None` when that does not bound
    /// it: offsets beyond ±90°, or rows reaching the zenith or nadir (a ≤ 0).
    pub fn film_x_range_for_azimuths(
        &self,
        lo: f64,
        hi: f64,
        y0: f64,
        y1: f64,
    ) -> Option<(f64, f64)> {
        let half_pi = std::f64::consts::FRAC_PI_2;
        if !(lo > -half_pi && hi < half_pi && lo <= hi) {
            return None;
        }
        // forward = (…, sin pitch), up = (…, cos pitch).
        let a = |y: f64| self.up[2] - (self.half_h - y) / self.focal_px * self.forward[2];
        let (a0, a1) = (a(y0), a(y1));
        if !(a0 > 0.0 && a1 > 0.0) {
            return None;
        }
        let (t_lo, t_hi) = (lo.tan(), hi.tan());
        let u_lo = (a0 * t_lo).min(a1 * t_lo);
        let u_hi = (a0 * t_hi).max(a1 * t_hi);
        Some((
            self.half_w + self.focal_px * u_lo,
            self.half_w + self.focal_px * u_hi,
        ))
    }

    /// Film y coordinate (pixels, down) at which the centre column (x = width/2) sees apparent
    /// elevation `elevation_rad`, for a camera with this frame's pitch.
    pub fn centre_row_of_elevation(&self, elevation_rad: f64, pitch_rad: f64) -> f64 {
        self.half_h - self.focal_px * (elevation_rad - pitch_rad).tan()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(heading_deg: f64, pitch_deg: f64) -> Camera {
        Camera {
            height_m: 10.0,
            heading_rad: heading_deg.to_radians(),
            pitch_rad: pitch_deg.to_radians(),
            hfov_rad: 60f64.to_radians(),
            width: 400,
            height: 200,
            samples_per_pixel: 1,
        }
    }

    #[test]
    fn small_atan_matches_the_library_atan() {
        for i in 0..=20_000 {
            let x = SMALL_ATAN_MAX * (i as f64 / 10_000.0 - 1.0);
            let (a, b) = (small_atan(x), x.atan());
            assert!(
                (a - b).abs() <= 2.0 * f64::EPSILON * b.abs(),
                "{x}: {a} vs {b}"
            );
        }
        // Through elevation_of, on both sides of the switch to atan2.
        for e in [0.0f64, 1e-9, -3e-3, 0.1, 0.124, 0.126, 0.5, -1.2] {
            let d = [0.3 * e.cos(), 0.4 * e.cos(), 0.5 * e.sin()];
            let got = CameraFrame::elevation_of(d);
            assert!((got - e).abs() <= 1e-15, "{e}: {got}");
        }
    }

    #[test]
    fn smallest_pixel_is_at_the_corner() {
        // Measure the elevation step between the last two rows at the corner column directly.
        let c = cam(0.0, 0.0);
        let f = c.frame();
        let (_, e1) = f.direction(0.0, 0.0);
        let (_, e2) = f.direction(0.0, 1.0);
        let (_, e3) = f.direction(1.0, 0.0);
        let corner_step = (e1 - e2).abs().min((e1 - e3).abs().max(1e-300));
        let min = c.min_pixel_angle_rad();
        assert!(
            min <= (e1 - e2).abs() * 1.001,
            "{min} vs {}",
            (e1 - e2).abs()
        );
        assert!(min < c.pixel_angle_rad());
        assert!(corner_step > 0.0);
        // A narrow paper frame: the corner pixel is the centre pixel to 1e-4.
        let narrow = Camera {
            hfov_rad: 1f64.to_radians(),
            ..c
        };
        assert!((narrow.min_pixel_angle_rad() / narrow.pixel_angle_rad() - 1.0).abs() < 1e-4);
        // An extreme wide angle is floored.
        let wide = Camera {
            hfov_rad: 178f64.to_radians(),
            ..c
        };
        assert!(
            (wide.min_pixel_angle_rad() * MAX_PIXEL_SHRINK / wide.pixel_angle_rad() - 1.0).abs()
                < 1e-12
        );
    }

    #[test]
    fn centre_looks_along_the_axis_and_edges_at_half_fov() {
        let c = cam(90.0, 5.0);
        let f = c.frame();
        let (az, el) = f.direction(200.0, 100.0);
        assert!((az - 90f64.to_radians()).abs() < 1e-12);
        assert!((el - 5f64.to_radians()).abs() < 1e-12);
        let c = cam(0.0, 0.0);
        let (az, el) = c.frame().direction(400.0, 100.0);
        assert!((az - 30f64.to_radians()).abs() < 1e-12, "{az}");
        assert!(el.abs() < 1e-12);
        // Top edge of the centre column: elevation atan(tan(30°)·100/200).
        let (az, el) = c.frame().direction(200.0, 0.0);
        assert!(az.abs() < 1e-12);
        assert!((el - (30f64.to_radians().tan() * 0.5).atan()).abs() < 1e-12);
    }

    #[test]
    fn centre_row_inverts_direction() {
        let c = cam(10.0, -2.0);
        let f = c.frame();
        for y in [3.5, 50.0, 100.0, 177.25] {
            let (_, el) = f.direction(200.0, y);
            assert!((f.centre_row_of_elevation(el, c.pitch_rad) - y).abs() < 1e-9);
        }
    }

    #[test]
    fn view_directions_match_the_direction_vector() {
        for (heading, pitch) in [(0.0, 0.0), (37.0, -12.0), (-150.0, 25.0), (90.0, 80.0)] {
            let c = cam(heading, pitch);
            let f = c.frame();
            let mut row = Vec::new();
            for y in [0u32, 57, 199] {
                f.row_view_directions(y, c.width, &mut row);
                for x in [0u32, 1, 133, 200, 399] {
                    let (fx, fy) = (x as f64 + 0.5, y as f64 + 0.5);
                    let (az, el) = f.direction(fx, fy);
                    let d = f.view_direction(fx, fy);
                    assert_eq!(d, row[x as usize]);
                    assert!((d.elevation_rad - el).abs() < 1e-14, "{heading} {pitch}");
                    let off = d.azimuth_offset_rad() + c.heading_rad - az;
                    let off = (off + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                        - std::f64::consts::PI;
                    assert!(off.abs() < 1e-14, "{heading} {pitch}: {off}");
                    let at = f.view_direction_at_elevation(fx, fy, 0.25);
                    assert_eq!(at.elevation_rad, 0.25);
                    assert_eq!(at.azimuth_offset_rad(), d.azimuth_offset_rad());
                }
            }
        }
    }

    #[test]
    fn a_rows_elevation_range_holds_its_pixels_elevations_and_no_more() {
        // Films even and odd in width, level and pitched cameras, rows from top to bottom
        // (elevations on both sides of the switch to the library's arctangent).
        let mut row = Vec::new();
        for (width, hfov_deg) in [(400, 60.0), (401, 60.0), (1, 10.0), (2, 10.0), (1920, 0.6)] {
            for pitch in [-70.0, -3.0, 0.0, 0.2, 30.0] {
                let c = Camera {
                    width,
                    height: 120,
                    hfov_rad: f64::to_radians(hfov_deg),
                    ..cam(20.0, pitch)
                };
                let f = c.frame();
                for y in (0..120).step_by(7) {
                    f.row_view_directions(y, width, &mut row);
                    let (lo, hi) = f.row_elevation_range(y, width);
                    let elevations = row.iter().map(|d| d.elevation_rad);
                    let min = elevations.clone().fold(f64::INFINITY, f64::min);
                    let max = elevations.fold(f64::NEG_INFINITY, f64::max);
                    let case = format!("{width} {pitch} {y}");
                    assert_eq!(lo, min - ROW_ELEVATION_PAD_RAD, "{case}");
                    assert_eq!(hi, max + ROW_ELEVATION_PAD_RAD, "{case}");
                }
            }
        }
        assert_eq!(
            cam(0.0, 0.0).frame().row_elevation_range(3, 0),
            (f64::INFINITY, f64::NEG_INFINITY)
        );
    }

    #[test]
    fn azimuth_range_bounds_the_columns_that_see_it() {
        for pitch in [-20.0, 0.0, 15.0] {
            let c = cam(30.0, pitch);
            let f = c.frame();
            let (lo, hi) = (-0.2, 0.05);
            let (a, b) = f.film_x_range_for_azimuths(lo, hi, 40.0, 41.0).unwrap();
            assert!(a < b);
            for i in 0..=800 {
                let x = i as f64 * 0.5;
                for y in [40.0, 40.5, 41.0] {
                    let off = f.view_direction(x, y).azimuth_offset_rad();
                    if (lo..=hi).contains(&off) {
                        assert!(x >= a - 1e-9 && x <= b + 1e-9, "{pitch}: x {x} off {off}");
                    }
                }
            }
        }
        // Offsets beyond ±90° are not bounded.
        let f = cam(0.0, 0.0).frame();
        assert!(f.film_x_range_for_azimuths(-2.0, 0.1, 0.0, 1.0).is_none());
        // Rows that reach past the zenith are not bounded (a ≤ 0).
        let f = cam(0.0, 89.0).frame();
        assert!(f.film_x_range_for_azimuths(-0.1, 0.1, 0.0, 1.0).is_none());
    }
}
