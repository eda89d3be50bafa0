//! Stage 6 — survey: what an observer would have seen, sounding by sounding, over a whole
//! archive. In: sounding files (IGRA2 records, Wyoming pages, folders or globs of single
//! soundings; [`sources`]) and [`SurveyOptions`] (observer heights, target distances and
//! height, fit and tracer settings). Out: one [`SurveyRow`] per sounding — its inversions and
//! ducts (stage 2–3 detectors), its apparent horizon dip against the standard atmosphere, and per
//! observer height × distance the images of the target, whether one is inverted, the largest
//! magnification and the lowest true solar elevation still visible (stage 5 analysis, no image)
//! — or the reason the sounding could not be used. [`table`] writes the rows as CSV and Parquet,
//! [`plot`] draws the monthly frequencies, the duct strengths and the dip anomalies.
//!
//! Per sounding only what the row needs is computed: the fit, the layer detectors up to
//! [`SurveyOptions::layers_top_m`], and one fan per observer height sized to the distances.

pub mod plot;
pub mod sources;
pub mod table;

use std::sync::Arc;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::analysis::{TraceReport, TraceRequest, trace_report};
use crate::atmosphere::AtmosphereOptions;
use crate::profile::{
    InversionKind, InversionOptions, Profile, StandardAtmosphere, detect_inversions,
};
use crate::refractivity::{
    RefractiveAtmosphere, RegimeKind, RegimeOptions, TableSpec, detect_regimes,
};
use crate::sounding::Sounding;
use crate::tracer::{Termination, TracerConfig};
use crate::units::EARTH_RADIUS_M;
pub use sources::{SurveyItem, expand_sources};

/// How a survey looks at each sounding. Every field has the `survey` command's default.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SurveyOptions {
    /// Observer heights above the surface (m), ascending.
    pub observer_heights_m: Vec<f64>,
    /// Target distances (m), ascending.
    pub distances_m: Vec<f64>,
    /// Height of the target standing at each distance (m): a ship's mast.
    pub target_height_m: f64,
    /// How each sounding is fitted and refracted (its `sounding_time` is ignored).
    pub atmosphere: AtmosphereOptions,
    /// Top of the inversion and duct search (m above the surface).
    pub layers_top_m: f64,
    /// Tracer tolerance (m).
    pub tolerance_m: f64,
    /// Spacing of the fan's rays (deg). The lowest visible solar elevation is resolved to it.
    pub fan_step_deg: f64,
    /// Highest ray of the fan (deg).
    pub fan_top_deg: f64,
    /// How far below the straight-ray horizon dip the fan starts (deg).
    pub fan_below_dip_deg: f64,
    /// A sounding shows the Novaya Zemlya effect when the sun is still seen this much lower
    /// (deg of true elevation) than through the standard atmosphere.
    pub novaya_zemlya_margin_deg: f64,
}

impl Default for SurveyOptions {
    fn default() -> Self {
        SurveyOptions {
            observer_heights_m: vec![10.0],
            distances_m: vec![20_000.0],
            target_height_m: 20.0,
            atmosphere: AtmosphereOptions::default(),
            layers_top_m: 3_000.0,
            tolerance_m: TracerConfig::default().tolerance_m,
            fan_step_deg: 0.01,
            fan_top_deg: 0.5,
            fan_below_dip_deg: 0.3,
            novaya_zemlya_margin_deg: 1.0,
        }
    }
}

