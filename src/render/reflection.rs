//! Render — the sea's reflections. In: a ray that met the sea (grazing angle g, ground distance
//! d from the camera, azimuth), the cards, the sky and the sun. Out: the radiance the sea sends
//! back along it beyond the sky reflection already tabulated by grazing angle: the mirror images
//! of the cards and the terrain, and the sun's glitter (calm: its mirror image).
//!
//! In a spherically stratified atmosphere a reflected ray is a ray launched from the sea surface
//! (height 0) at elevation e = the reflected angle, in the same vertical plane, so one **sea
//! fan** ([`SeaFan`]) traced from height 0 once per frame serves every sample: it records each
//! ray's height on a uniform grid of ranges (from the reflection point) and is interpolated
//! bilinearly. A reflected ray from a hit at distance d meets a card at distance D > d at range
//! D − d; the terrain's profile along the sample's azimuth is marched from d on
//! (`super::terrain`). The wave facets ([`Sea::facet_nodes`]) spread the reflected rays over a few elevations;
//! their card images are Fresnel-weighted, and seen through the air from the card to the sea
//! (the chord) when the sky has aerial perspective (the renderer then attenuates the whole sea
//! radiance from the sea to the camera). Exact mode uses the same sea fan.

use std::sync::Arc;

use rayon::prelude::*;

use super::objects::{RayAlong, SampleRay};
use super::ray_model::{FanEnd, RayTracer};
use super::shade::{AngleTable, Shader};
use super::terrain::piece_density;
use crate::scene::camera::ViewDirection;
use crate::scene::sea::{FacetNode, GlintGeometry};
use crate::scene::sky::SunDisc;
use crate::scene::{Sea, Sky, Sun};

/// Facet classes per sample for the cards' mirror images (the sky uses more, in its table).
pub(super) const CARD_FACET_NODES: usize = 8;

/// Facet classes whose share of the reflected light (weight × Fresnel reflectance) is below this
/// are not traced to the cards: they change a pixel by less than 1e-3 of the card's radiance,
/// a quarter of an 8-bit step.
pub(super) const MIN_NODE_SHARE: f64 = 1e-3;

/// Most elevations in a sea fan.
const MAX_SEA_FAN_RAYS: usize = 2048;
/// Most ranges on a sea fan's grid (linear interpolation between them errs by about
/// Δr²·κ/8, κ the ray's curvature relative to the surface: millimetres at 250 m steps).
const MAX_SEA_FAN_RANGES: usize = 256;
/// Finest range step (m).
const MIN_RANGE_STEP_M: f64 = 25.0;

/// Rays launched from the sea surface at elevations 0 … `e_hi`, uniformly spaced, with their
/// heights on a uniform grid of ranges and their final sky elevations.
pub(super) struct SeaFan {
    inv_step_e: f64,
    n_e: usize,
    inv_step_r: f64,
    n_r: usize,
    /// Row-major by elevation: height (m) at each range, NaN where the ray had ended.
    heights: Vec<f32>,
    /// Row-major like `heights`: the lowest height of the ray at this range and beyond (+∞
    /// where it had ended: it meets nothing there).
    min_beyond: Vec<f32>,
    /// Row-major like `heights`, when asked for: the density-weighted path lengths [D_R, D_A]
    /// (m) from the sea to each range along the ray's own heights (NaN past its end).
    density: Vec<[f32; 2]>,
    /// Final elevation (rad, relative to the reflection point's horizontal), NaN unless the ray
    /// left into the sky.
    sky_elevation: Vec<f64>,
}

