//! Refractive regimes of a column: trapping layers and ducts, super-refraction, inferior-mirage
//! layers, and the critical temperature gradient.
//!
//! In: a [`RefractiveAtmosphere`] and a height range. Out: a list of [`RefractiveLayer`]s, each
//! with its base, top, extreme gradients, local critical temperature gradient and, for trapping
//! layers, the [`Duct`] it creates.
//!
//! Conventions (N = (n − 1)·10⁶, gradients in N-units per km):
//! * **trapping**: dN/dh < −10⁹/R ≈ −157 N/km — a horizontal ray curves more than the Earth;
//! * **super-refraction**: −157 ≤ dN/dh < −79 N/km, the usual radio (ITU-R P.453) convention —
//!   rays curve at least half as much as the Earth, so the horizon is raised strongly;
//! * **inferior mirage**: dn/dh > 0 — rays curve upward (away from the ground). For dry
//!   hydrostatic air this is dT/dh < −g/R_d ≈ −0.0342 K/m (the autoconvective lapse rate); the
//!   classification uses dn/dh itself, so humidity gradients are included.
//!
//! Layers of different kinds do not overlap: a strong inversion shows as a trapping layer framed by
//! super-refractive ones.
//!
//! **Ducts**: a trapping layer with top h_t traps rays in a duct that reaches below the layer,
//! down to where the modified refractivity M(h) = N(h) + h/R·10⁶ comes back to M(h_t) (or to the
//! surface: a surface-based duct). Each trapping layer reports its duct (base, top = top of the
//! trapping layer, and the M deficit = largest M in the duct − M(h_t)).

use serde::Serialize;

use super::RefractiveAtmosphere;
use super::ciddor::CiddorDispersion;
use crate::units::{DRY_AIR_GAS_CONSTANT_J_KG_K, EARTH_RADIUS_M, STANDARD_GRAVITY_M_S2};

/// Super-refraction threshold of the radio convention (N-units per km).
pub const SUPER_REFRACTION_DNDH_PER_KM: f64 = -79.0;
/// g/R_d (K m⁻¹): the autoconvective lapse rate; dT/dh below −g/R_d makes rays curve upward.
pub const AUTOCONVECTIVE_LAPSE_K_PER_M: f64 = STANDARD_GRAVITY_M_S2 / DRY_AIR_GAS_CONSTANT_J_KG_K;

/// The kind of a refractive layer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RegimeKind {
    /// dN/dh below −10⁹/R (≈ −157 N/km): rays curve more than the Earth (ducting, superior
    /// mirages, Novaya Zemlya effect).
    Trapping,
    /// −157 ≤ dN/dh < −79 N/km.
    SuperRefraction,
    /// dn/dh > 0: rays curve upward (inferior mirages).
    InferiorMirage,
}

/// Options of [`detect_regimes`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RegimeOptions {
    /// Sampling step (m); layer boundaries are refined by linear interpolation between samples.
    pub step_m: f64,
    /// Layers thinner than this (m) are dropped.
    pub min_thickness_m: f64,
    /// Earth radius (m) defining the trapping threshold −1/R.
    pub earth_radius_m: f64,
}

impl Default for RegimeOptions {
    /// 0.25 m steps, no minimum thickness, R = 6 371 km.
    fn default() -> Self {
        Self {
            step_m: 0.25,
            min_thickness_m: 0.0,
            earth_radius_m: EARTH_RADIUS_M,
        }
    }
}

/// A duct: the height range in which rays can be trapped by a trapping layer.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Duct {
    /// Duct base above mean sea level (m): where M comes back to its value at the top, or the
    /// surface.
    pub base_m: f64,
    /// Duct top above mean sea level (m): the top of the trapping layer.
    pub top_m: f64,
    /// Duct base above the surface (m).
    pub base_agl_m: f64,
    /// Duct top above the surface (m).
    pub top_agl_m: f64,
    /// Base of the trapping layer above mean sea level (m).
    pub trapping_base_m: f64,
    /// Smallest dN/dh in the trapping layer (N-units per km).
    pub min_dndh_per_km: f64,
    /// Duct strength: largest M in the duct minus M at the top (M-units).
    pub m_deficit: f64,
    /// Whether the duct reaches the surface.
    pub surface_based: bool,
}

/// A layer of one refractive regime.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RefractiveLayer {
    /// The regime.
    pub kind: RegimeKind,
    /// Base above mean sea level (m).
    pub base_m: f64,
    /// Top above mean sea level (m).
    pub top_m: f64,
    /// Base above the surface (m).
    pub base_agl_m: f64,
    /// Top above the surface (m).
    pub top_agl_m: f64,
    /// Smallest dN/dh in the layer (N-units per km).
    pub min_dndh_per_km: f64,
    /// Largest dN/dh in the layer (N-units per km).
    pub max_dndh_per_km: f64,
    /// Smallest dT/dh in the layer (K m⁻¹).
    pub min_dtdh_k_per_m: f64,
    /// Largest dT/dh in the layer (K m⁻¹).
    pub max_dtdh_k_per_m: f64,
    /// Critical (ducting) temperature gradient at the height of the extreme dN/dh (K m⁻¹), see
    /// [`critical_temperature_gradient_k_per_m`].
    pub critical_gradient_k_per_m: f64,
    /// For trapping layers: the duct they create.
    pub duct: Option<Duct>,
}