/// Why survey options are unusable.
#[derive(Debug, thiserror::Error)]
pub enum SurveyError {
    /// An option is out of range.
    #[error("invalid survey option: {0}")]
    Invalid(String),
    /// The standard-atmosphere reference could not be traced.
    #[error("cannot trace the standard-atmosphere reference")]
    Reference(#[source] crate::analysis::AnalysisError),
    /// The standard atmosphere could not be refracted.
    #[error("cannot refract the standard atmosphere")]
    Refractivity(#[source] crate::refractivity::RefractivityError),
    /// The table could not be encoded.
    #[error("cannot write the survey table: {0}")]
    Table(String),
    /// The parts of a split survey do not join into one.
    #[error("cannot merge the survey parts: {0}")]
    Merge(String),
    /// A plot could not be drawn.
    #[error("cannot draw the survey plot {name}: {message}")]
    Plot {
        /// The plot's file name.
        name: String,
        /// Why.
        message: String,
    },
}

impl SurveyOptions {
    /// Check every option.
    pub fn validate(&self) -> Result<(), SurveyError> {
        let bad = |m: String| Err(SurveyError::Invalid(m));
        let ascending_positive = |v: &[f64]| {
            !v.is_empty()
                && v.iter().all(|x| x.is_finite() && *x > 0.0)
                && v.windows(2).all(|w| w[1] > w[0])
        };
        if !ascending_positive(&self.observer_heights_m) {
            return bad("observer heights must be > 0 m, finite and strictly ascending".into());
        }
        if !ascending_positive(&self.distances_m) {
            return bad("distances must be > 0 m, finite and strictly ascending".into());
        }
        let positive = [
            ("target_height_m", self.target_height_m),
            ("layers_top_m", self.layers_top_m),
            ("tolerance_m", self.tolerance_m),
            ("fan_step_deg", self.fan_step_deg),
            ("fan_below_dip_deg", self.fan_below_dip_deg),
            ("novaya_zemlya_margin_deg", self.novaya_zemlya_margin_deg),
        ];
        for (key, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return bad(format!("{key} must be finite and > 0, got {v}"));
            }
        }
        if !(self.fan_top_deg.is_finite() && self.fan_top_deg > 0.0 && self.fan_top_deg < 45.0) {
            return bad(format!(
                "fan_top_deg must be in (0, 45), got {}",
                self.fan_top_deg
            ));
        }
        self.atmosphere
            .validate()
            .map_err(|e| SurveyError::Invalid(e.to_string()))?;
        let max = crate::analysis::MAX_FAN_RAYS;
        for &h in &self.observer_heights_m {
            let dip_deg = (2.0 * h / EARTH_RADIUS_M).sqrt().to_degrees();
            let span_deg = self.fan_top_deg + dip_deg + self.fan_below_dip_deg;
            let rays = span_deg / self.fan_step_deg + 1.0;
            if rays.is_nan() || rays > max as f64 {
                return bad(format!(
                    "fan_step_deg {:?} makes a fan of {rays:.3e} rays from {h} m; at most {max} \
                     are allowed (give a larger step)",
                    self.fan_step_deg
                ));
            }
            self.trace_request(h)
                .validate()
                .map_err(|e| SurveyError::Invalid(e.to_string()))?;
        }
        Ok(())
    }

    /// The fan traced from `observer_height_m`: from `fan_below_dip_deg` below the straight-ray
    /// dip of the sea horizon to `fan_top_deg`, every `fan_step_deg`.
    pub fn trace_request(&self, observer_height_m: f64) -> TraceRequest {
        let dip_deg = (2.0 * observer_height_m / EARTH_RADIUS_M)
            .sqrt()
            .to_degrees();
        let from_deg = -(dip_deg + self.fan_below_dip_deg);
        let count = ((self.fan_top_deg - from_deg) / self.fan_step_deg).ceil() as usize + 1;
        TraceRequest {
            observer_height_m,
            elevation_min_deg: from_deg,
            elevation_max_deg: from_deg + (count - 1) as f64 * self.fan_step_deg,
            elevation_count: count,
            elevations_deg: Vec::new(),
            distances_m: self.distances_m.clone(),
            target_heights_m: vec![self.target_height_m],
            wavelength_nm: self.atmosphere.wavelength_nm,
            tracer: TracerConfig {
                tolerance_m: self.tolerance_m,
                ..TracerConfig::default()
            },
        }
    }
}

/// The layers of one sounding, as a survey row holds them.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LayerFacts {
    /// Surface height above mean sea level (m).
    pub surface_height_m: f64,
    /// Surface temperature (K).
    pub surface_temperature_k: f64,
    /// Surface pressure (hPa).
    pub surface_pressure_hpa: f64,
    /// Surface dT/dh of the fit (K/m).
    pub surface_dt_dh_k_per_m: f64,
    /// Inversions up to `layers_top_m`.
    pub inversion_count: usize,
    /// Whether the lowest inversion is surface-based.
    pub surface_inversion: bool,
    /// The strongest inversion's ΔT (K), base and top (m above the surface).
    pub strongest_inversion: Option<(f64, f64, f64)>,
    /// Largest dT/dh inside any inversion (K/m).
    pub max_inversion_gradient_k_per_m: Option<f64>,
    /// Ducts up to `layers_top_m`.
    pub duct_count: usize,
    /// The strongest duct (largest M deficit): base, top (m above the surface), ΔM.
    pub strongest_duct: Option<(f64, f64, f64)>,
    /// Whether any duct is surface-based.
    pub surface_duct: bool,
    /// Lowest base of a trapping layer (m above the surface).
    pub lowest_trapping_m: Option<f64>,
}