impl SeaFan {
    /// Trace the sea fan over elevations [0, `e_hi`] with spacing `step_rad` (at most
    /// [`MAX_SEA_FAN_RAYS`] rays) and ranges [0, `max_range_m`]; `None` if there is nothing to
    /// cover. `density`: the scale heights (m) and the sphere's radius (m) to sum each ray's
    /// density-weighted path lengths with ([`Self::density_paths_m`]).
    pub(super) fn build(
        tracer: &dyn RayTracer,
        e_hi: f64,
        step_rad: f64,
        max_range_m: f64,
        need_sky_direction: bool,
        density: Option<([f64; 2], f64)>,
    ) -> Option<Self> {
        if !(e_hi > 0.0 && e_hi.is_finite() && max_range_m > 0.0 && max_range_m.is_finite()) {
            return None;
        }
        let n_e = ((e_hi / step_rad).ceil() as usize + 1).clamp(2, MAX_SEA_FAN_RAYS);
        let n_r =
            ((max_range_m / MIN_RANGE_STEP_M).ceil() as usize + 1).clamp(2, MAX_SEA_FAN_RANGES);
        let step_e = e_hi / (n_e - 1) as f64;
        let step_r = max_range_m / (n_r - 1) as f64;
        let mut ranges: Vec<f64> = (0..n_r).map(|m| m as f64 * step_r).collect();
        ranges[n_r - 1] = max_range_m;
        let rays: Vec<(Vec<f32>, f64)> = (0..n_e)
            .into_par_iter()
            .map(|i| {
                let ray = tracer.trace(0.0, i as f64 * step_e, &ranges, need_sky_direction);
                let mut h: Vec<f32> = ray
                    .heights_m
                    .iter()
                    .map(|h| h.map_or(f32::NAN, |v| v as f32))
                    .collect();
                h.resize(n_r, f32::NAN);
                let sky = match ray.end {
                    FanEnd::Sky { elevation_rad } => elevation_rad,
                    _ => f64::NAN,
                };
                (h, sky)
            })
            .collect();
        let mut heights = Vec::with_capacity(n_e * n_r);
        let mut sky_elevation = Vec::with_capacity(n_e);
        for (h, s) in rays {
            heights.extend(h);
            sky_elevation.push(s);
        }
        let density = match density {
            Some((scales_m, radius_m)) => heights
                .par_chunks_exact(n_r)
                .with_min_len(8)
                .flat_map_iter(|row| {
                    let ranges = &ranges;
                    let mut sum = [0.0f64; 2];
                    let mut prev = (0.0, 0.0);
                    row.iter().enumerate().map(move |(m, &h)| {
                        if h.is_nan() || sum[0].is_nan() {
                            sum = [f64::NAN; 2];
                        } else {
                            let at = (ranges[m], f64::from(h));
                            let piece = piece_density(prev, at, radius_m, scales_m);
                            sum = [sum[0] + piece[0], sum[1] + piece[1]];
                            prev = at;
                        }
                        sum.map(|v| v as f32)
                    })
                })
                .collect(),
            None => Vec::new(),
        };
        let mut min_beyond = heights.clone();
        for row in min_beyond.chunks_exact_mut(n_r) {
            let mut low = f32::INFINITY;
            for h in row.iter_mut().rev() {
                if !h.is_nan() {
                    low = low.min(*h);
                }
                *h = low;
            }
        }
        Some(Self {
            inv_step_e: 1.0 / step_e,
            n_e,
            inv_step_r: 1.0 / step_r,
            n_r,
            heights,
            min_beyond,
            density,
            sky_elevation,
        })
    }

    /// Rays in the fan.
    pub(super) fn len(&self) -> usize {
        self.n_e
    }

    /// Cell and fraction of `x` (already scaled to grid units) on a grid of `n` nodes.
    #[inline]
    fn cell(x: f64, n: usize) -> Option<(usize, f64)> {
        let last = (n - 1) as f64;
        if !(x >= 0.0 && x <= last) {
            return None;
        }
        let i = (x as usize).min(n - 2);
        Some((i, x - i as f64))
    }

