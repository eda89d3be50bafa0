//! Stage 5 (analysis), the `trace` command as a library function.
//!
//! In: a stratified atmosphere (`&dyn StratifiedIndex`) and a [`TraceRequest`] (observer, fan of
//! elevations, target distances and heights, tracer settings). Out: a serialisable
//! [`TraceReport`] — every ray of the fan with its heights at the distances, termination and
//! refraction; every image of every target; the apparent horizons; the trapped rays — and its CSV
//! forms. The CLI wiring and atmosphere loading live elsewhere.

use rayon::prelude::*;
use serde::Serialize;

use super::AnalysisError;
use super::transfer::{FoldTest, Image, Reach, TransferCurve, apparent_horizon, find_images};
use crate::tracer::{RayRecord, StratifiedIndex, Termination, Tracer, TracerConfig};

/// What to trace.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TraceRequest {
    /// Observer height above the surface (m).
    pub observer_height_m: f64,
    /// Lowest apparent elevation of the fan (deg).
    pub elevation_min_deg: f64,
    /// Highest apparent elevation of the fan (deg); equal to the lowest for a single ray.
    pub elevation_max_deg: f64,
    /// Number of rays in the fan (≥ 1), evenly spaced. Images and apparent horizons need at
    /// least [`MIN_ANALYSIS_RAYS`].
    pub elevation_count: usize,
    /// Explicit apparent elevations (deg), strictly ascending; when not empty they are the fan
    /// and the three fields above are ignored.
    pub elevations_deg: Vec<f64>,
    /// Ground distances at which heights are reported (m), ascending.
    pub distances_m: Vec<f64>,
    /// Heights of targets standing at every distance (m): images of [0, H] are searched.
    pub target_heights_m: Vec<f64>,
    /// Wavelength the atmosphere was built for (nm); recorded in the report.
    pub wavelength_nm: f64,
    /// Tracer settings (tolerance, Earth radius, top, ...). Its `max_distance_m` is only a
    /// safety limit (none by default): a ray is trapped when Bouguer's invariant proves it
    /// ([`Termination::Trapped`]), not at a distance.
    pub tracer: TracerConfig,
}

/// Fewest rays for which a report searches images and apparent horizons: a fold of the transfer
/// curve (where an inverted image begins) shows only as a turning point of three consecutive
/// rays, and a horizon needs a ray on each side. A smaller fan still reports every ray, with
/// empty `images` and `horizons` and a note saying why.
pub const MIN_ANALYSIS_RAYS: usize = 3;

/// Most rays a fan may have.
pub const MAX_FAN_RAYS: usize = 100_000;

impl Default for TraceRequest {
    fn default() -> Self {
        TraceRequest {
            observer_height_m: 10.0,
            elevation_min_deg: -0.5,
            elevation_max_deg: 0.5,
            elevation_count: 1001,
            elevations_deg: Vec::new(),
            distances_m: vec![10_000.0, 20_000.0, 30_000.0],
            target_heights_m: vec![20.0],
            wavelength_nm: 550.0,
            tracer: TracerConfig::default(),
        }
    }
}

impl TraceRequest {
    /// The fan's apparent elevations (deg), ascending: the explicit list, or `elevation_count`
    /// evenly spaced from `elevation_min_deg` to `elevation_max_deg` (just the lowest for one).
    pub fn elevations_deg(&self) -> Vec<f64> {
        if !self.elevations_deg.is_empty() {
            return self.elevations_deg.clone();
        }
        let (lo, hi) = (self.elevation_min_deg, self.elevation_max_deg);
        match self.elevation_count {
            0 => Vec::new(),
            1 => vec![lo],
            n => (0..n)
                .map(|i| lo + (hi - lo) * i as f64 / (n - 1) as f64)
                .collect(),
        }
    }

    /// The fan's apparent elevations (rad), ascending.
    pub fn elevations_rad(&self) -> Vec<f64> {
        self.elevations_deg()
            .into_iter()
            .map(f64::to_radians)
            .collect()
    }