/// The temperature gradient (K m⁻¹) at which a horizontal ray follows the Earth's curvature
/// (dn/dh = −1/R), for air at `temperature_k`, `pressure_pa`, `vapour_pressure_pa` and
/// wavelength `wavelength_m`, with n − 1 from Ciddor and a hydrostatic atmosphere in which
/// n − 1 ∝ P/T: dT/dh_crit = T/((n − 1)·R) − g/R_d. About 0.1121 K/m at 0 °C, 1013.25 hPa,
/// 550 nm (the paper's "11.2 °C per 100 m") and 0.1286 K/m at 15 °C.
pub fn critical_temperature_gradient_k_per_m(
    temperature_k: f64,
    pressure_pa: f64,
    vapour_pressure_pa: f64,
    wavelength_m: f64,
    earth_radius_m: f64,
) -> f64 {
    let n_minus_1 = CiddorDispersion::new(wavelength_m, super::ciddor::DEFAULT_CO2_PPM)
        .refractivity_value(temperature_k, pressure_pa, vapour_pressure_pa);
    temperature_k / (n_minus_1 * earth_radius_m) - AUTOCONVECTIVE_LAPSE_K_PER_M
}

/// One sample of the scan.
#[derive(Debug, Clone, Copy)]
struct Sample {
    h_agl: f64,
    dndh_km: f64,
    m: f64,
    class: Option<RegimeKind>,
}

/// (lower, upper) bounds of each class in dN/dh (N/km).
fn bounds(kind: Option<RegimeKind>, trap: f64) -> (f64, f64) {
    match kind {
        Some(RegimeKind::Trapping) => (f64::NEG_INFINITY, trap),
        Some(RegimeKind::SuperRefraction) => (trap, SUPER_REFRACTION_DNDH_PER_KM),
        None => (SUPER_REFRACTION_DNDH_PER_KM, 0.0),
        Some(RegimeKind::InferiorMirage) => (0.0, f64::INFINITY),
    }
}

fn classify(dndh_km: f64, trap: f64) -> Option<RegimeKind> {
    if dndh_km > 0.0 {
        Some(RegimeKind::InferiorMirage)
    } else if dndh_km < trap {
        Some(RegimeKind::Trapping)
    } else if dndh_km < SUPER_REFRACTION_DNDH_PER_KM {
        Some(RegimeKind::SuperRefraction)
    } else {
        None
    }
}

/// Height where the linear interpolation between samples `a` and `b` crosses `threshold`.
fn crossing(a: &Sample, b: &Sample, threshold: f64) -> f64 {
    let dv = b.dndh_km - a.dndh_km;
    if dv == 0.0 || !threshold.is_finite() {
        return 0.5 * (a.h_agl + b.h_agl);
    }
    let f = ((threshold - a.dndh_km) / dv).clamp(0.0, 1.0);
    a.h_agl + f * (b.h_agl - a.h_agl)
}