    /// The ray launched from the sea at `elevation_rad`, for its heights at many ranges
    /// ([`SeaRay::height`], the same values as [`Self::height`]); `None` outside the fan.
    #[inline]
    pub(super) fn ray(&self, elevation_rad: f64) -> Option<SeaRay<'_>> {
        let (i, t) = Self::cell(elevation_rad * self.inv_step_e, self.n_e)?;
        Some(SeaRay {
            low: &self.heights[i * self.n_r..(i + 1) * self.n_r],
            high: &self.heights[(i + 1) * self.n_r..(i + 2) * self.n_r],
            t,
            inv_step_r: self.inv_step_r,
        })
    }

    /// Height (m) at range `range_m` of the ray launched from the sea at `elevation_rad`:
    /// bilinear in the fan, `None` outside it or where a neighbour had ended.
    #[inline]
    pub(super) fn height(&self, elevation_rad: f64, range_m: f64) -> Option<f64> {
        let (i, t) = Self::cell(elevation_rad * self.inv_step_e, self.n_e)?;
        let (m, u) = Self::cell(range_m * self.inv_step_r, self.n_r)?;
        let at = |i: usize, m: usize| self.heights[i * self.n_r + m] as f64;
        let (a, b) = (at(i, m), at(i, m + 1));
        let (c, d) = (at(i + 1, m), at(i + 1, m + 1));
        let low = a + (b - a) * u;
        let high = c + (d - c) * u;
        let h = low + (high - low) * t;
        h.is_finite().then_some(h)
    }

    /// The density-weighted path lengths [D_R, D_A] (m) from the sea along the ray launched at
    /// `elevation_rad` to range `range_m` (bilinear, as [`Self::height`]); `None` where they
    /// were not summed or a neighbour had ended.
    #[inline]
    pub(super) fn density_paths_m(&self, elevation_rad: f64, range_m: f64) -> Option<[f64; 2]> {
        if self.density.is_empty() {
            return None;
        }
        let (i, t) = Self::cell(elevation_rad * self.inv_step_e, self.n_e)?;
        let (m, u) = Self::cell(range_m * self.inv_step_r, self.n_r)?;
        let at = |i: usize, m: usize| self.density[i * self.n_r + m];
        let (a, b) = (at(i, m), at(i, m + 1));
        let (c, d) = (at(i + 1, m), at(i + 1, m + 1));
        let out = [0, 1].map(|k| {
            let low = f64::from(a[k]) + f64::from(b[k] - a[k]) * u;
            let high = f64::from(c[k]) + f64::from(d[k] - c[k]) * u;
            low + (high - low) * t
        });
        out.iter().all(|v| v.is_finite()).then_some(out)
    }

    /// A lower bound (m) on the height, at every range from `range_m` on, of the ray launched
    /// from the sea at `elevation_rad` as [`Self::height`] interpolates it (+∞ outside the fan:
    /// it has no height there).
    #[inline]
    pub(super) fn min_height_beyond(&self, elevation_rad: f64, range_m: f64) -> f64 {
        let Some((i, _)) = Self::cell(elevation_rad * self.inv_step_e, self.n_e) else {
            return f64::INFINITY;
        };
        // (`max` maps a NaN range to 0: every height of the ray bounds it.)
        let x = (range_m * self.inv_step_r).max(0.0);
        if x > (self.n_r - 1) as f64 {
            return f64::INFINITY;
        }
        // The interpolated height in cell m is a weighted mean of the nodes m, m + 1 of rows
        // i, i + 1, so the nodes' minimum from m on bounds it there and beyond.
        let m = x as usize;
        let at = |i: usize| self.min_beyond[i * self.n_r + m];
        f64::from(at(i).min(at(i + 1)))
    }

    /// Final elevation (rad, relative to the reflection point's horizontal) of the ray launched
    /// from the sea at `elevation_rad`, where it and its neighbour left into the sky.
    #[inline]
    pub(super) fn sky_elevation(&self, elevation_rad: f64) -> Option<f64> {
        let (i, t) = Self::cell(elevation_rad * self.inv_step_e, self.n_e)?;
        let (a, b) = (self.sky_elevation[i], self.sky_elevation[i + 1]);
        let e = a + (b - a) * t;
        e.is_finite().then_some(e)
    }
}

/// One ray of a [`SeaFan`]: its two neighbouring fan rays and the fraction between them.
pub(super) struct SeaRay<'f> {
    low: &'f [f32],
    high: &'f [f32],
    t: f64,
    inv_step_r: f64,
}

impl SeaRay<'_> {
    /// Height (m) at range `range_m`, as [`SeaFan::height`] gives it.
    #[inline]
    pub(super) fn height(&self, range_m: f64) -> Option<f64> {
        let (m, u) = SeaFan::cell(range_m * self.inv_step_r, self.low.len())?;
        let (a, b) = (self.low[m] as f64, self.low[m + 1] as f64);
        let (c, d) = (self.high[m] as f64, self.high[m + 1] as f64);
        let low = a + (b - a) * u;
        let high = c + (d - c) * u;
        let h = low + (high - low) * self.t;
        h.is_finite().then_some(h)
    }
}