    /// Check the request.
    pub fn validate(&self) -> Result<(), AnalysisError> {
        let bad = |m: &str| Err(AnalysisError::InvalidRequest(m.to_string()));
        let inside = |a: f64| a.is_finite() && a > -90.0 && a < 90.0;
        if self.elevations_deg.is_empty() {
            if !(1..=MAX_FAN_RAYS).contains(&self.elevation_count) {
                return bad(&format!("elevation_count must be from 1 to {MAX_FAN_RAYS}"));
            }
            let ordered = if self.elevation_count == 1 {
                self.elevation_min_deg <= self.elevation_max_deg
            } else {
                self.elevation_min_deg < self.elevation_max_deg
            };
            if !(inside(self.elevation_min_deg) && inside(self.elevation_max_deg) && ordered) {
                return bad(
                    "need -90 < elevation_min_deg < elevation_max_deg < 90 (equal for one ray)",
                );
            }
        } else {
            if self.elevations_deg.len() > MAX_FAN_RAYS {
                return bad(&format!("elevations_deg has more than {MAX_FAN_RAYS} rays"));
            }
            if !self.elevations_deg.iter().all(|&a| inside(a))
                || self.elevations_deg.windows(2).any(|w| w[1] <= w[0])
            {
                return bad(
                    "elevations_deg must lie strictly between -90 and 90 and be strictly ascending",
                );
            }
        }
        if self
            .distances_m
            .iter()
            .any(|d| !(d.is_finite() && *d > 0.0))
            || self.distances_m.windows(2).any(|w| w[1] <= w[0])
        {
            return bad("distances_m must be finite, > 0 and strictly ascending");
        }
        if self
            .target_heights_m
            .iter()
            .any(|h| !(h.is_finite() && *h > 0.0))
        {
            return bad("target_heights_m must be finite and > 0");
        }
        if let Some(d) = self.tracer.max_distance_m
            && d < self.distances_m.last().copied().unwrap_or(0.0)
        {
            return bad("max_distance_m must be at least the largest distance");
        }
        self.tracer.validate()?;
        Ok(())
    }
}

/// One ray of the fan, as reported.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RayReport {
    /// Apparent elevation (deg).
    pub elevation_deg: f64,
    /// Why the ray stopped (traced to its end: ground, top, or trapped by Bouguer's invariant).
    pub termination: Termination,
    /// Height at each requested distance (m), null where the ray ended before it.
    pub heights_m: Vec<Option<f64>>,
    /// Ground distance where the ray ended (m).
    pub end_distance_m: f64,
    /// Height where the ray ended (m).
    pub end_height_m: f64,
    /// Elevation of the final direction relative to the observer's horizontal (deg).
    pub end_elevation_deg: f64,
    /// Astronomical refraction of an escaped ray (deg), else null.
    pub refraction_deg: Option<f64>,
    /// Steps taken (accepted + rejected).
    pub steps: u32,
    /// Rejected steps among them.
    pub rejected_steps: u32,
    /// Largest relative drift of Bouguer's invariant along the ray.
    pub invariant_drift: f64,
    /// Trapped in a duct: past the last distance it has turning points above and below it
    /// (Bouguer's invariant proves it oscillates there for ever); `termination` is `trapped`.
    pub trapped: bool,
}

impl RayReport {
    fn from_record(r: &RayRecord, distances: usize) -> RayReport {
        let termination = r.termination.unwrap_or(Termination::NonFinite);
        RayReport {
            elevation_deg: r.elevation_rad.to_degrees(),
            termination,
            heights_m: r.heights_m.iter().take(distances).copied().collect(),
            end_distance_m: r.end.distance_m,
            end_height_m: r.end.height_m,
            end_elevation_deg: r.end_observer_elevation_rad.to_degrees(),
            refraction_deg: r.refraction_rad.map(f64::to_degrees),
            steps: r.steps(),
            rejected_steps: r.rejected_steps,
            invariant_drift: r.invariant_drift,
            trapped: termination == Termination::Trapped,
        }
    }
}

/// The apparent horizon for one distance.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Horizon {
    /// Ground distance (m); null for the sea horizon (rays that never meet the ground).
    pub distance_m: Option<f64>,
    /// Lowest apparent elevation whose ray is not stopped by the ground before the distance
    /// (deg); null when it lies below the fan or no ray of the fan qualifies.
    pub elevation_deg: Option<f64>,
}

/// The `trace` command's result.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TraceReport {
    /// Observer height (m).
    pub observer_height_m: f64,
    /// Tracer tolerance (m).
    pub tolerance_m: f64,
    /// Smallest height reversal of h(D; α), on rays re-traced at `retrace_tolerance_m`, that
    /// counts as a fold between two images (m); see [`FoldTest`].
    pub fold_threshold_m: f64,
    /// Tolerance of the rays re-traced to test and refine folds and image edges (m).
    pub retrace_tolerance_m: f64,
    /// Wavelength (nm).
    pub wavelength_nm: f64,
    /// Earth radius (m).
    pub earth_radius_m: f64,
    /// Top of the atmosphere (m).
    pub top_m: f64,
    /// The tracer's safety limit on ground distance (m), if any; rays stopped there end
    /// `max_distance` (their fate undecided), not trapped.
    pub max_distance_m: Option<f64>,
    /// Requested distances (m).
    pub distances_m: Vec<f64>,
    /// Target heights (m).
    pub target_heights_m: Vec<f64>,
    /// The fan.
    pub rays: Vec<RayReport>,
    /// Every image of every target, by distance, height and elevation.
    pub images: Vec<Image>,
    /// Apparent horizon at each distance, then the sea horizon.
    pub horizons: Vec<Horizon>,
    /// Elevations (deg) of the fan rays that are trapped.
    pub trapped_elevations_deg: Vec<f64>,
    /// What the report leaves out and why (e.g. no images or horizons for a fan of fewer than
    /// [`MIN_ANALYSIS_RAYS`] rays); empty normally.
    pub notes: Vec<String>,
}