/// Find the trapping, super-refractive and inferior-mirage layers between the surface and
/// `top_m` (above mean sea level), sampling dn/dh every `options.step_m` as the atmosphere's
/// scans do ([`RefractiveAtmosphere::scan_refractivity`]: exact, or the table where its spec
/// says so). Layers are
/// returned bottom to top. A non-positive or NaN range or step gives an empty list.
pub fn detect_regimes(
    atm: &RefractiveAtmosphere,
    top_m: f64,
    options: &RegimeOptions,
) -> Vec<RefractiveLayer> {
    let surface = atm.surface_height_m();
    let top_agl = top_m - surface;
    let positive = |v: f64| v > 0.0 && v.is_finite();
    if !positive(top_agl) || !positive(options.step_m) || !positive(options.earth_radius_m) {
        return Vec::new();
    }
    let r = options.earth_radius_m;
    let trap = -1e9 / r;
    let count = (top_agl / options.step_m).ceil().min(1e8) as usize;
    let samples: Vec<Sample> = (0..=count)
        .map(|i| {
            let h_agl = (i as f64 * options.step_m).min(top_agl);
            let (n_minus_1, dn_dh_per_m) = atm.scan_refractivity(h_agl);
            let dndh_km = dn_dh_per_m * 1e9;
            Sample {
                h_agl,
                dndh_km,
                m: n_minus_1 * 1e6 + h_agl / r * 1e6,
                class: if dndh_km.is_finite() {
                    classify(dndh_km, trap)
                } else {
                    None
                },
            }
        })
        .collect();

    let mut layers = Vec::new();
    let mut i = 0;
    while i < samples.len() {
        let Some(kind) = samples[i].class else {
            i += 1;
            continue;
        };
        let start = i;
        while i + 1 < samples.len() && samples[i + 1].class == Some(kind) {
            i += 1;
        }
        let end = i;
        i += 1;
        let (lo, hi) = bounds(Some(kind), trap);
        let base_agl = if start == 0 {
            0.0
        } else {
            let (a, b) = (&samples[start - 1], &samples[start]);
            crossing(a, b, if a.dndh_km < b.dndh_km { lo } else { hi })
        };
        let top_agl_layer = if end + 1 == samples.len() {
            samples[end].h_agl
        } else {
            let (a, b) = (&samples[end], &samples[end + 1]);
            crossing(a, b, if b.dndh_km > a.dndh_km { hi } else { lo })
        };
        if top_agl_layer - base_agl < options.min_thickness_m {
            continue;
        }
        let run = &samples[start..=end];
        let fold = |f: fn(&Sample) -> f64, pick: fn(f64, f64) -> f64, init: f64| {
            run.iter().map(f).fold(init, pick)
        };
        let min_dndh = fold(|s| s.dndh_km, f64::min, f64::INFINITY);
        let max_dndh = fold(|s| s.dndh_km, f64::max, f64::NEG_INFINITY);
        let extreme = if kind == RegimeKind::InferiorMirage {
            max_dndh
        } else {
            min_dndh
        };
        let at = run
            .iter()
            .find(|s| s.dndh_km == extreme)
            .map_or(run[0].h_agl, |s| s.h_agl);
        // dT/dh only inside the layer: a scan that reads the table has no air.
        let dtdh: Vec<f64> = run
            .iter()
            .map(|s| atm.sample_at(surface + s.h_agl).air.dtemperature_dh_k_per_m)
            .collect();
        let air = atm.sample_at(surface + at).air;
        let critical = critical_temperature_gradient_k_per_m(
            air.temperature_k,
            air.pressure_pa,
            air.vapour_pressure_pa,
            atm.wavelength_nm() * 1e-9,
            r,
        );
        let duct = (kind == RegimeKind::Trapping)
            .then(|| duct_below(atm, &samples, base_agl, top_agl_layer, start, min_dndh, r));
        layers.push(RefractiveLayer {
            kind,
            base_m: surface + base_agl,
            top_m: surface + top_agl_layer,
            base_agl_m: base_agl,
            top_agl_m: top_agl_layer,
            min_dndh_per_km: min_dndh,
            max_dndh_per_km: max_dndh,
            min_dtdh_k_per_m: dtdh.iter().copied().fold(f64::INFINITY, f64::min),
            max_dtdh_k_per_m: dtdh.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            critical_gradient_k_per_m: critical,
            duct,
        });
    }
    layers
}

/// The duct below a trapping layer (see the module documentation).
fn duct_below(
    atm: &RefractiveAtmosphere,
    samples: &[Sample],
    base_agl: f64,
    top_agl: f64,
    start: usize,
    min_dndh: f64,
    r: f64,
) -> Duct {
    let m_at = |h_agl: f64| atm.exact_refractivity(h_agl).0 * 1e6 + h_agl / r * 1e6;
    let m_top = m_at(top_agl);
    let mut m_max = m_at(base_agl).max(m_top);
    let mut duct_base = 0.0;
    let mut surface_based = true;
    // Walk down from the sample at or below the trapping layer's base.
    let mut k = start.min(samples.len() - 1);
    while k > 0 && samples[k].h_agl > base_agl {
        k -= 1;
    }
    loop {
        let s = &samples[k];
        if s.m <= m_top && s.h_agl < base_agl {
            // M crossed back to m_top between s and the sample above it.
            let above = &samples[k + 1];
            let dm = above.m - s.m;
            let f = if dm != 0.0 {
                ((m_top - s.m) / dm).clamp(0.0, 1.0)
            } else {
                0.5
            };
            duct_base = s.h_agl + f * (above.h_agl - s.h_agl);
            surface_based = false;
            break;
        }
        m_max = m_max.max(s.m);
        if k == 0 {
            break;
        }
        k -= 1;
    }
    let surface = atm.surface_height_m();
    Duct {
        base_m: surface + duct_base,
        top_m: surface + top_agl,
        base_agl_m: duct_base,
        top_agl_m: top_agl,
        trapping_base_m: surface + base_agl,
        min_dndh_per_km: min_dndh,
        m_deficit: m_max - m_top,
        surface_based,
    }
}

/// The ducts of the trapping layers in `layers`, bottom to top.
pub fn ducts(layers: &[RefractiveLayer]) -> Vec<Duct> {
    layers.iter().filter_map(|l| l.duct.clone()).collect()
}