/// [`Sea::facet_nodes`] with [`CARD_FACET_NODES`] classes, tabulated by grazing angle over
/// [0, `g_hi`] and interpolated linearly (node by node: the classes move continuously with the
/// grazing angle), so a sample pays a lookup, not eight exponentials.
pub(super) struct FacetTable {
    inv_step: f64,
    nodes: Vec<[FacetNode; CARD_FACET_NODES]>,
}

impl FacetTable {
    /// Entries in the table.
    const ENTRIES: usize = 2048;

    pub(super) fn new(sea: &Sea, g_hi: f64) -> Self {
        let g_hi = if g_hi > 0.0 && g_hi.is_finite() {
            g_hi.min(std::f64::consts::FRAC_PI_2)
        } else {
            std::f64::consts::FRAC_PI_2
        };
        let step = g_hi / (Self::ENTRIES - 1) as f64;
        Self {
            inv_step: 1.0 / step,
            nodes: (0..Self::ENTRIES)
                .map(|i| sea.facet_nodes::<CARD_FACET_NODES>(i as f64 * step))
                .collect(),
        }
    }

    /// The facet classes at grazing angle `grazing_rad` (clamped to the table).
    #[inline]
    pub(super) fn at(&self, grazing_rad: f64) -> [FacetNode; CARD_FACET_NODES] {
        let last = (self.nodes.len() - 1) as f64;
        let p = (grazing_rad * self.inv_step).clamp(0.0, last);
        let p = if p.is_nan() { 0.0 } else { p };
        let i = (p as usize).min(self.nodes.len() - 2);
        let t = p - i as f64;
        let (a, b) = (&self.nodes[i], &self.nodes[i + 1]);
        std::array::from_fn(|j| FacetNode {
            reflected_elevation_rad: a[j].reflected_elevation_rad
                + (b[j].reflected_elevation_rad - a[j].reflected_elevation_rad) * t,
            weight: a[j].weight + (b[j].weight - a[j].weight) * t,
            reflectance: a[j].reflectance + (b[j].reflectance - a[j].reflectance) * t,
        })
    }
}

/// The sun's glitter on a rough sea, resolved once per frame.
pub(super) struct Glint {
    pub(super) sun: Sun,
    /// Apparent minus true elevation of the sun seen from the sea surface (rad).
    pub(super) refraction_rad: f64,
    /// Solar irradiance normal to the beam at the sea, per channel (film units × sr): the sun
    /// attenuated along its own curved ray from the sea surface below the camera to the top.
    pub(super) irradiance: [f64; 3],
    /// The sun's attenuated disc-centre radiance at the sea (the glint's cap before ρ).
    pub(super) radiance_cap: [f64; 3],
}

/// Everything the sea's reflections need, per frame.
pub(super) struct Reflection {
    pub(super) sea: Sea,
    pub(super) sky: Sky,
    pub(super) earth_radius_m: f64,
    /// Rays from the sea surface (absent without cards beyond the nearest sea).
    pub(super) fan: Option<Arc<SeaFan>>,
    /// Sky radiance by the reflected rays' elevation.
    pub(super) sky_table: Arc<AngleTable>,
    /// The facet classes by grazing angle.
    pub(super) facets: Arc<FacetTable>,
    /// Rough-sea sun glitter (a sun and σ > 0).
    pub(super) glint: Option<Glint>,
    /// The sun, for its mirror image on a mirror sea (σ = 0), and its disc prepared once.
    pub(super) mirror_sun: Option<(Sun, SunDisc)>,
}

