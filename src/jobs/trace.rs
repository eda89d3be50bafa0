//! Jobs — trace. In: a [`TraceJobRequest`] (observer, fan of elevations, target distances and
//! heights, tracer settings, optional ensemble size) and its loaded atmosphere. Out: the
//! [`TraceReport`], the optional [`EnsembleReport`], and the products `trace.json` (rays, images,
//! horizons, trapped rays; an `ensemble` section when asked for) and `trace.png` (fan and
//! transfer curves).

use super::cache::AtmosphereRequest;
use super::ensemble::{EnsembleReport, ensemble_report};
use super::{JobError, Product};
use crate::analysis::{TraceReport, TraceRequest, trace_plot_png, trace_report};
use crate::atmosphere::{AtmosphereSource, LoadedAtmosphere};
use crate::profile::ensemble::{EnsembleOptions, MAX_MEMBERS};
use crate::tracer::UniformIndex;
use crate::tracer::{StratifiedIndex, TracerConfig};

/// Most rays a fan may have.
pub const MAX_RAYS: usize = crate::analysis::MAX_FAN_RAYS;

/// The rays to trace, as `--elevation-deg` or a pipeline's `elevation_deg` gives them.
#[derive(Debug, Clone, PartialEq)]
pub enum ElevationSpec {
    /// `count` rays from `from_deg` to `to_deg`, evenly spaced (`FROM:TO:STEP`).
    Range {
        /// Lowest elevation (deg).
        from_deg: f64,
        /// Highest elevation (deg): FROM + (count − 1)·STEP, at most TO.
        to_deg: f64,
        /// Number of rays (≥ 1).
        count: usize,
    },
    /// Explicit elevations (deg), strictly ascending: one value or a comma-separated list.
    List(Vec<f64>),
}

/// Parse the `--elevation-deg` value (degrees): one elevation (`0.5`), a comma-separated list in
/// strictly ascending order (`-0.1,0,0.25`; a list out of order, or with a repeated value, is
/// refused rather than silently sorted, so the rows of the report are the rays as listed), or
/// an evenly spaced fan `FROM:TO:STEP` (STEP > 0, TO ≥ FROM; when (TO − FROM)/STEP is not a whole
/// number the fan stops at the last step below TO). 1 to [`MAX_RAYS`] rays, every elevation
/// strictly between −90° and 90°.
pub fn parse_elevation_spec(text: &str) -> Result<ElevationSpec, String> {
    let inside = |v: f64| v > -90.0 && v < 90.0;
    if !text.contains(':') {
        let mut list = Vec::new();
        for item in text.split(',') {
            let v = item
                .trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    format!(
                        "elevation {item:?} in {text:?} is not a number of degrees (give one \
                         elevation, a comma-separated list like \"-0.1,0,0.25\" or a fan \
                         FROM:TO:STEP like \"-0.4:0.6:0.001\")"
                    )
                })?;
            if !inside(v) {
                return Err(format!(
                    "elevation {v} in {text:?}: elevations must lie strictly between -90° and 90°"
                ));
            }
            if let Some(&last) = list.last()
                && v <= last
            {
                return Err(format!(
                    "elevations {text:?} must be listed in strictly ascending order ({v} follows \
                     {last})"
                ));
            }
            list.push(v);
        }
        if list.len() > MAX_RAYS {
            return Err(format!(
                "elevation list {text:?} has {} rays; at most {MAX_RAYS} are allowed",
                list.len()
            ));
        }
        return Ok(ElevationSpec::List(list));
    }
    let (from, step, count) = parse_from_to_step(
        text,
        &RangeSyntax {
            label: "elevation fan",
            unit: "in degrees",
            example: "-0.4:0.6:0.001",
            noun: "rays",
            max_count: MAX_RAYS,
        },
        |from, to| {
            if inside(from) && inside(to) {
                Ok(())
            } else {
                Err("elevations must lie strictly between -90° and 90°".into())
            }
        },
    )?;
    Ok(ElevationSpec::Range {
        from_deg: from,
        to_deg: from + (count - 1) as f64 * step,
        count,
    })
}

