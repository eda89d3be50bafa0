//! Jobs — the trace job's sensitivity ensemble. In: a trace request, its loaded measured
//! atmosphere and the trace report of its fit; [`EnsembleOptions`]. Out: an [`EnsembleReport`]:
//! for the fit and for every member profile of [`crate::profile::ensemble`] (temperature moved
//! between the levels within the significant-level bound), the images of every target (number
//! and apparent elevations), the sea horizon and the ducts (the profile report's detection), and
//! their spread, with a few summary lines — whether what the fit predicts is robust or an
//! artefact of interpolating between levels.

use std::sync::Arc;

use rayon::prelude::*;
use serde::Serialize;

use super::JobError;
use crate::analysis::{TraceReport, TraceRequest, trace_report};
use crate::atmosphere::{AtmosphereError, LoadedAtmosphere};
use crate::profile::ensemble::{EnsembleOptions, ensemble_members, perturbed_gaps};
use crate::profile::{FitChoice, Profile, TemperatureFit};
use crate::refractivity::{RefractiveAtmosphere, RegimeOptions, detect_regimes};

/// What one profile (the fit or a member) shows.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Outcome {
    /// Images per target, in the order of [`EnsembleReport::targets`].
    pub images: Vec<TargetImages>,
    /// Apparent elevation of the sea horizon (deg; negative: a dip); null when the fan misses it.
    pub sea_horizon_elevation_deg: Option<f64>,
    /// The ducts, as the profile report finds them.
    pub ducts: Vec<DuctExtent>,
}

/// The images of one target seen through one profile.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TargetImages {
    /// Number of images.
    pub count: usize,
    /// Their centre apparent elevations (deg), lowest first as the report lists them.
    pub elevations_deg: Vec<f64>,
}

/// One duct's extent.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DuctExtent {
    /// Base above the surface (m).
    pub base_agl_m: f64,
    /// Top above the surface (m).
    pub top_agl_m: f64,
}

/// How many members showed a number of images.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct CountShare {
    /// Number of images.
    pub images: usize,
    /// Members that showed that many.
    pub members: usize,
}

/// The spread of the images of one target.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TargetSpread {
    /// Target distance (m).
    pub distance_m: f64,
    /// Target height (m).
    pub height_m: f64,
    /// Images through the fit.
    pub fit_images: usize,
    /// Members by number of images, most members first.
    pub image_counts: Vec<CountShare>,
    /// Lowest and highest image centre over all members (deg); null when no member sees one.
    pub elevation_range_deg: Option<(f64, f64)>,
}

/// The spread of the sea horizon.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct HorizonSpread {
    /// Through the fit (deg).
    pub fit_deg: Option<f64>,
    /// Lowest and highest over the members (deg); null when no member's fan found it.
    pub range_deg: Option<(f64, f64)>,
}

/// How often ducts appear.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DuctSpread {
    /// Ducts in the fit.
    pub fit_ducts: usize,
    /// Members with at least one duct.
    pub members_with_duct: usize,
}

/// The `ensemble` section of a trace report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EnsembleReport {
    /// Number of members.
    pub members: usize,
    /// Bound of the departure from the fit between levels (K).
    pub tolerance_k: f64,
    /// Seed of the draws.
    pub seed: u64,
    /// The fit the members depart from.
    pub fit: FitChoice,
    /// Gaps between levels.
    pub gaps: usize,
    /// Gaps perturbed (all for significant levels; for a dense ascent those wider than 25 m).
    pub perturbed_gaps: usize,
    /// Top of the duct search (m above the surface).
    pub duct_search_top_agl_m: f64,
    /// Spread of the images, per target (distance × height, in the request's order).
    pub targets: Vec<TargetSpread>,
    /// Spread of the sea horizon.
    pub sea_horizon: HorizonSpread,
    /// How often ducts appear.
    pub ducts: DuctSpread,
    /// What the fit itself shows.
    pub fit_outcome: Outcome,
    /// What each member shows, member 0 first.
    pub member_outcomes: Vec<Outcome>,
    /// The spread in a few readable lines.
    pub summary: Vec<String>,
}