/// The launch elevation (rad) at the sea surface of the ray that leaves the atmosphere towards
/// a sun at true elevation `sun_elevation_rad`, to within [`SEA_SUN_LAUNCH_TOLERANCE_RAD`]:
/// a bracketed search on the launch elevation of rays from height 0 over [0, 0.5 rad], where a
/// ray that does not leave (trapped in a surface duct, or back on the sea) counts as passing
/// below the sun. Above the reach of the 0.5 rad ray, the sun's true elevation plus that ray's
/// refraction. `None` when every ray from the sea surface leaves above the sun: the sun's centre
/// is below the sea's apparent horizon.
///
/// The search is regula falsi with the Illinois modification (the final elevation is smooth in
/// the launch elevation wherever rays leave), falling back to bisection where an end of the
/// bracket does not leave or the bracket has not halved in two steps: a handful of rays where
/// bisection alone took 32 (each frame of a sun sweep needs its own search).
pub(super) fn sea_level_sun_launch_rad(
    tracer: &dyn RayTracer,
    sun_elevation_rad: f64,
) -> Option<f64> {
    let end = |e: f64| match tracer.trace(0.0, e, &[], true).end {
        FanEnd::Sky { elevation_rad } => Some(elevation_rad),
        _ => None,
    };
    let (mut lo, mut hi) = (0.0f64, 0.5f64);
    let top = end(hi)?;
    if top < sun_elevation_rad {
        return Some(sun_elevation_rad + (hi - top));
    }
    let mut f_lo = end(lo).map(|e| e - sun_elevation_rad);
    if f_lo.is_some_and(|f| f > 0.0) {
        return None;
    }
    // f_hi ≥ 0 ≥ f_lo (when the low end leaves): the crossing lies in [lo, hi].
    let mut f_hi = top - sun_elevation_rad;
    // Which end the last step moved (1: high, −1: low), and the bracket's widths one and two
    // steps ago.
    let (mut side, mut widths) = (0i8, [f64::INFINITY; 2]);
    for _ in 0..MAX_LAUNCH_STEPS {
        let width = hi - lo;
        if width <= SEA_SUN_LAUNCH_TOLERANCE_RAD {
            break;
        }
        let mid = match f_lo {
            Some(fl) if f_hi > fl && width < 0.5 * widths[1] => {
                let t = (-fl / (f_hi - fl)).clamp(0.0, 1.0);
                // Strictly inside, so every step shrinks the bracket.
                (lo + width * t).clamp(lo + 1e-3 * width, hi - 1e-3 * width)
            }
            _ => 0.5 * (lo + hi),
        };
        widths = [width, widths[0]];
        match end(mid) {
            Some(e) if e >= sun_elevation_rad => {
                (hi, f_hi) = (mid, e - sun_elevation_rad);
                if side > 0 {
                    f_lo = f_lo.map(|f| 0.5 * f);
                }
                side = 1;
            }
            r => {
                (lo, f_lo) = (mid, r.map(|e| e - sun_elevation_rad));
                if side < 0 {
                    f_hi *= 0.5;
                }
                side = -1;
            }
        }
    }
    Some(0.5 * (lo + hi))
}

/// How closely [`sea_level_sun_launch_rad`] brackets the launch elevation (rad): a thousandth of
/// an arcsecond, far below any pixel.
pub(super) const SEA_SUN_LAUNCH_TOLERANCE_RAD: f64 = 5e-9;

/// The most rays [`sea_level_sun_launch_rad`] traces after its first two (bisection alone
/// reaches its tolerance from 0.5 rad in 27).
const MAX_LAUNCH_STEPS: usize = 64;

impl Reflection {
    /// Whether a ray meeting the sea at `grazing_rad`, `distance_m` may show the sun's glitter
    /// or mirror image (then the sea's colour depends on the azimuth).
    pub(super) fn may_show_sun(&self, grazing_rad: f64, distance_m: f64) -> bool {
        let tilt = distance_m / self.earth_radius_m;
        if let Some(g) = &self.glint {
            let e = g.sun.elevation_rad + g.refraction_rad;
            return self
                .sea
                .may_glint(grazing_rad, (e - tilt.abs(), e + tilt.abs()));
        }
        match (&self.mirror_sun, &self.fan) {
            (Some((sun, _)), Some(fan)) => fan.sky_elevation(grazing_rad).is_some_and(|e| {
                (e - tilt - sun.elevation_rad).abs()
                    <= 0.5 * sun.angular_diameter_rad + 2.0 * tilt.abs() + 1e-4
            }),
            _ => false,
        }
    }