/// Trace the request's fan through `atmosphere` and analyse it.
pub fn trace_report(
    atmosphere: &dyn StratifiedIndex,
    request: &TraceRequest,
) -> Result<TraceReport, AnalysisError> {
    request.validate()?;
    let fan_cfg = TracerConfig {
        stop_after_last_target: false,
        ..request.tracer.clone()
    };
    let probe_cfg = TracerConfig {
        stop_after_last_target: true,
        max_distance_m: None,
        ..request.tracer.clone()
    };
    let fan_tracer = Tracer::new(atmosphere, fan_cfg)?.with_fates();
    let probe_tracer = Tracer::new(atmosphere, probe_cfg)?;
    let h0 = request.observer_height_m;
    let elevations = request.elevations_rad();
    let records = fan_tracer.trace_fan(h0, &elevations, &request.distances_m)?;
    let rays: Vec<RayReport> = records
        .iter()
        .map(|r| RayReport::from_record(r, request.distances_m.len()))
        .collect();
    let trapped_elevations_deg = rays
        .iter()
        .filter(|r| r.trapped)
        .map(|r| r.elevation_deg)
        .collect();
    let mut report = TraceReport {
        observer_height_m: h0,
        tolerance_m: request.tracer.tolerance_m,
        fold_threshold_m: FoldTest::default().threshold_m(request.tracer.tolerance_m),
        retrace_tolerance_m: FoldTest::default().retrace_tolerance_m(request.tracer.tolerance_m),
        wavelength_nm: request.wavelength_nm,
        earth_radius_m: request.tracer.earth_radius_m,
        top_m: request.tracer.top_m,
        max_distance_m: request.tracer.max_distance_m,
        distances_m: request.distances_m.clone(),
        target_heights_m: request.target_heights_m.clone(),
        rays,
        images: Vec::new(),
        horizons: Vec::new(),
        trapped_elevations_deg,
        notes: Vec::new(),
    };
    if elevations.len() < MIN_ANALYSIS_RAYS {
        report.notes.push(format!(
            "images and apparent horizons need a fan of at least {MIN_ANALYSIS_RAYS} rays; this \
             one has {}, so only the rays are reported",
            elevations.len()
        ));
        return Ok(report);
    }
    // Images, one job per (distance, height), in parallel; the order is fixed by the job list.
    let jobs: Vec<(usize, f64)> = (0..request.distances_m.len())
        .flat_map(|j| request.target_heights_m.iter().map(move |&h| (j, h)))
        .collect();
    let images: Vec<Image> = jobs
        .par_iter()
        .map(|&(j, height)| {
            let curve = TransferCurve {
                distance_m: request.distances_m[j],
                elevations_rad: elevations.clone(),
                reach: records.iter().map(|r| Reach::from_record(r, j)).collect(),
            };
            find_images(&probe_tracer, h0, &curve, height)
        })
        .collect::<Vec<_>>()
        .into_iter()
        .flatten()
        .collect();
    let mut horizon_targets: Vec<Option<f64>> =
        request.distances_m.iter().copied().map(Some).collect();
    horizon_targets.push(None);
    let horizons: Vec<Horizon> = horizon_targets
        .par_iter()
        .map(|&d| {
            // From the fan: a ray is clear of the ground before D if it has a height there; clear
            // of it altogether if it did not end on the ground.
            let clear: Vec<bool> = records
                .iter()
                .map(|r| match d {
                    Some(_) => {
                        let j = request
                            .distances_m
                            .iter()
                            .position(|&x| Some(x) == d)
                            .unwrap_or(0);
                        r.heights_m[j].is_some()
                    }
                    None => r.termination != Some(Termination::Ground),
                })
                .collect();
            Horizon {
                distance_m: d,
                // The sea horizon is refined with the fan's own settings (and fate rule).
                elevation_deg: match d {
                    Some(_) => apparent_horizon(&probe_tracer, h0, &elevations, &clear, d),
                    None => apparent_horizon(&fan_tracer, h0, &elevations, &clear, d),
                }
                .map(f64::to_degrees),
            }
        })
        .collect();
    report.images = images;
    report.horizons = horizons;
    Ok(report)
}

