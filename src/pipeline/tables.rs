//! Pipeline — job tables. In: one `[[profile]]`, `[[trace]]`, `[[render]]`, `[[sequence]]`,
//! `[[compare]]` or `[[survey]]` table (the
//! `[defaults]` merged in) with the spans of its keys. Out: the named, validated job requests
//! it expands to (every atmosphere × scene × observer height it names), or the problems found,
//! each at the key it concerns.

use std::ops::Range;
use std::path::Path;

use serde::Deserialize;
use toml::de::{DeTable, DeValue};

use super::expand::{AtmosphereChoice, TimeSelection, atmospheres, check_file, glob_files};
use crate::atmosphere::AtmosphereOptions;
use crate::jobs::cache::AtmosphereRequest;
use crate::jobs::render::{RenderSettings, parse_size};
use crate::jobs::sequence::{
    SequenceSettings, SweepKind, SweepSpec, TimeSpan, parse_key_sweep, parse_sweep,
};
use crate::jobs::trace::parse_elevation_spec;
use crate::jobs::{
    CompareRequest, JobRequest, ProfileRequest, RenderRequest, SequenceRequest, SurveyRequest,
    TraceJobRequest,
};
use crate::output::film::ImageFormat;
use crate::profile::TemperatureFit;
use crate::scene::Scene;
use crate::survey::SurveyOptions;
use crate::survey::sources::DateRange;
use crate::tracer::TracerConfig;

/// Keys a `[[profile]]` table accepts.
pub const PROFILE_KEYS: &[&str] = &[
    "name",
    "atmosphere",
    "sounding_time",
    "igra2_time",
    "wavelength_nm",
    "smooth_m",
    "fit",
    "strict",
    "plot_top_m",
    "layers_top_m",
];
/// Keys a `[[trace]]` table accepts.
pub const TRACE_KEYS: &[&str] = &[
    "name",
    "atmosphere",
    "sounding_time",
    "igra2_time",
    "wavelength_nm",
    "smooth_m",
    "fit",
    "strict",
    "observer_height_m",
    "elevation_deg",
    "distances_m",
    "target_heights_m",
    "tolerance_m",
    "top_m",
    "max_distance_m",
    "straight",
    "ensemble",
];

/// The keys a `[[sequence]]` table accepts.
pub const SEQUENCE_KEYS: &[&str] = &[
    "name",
    "scene",
    "sun_elevation_deg",
    "observer_height_m",
    "sweep",
    "time_utc",
    "step_min",
    "lat_deg",
    "lon_deg",
    "follow_sun",
    "to_sounding",
    "to_sounding_time",
    "size",
    "spp",
    "tolerance_m",
    "exposure",
    "straight",
    "exr",
    "mp4",
];
/// Keys a `[[survey]]` table accepts.
pub const SURVEY_KEYS: &[&str] = &[
    "name",
    "sources",
    "from",
    "to",
    "observer_height_m",
    "distances_m",
    "target_height_m",
    "layers_top_m",
    "tolerance_m",
    "fan_step_deg",
    "wavelength_nm",
    "smooth_m",
    "fit",
    "strict",
    "parts",
];
/// Keys a `[[render]]` table accepts.
pub const RENDER_KEYS: &[&str] = &[
    "name",
    "scene",
    "atmosphere",
    "sounding_time",
    "igra2_time",
    "observer_height_m",
    "sizes",
    "formats",
    "spp",
    "tolerance_m",
    "exposure",
    "exact",
    "straight",
];

/// Keys a `[[compare]]` table accepts.
pub const COMPARE_KEYS: &[&str] = &[
    "name",
    "atmosphere",
    "sounding_time",
    "igra2_time",
    "synthetic",
    "scene",
    "smooth_m",
    "fit",
    "layers",
    "size",
    "spp",
    "tolerance_m",
    "exposure",
    "rays",
];

/// A problem at a byte range of the pipeline file.
pub type Problem = (Range<usize>, String);