    /// Whether some ray meeting the sea at a grazing angle in `grazing_rad` (lo, hi) and a
    /// ground distance in `distance_m` (lo, hi) may show the sun: when this is false,
    /// [`Self::may_show_sun`] is false for every such ray. A mirror sea's sun image is not
    /// bounded here: any ray that meets such a sea may show it.
    pub(super) fn may_show_sun_range(
        &self,
        grazing_rad: (f64, f64),
        distance_m: (f64, f64),
    ) -> bool {
        if let Some(g) = &self.glint {
            // The farthest hit tilts the sun most (padded for the rounding of interpolated
            // distances); a NaN distance bounds nothing.
            let far = distance_m.0.abs().max(distance_m.1.abs());
            let tilt = far / self.earth_radius_m * (1.0 + 1e-9) + 1e-12;
            if !tilt.is_finite() || distance_m.0.is_nan() || distance_m.1.is_nan() {
                return true;
            }
            let e = g.sun.elevation_rad + g.refraction_rad;
            return self.sea.may_glint_range(grazing_rad, (e - tilt, e + tilt));
        }
        self.mirror_sun.is_some() && self.fan.is_some()
    }

    /// The sun's glitter (rough sea) or mirror image (mirror sea) along a ray meeting the sea at
    /// `grazing_rad`, `distance_m` towards absolute azimuth `azimuth_rad`.
    pub(super) fn sun(&self, grazing_rad: f64, distance_m: f64, azimuth_rad: f64) -> [f64; 3] {
        self.sun_at(grazing_rad, distance_m).at(self, azimuth_rad)
    }

    /// [`Self::sun`] for rays meeting the sea at `grazing_rad` and `distance_m`, towards any
    /// azimuth ([`SeaSunAt::at`]).
    pub(super) fn sun_at(&self, grazing_rad: f64, distance_m: f64) -> SeaSunAt {
        // The reflection point's vertical is tilted by d/R towards the ray's azimuth.
        let tilt = distance_m / self.earth_radius_m;
        let facet = || self.sea.facet_nodes::<1>(grazing_rad)[0].reflectance;
        if self.glint.is_some() {
            return SeaSunAt::Glint {
                geometry: self.sea.glint_geometry(grazing_rad),
                tilt,
                rho: facet(),
            };
        }
        let (Some(_), Some(fan)) = (&self.mirror_sun, &self.fan) else {
            return SeaSunAt::Nothing;
        };
        match fan.sky_elevation(grazing_rad) {
            Some(end) => SeaSunAt::Mirror {
                elevation_rad: end - tilt,
                reflectance: facet(),
                transmittance: self.sky.transmittance(grazing_rad),
            },
            None => SeaSunAt::Nothing,
        }
    }
}

/// What [`Reflection::sun`] needs of rays meeting the sea at one grazing angle and distance,
/// worked out once for every azimuth (the same values as worked out per ray).
#[derive(Debug, Clone, Copy)]
pub(super) enum SeaSunAt {
    /// No sun on this sea.
    Nothing,
    /// A rough sea's glitter: the facet geometry of the grazing angle, the tilt (rad) of the
    /// reflection point's vertical, and the Fresnel reflectance that caps the glint.
    Glint {
        geometry: GlintGeometry,
        tilt: f64,
        rho: f64,
    },
    /// A mirror sea's image of the disc: the reflected ray's final elevation above the
    /// observer's horizontal (rad), the reflectance and the sky's transmittance at the grazing
    /// angle.
    Mirror {
        elevation_rad: f64,
        reflectance: f64,
        transmittance: [f64; 3],
    },
}

impl SeaSunAt {
    /// A rough sea's glitter towards absolute azimuth `azimuth_rad` per unit irradiance from
    /// the sun ([`GlintGeometry::per_irradiance`]): a smooth function of the azimuth, which
    /// [`Self::glint_radiance`] turns into radiance. `None` when this is not glitter.
    #[inline]
    pub(super) fn glint_factor(&self, refl: &Reflection, azimuth_rad: f64) -> Option<f64> {
        let (SeaSunAt::Glint { geometry, tilt, .. }, Some(g)) = (self, &refl.glint) else {
            return None;
        };
        // The sun's elevation above the local horizontal of the sea point (the true direction
        // tilted by the Earth's curvature, plus the sea-level refraction), and its azimuth
        // relative to the ray there.
        let phi = g.sun.azimuth_rad - azimuth_rad;
        let e = g.sun.elevation_rad + g.refraction_rad + tilt * phi.cos();
        Some(geometry.per_irradiance(e, phi))
    }