/// Build the ensemble of `atm`'s fitted profile, trace `request` through every member and
/// compare with `fit_report` (the trace through the fit itself). Fails for an atmosphere that is
/// not a measured sounding.
pub fn ensemble_report(
    atm: &LoadedAtmosphere,
    request: &TraceRequest,
    fit_report: &TraceReport,
    options: &EnsembleOptions,
) -> Result<EnsembleReport, JobError> {
    let profile = atm.profile.as_ref().ok_or_else(|| {
        JobError::Invalid(format!(
            "an ensemble needs a measured sounding; {} is a model atmosphere with no levels to \
             interpolate between",
            atm.source
        ))
    })?;
    let invalid = |e: crate::profile::ProfileError| JobError::Invalid(e.to_string());
    options.validate().map_err(invalid)?;
    let surface_m = atm.refractive.surface_height_m();
    let top_m = (surface_m + super::profile::DEFAULT_LAYERS_TOP_M)
        .min(atm.top_of_data_m.unwrap_or(f64::INFINITY));
    let fit_outcome = outcome(&atm.refractive, fit_report, request, top_m);
    let gaps = perturbed_gaps(profile);
    let perturbed = gaps.iter().filter(|&&g| g).count();
    let member_outcomes = if perturbed == 0 {
        // Every member is the fit itself.
        vec![fit_outcome.clone(); options.members]
    } else {
        let members = ensemble_members(profile, options).map_err(invalid)?;
        members
            .into_par_iter()
            .map(|m| member_outcome(atm, m, request, top_m))
            .collect::<Result<Vec<_>, _>>()?
    };
    let mut report = EnsembleReport {
        members: options.members,
        tolerance_k: options.tolerance_k,
        seed: options.seed,
        fit: profile.fit_choice().clone(),
        gaps: gaps.len(),
        perturbed_gaps: perturbed,
        duct_search_top_agl_m: top_m - surface_m,
        targets: target_spreads(request, &fit_outcome, &member_outcomes),
        sea_horizon: horizon_spread(&fit_outcome, &member_outcomes),
        ducts: DuctSpread {
            fit_ducts: fit_outcome.ducts.len(),
            members_with_duct: member_outcomes
                .iter()
                .filter(|o| !o.ducts.is_empty())
                .count(),
        },
        fit_outcome,
        member_outcomes,
        summary: Vec::new(),
    };
    report.summary = summary_lines(&report);
    Ok(report)
}

/// Trace `request` through one member profile.
fn member_outcome(
    atm: &LoadedAtmosphere,
    member: Profile,
    request: &TraceRequest,
    top_m: f64,
) -> Result<Outcome, JobError> {
    let refractive = RefractiveAtmosphere::new(Arc::new(member), atm.refractive.wavelength_nm())
        .map_err(|source| {
            JobError::from(AtmosphereError::Refractivity {
                source_name: atm.source.to_string(),
                source,
            })
        })?;
    let report = trace_report(&refractive, request).map_err(|source| JobError::Trace {
        atmosphere: atm.source.to_string(),
        source,
    })?;
    Ok(outcome(&refractive, &report, request, top_m))
}

/// What `report` (traced through `refractive`) shows, with the ducts below `top_m` (MSL).
fn outcome(
    refractive: &RefractiveAtmosphere,
    report: &TraceReport,
    request: &TraceRequest,
    top_m: f64,
) -> Outcome {
    let images = targets(request)
        .map(|(d, h)| {
            let elevations_deg: Vec<f64> = report
                .images
                .iter()
                .filter(|i| i.distance_m == d && i.height_m == h)
                .map(|i| i.elevation_deg)
                .collect();
            TargetImages {
                count: elevations_deg.len(),
                elevations_deg,
            }
        })
        .collect();
    let ducts = detect_regimes(refractive, top_m, &RegimeOptions::default())
        .iter()
        .filter_map(|l| l.duct.as_ref())
        .map(|d| DuctExtent {
            base_agl_m: d.base_agl_m,
            top_agl_m: d.top_agl_m,
        })
        .collect();
    Outcome {
        images,
        sea_horizon_elevation_deg: report
            .horizons
            .iter()
            .find(|h| h.distance_m.is_none())
            .and_then(|h| h.elevation_deg),
        ducts,
    }
}