/// What an observer at one height saw of the target at one distance.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaseFacts {
    /// Observer height above the surface (m).
    pub observer_height_m: f64,
    /// Target distance (m).
    pub distance_m: f64,
    /// Number of images of the target [0, H].
    pub images: usize,
    /// Whether one image is inverted.
    pub inverted: bool,
    /// An inverted image lies above an erect one (superior mirage, a "ghost ship").
    pub superior: bool,
    /// An inverted image lies below an erect one (inferior mirage).
    pub inferior: bool,
    /// Largest magnification of any image (`None` without images).
    pub max_magnification: Option<f64>,
}

/// What an observer at one height saw of the horizon and the sun.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ObserverFacts {
    /// Observer height above the surface (m).
    pub observer_height_m: f64,
    /// Dip of the apparent sea horizon below the horizontal (deg); `None` if the fan found none.
    pub horizon_dip_deg: Option<f64>,
    /// Dip minus the standard atmosphere's dip at the same height (deg).
    pub dip_anomaly_deg: Option<f64>,
    /// Lowest true solar elevation at which the sun is still seen (deg), at the fan's spacing.
    pub lowest_sun_deg: Option<f64>,
    /// The standard atmosphere's lowest minus this one (deg): how much deeper the sun is seen.
    pub sun_depth_anomaly_deg: Option<f64>,
    /// Fan rays trapped in a duct.
    pub trapped_rays: usize,
    /// The sun is seen `novaya_zemlya_margin_deg` or more deeper than in the standard atmosphere.
    pub novaya_zemlya: bool,
}

/// One sounding's row.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SurveyRow {
    /// Where the sounding is: the file, and `:line` of its header in a multi-sounding file.
    pub origin: String,
    /// Station, as the file names it.
    pub station: Option<String>,
    /// Nominal time (`"YYYY-MM-DD HH"`, UTC) when the file gives it.
    pub time_utc: Option<String>,
    /// Why the sounding could not be used (`None` for a used one).
    pub unusable: Option<String>,
    /// Its layers (default values for an unusable sounding).
    pub layers: LayerFacts,
    /// Per observer height.
    pub observers: Vec<ObserverFacts>,
    /// Per observer height × distance, observer-major.
    pub cases: Vec<CaseFacts>,
}

impl SurveyRow {
    /// The row of a sounding that cannot be used, saying why (the whole error chain).
    pub fn unusable(
        origin: String,
        time_utc: Option<String>,
        error: &dyn std::error::Error,
    ) -> Self {
        let mut reason = error.to_string();
        let mut source = error.source();
        while let Some(e) = source {
            reason.push_str(": ");
            reason.push_str(&e.to_string());
            source = e.source();
        }
        SurveyRow {
            origin,
            station: None,
            time_utc,
            unusable: Some(reason),
            layers: LayerFacts::default(),
            observers: Vec::new(),
            cases: Vec::new(),
        }
    }

    /// The month (1–12) of its time, if known.
    pub fn month(&self) -> Option<u32> {
        self.time_utc.as_deref()?.get(5..7)?.parse().ok()
    }
}