    /// The glitter's radiance for the factor `k` of [`Self::glint_factor`]: the sun's
    /// irradiance times `k`, capped by the Fresnel-reflected disc (zero where `k` ≤ 0, or when
    /// this is not glitter).
    #[inline]
    pub(super) fn glint_radiance(&self, refl: &Reflection, k: f64) -> [f64; 3] {
        let (SeaSunAt::Glint { rho, .. }, Some(g)) = (self, &refl.glint) else {
            return [0.0; 3];
        };
        if k <= 0.0 {
            return [0.0; 3];
        }
        [0, 1, 2].map(|c| (k * g.irradiance[c]).min(rho * g.radiance_cap[c]))
    }

    /// [`Reflection::sun`] towards absolute azimuth `azimuth_rad`.
    pub(super) fn at(&self, refl: &Reflection, azimuth_rad: f64) -> [f64; 3] {
        match *self {
            SeaSunAt::Glint { .. } => match self.glint_factor(refl, azimuth_rad) {
                Some(k) => self.glint_radiance(refl, k),
                None => [0.0; 3],
            },
            SeaSunAt::Mirror {
                elevation_rad,
                reflectance,
                transmittance,
            } => {
                let Some((_, disc)) = &refl.mirror_sun else {
                    return [0.0; 3];
                };
                let disc = disc.radiance(azimuth_rad, elevation_rad);
                if disc <= 0.0 {
                    return [0.0; 3];
                }
                transmittance.map(|t| reflectance * disc * t)
            }
            SeaSunAt::Nothing => [0.0; 3],
        }
    }
}