/// One value or a list of them.
#[derive(Debug, Clone, Deserialize)]
#[serde(
    untagged,
    expecting = "a number or a list of numbers (for paths: a string or a list of strings)"
)]
pub enum OneOrMany<T> {
    /// A single value.
    One(T),
    /// A list.
    Many(Vec<T>),
}

impl<T: Clone> OneOrMany<T> {
    fn to_vec(&self) -> Vec<T> {
        match self {
            OneOrMany::One(v) => vec![v.clone()],
            OneOrMany::Many(v) => v.clone(),
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawProfile {
    name: Option<String>,
    atmosphere: OneOrMany<String>,
    #[serde(alias = "igra2_time")]
    sounding_time: Option<String>,
    wavelength_nm: Option<f64>,
    smooth_m: Option<f64>,
    fit: Option<TemperatureFit>,
    strict: Option<bool>,
    plot_top_m: Option<f64>,
    layers_top_m: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTrace {
    name: Option<String>,
    atmosphere: OneOrMany<String>,
    #[serde(alias = "igra2_time")]
    sounding_time: Option<String>,
    wavelength_nm: Option<f64>,
    smooth_m: Option<f64>,
    fit: Option<TemperatureFit>,
    strict: Option<bool>,
    observer_height_m: OneOrMany<f64>,
    elevation_deg: String,
    distances_m: Vec<f64>,
    target_heights_m: Option<Vec<f64>>,
    tolerance_m: Option<f64>,
    top_m: Option<f64>,
    max_distance_m: Option<f64>,
    straight: Option<bool>,
    ensemble: Option<usize>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRender {
    name: Option<String>,
    scene: OneOrMany<String>,
    atmosphere: Option<OneOrMany<String>>,
    #[serde(alias = "igra2_time")]
    sounding_time: Option<String>,
    observer_height_m: Option<OneOrMany<f64>>,
    sizes: Option<Vec<String>>,
    formats: Option<Vec<ImageFormat>>,
    spp: Option<u32>,
    tolerance_m: Option<f64>,
    exposure: Option<f64>,
    exact: Option<bool>,
    straight: Option<bool>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSequence {
    name: Option<String>,
    scene: String,
    sun_elevation_deg: Option<String>,
    observer_height_m: Option<String>,
    sweep: Option<String>,
    time_utc: Option<String>,
    step_min: Option<f64>,
    lat_deg: Option<f64>,
    lon_deg: Option<f64>,
    follow_sun: Option<bool>,
    to_sounding: Option<String>,
    to_sounding_time: Option<String>,
    size: Option<String>,
    spp: Option<u32>,
    tolerance_m: Option<f64>,
    exposure: Option<f64>,
    straight: Option<bool>,
    exr: Option<bool>,
    mp4: Option<bool>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSurvey {
    name: Option<String>,
    sources: OneOrMany<String>,
    from: Option<String>,
    to: Option<String>,
    observer_height_m: Option<OneOrMany<f64>>,
    distances_m: Option<Vec<f64>>,
    target_height_m: Option<f64>,
    layers_top_m: Option<f64>,
    tolerance_m: Option<f64>,
    fan_step_deg: Option<f64>,
    wavelength_nm: Option<f64>,
    smooth_m: Option<f64>,
    fit: Option<TemperatureFit>,
    strict: Option<bool>,
    parts: Option<usize>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCompare {
    name: Option<String>,
    atmosphere: OneOrMany<String>,
    #[serde(alias = "igra2_time")]
    sounding_time: Option<String>,
    synthetic: Option<String>,
    scene: String,
    smooth_m: Option<f64>,
    fit: Option<crate::profile::TemperatureFit>,
    layers: Option<crate::jobs::compare::LayerShape>,
    size: Option<String>,
    spp: Option<u32>,
    tolerance_m: Option<f64>,
    exposure: Option<f64>,
    rays: Option<usize>,
}

/// A job table with the spans of its keys, and where problems go.
pub struct Table<'a, 'i> {
    /// The merged table.
    pub table: &'a DeTable<'i>,
    /// Span of the table (its header line for `[[…]]` tables).
    pub span: Range<usize>,
    /// The pipeline file's folder (relative paths are resolved against it).
    pub folder: &'a Path,
    /// Problems found so far.
    pub problems: Vec<Problem>,
}

impl Table<'_, '_> {
    fn span_of(&self, key: &str) -> Range<usize> {
        self.table
            .get(key)
            .map(|v| v.span())
            .unwrap_or_else(|| self.span.clone())
    }

    fn problem(&mut self, key: &str, message: impl Into<String>) {
        let span = self.span_of(key);
        self.problems.push((span, message.into()));
    }

    /// A problem whose message names the key it is about (the longest key of the table that
    /// the message mentions), or else the table.
    fn problem_in_message(&mut self, message: String) {
        let key = self
            .table
            .keys()
            .map(|k| k.get_ref().as_ref())
            .filter(|k: &&str| message.contains(*k))
            .max_by_key(|k| k.len())
            .map(str::to_string)
            .unwrap_or_default();
        self.problem(&key, message);
    }

    fn raw<T: for<'de> Deserialize<'de>>(&mut self) -> Option<T> {
        let spanned = toml::Spanned::new(self.span.clone(), self.table.clone());
        let value = toml::Spanned::new(self.span.clone(), DeValue::Table(spanned.into_inner()));
        match T::deserialize(toml::de::ValueDeserializer::from(value)) {
            Ok(raw) => Some(raw),
            Err(e) => {
                let span = e.span().unwrap_or_else(|| self.span.clone());
                self.problems.push((span, e.message().to_string()));
                None
            }
        }
    }

    fn atmospheres(
        &mut self,
        names: &[String],
        sounding_time: Option<&str>,
    ) -> Vec<AtmosphereChoice> {
        let times = match TimeSelection::parse(sounding_time) {
            Ok(t) => t,
            Err(e) => {
                self.problem("sounding_time", e);
                return Vec::new();
            }
        };
        match atmospheres(names, &times, self.folder) {
            Ok(list) => list,
            Err(e) => {
                self.problem("atmosphere", e);
                Vec::new()
            }
        }
    }

    fn name(&mut self, template: &str, stem: &str, scene: &str, height: Option<f64>) -> String {
        super::expand::job_name(template, stem, scene, height).unwrap_or_else(|e| {
            self.problem("name", e);
            String::new()
        })
    }
}

/// A job with its name.
pub type NamedJob = (String, JobRequest);

fn atmosphere_request(
    choice: &AtmosphereChoice,
    wavelength_nm: Option<f64>,
    smooth_m: Option<f64>,
    fit: Option<TemperatureFit>,
    strict: Option<bool>,
) -> AtmosphereRequest {
    let d = AtmosphereOptions::default();
    AtmosphereRequest {
        source: choice.source.clone(),
        options: AtmosphereOptions {
            smooth_m: smooth_m.unwrap_or(d.smooth_m),
            fit: fit.unwrap_or(d.fit),
            wavelength_nm: wavelength_nm.unwrap_or(d.wavelength_nm),
            sounding_time: choice.sounding_time.clone(),
            strict: strict.unwrap_or(false),
        },
    }
}

/// The jobs of a `[[profile]]` table.
pub fn profile_jobs(t: &mut Table) -> Vec<NamedJob> {
    let Some(raw) = t.raw::<RawProfile>() else {
        return Vec::new();
    };
    let template = raw.name.clone().unwrap_or_else(|| "{stem}".into());
    let mut jobs = Vec::new();
    for choice in t.atmospheres(&raw.atmosphere.to_vec(), raw.sounding_time.as_deref()) {
        let name = t.name(&template, &choice.stem, "", None);
        let request = ProfileRequest::new(
            atmosphere_request(
                &choice,
                raw.wavelength_nm,
                raw.smooth_m,
                raw.fit,
                raw.strict,
            ),
            raw.plot_top_m
                .unwrap_or(crate::jobs::profile::DEFAULT_PLOT_TOP_M),
            raw.layers_top_m
                .unwrap_or(crate::jobs::profile::DEFAULT_LAYERS_TOP_M),
        );
        match request {
            Ok(r) => jobs.push((name, JobRequest::Profile(r))),
            Err(e) => t.problem_in_message(e.to_string()),
        }
    }
    jobs
}

/// The jobs of a `[[trace]]` table.
pub fn trace_jobs(t: &mut Table) -> Vec<NamedJob> {
    let Some(raw) = t.raw::<RawTrace>() else {
        return Vec::new();
    };
    let heights = raw.observer_height_m.to_vec();
    let template = raw.name.clone().unwrap_or_else(|| {
        if heights.len() > 1 {
            "{stem}_transfer_{height}".into()
        } else {
            "{stem}_transfer".into()
        }
    });
    let spec = match parse_elevation_spec(&raw.elevation_deg) {
        Ok(s) => s,
        Err(e) => {
            t.problem("elevation_deg", e);
            return Vec::new();
        }
    };
    let d = TracerConfig::default();
    let tracer = TracerConfig {
        tolerance_m: raw.tolerance_m.unwrap_or(d.tolerance_m),
        top_m: raw.top_m.unwrap_or(d.top_m),
        max_distance_m: raw.max_distance_m,
        ..d
    };
    let mut jobs = Vec::new();
    for choice in t.atmospheres(&raw.atmosphere.to_vec(), raw.sounding_time.as_deref()) {
        for &height in &heights {
            let name = t.name(&template, &choice.stem, "", Some(height));
            let request = TraceJobRequest::new(
                atmosphere_request(
                    &choice,
                    raw.wavelength_nm,
                    raw.smooth_m,
                    raw.fit,
                    raw.strict,
                ),
                height,
                &spec,
                raw.distances_m.clone(),
                raw.target_heights_m.clone().unwrap_or_else(|| vec![20.0]),
                tracer.clone(),
                raw.straight.unwrap_or(false),
            )
            .and_then(|r| r.with_ensemble(raw.ensemble.unwrap_or(0)));
            match request {
                Ok(r) => jobs.push((name, JobRequest::Trace(r))),
                Err(e) => t.problem_in_message(e.to_string()),
            }
        }
    }
    jobs
}

/// The jobs of a `[[render]]` table.
pub fn render_jobs(t: &mut Table, own_keys: &[String]) -> Vec<NamedJob> {
    let Some(raw) = t.raw::<RawRender>() else {
        return Vec::new();
    };
    let Some(settings) = render_settings(t, &raw) else {
        return Vec::new();
    };
    if raw.atmosphere.is_none()
        && own_keys
            .iter()
            .any(|k| k == "sounding_time" || k == "igra2_time")
    {
        t.problem(
            "sounding_time",
            "sounding_time needs an `atmosphere` in this table",
        );
    }
    let choices: Vec<Option<AtmosphereChoice>> = match &raw.atmosphere {
        None => vec![None],
        Some(names) => t
            .atmospheres(&names.to_vec(), raw.sounding_time.as_deref())
            .into_iter()
            .map(Some)
            .collect(),
    };
    let heights: Vec<Option<f64>> = match &raw.observer_height_m {
        None => vec![None],
        Some(h) => h.to_vec().into_iter().map(Some).collect(),
    };
    let template = raw.name.clone().unwrap_or_else(|| {
        let mut n = String::from("{scene}");
        if raw.atmosphere.is_some() {
            n.push_str("_{stem}");
        }
        if heights.len() > 1 {
            n.push_str("_{height}");
        }
        n
    });
    let mut jobs = Vec::new();
    for scene_path in scene_paths(t, &raw.scene.to_vec()) {
        let scene = match Scene::from_file(&scene_path) {
            Ok(s) => s,
            Err(e) => {
                t.problem("scene", crate::jobs::run::error_text(&e));
                continue;
            }
        };
        let scene_stem = stem(&scene_path);
        for choice in &choices {
            for &height in &heights {
                let stem = choice.as_ref().map_or("", |c| c.stem.as_str());
                let name = t.name(&template, stem, &scene_stem, height);
                let settings = RenderSettings {
                    atmosphere: choice.as_ref().map(|c| c.source.clone()),
                    sounding_time: choice.as_ref().and_then(|c| c.sounding_time.clone()),
                    observer_height_m: height,
                    ..settings.clone()
                };
                match RenderRequest::new(scene.clone(), settings) {
                    Ok(r) => jobs.push((name, JobRequest::Render(r))),
                    Err(e) => t.problem_in_message(e.to_string()),
                }
            }
        }
    }
    jobs
}

fn render_settings(t: &mut Table, raw: &RawRender) -> Option<RenderSettings> {
    let d = RenderSettings::default();
    let mut sizes = Vec::new();
    for s in raw.sizes.iter().flatten() {
        match parse_size(s) {
            Ok(size) => sizes.push(Some(size)),
            Err(e) => t.problem("sizes", e),
        }
    }
    if raw.sizes.as_ref().is_some_and(|s| s.is_empty()) {
        t.problem(
            "sizes",
            "sizes is empty (leave it out for the scene's own size)",
        );
    }
    if raw.formats.as_ref().is_some_and(|f| f.is_empty()) {
        t.problem("formats", "formats is empty");
        return None;
    }
    let mut formats = raw.formats.clone().unwrap_or(d.formats.clone());
    formats.sort();
    formats.dedup();
    Some(RenderSettings {
        sizes: if sizes.is_empty() {
            d.sizes.clone()
        } else {
            sizes
        },
        formats,
        spp: raw.spp,
        tolerance_m: raw.tolerance_m.unwrap_or(d.tolerance_m),
        exposure: raw.exposure.unwrap_or(d.exposure),
        exact: raw.exact.unwrap_or(false),
        straight: raw.straight.unwrap_or(false),
        ..d
    })
}

/// The one sweep of a `[[sequence]]` table, or a problem (at the key it concerns).
fn sequence_sweep(t: &mut Table, raw: &RawSequence) -> Option<SweepSpec> {
    let step_min = raw.step_min.unwrap_or(f64::NAN);
    let mut given: Vec<(&str, Result<SweepSpec, String>)> = Vec::new();
    if let Some(s) = &raw.sun_elevation_deg {
        given.push((
            "sun_elevation_deg",
            parse_sweep(SweepKind::SunElevationDeg, s),
        ));
    }
    if let Some(s) = &raw.observer_height_m {
        given.push((
            "observer_height_m",
            parse_sweep(SweepKind::ObserverHeightM, s),
        ));
    }
    if let Some(s) = &raw.sweep {
        given.push(("sweep", parse_key_sweep(s)));
    }
    if let Some(s) = &raw.time_utc {
        let spec = TimeSpan::parse(s, step_min).map(|span| SweepSpec::SunTime {
            span,
            lat_lon_deg: raw.lat_deg.zip(raw.lon_deg),
            follow_sun: raw.follow_sun.unwrap_or(false),
        });
        given.push(("time_utc", spec));
    }
    if let Some(s) = &raw.to_sounding {
        let spec = SweepSpec::Soundings {
            to: t.folder.join(s),
            to_time: raw.to_sounding_time.clone(),
            step_min,
        };
        given.push(("to_sounding", Ok(spec)));
    }
    if raw.lat_deg.is_some() != raw.lon_deg.is_some() {
        t.problem("lat_deg", "give both lat_deg and lon_deg, or neither");
        return None;
    }
    match given.len() {
        1 => {
            let (key, spec) = given.remove(0);
            spec.map_err(|e| t.problem(key, e)).ok()
        }
        0 => {
            t.problem(
                "scene",
                "give a sweep: sun_elevation_deg, observer_height_m or sweep (FROM:TO:STEP), \
                 time_utc or to_sounding (with step_min)",
            );
            None
        }
        _ => {
            t.problem(
                given[1].0,
                "give one sweep per sequence: one of sun_elevation_deg, observer_height_m, \
                 sweep, time_utc and to_sounding",
            );
            None
        }
    }
}

/// One `[[sequence]]` table → its job (the same [`SequenceRequest`] as `ghostship sequence`).
pub fn sequence_jobs(t: &mut Table) -> Vec<NamedJob> {
    let Some(raw) = t.raw::<RawSequence>() else {
        return Vec::new();
    };
    let Some(sweep) = sequence_sweep(t, &raw) else {
        return Vec::new();
    };
    let size = match raw.size.as_deref().map(parse_size).transpose() {
        Ok(size) => size,
        Err(e) => {
            t.problem("size", e);
            return Vec::new();
        }
    };
    let d = SequenceSettings::new(sweep);
    let settings = SequenceSettings {
        size,
        spp: raw.spp,
        tolerance_m: raw.tolerance_m.unwrap_or(d.tolerance_m),
        exposure: raw.exposure.unwrap_or(d.exposure),
        straight: raw.straight.unwrap_or(false),
        exr: raw.exr.unwrap_or(false),
        mp4: raw.mp4.unwrap_or(false),
        ..d
    };
    let scene_path = t.folder.join(&raw.scene);
    let Some(scene) = one_scene(t, &scene_path) else {
        return Vec::new();
    };
    let template = raw
        .name
        .clone()
        .unwrap_or_else(|| "sequence_{scene}".into());
    let name = t.name(&template, "", &stem(&scene_path), None);
    match SequenceRequest::new(scene, settings) {
        Ok(r) => vec![(name, JobRequest::Sequence(Box::new(r)))],
        Err(e) => {
            t.problem_in_message(e.to_string());
            Vec::new()
        }
    }
}

/// One `[[survey]]` table → its job (the same [`SurveyRequest`] as `ghostship survey`), its
/// sources resolved against the pipeline's folder and expanded to files (so the manifest hashes
/// every file).
pub fn survey_jobs(t: &mut Table) -> Vec<NamedJob> {
    let Some(raw) = t.raw::<RawSurvey>() else {
        return Vec::new();
    };
    let d = SurveyOptions::default();
    let a = AtmosphereOptions::default();
    let options = SurveyOptions {
        observer_heights_m: raw
            .observer_height_m
            .map_or(d.observer_heights_m.clone(), |h| h.to_vec()),
        distances_m: raw.distances_m.unwrap_or(d.distances_m.clone()),
        target_height_m: raw.target_height_m.unwrap_or(d.target_height_m),
        atmosphere: AtmosphereOptions {
            smooth_m: raw.smooth_m.unwrap_or(a.smooth_m),
            fit: raw.fit.unwrap_or(a.fit),
            wavelength_nm: raw.wavelength_nm.unwrap_or(a.wavelength_nm),
            strict: raw.strict.unwrap_or(false),
            ..a
        },
        layers_top_m: raw.layers_top_m.unwrap_or(d.layers_top_m),
        tolerance_m: raw.tolerance_m.unwrap_or(d.tolerance_m),
        fan_step_deg: raw.fan_step_deg.unwrap_or(d.fan_step_deg),
        ..d
    };
    let named: Vec<std::path::PathBuf> = raw
        .sources
        .to_vec()
        .iter()
        .map(|s| t.folder.join(s))
        .collect();
    let files = match crate::survey::sources::expand_files(&named) {
        Ok(files) => files,
        Err(e) => {
            t.problem("sources", e.to_string());
            return Vec::new();
        }
    };
    let dates = DateRange {
        from: raw.from,
        to: raw.to,
    };
    let template = raw.name.clone().unwrap_or_else(|| "survey".into());
    let name = t.name(&template, "", "", None);
    let parts = raw.parts.unwrap_or(1);
    if !(1..=MAX_SURVEY_PARTS).contains(&parts) {
        t.problem(
            "parts",
            format!("parts must be 1 to {MAX_SURVEY_PARTS}, got {parts}"),
        );
        return Vec::new();
    }
    let request = match SurveyRequest::new(files, dates, options) {
        Ok(r) => r.with_label_base(t.folder),
        Err(e) => {
            t.problem_in_message(e.to_string());
            return Vec::new();
        }
    };
    if parts == 1 {
        return vec![(name, JobRequest::Survey(Box::new(request)))];
    }
    (1..=parts)
        .map(|index| {
            let shard = crate::jobs::manifest::Shard {
                index,
                count: parts,
            };
            let job = crate::jobs::survey::part_name(&name, shard);
            (
                job,
                JobRequest::Survey(Box::new(request.clone().with_shard(shard))),
            )
        })
        .collect()
}

/// Most parts a `[[survey]]` table may be split into.
pub const MAX_SURVEY_PARTS: usize = 10_000;

/// The one scene file of a `[[sequence]]` or `[[compare]]` table, loaded, or a problem at `scene`.
fn one_scene(t: &mut Table, scene_path: &Path) -> Option<Scene> {
    if let Err(e) = check_file(scene_path) {
        t.problem("scene", e);
        return None;
    }
    match Scene::from_file(scene_path) {
        Ok(s) => Some(s),
        Err(e) => {
            t.problem("scene", crate::jobs::run::error_text(&e));
            None
        }
    }
}

/// The jobs of a `[[compare]]` table: one per measured sounding.
pub fn compare_jobs(t: &mut Table) -> Vec<NamedJob> {
    let Some(raw) = t.raw::<RawCompare>() else {
        return Vec::new();
    };
    let d = RenderSettings::default();
    let size = match raw.size.as_deref().map(parse_size).transpose() {
        Ok(size) => size,
        Err(e) => {
            t.problem("size", e);
            return Vec::new();
        }
    };
    let settings = RenderSettings {
        sizes: vec![size],
        spp: raw.spp,
        tolerance_m: raw.tolerance_m.unwrap_or(d.tolerance_m),
        exposure: raw.exposure.unwrap_or(d.exposure),
        ..d
    };
    let scene_path = t.folder.join(&raw.scene);
    let Some(scene) = one_scene(t, &scene_path) else {
        return Vec::new();
    };
    let synthetic = raw.synthetic.as_deref().map(|name| {
        let source = crate::atmosphere::AtmosphereSource::parse(name);
        match source.path() {
            Some(p) => {
                crate::atmosphere::AtmosphereSource::parse(&t.folder.join(p).to_string_lossy())
            }
            None => source,
        }
    });
    if let Some(Err(e)) = synthetic.as_ref().and_then(|s| s.path()).map(check_file) {
        t.problem("synthetic", e);
        return Vec::new();
    }
    if let Some(s @ crate::atmosphere::AtmosphereSource::Sounding(_)) = &synthetic {
        t.problem(
            "synthetic",
            format!("synthetic: {s} is a sounding; give a layered .toml or us1976"),
        );
        return Vec::new();
    }
    let template = raw.name.clone().unwrap_or_else(|| "compare_{stem}".into());
    let mut jobs = Vec::new();
    for choice in t.atmospheres(&raw.atmosphere.to_vec(), raw.sounding_time.as_deref()) {
        let name = t.name(&template, &choice.stem, &stem(&scene_path), None);
        let options = crate::jobs::compare::CompareOptions {
            sounding_time: choice.sounding_time.clone(),
            smooth_m: raw.smooth_m,
            fit: raw.fit,
            layers: raw.layers.unwrap_or_default(),
            rays: raw
                .rays
                .unwrap_or(crate::jobs::compare::DEFAULT_COMPARE_RAYS),
        };
        let request = CompareRequest::new(
            scene.clone(),
            choice.source.clone(),
            synthetic.clone(),
            settings.clone(),
            &options,
        );
        match request {
            Ok(r) => jobs.push((name, JobRequest::Compare(Box::new(r)))),
            Err(e) => t.problem_in_message(e.to_string()),
        }
    }
    jobs
}

fn scene_paths(t: &mut Table, names: &[String]) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for name in names {
        let path = t.folder.join(name);
        let found = if super::expand::is_glob(name) {
            glob_files(&path)
        } else {
            check_file(&path).map(|()| vec![path])
        };
        match found {
            Ok(list) => out.extend(list),
            Err(e) => t.problem("scene", e),
        }
    }
    out
}

fn stem(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "job".into())
}