/// The standard atmosphere's horizon dip and lowest visible sun per observer height, which every
/// row is compared with.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Reference {
    /// Per observer height: (dip, lowest sun) in deg.
    pub per_observer: Vec<(Option<f64>, Option<f64>)>,
}

impl Reference {
    /// Trace the standard atmosphere (U.S. 1976, surface at sea level) with `options`' fans.
    pub fn standard(options: &SurveyOptions) -> Result<Reference, SurveyError> {
        let column = Arc::new(StandardAtmosphere::default());
        let atm = RefractiveAtmosphere::new(column, options.atmosphere.wavelength_nm)
            .map_err(SurveyError::Refractivity)?;
        let per_observer = options
            .observer_heights_m
            .iter()
            .map(|&h| {
                let report = trace_report(&atm, &options.trace_request(h))
                    .map_err(SurveyError::Reference)?;
                Ok((dip_deg(&report), lowest_sun_deg(&report)))
            })
            .collect::<Result<_, SurveyError>>()?;
        Ok(Reference { per_observer })
    }
}

/// Survey every item, in parallel; rows in item order whatever the thread count. `progress` is
/// advanced once per item.
pub fn survey(
    items: Vec<SurveyItem>,
    options: &SurveyOptions,
    reference: &Reference,
    progress: &indicatif::ProgressBar,
) -> Vec<SurveyRow> {
    items
        .into_par_iter()
        .map(|item| {
            let row = survey_item(item, options, reference);
            progress.inc(1);
            row
        })
        .collect()
}

/// The row of one item: its sounding surveyed, or why it cannot be.
pub fn survey_item(item: SurveyItem, options: &SurveyOptions, reference: &Reference) -> SurveyRow {
    match item.sounding {
        Ok(sounding) => survey_sounding(item.origin, &sounding, options, reference),
        Err(e) => SurveyRow::unusable(item.origin, item.time, &e),
    }
}

/// The row of one sounding.
pub fn survey_sounding(
    origin: String,
    sounding: &Sounding,
    options: &SurveyOptions,
    reference: &Reference,
) -> SurveyRow {
    let time_utc = sounding_time(sounding);
    let profile = match Profile::from_sounding(sounding, &options.atmosphere.fit_options()) {
        Ok(p) => Arc::new(p),
        Err(e) => return SurveyRow::unusable(origin, time_utc, &e),
    };
    let top_of_data_m = profile.top_of_data_m();
    let wavelength_nm = options.atmosphere.wavelength_nm;
    let atm = RefractiveAtmosphere::with_spec(profile.clone(), wavelength_nm, survey_table());
    let atm = match atm {
        Ok(a) => a,
        Err(e) => return SurveyRow::unusable(origin, time_utc, &e),
    };
    let layers = layer_facts(&atm, profile.as_ref(), top_of_data_m, options);
    let mut observers = Vec::new();
    let mut cases = Vec::new();
    for (k, &h) in options.observer_heights_m.iter().enumerate() {
        let report = match trace_report(&atm, &options.trace_request(h)) {
            Ok(r) => r,
            Err(e) => return SurveyRow::unusable(origin, time_utc, &e),
        };
        observers.push(observer_facts(&report, reference.per_observer[k], options));
        cases.extend(options.distances_m.iter().map(|&d| case_facts(&report, d)));
    }
    SurveyRow {
        origin,
        station: sounding.metadata.get("station").cloned(),
        time_utc,
        unusable: None,
        layers,
        observers,
        cases,
    }
}

/// The survey's n(h) table: coarser than the renderer's (5 m cells to 1 km, 100 m above; each
/// cell holding a sounding level is cut there) and with a looser bound, see
/// [`SURVEY_TABLE_DNDH_PER_M`]; scans read it, since a survey's fan climbs through the whole
/// column anyway. The spacing was chosen by instruction counts of the survey bench's record:
/// finer cells cost more nodes, coarser ones hold more than one level and evaluate exactly.
pub fn survey_table() -> TableSpec {
    TableSpec {
        fine_step_m: 5.0,
        coarse_step_m: 100.0,
        fine_top_agl_m: 1_000.0,
        tolerance_n: SURVEY_TABLE_DNDH_PER_M,
        tolerance_dndh_per_m: SURVEY_TABLE_DNDH_PER_M,
        scans_read_table: true,
        ..TableSpec::default()
    }
}