impl Shader<'_> {
    /// What the sea adds along `dir` to its tabulated sky reflection, for a ray that met it at
    /// `grazing_rad` and `distance_m`: the sun's glitter (when `with_sun`) and the mirror images
    /// of the cards and the terrain (composed in depth order, Fresnel-weighted, over the facet
    /// classes, each in front of the sky it hides, which is taken out again).
    pub(super) fn sea_reflections(
        &self,
        dir: &ViewDirection,
        grazing_rad: f64,
        distance_m: f64,
        with_sun: bool,
    ) -> [f64; 3] {
        let mut out = [0.0; 3];
        let Some(refl) = &self.reflection else {
            return out;
        };
        let mut azimuth_cache: Option<f64> = None;
        let mut azimuth = || *azimuth_cache.get_or_insert_with(|| dir.azimuth_offset_rad());
        if with_sun && refl.may_show_sun(grazing_rad, distance_m) {
            out = refl.sun(grazing_rad, distance_m, self.heading_rad + azimuth());
        }
        let Some(fan) = &refl.fan else {
            return out;
        };
        // Only cards beyond the hit point, in whose azimuth range the sample lies.
        let in_range = |card: &super::shade::ViewCard<'_>, az: f64| {
            let mut offset = az - card.offset_rad;
            if offset.abs() > std::f64::consts::PI {
                offset = super::shade::wrap_pi(offset);
            }
            offset.abs() <= card.half_width_rad
        };
        let beyond = |card: &super::shade::ViewCard<'_>| card.distance_m > distance_m;
        let terrain = self.terrain.as_ref();
        let may_show_terrain =
            |e: f64| terrain.is_some_and(|t| t.may_be_reflected(fan, e, distance_m));
        let nodes = refl.facets.at(grazing_rad);
        let counts = |node: &FacetNode| node.weight * node.reflectance >= MIN_NODE_SHARE;
        let terrain_nodes = nodes
            .iter()
            .any(|n| counts(n) && may_show_terrain(n.reflected_elevation_rad));
        if !terrain_nodes && !self.cards.iter().any(beyond) {
            return out;
        }
        let az = azimuth();
        if !terrain_nodes && !self.cards.iter().any(|c| beyond(c) && in_range(c, az)) {
            return out;
        }
        for node in nodes {
            if !counts(&node) {
                continue;
            }
            let e = node.reflected_elevation_rad;
            let ray = SampleRay::with_azimuth(
                dir,
                RayAlong::Reflected {
                    fan,
                    elevation_rad: e,
                    from_m: distance_m,
                },
                az,
            );
            let found = self.compose(&ray);
            let covered = 1.0 - found.transmittance;
            if covered == 0.0 {
                continue;
            }
            let sky = refl.sky_table.at(e);
            let wf = node.weight * node.reflectance;
            for c in 0..3 {
                out[c] += wf * (found.radiance[c] - covered * sky[c]);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::{AtomicUsize, Ordering};

    use super::*;
    use crate::render::ray_model::FanRay;

    /// Rays from the sea whose final elevation is `leave(launch)` (`None`: they do not leave),
    /// counting the traces.
    struct Leaving<F> {
        leave: F,
        traces: AtomicUsize,
    }

    impl<F: Fn(f64) -> Option<f64> + Sync> RayTracer for Leaving<F> {
        fn trace(&self, _h: f64, elevation_rad: f64, _d: &[f64], _sky: bool) -> FanRay {
            self.traces.fetch_add(1, Ordering::Relaxed);
            FanRay {
                elevation_rad,
                heights_m: Vec::new(),
                end: match (self.leave)(elevation_rad) {
                    Some(e) => FanEnd::Sky { elevation_rad: e },
                    None => FanEnd::Trapped,
                },
                monotone: false,
            }
        }
    }

    /// The launch whose ray leaves at `sun` by 200 bisection steps (the reference).
    fn bisected(leave: impl Fn(f64) -> Option<f64>, sun: f64) -> f64 {
        let (mut lo, mut hi) = (0.0f64, 0.5f64);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            match leave(mid) {
                Some(e) if e >= sun => hi = mid,
                _ => lo = mid,
            }
        }
        0.5 * (lo + hi)
    }

    #[test]
    fn the_sea_level_sun_launch_is_found_within_its_tolerance_in_few_rays() {
        // Refraction falling from 0.6° at the surface (a strong duct) and a duct that traps
        // every ray launched below 0.2°.
        let smooth = |e: f64| Some(e - 0.0105 * (-e / 0.02).exp());
        let ducted = |e: f64| (e >= 0.0035).then(|| e - 0.0105 * (-e / 0.02).exp());
        for sun_deg in [-0.5, -0.1, 0.0, 0.3, 1.0, 5.0, 20.0] {
            let sun = f64::to_radians(sun_deg);
            // Bisection alone traces 32 rays; a trapped low end costs bisection steps until
            // the bracket's low end leaves.
            for (name, limit, leave) in [
                (
                    "smooth",
                    12,
                    &smooth as &(dyn Fn(f64) -> Option<f64> + Sync),
                ),
                ("ducted", 20, &ducted),
            ] {
                let tracer = Leaving {
                    leave,
                    traces: AtomicUsize::new(0),
                };
                let want = bisected(leave, sun);
                match sea_level_sun_launch_rad(&tracer, sun) {
                    Some(got) => {
                        assert!(
                            (got - want).abs() <= 0.5 * SEA_SUN_LAUNCH_TOLERANCE_RAD,
                            "{name} {sun_deg}°: {got} vs {want}"
                        );
                        // Where the sun is below every ray that leaves, the launch is the
                        // duct's edge, found by bisection alone.
                        let traces = tracer.traces.load(Ordering::Relaxed);
                        let smooth_there = leave(want - 1e-6).is_some();
                        assert!(
                            traces <= limit || !smooth_there,
                            "{name} {sun_deg}°: {traces} rays"
                        );
                    }
                    None => assert!(
                        leave(0.0).is_some_and(|e| e > sun),
                        "{name} {sun_deg}°: none, yet the surface ray leaves below the sun"
                    ),
                }
            }
        }
        // Every ray from the surface leaves above a sun 0.8° below the horizon: hidden.
        let tracer = Leaving {
            leave: smooth,
            traces: AtomicUsize::new(0),
        };
        assert_eq!(
            sea_level_sun_launch_rad(&tracer, f64::to_radians(-0.8)),
            None
        );
    }
}