/// How [`parse_from_to_step`] names what it parses in its messages.
#[derive(Debug, Clone, Copy)]
pub struct RangeSyntax<'a> {
    /// What the range is, e.g. `"elevation fan"`.
    pub label: &'a str,
    /// Its unit as a phrase, e.g. `"in degrees"`.
    pub unit: &'a str,
    /// A valid example, e.g. `"-0.4:0.6:0.001"`.
    pub example: &'a str,
    /// What it counts, e.g. `"rays"`.
    pub noun: &'a str,
    /// Most values it may have.
    pub max_count: usize,
}

/// Parse an evenly spaced range `FROM:TO:STEP` (STEP > 0, TO ≥ FROM; when (TO − FROM)/STEP is
/// not a whole number the range stops at the last step below TO) into (FROM, STEP, count): the
/// values are FROM + i·STEP for i < count. `check(FROM, TO)` may refuse the bounds (its message
/// follows the range's label). At most `syntax.max_count` values.
pub fn parse_from_to_step(
    text: &str,
    syntax: &RangeSyntax<'_>,
    check: impl Fn(f64, f64) -> Result<(), String>,
) -> Result<(f64, f64, usize), String> {
    let RangeSyntax {
        label,
        unit,
        example,
        noun,
        max_count,
    } = *syntax;
    let parts: Vec<&str> = text.split(':').collect();
    let [from, to, step] = parts.as_slice() else {
        return Err(format!(
            "{label} {text:?} is not FROM:TO:STEP {unit} (e.g. \"{example}\")"
        ));
    };
    let num = |name: &str, s: &str| {
        s.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("{label} {text:?}: {name} {s:?} is not a number"))
    };
    let (from, to, step) = (num("FROM", from)?, num("TO", to)?, num("STEP", step)?);
    if step <= 0.0 {
        return Err(format!("{label} {text:?}: STEP must be > 0"));
    }
    if to < from {
        return Err(format!("{label} {text:?}: TO must not be below FROM"));
    }
    check(from, to).map_err(|e| format!("{label} {text:?}: {e}"))?;
    // A relative slack so that 0.6 reached by steps of 0.001 counts despite rounding.
    let intervals = ((to - from) / step * (1.0 + 1e-9)).floor();
    if intervals + 1.0 > max_count as f64 {
        return Err(format!(
            "{label} {text:?} has {} {noun}; at most {max_count} are allowed (use a larger STEP)",
            intervals + 1.0
        ));
    }
    Ok((from, step, intervals as usize + 1))
}

/// A validated trace request.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TraceJobRequest {
    /// The atmosphere.
    pub atmosphere: AtmosphereRequest,
    /// What to trace.
    pub request: TraceRequest,
    /// Trace through n ≡ 1 instead of the atmosphere.
    pub straight: bool,
    /// Members of the sensitivity ensemble (0: none); see [`Self::with_ensemble`].
    #[serde(skip_serializing_if = "is_zero")]
    pub ensemble: usize,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// The trace report with its optional `ensemble` section, as `trace.json` holds it.
#[derive(serde::Serialize)]
struct TraceJson<'a> {
    #[serde(flatten)]
    report: &'a TraceReport,
    #[serde(skip_serializing_if = "Option::is_none")]
    ensemble: Option<&'a EnsembleReport>,
}

/// `trace.json`'s text (pretty JSON, no final newline): the report, and the ensemble section
/// after its fields when there is one.
pub fn trace_json(
    report: &TraceReport,
    ensemble: Option<&EnsembleReport>,
) -> Result<String, JobError> {
    Ok(serde_json::to_string_pretty(&TraceJson {
        report,
        ensemble,
    })?)
}