/// Error bound of the survey's n(h) table on n and on dn/dh (m⁻¹); cells that miss it
/// evaluate the exact formula. An error δ in dn/dh bends a ray by δ per metre, ½·δ·x² in height
/// after x metres: 0.45 mm at 30 km, 5 mm at 100 km — far below what the survey reports (image
/// counts, 0.01° fans).
pub const SURVEY_TABLE_DNDH_PER_M: f64 = 1e-12;

/// The sounding's nominal time as `"YYYY-MM-DD HH"` when its metadata gives one.
pub(crate) fn sounding_time(sounding: &Sounding) -> Option<String> {
    let m = &sounding.metadata;
    let text = m
        .get("nominal_time_utc")
        .or_else(|| m.get("launch_time_utc"))?;
    if let Some(t) = crate::sounding::time::CommaTime::parse(text) {
        return t.nominal().or_else(|| Some(t.readable()));
    }
    crate::sounding::time::canonical_time(text)
        .ok()
        .or_else(|| time_in_text(text))
        .or_else(|| Some(text.trim().to_string()))
}

/// The `"YYYY-MM-DD HH"` a free-text time holds: the one after `nominal` if there is one (a
/// launch time with its nominal synoptic hour), else the first.
fn time_in_text(text: &str) -> Option<String> {
    let is_time = |s: &[u8]| {
        s.len() >= 13
            && s[..13].iter().enumerate().all(|(i, b)| match i {
                4 | 7 => *b == b'-',
                10 => *b == b' ',
                _ => b.is_ascii_digit(),
            })
            && s.get(13).is_none_or(|b| !b.is_ascii_digit() && *b != b':')
    };
    let first = |t: &str| {
        (0..t.len())
            .filter(|&i| t.is_char_boundary(i))
            .find(|&i| is_time(&t.as_bytes()[i..]))
            .map(|i| t[i..i + 13].to_string())
    };
    text.find("nominal")
        .and_then(|at| first(&text[at..]))
        .or_else(|| first(text))
}

/// Inversions and ducts up to `layers_top_m` above the surface (or the top of the data).
fn layer_facts(
    atm: &RefractiveAtmosphere,
    column: &dyn crate::profile::AirColumn,
    top_of_data_m: f64,
    options: &SurveyOptions,
) -> LayerFacts {
    let surface_m = atm.surface_height_m();
    let top_m = (surface_m + options.layers_top_m).min(top_of_data_m);
    let inversions = detect_inversions(column, top_m, &InversionOptions::default());
    let regimes = detect_regimes(atm, top_m, &RegimeOptions::default());
    let ducts: Vec<_> = regimes.iter().filter_map(|l| l.duct.as_ref()).collect();
    let s = atm.sample_at(surface_m);
    let strongest = inversions
        .iter()
        .max_by(|a, b| a.delta_t_k.total_cmp(&b.delta_t_k));
    let strongest_duct = ducts
        .iter()
        .max_by(|a, b| a.m_deficit.total_cmp(&b.m_deficit));
    LayerFacts {
        surface_height_m: surface_m,
        surface_temperature_k: s.air.temperature_k,
        surface_pressure_hpa: crate::units::pa_to_hpa(s.air.pressure_pa),
        surface_dt_dh_k_per_m: s.air.dtemperature_dh_k_per_m,
        inversion_count: inversions.len(),
        surface_inversion: inversions
            .first()
            .is_some_and(|l| l.kind == InversionKind::Surface),
        strongest_inversion: strongest.map(|l| (l.delta_t_k, l.base_agl_m, l.top_agl_m)),
        max_inversion_gradient_k_per_m: inversions
            .iter()
            .map(|l| l.max_gradient_k_per_m)
            .reduce(f64::max),
        duct_count: ducts.len(),
        strongest_duct: strongest_duct.map(|d| (d.base_agl_m, d.top_agl_m, d.m_deficit)),
        surface_duct: ducts.iter().any(|d| d.surface_based),
        lowest_trapping_m: regimes
            .iter()
            .filter(|l| l.kind == RegimeKind::Trapping)
            .map(|l| l.base_m - surface_m)
            .reduce(f64::min),
    }
}