/// The (distance, height) of every target, in the report's order.
fn targets(request: &TraceRequest) -> impl Iterator<Item = (f64, f64)> + '_ {
    request
        .distances_m
        .iter()
        .flat_map(|&d| request.target_heights_m.iter().map(move |&h| (d, h)))
}

fn target_spreads(request: &TraceRequest, fit: &Outcome, members: &[Outcome]) -> Vec<TargetSpread> {
    targets(request)
        .enumerate()
        .map(|(k, (distance_m, height_m))| {
            let mut counts: Vec<CountShare> = Vec::new();
            for m in members {
                let n = m.images[k].count;
                match counts.iter_mut().find(|c| c.images == n) {
                    Some(c) => c.members += 1,
                    None => counts.push(CountShare {
                        images: n,
                        members: 1,
                    }),
                }
            }
            counts.sort_by(|a, b| b.members.cmp(&a.members).then(a.images.cmp(&b.images)));
            let all = members
                .iter()
                .flat_map(|m| m.images[k].elevations_deg.iter().copied());
            TargetSpread {
                distance_m,
                height_m,
                fit_images: fit.images[k].count,
                image_counts: counts,
                elevation_range_deg: range(all),
            }
        })
        .collect()
}

fn horizon_spread(fit: &Outcome, members: &[Outcome]) -> HorizonSpread {
    HorizonSpread {
        fit_deg: fit.sea_horizon_elevation_deg,
        range_deg: range(members.iter().filter_map(|m| m.sea_horizon_elevation_deg)),
    }
}

/// Smallest and largest of `values`; `None` when empty.
fn range(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    values.fold(None, |acc, v| match acc {
        None => Some((v, v)),
        Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
    })
}

/// "20 km" for whole kilometres, else "2500 m".
fn distance_text(d: f64) -> String {
    if d >= 1000.0 && (d / 1000.0).fract() == 0.0 {
        format!("{} km", d / 1000.0)
    } else {
        format!("{d} m")
    }
}

fn summary_lines(r: &EnsembleReport) -> Vec<String> {
    let n = r.members;
    let fit = match r.fit.used {
        TemperatureFit::Linear => "linear-in-ln-p",
        _ => "PCHIP",
    };
    let mut lines = vec![format!(
        "Ensemble of {n} profiles: temperature within ±{} K of the {fit} fit in {} of {} gaps \
         between levels (seed {})",
        r.tolerance_k, r.perturbed_gaps, r.gaps, r.seed
    )];
    if r.perturbed_gaps == 0 {
        lines.push(
            "  no gap to perturb: a dense ascent's levels are the measured curve, every member \
             is the fit"
                .into(),
        );
    }
    for t in &r.targets {
        let shares: Vec<String> = t
            .image_counts
            .iter()
            .map(|c| format!("{} in {}/{n}", c.images, c.members))
            .collect();
        lines.push(format!(
            "  images of the {} m target at {}: {} (fit: {})",
            t.height_m,
            distance_text(t.distance_m),
            shares.join(", "),
            t.fit_images
        ));
    }
    let deg = |v: Option<f64>| v.map_or("not found".to_string(), |v| format!("{v:+.3}°"));
    lines.push(match r.sea_horizon.range_deg {
        Some((lo, hi)) => format!(
            "  sea horizon {} … {} (fit {})",
            deg(Some(lo)),
            deg(Some(hi)),
            deg(r.sea_horizon.fit_deg)
        ),
        None => "  sea horizon: not found in the fan of any member".into(),
    });
    lines.push(format!(
        "  duct present in {}/{n} members (fit: {} duct{})",
        r.ducts.members_with_duct,
        r.ducts.fit_ducts,
        if r.ducts.fit_ducts == 1 { "" } else { "s" }
    ));
    lines
}