fn opt(v: Option<f64>) -> String {
    v.map(|x| format!("{x}")).unwrap_or_default()
}

impl TraceReport {
    /// The report as pretty JSON.
    pub fn to_json(&self) -> Result<String, serde_json::Error> {
        serde_json::to_string_pretty(self)
    }

    /// The fan as CSV: one row per ray, one `height_m_at_<D>` column per distance (empty where the
    /// ray ended before it).
    pub fn rays_csv(&self) -> Result<Vec<u8>, AnalysisError> {
        let mut w = csv::Writer::from_writer(Vec::new());
        let mut header: Vec<String> = [
            "elevation_deg",
            "termination",
            "trapped",
            "end_distance_m",
            "end_height_m",
            "end_elevation_deg",
            "refraction_deg",
            "steps",
            "invariant_drift",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        header.extend(self.distances_m.iter().map(|d| format!("height_m_at_{d}")));
        w.write_record(&header)?;
        for r in &self.rays {
            let mut row = vec![
                format!("{}", r.elevation_deg),
                r.termination.to_string(),
                r.trapped.to_string(),
                format!("{}", r.end_distance_m),
                format!("{}", r.end_height_m),
                format!("{}", r.end_elevation_deg),
                opt(r.refraction_deg),
                r.steps.to_string(),
                format!("{}", r.invariant_drift),
            ];
            row.extend(r.heights_m.iter().map(|h| opt(*h)));
            w.write_record(&row)?;
        }
        w.into_inner()
            .map_err(|e| AnalysisError::Csv(e.into_error().into()))
    }

    /// The images as CSV, one row per image.
    pub fn images_csv(&self) -> Result<Vec<u8>, AnalysisError> {
        let mut w = csv::Writer::from_writer(Vec::new());
        for image in &self.images {
            w.serialize(image)?;
        }
        w.into_inner()
            .map_err(|e| AnalysisError::Csv(e.into_error().into()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tracer::UniformIndex;

    fn request(count: usize, lo: f64, hi: f64, list: Vec<f64>) -> TraceRequest {
        TraceRequest {
            elevation_min_deg: lo,
            elevation_max_deg: hi,
            elevation_count: count,
            elevations_deg: list,
            distances_m: vec![5_000.0],
            ..TraceRequest::default()
        }
    }

    #[test]
    fn small_fans_report_rays_without_images_or_horizons() {
        for (req, n) in [
            (request(1, 0.1, 0.1, vec![]), 1),
            (request(2, -0.1, 0.1, vec![]), 2),
            (request(0, 0.0, 0.0, vec![0.3]), 1),
            (request(0, 0.0, 0.0, vec![-0.2, 0.3]), 2),
        ] {
            let report = trace_report(&UniformIndex, &req).unwrap();
            assert_eq!(report.rays.len(), n);
            assert!(report.images.is_empty() && report.horizons.is_empty());
            assert_eq!(report.notes.len(), 1);
            assert!(report.notes[0].contains("at least 3"), "{:?}", report.notes);
        }
        let report = trace_report(&UniformIndex, &request(3, -0.1, 0.1, vec![])).unwrap();
        assert_eq!(report.rays.len(), 3);
        assert_eq!(report.horizons.len(), 2);
        assert!(report.notes.is_empty());
    }

    #[test]
    fn explicit_elevations_are_the_fan() {
        let req = request(7, -1.0, 1.0, vec![-0.1, 0.0, 0.25]);
        assert_eq!(req.elevations_deg(), vec![-0.1, 0.0, 0.25]);
        let report = trace_report(&UniformIndex, &req).unwrap();
        let got: Vec<f64> = report.rays.iter().map(|r| r.elevation_deg).collect();
        assert_eq!(got, vec![-0.1, 0.0, 0.25]);
        // An even fan is unchanged by the new field.
        let even = request(3, -0.1, 0.1, vec![]).elevations_deg();
        assert_eq!(even, vec![-0.1, 0.0, 0.1]);
    }

    #[test]
    fn bad_fans_are_refused() {
        for req in [
            request(0, 0.0, 1.0, vec![]),
            request(2, 0.1, 0.1, vec![]),
            request(3, 0.2, 0.1, vec![]),
            request(MAX_FAN_RAYS + 1, 0.0, 1.0, vec![]),
            request(0, 0.0, 0.0, vec![0.2, 0.1]),
            request(0, 0.0, 0.0, vec![0.1, 0.1]),
            request(0, 0.0, 0.0, vec![f64::NAN]),
            request(0, 0.0, 0.0, vec![90.0]),
        ] {
            assert!(req.validate().is_err(), "{req:?}");
        }
    }
}