/// Dip of the sea horizon (deg, positive below the horizontal).
fn dip_deg(report: &TraceReport) -> Option<f64> {
    let sea = report.horizons.iter().find(|h| h.distance_m.is_none())?;
    sea.elevation_deg.map(|e| -e)
}

/// Lowest true elevation (deg) of an escaped ray's final direction: the lowest sun still seen.
fn lowest_sun_deg(report: &TraceReport) -> Option<f64> {
    report
        .rays
        .iter()
        .filter(|r| r.termination == Termination::Escaped)
        .map(|r| r.end_elevation_deg)
        .reduce(f64::min)
}

/// Horizon and sun facts of one observer height, against the standard atmosphere's.
fn observer_facts(
    report: &TraceReport,
    (standard_dip, standard_sun): (Option<f64>, Option<f64>),
    options: &SurveyOptions,
) -> ObserverFacts {
    let dip = dip_deg(report);
    let sun = lowest_sun_deg(report);
    let depth = sun.zip(standard_sun).map(|(s, r)| r - s);
    ObserverFacts {
        observer_height_m: report.observer_height_m,
        horizon_dip_deg: dip,
        dip_anomaly_deg: dip.zip(standard_dip).map(|(d, r)| d - r),
        lowest_sun_deg: sun,
        sun_depth_anomaly_deg: depth,
        trapped_rays: report.trapped_elevations_deg.len(),
        novaya_zemlya: depth.is_some_and(|d| d >= options.novaya_zemlya_margin_deg),
    }
}

/// The images of the target at `distance_m`.
fn case_facts(report: &TraceReport, distance_m: f64) -> CaseFacts {
    let images: Vec<_> = report
        .images
        .iter()
        .filter(|i| i.distance_m == distance_m)
        .collect();
    let erect: Vec<f64> = images
        .iter()
        .filter(|i| i.erect)
        .map(|i| i.elevation_deg)
        .collect();
    let inverted: Vec<f64> = images
        .iter()
        .filter(|i| !i.erect)
        .map(|i| i.elevation_deg)
        .collect();
    let above = |e: f64| erect.iter().any(|&x| e > x);
    let below = |e: f64| erect.iter().any(|&x| e < x);
    CaseFacts {
        observer_height_m: report.observer_height_m,
        distance_m,
        images: images.len(),
        inverted: !inverted.is_empty(),
        superior: inverted.iter().any(|&e| above(e)),
        inferior: inverted.iter().any(|&e| below(e)),
        max_magnification: images.iter().map(|i| i.magnification).reduce(f64::max),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn free_text_times_give_their_nominal_hour() {
        let t = |s: &str| time_in_text(s);
        assert_eq!(
            t("2026-02-06 00 UTC (TTAA identifier YYGGI=06002: day 6, hour 00)").as_deref(),
            Some("2026-02-06 00")
        );
        assert_eq!(
            t("2014-09-10 11:03 UTC (IGRA RELTIME=1103); nominal 2014-09-10 12 UTC").as_deref(),
            Some("2014-09-10 12")
        );
        assert_eq!(t("2024-02-26 11:20 UTC"), None);
        assert_eq!(t("launch at dawn"), None);
    }

    #[test]
    fn a_time_that_is_no_date_is_kept_by_any_date_range() {
        let range = sources::DateRange {
            from: Some("2020-01-01".into()),
            to: Some("2020-12-31".into()),
        };
        assert!(range.keeps(Some("launch at dawn, day 5")));
        assert!(range.keeps(None));
        assert!(range.keeps(Some("2020-06-01 12")));
        assert!(!range.keeps(Some("2021-06-01 12")));
    }
}