impl TraceJobRequest {
    /// Build and check the request from its parts.
    pub fn new(
        atmosphere: AtmosphereRequest,
        observer_height_m: f64,
        elevations: &ElevationSpec,
        mut distances_m: Vec<f64>,
        target_heights_m: Vec<f64>,
        tracer: TracerConfig,
        straight: bool,
    ) -> Result<Self, JobError> {
        atmosphere.validate()?;
        let invalid = |m: String| Err(JobError::Invalid(m));
        if !(observer_height_m.is_finite() && observer_height_m >= 0.0) {
            return invalid(format!(
                "observer height {observer_height_m} m (observer_height_m) must be ≥ 0 m above the surface"
            ));
        }
        if distances_m.is_empty() {
            return invalid("give at least one target distance".into());
        }
        distances_m.sort_by(f64::total_cmp);
        let (elevation_min_deg, elevation_max_deg, elevation_count, elevations_deg) =
            match elevations {
                ElevationSpec::Range {
                    from_deg,
                    to_deg,
                    count,
                } => (*from_deg, *to_deg, *count, Vec::new()),
                ElevationSpec::List(list) => {
                    (list[0], list[list.len() - 1], list.len(), list.clone())
                }
            };
        let request = TraceRequest {
            observer_height_m,
            elevation_min_deg,
            elevation_max_deg,
            elevation_count,
            elevations_deg,
            distances_m,
            target_heights_m,
            wavelength_nm: atmosphere.options.wavelength_nm,
            tracer,
        };
        request
            .validate()
            .map_err(|e| JobError::Invalid(e.to_string()))?;
        if observer_height_m >= request.tracer.top_m {
            return invalid(format!(
                "observer height {observer_height_m} m (observer_height_m) is not below the top of \
                 the atmosphere ({} m)",
                request.tracer.top_m
            ));
        }
        Ok(TraceJobRequest {
            atmosphere,
            request,
            straight,
            ensemble: 0,
        })
    }

    /// The same request with a sensitivity ensemble of `members` profiles (0: none; at most
    /// [`MAX_MEMBERS`]): the temperature between the sounding's levels is moved within the
    /// significant-level bound and the fan traced through each (see [`ensemble_report`]).
    /// Refused for synthetic and standard atmospheres (no levels to interpolate between) and for
    /// straight rays.
    pub fn with_ensemble(mut self, members: usize) -> Result<Self, JobError> {
        if members == 0 {
            self.ensemble = 0;
            return Ok(self);
        }
        let no_levels = match &self.atmosphere.source {
            AtmosphereSource::Sounding(_) => None,
            AtmosphereSource::Synthetic(p) => {
                Some(format!("{} is a synthetic atmosphere", p.display()))
            }
            AtmosphereSource::Us1976 => Some("us1976 is the standard atmosphere".to_string()),
        };
        let why = if let Some(what) = no_levels {
            format!(
                "ensemble needs a measured sounding: {what}, defined at every height, with no \
                 levels to interpolate between"
            )
        } else if self.straight {
            "ensemble and straight rays exclude each other (n ≡ 1 has no temperature to perturb)"
                .to_string()
        } else if members > MAX_MEMBERS {
            format!("ensemble of {members} members: at most {MAX_MEMBERS} are allowed")
        } else {
            self.ensemble = members;
            return Ok(self);
        };
        Err(JobError::Invalid(why))
    }

    /// The ensemble section for `report` (the trace through `atm` itself), if one was asked for.
    pub fn ensemble_report(
        &self,
        atm: &LoadedAtmosphere,
        report: &TraceReport,
    ) -> Result<Option<EnsembleReport>, JobError> {
        if self.ensemble == 0 {
            return Ok(None);
        }
        let options = EnsembleOptions {
            members: self.ensemble,
            ..EnsembleOptions::default()
        };
        ensemble_report(atm, &self.request, report, &options).map(Some)
    }

    /// Number of rays in the fan.
    pub fn ray_count(&self) -> usize {
        self.request.elevation_count
    }

    /// Trace through `atm` (or n ≡ 1 when `straight`); with `plot`, also draw the fan and the
    /// transfer curves.
    pub fn report(
        &self,
        atm: &LoadedAtmosphere,
        plot: bool,
    ) -> Result<(TraceReport, Option<Vec<u8>>), JobError> {
        let index: &dyn StratifiedIndex = if self.straight {
            &UniformIndex
        } else {
            &atm.refractive
        };
        let wrap = |source| JobError::Trace {
            atmosphere: atm.source.to_string(),
            source,
        };
        let report = trace_report(index, &self.request).map_err(wrap)?;
        let png = if plot {
            Some(trace_plot_png(index, &self.request, &report).map_err(wrap)?)
        } else {
            None
        };
        Ok((report, png))
    }

    /// The products: `trace.json` and, with `plot`, `trace.png`.
    pub fn products(&self, atm: &LoadedAtmosphere, plot: bool) -> Result<Vec<Product>, JobError> {
        let (report, png) = self.report(atm, plot)?;
        let ensemble = self.ensemble_report(atm, &report)?;
        let mut json = trace_json(&report, ensemble.as_ref())?;
        json.push('\n');
        let mut products = vec![Product::new("trace.json", json.into_bytes())];
        if let Some(png) = png {
            products.push(Product::new("trace.png", png));
        }
        Ok(products)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rays(text: &str) -> usize {
        match parse_elevation_spec(text).unwrap() {
            ElevationSpec::Range { count, .. } => count,
            ElevationSpec::List(v) => v.len(),
        }
    }

    #[test]
    fn fan_spec() {
        let ElevationSpec::Range {
            from_deg,
            to_deg,
            count,
        } = parse_elevation_spec("-0.4:0.6:0.001").unwrap()
        else {
            panic!("a range")
        };
        assert_eq!((from_deg, count), (-0.4, 1001));
        assert!((to_deg - 0.6).abs() < 1e-12);
        let ElevationSpec::Range { to_deg, count, .. } = parse_elevation_spec("0:1:0.3").unwrap()
        else {
            panic!("a range")
        };
        assert_eq!(count, 4);
        assert!((to_deg - 0.9).abs() < 1e-12);
        // Fewer than 3 rays are fine now: the report says what it cannot analyse.
        assert_eq!(rays("0:1:1"), 2);
        assert_eq!(rays("0.5:0.5:0.1"), 1);
        for bad in [
            "1:0:0.1",
            "0:1:0",
            "0:1:-1",
            "0:1",
            "0:1:0.1:2",
            "a:1:0.1",
            "0:10:0.00001",
            "-90:0:1",
        ] {
            assert!(parse_elevation_spec(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn single_elevations_and_lists() {
        assert_eq!(
            parse_elevation_spec("0.5").unwrap(),
            ElevationSpec::List(vec![0.5])
        );
        assert_eq!(
            parse_elevation_spec("-0.1,0, 0.25").unwrap(),
            ElevationSpec::List(vec![-0.1, 0.0, 0.25])
        );
        let err = parse_elevation_spec("0.2,0.1").unwrap_err();
        assert!(err.contains("ascending"), "{err}");
        let err = parse_elevation_spec("0.1,0.1").unwrap_err();
        assert!(err.contains("ascending"), "{err}");
        for bad in ["", "0.1,", "x", "0.1,,0.2", "95", "nan", "inf"] {
            assert!(parse_elevation_spec(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn a_list_becomes_the_request_fan() {
        let spec = parse_elevation_spec("-0.1,0,0.25").unwrap();
        let request = TraceJobRequest::new(
            AtmosphereRequest {
                source: crate::atmosphere::AtmosphereSource::Us1976,
                options: crate::atmosphere::AtmosphereOptions::default(),
            },
            10.0,
            &spec,
            vec![1000.0],
            vec![20.0],
            TracerConfig::default(),
            false,
        )
        .unwrap();
        assert_eq!(request.request.elevations_deg(), vec![-0.1, 0.0, 0.25]);
    }
}
