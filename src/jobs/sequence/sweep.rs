//! Jobs — sequence: what is swept. In: a sweep as the user writes it (`FROM:TO:STEP` of the sun's
//! true elevation, the observer's height or any numeric scene key; a UTC time span `FROM/TO`
//! with a step in minutes, for the sun's true position or for the air between two soundings).
//! Out: a validated [`SweepSpec`], and for a loaded scene the scene of every frame
//! ([`FramePlan`]) with the values `frames.csv` records for it.

use std::path::PathBuf;

use super::{JobError, MAX_FRAMES};
use crate::atmosphere::AtmosphereSource;
use crate::jobs::trace::{RangeSyntax, parse_from_to_step};
use crate::scene::Scene;
use crate::scene::keys::SceneKey;
use crate::solar::{Site, UtcTime, sun_position};
use crate::sounding::{ReadOptions, Sounding, read_sounding};

/// Swept values are rounded to 1/this of their unit (degrees or metres).
const SWEEP_STEPS_PER_UNIT: f64 = 1e9;

/// The sweeps given as a FROM:TO:STEP range of one named quantity.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SweepKind {
    /// The sun's true (geometric) elevation, degrees.
    SunElevationDeg,
    /// The camera's height above the surface, metres.
    ObserverHeightM,
}

/// Evenly spaced values FROM + i·STEP, i < `count`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Range {
    /// First value.
    pub from: f64,
    /// Step between frames (> 0).
    pub step: f64,
    /// Number of frames (1 to [`MAX_FRAMES`]).
    pub count: usize,
}

impl Range {
    /// The value of every frame, in order: FROM + i·STEP rounded to 1e-9 units (so that
    /// −3 + 7 × 0.04 is −2.72, the number a scene file would give, not −2.7199999999999998).
    pub fn values(&self) -> Vec<f64> {
        (0..self.count)
            .map(|i| {
                let v = self.from + i as f64 * self.step;
                // An integer divided by 1e9 rounds once: the nearest f64 to the decimal.
                (v * SWEEP_STEPS_PER_UNIT).round() / SWEEP_STEPS_PER_UNIT
            })
            .collect()
    }

    /// The last value.
    pub fn last(&self) -> f64 {
        self.from + (self.count.max(1) - 1) as f64 * self.step
    }
}

/// A UTC time span FROM/TO in steps of `step_s` seconds (the frames FROM + i·step ≤ TO).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct TimeSpan {
    /// First frame's time.
    pub from: UtcTime,
    /// The time no frame passes.
    pub to: UtcTime,
    /// Whole seconds between frames (≥ 1).
    pub step_s: i64,
}

impl TimeSpan {
    /// Read `FROM/TO` (two UTC times, [`UtcTime::parse`]) and a step in minutes (rounded to the
    /// second): TO not before FROM, 1 to [`MAX_FRAMES`] frames.
    pub fn parse(text: &str, step_min: f64) -> Result<Self, String> {
        let (from, to) = text.split_once('/').ok_or_else(|| {
            format!(
                "time span {text:?} is not FROM/TO (two UTC times, e.g. \
                 \"2026-02-12T11:00Z/2026-02-12T15:00Z\")"
            )
        })?;
        let from = UtcTime::parse(from).map_err(|e| format!("time span FROM: {e}"))?;
        let to = UtcTime::parse(to).map_err(|e| format!("time span TO: {e}"))?;
        Self::new(from, to, step_min)
    }

    /// The span from `from` to `to` in steps of `step_min` minutes (checked as [`Self::parse`]).
    pub fn new(from: UtcTime, to: UtcTime, step_min: f64) -> Result<Self, String> {
        let step_s = (step_min * 60.0).round();
        if !(step_min.is_finite() && step_s >= 1.0) {
            return Err(format!(
                "the time step must be at least 1 second (step_min ≥ 0.0084), got {step_min} min"
            ));
        }
        if to < from {
            return Err(format!(
                "the time span ends ({to}) before it starts ({from})"
            ));
        }
        let step_s = step_s as i64;
        let count = (to.unix_s - from.unix_s) / step_s + 1;
        if count > MAX_FRAMES as i64 {
            return Err(format!(
                "the time span {from}/{to} in steps of {step_min} min has {count} frames; at \
                 most {MAX_FRAMES} are allowed (use a larger step)"
            ));
        }
        Ok(TimeSpan { from, to, step_s })
    }

    /// The time of every frame.
    pub fn times(&self) -> Vec<UtcTime> {
        let count = (self.to.unix_s - self.from.unix_s) / self.step_s + 1;
        (0..count)
            .map(|i| self.from.plus_s(i * self.step_s))
            .collect()
    }
}

/// What a sequence sweeps, as asked (before the scene is looked at).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SweepSpec {
    /// The sun's true elevation (degrees); the rays are shared by all frames.
    SunElevationDeg(Range),
    /// The camera's height above the surface (m); each frame has its own rays.
    ObserverHeightM(Range),
    /// Any numeric scene key ([`SceneKey`]), set in the scene file's text.
    Key {
        /// The key.
        key: SceneKey,
        /// Its values.
        range: Range,
    },
    /// The sun's true position over a time span (NREL SPA, [`crate::solar`]).
    SunTime {
        /// The frames' times.
        span: TimeSpan,
        /// Latitude and longitude (degrees); `None`: the scene's terrain observer, else its
        /// sounding's station.
        lat_lon_deg: Option<(f64, f64)>,
        /// Turn the camera to the sun's azimuth in every frame.
        follow_sun: bool,
    },
    /// The air between the scene's sounding and a later one of the same station, interpolated
    /// in time ([`crate::profile::TimeBlend`]).
    Soundings {
        /// The later sounding.
        to: PathBuf,
        /// Which sounding of a multi-sounding file `to` is.
        to_time: Option<String>,
        /// Minutes between frames.
        step_min: f64,
    },
}

/// Parse a sweep `FROM:TO:STEP` of `kind` (the trace fan's syntax): sun elevations within
/// −90°…90°, observer heights ≥ 0 m, 1 to [`MAX_FRAMES`] frames.
pub fn parse_sweep(kind: SweepKind, text: &str) -> Result<SweepSpec, String> {
    let (label, unit, example) = match kind {
        SweepKind::SunElevationDeg => ("sun elevation sweep", "in degrees", "-3:1:0.04"),
        SweepKind::ObserverHeightM => ("observer height sweep", "in metres", "5:120:5"),
    };
    let range = parse_range(text, label, unit, example, |from, to| match kind {
        SweepKind::SunElevationDeg if from < -90.0 || to > 90.0 => {
            Err("sun elevations must lie within -90° and 90°".into())
        }
        SweepKind::ObserverHeightM if from < 0.0 => {
            Err("observer heights must be ≥ 0 m above the surface".into())
        }
        _ => Ok(()),
    })?;
    Ok(match kind {
        SweepKind::SunElevationDeg => SweepSpec::SunElevationDeg(range),
        SweepKind::ObserverHeightM => SweepSpec::ObserverHeightM(range),
    })
}

/// Parse `KEY=FROM:TO:STEP`: a numeric scene key ([`SceneKey::parse`]) and its range. Whether
/// every value is valid for the key is checked against the scene ([`plan_frames`]).
pub fn parse_key_sweep(text: &str) -> Result<SweepSpec, String> {
    let (key, range) = text.split_once('=').ok_or_else(|| {
        format!(
            "sweep {text:?} is not KEY=FROM:TO:STEP (e.g. \"cards[0].distance_m=10000:60000:5000\")"
        )
    })?;
    let key = SceneKey::parse(key)?;
    let label = format!("sweep of {key}");
    let range = parse_range(
        range,
        &label,
        "in the key's unit",
        "10000:60000:5000",
        |_, _| Ok(()),
    )?;
    Ok(SweepSpec::Key { key, range })
}

/// [`parse_from_to_step`] with the sequence's frame limit.
fn parse_range(
    text: &str,
    label: &str,
    unit: &str,
    example: &str,
    check: impl Fn(f64, f64) -> Result<(), String>,
) -> Result<Range, String> {
    let syntax = RangeSyntax {
        label,
        unit,
        example,
        noun: "frames",
        max_count: MAX_FRAMES,
    };
    let (from, step, count) = parse_from_to_step(text, &syntax, check)?;
    Ok(Range { from, step, count })
}

impl SweepSpec {
    /// A short description for messages and EXR provenance, e.g. `sun.elevation_deg -3:1:0.04`.
    pub fn describe(&self) -> String {
        let range = |r: &Range| format!("{}:{}:{}", r.from, r.last(), r.step);
        match self {
            SweepSpec::SunElevationDeg(r) => format!("sun.elevation_deg {}", range(r)),
            SweepSpec::ObserverHeightM(r) => format!("camera.height_m {}", range(r)),
            SweepSpec::Key { key, range: r } => format!("{key} {}", range(r)),
            SweepSpec::SunTime { span, .. } => {
                format!(
                    "sun position {}/{} every {} s",
                    span.from, span.to, span.step_s
                )
            }
            SweepSpec::Soundings { to, step_min, .. } => {
                format!("atmosphere towards {} every {step_min} min", to.display())
            }
        }
    }

    /// Whether the sun moves (frames get `sun.png`).
    pub fn moves_sun(&self) -> bool {
        matches!(
            self,
            SweepSpec::SunElevationDeg(_) | SweepSpec::SunTime { .. }
        )
    }

    /// Whether the camera height changes (frames get `transfer.png`).
    pub fn moves_observer(&self) -> bool {
        match self {
            SweepSpec::ObserverHeightM(_) => true,
            SweepSpec::Key { key, .. } => key.to_string() == "camera.height_m",
            _ => false,
        }
    }

    /// The `frames.csv` columns of the swept values (units in the names).
    pub fn columns(&self) -> Vec<String> {
        let names: &[&str] = match self {
            SweepSpec::SunElevationDeg(_) => &["sun_true_elevation_deg"],
            SweepSpec::ObserverHeightM(_) => &["observer_height_m"],
            SweepSpec::Key { key, .. } => return vec![key.to_string()],
            SweepSpec::SunTime { follow_sun, .. } if *follow_sun => &[
                "time_utc",
                "sun_true_elevation_deg",
                "sun_azimuth_deg",
                "camera_heading_deg",
            ],
            SweepSpec::SunTime { .. } => &["time_utc", "sun_true_elevation_deg", "sun_azimuth_deg"],
            SweepSpec::Soundings { .. } => &["time_utc", "second_sounding_weight"],
        };
        names.iter().map(|s| s.to_string()).collect()
    }
}

/// One frame to render.
#[derive(Debug, Clone)]
pub struct FramePlan {
    /// The frame's scene (the sun, camera or key moved; at the sequence's size).
    pub scene: Scene,
    /// Its swept values, as `frames.csv` prints them ([`SweepSpec::columns`]).
    pub values: Vec<String>,
    /// For a sweep between soundings: the weight of the second (0 first, 1 second).
    pub weight: Option<f64>,
}

/// The second sounding of a sweep between soundings and the two times.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SoundingPair {
    /// The later sounding, loaded with the scene's options.
    pub second: AtmosphereSource,
    /// Which sounding of its file.
    pub second_time: Option<String>,
    /// Time of the scene's sounding.
    pub first_at: UtcTime,
    /// Time of the second.
    pub second_at: UtcTime,
}

/// A frame plan with `scene` changed by `change`.
fn frame(base: &Scene, values: Vec<String>, change: impl FnOnce(&mut Scene)) -> FramePlan {
    let mut scene = base.clone();
    change(&mut scene);
    FramePlan {
        scene,
        values,
        weight: None,
    }
}

/// The frames of `spec` for `base` (the scene at the sequence's size, overrides applied;
/// `reparse(text)` loads a scene text as the scene file would be, overrides applied). For a
/// sweep between soundings also the pair it interpolates.
pub fn plan_frames(
    spec: &SweepSpec,
    base: &Scene,
    reparse: &dyn Fn(&str) -> Result<Scene, JobError>,
) -> Result<(Vec<FramePlan>, Option<SoundingPair>), JobError> {
    let invalid = |m: String| JobError::Invalid(m);
    let needs_sun = || {
        base.sun.ok_or_else(|| {
            invalid("the scene has no [sun]: a sweep of the sun needs one to move".into())
        })
    };
    let frames = match spec {
        SweepSpec::SunElevationDeg(range) => {
            let sun = needs_sun()?;
            range
                .values()
                .into_iter()
                .map(|v| {
                    frame(base, vec![v.to_string()], |s| {
                        s.sun = Some(crate::scene::Sun {
                            elevation_rad: v.to_radians(),
                            ..sun
                        })
                    })
                })
                .collect()
        }
        SweepSpec::ObserverHeightM(range) => range
            .values()
            .into_iter()
            .map(|v| frame(base, vec![v.to_string()], |s| s.camera.height_m = v))
            .collect(),
        SweepSpec::Key { key, range } => key_frames(key, range, base, reparse)?,
        SweepSpec::SunTime {
            span,
            lat_lon_deg,
            follow_sun,
        } => {
            needs_sun()?;
            sun_time_frames(span, *lat_lon_deg, *follow_sun, base)?
        }
        SweepSpec::Soundings {
            to,
            to_time,
            step_min,
        } => {
            let pair = sounding_pair(base, to, to_time.as_deref())?;
            let frames = sounding_frames(&pair, *step_min, base)?;
            return Ok((frames, Some(pair)));
        }
    };
    Ok((frames, None))
}

/// Frames of a key sweep: the scene file's text with the key set, loaded like a scene file.
fn key_frames(
    key: &SceneKey,
    range: &Range,
    base: &Scene,
    reparse: &dyn Fn(&str) -> Result<Scene, JobError>,
) -> Result<Vec<FramePlan>, JobError> {
    let path = base.source_path.as_deref().ok_or_else(|| {
        JobError::Invalid(format!(
            "a sweep of {key} needs the scene's file to set it in"
        ))
    })?;
    let text =
        crate::input::read_limited_text(path, crate::input::MAX_TOML_BYTES).map_err(|source| {
            crate::scene::SceneError::Read {
                path: path.to_path_buf(),
                source,
            }
        })?;
    range
        .values()
        .into_iter()
        .map(|v| {
            let edited = key.set_in(&text, v).map_err(JobError::Invalid)?;
            let scene = reparse(&edited).map_err(|e| {
                JobError::Invalid(format!(
                    "sweep of {key}: the value {v} is refused: {}",
                    crate::jobs::run::error_text(&e)
                ))
            })?;
            Ok(FramePlan {
                scene,
                values: vec![v.to_string()],
                weight: None,
            })
        })
        .collect()
}

/// The observer's site for a sun-position sweep: `lat_lon_deg`, else the scene's terrain
/// observer, else its sounding's station (`latitude`/`longitude` metadata).
fn sun_site(base: &Scene, lat_lon_deg: Option<(f64, f64)>) -> Result<Site, JobError> {
    let from_scene = || -> Option<(f64, f64)> {
        if let Some(t) = &base.terrain {
            return Some((t.observer_lat_deg, t.observer_lon_deg));
        }
        let sounding = scene_sounding(base).ok()?;
        let number = |k: &str| {
            sounding
                .metadata
                .get(k)?
                .split_whitespace()
                .next()?
                .parse::<f64>()
                .ok()
        };
        Some((number("latitude")?, number("longitude")?))
    };
    let (lat_deg, lon_deg) = lat_lon_deg.or_else(from_scene).ok_or_else(|| {
        JobError::Invalid(
            "a sun-position sweep needs the observer's site: give --lat-deg and --lon-deg \
             (lat_deg, lon_deg), or use a scene with [terrain] or a sounding that records its \
             station's latitude and longitude"
                .into(),
        )
    })?;
    let site = Site {
        lat_deg,
        lon_deg,
        height_m: base.camera.height_m,
    };
    site.validate()
        .map_err(|e| JobError::Invalid(e.to_string()))?;
    Ok(site)
}

/// Frames of a sun-position sweep: the sun at its true position at each time.
fn sun_time_frames(
    span: &TimeSpan,
    lat_lon_deg: Option<(f64, f64)>,
    follow_sun: bool,
    base: &Scene,
) -> Result<Vec<FramePlan>, JobError> {
    let site = sun_site(base, lat_lon_deg)?;
    let sun = base
        .sun
        .ok_or_else(|| JobError::Invalid("the scene has no [sun]".into()))?;
    span.times()
        .into_iter()
        .map(|t| {
            let p = sun_position(t, &site).map_err(|e| JobError::Invalid(e.to_string()))?;
            let mut values = vec![
                t.iso(),
                p.elevation_deg.to_string(),
                p.azimuth_deg.to_string(),
            ];
            if follow_sun {
                values.push(p.azimuth_deg.to_string());
            }
            Ok(frame(base, values, |s| {
                s.sun = Some(crate::scene::Sun {
                    elevation_rad: p.elevation_deg.to_radians(),
                    azimuth_rad: p.azimuth_deg.to_radians(),
                    ..sun
                });
                if follow_sun {
                    s.camera.heading_rad = p.azimuth_deg.to_radians();
                }
            }))
        })
        .collect()
}

/// The scene's sounding, read as the scene reads it.
fn scene_sounding(base: &Scene) -> Result<Sounding, JobError> {
    let AtmosphereSource::Sounding(path) = &base.atmosphere.source else {
        return Err(JobError::Invalid(
            "a sweep between soundings starts from the scene's sounding: its [atmosphere] \
             must name a `sounding`"
                .into(),
        ));
    };
    read(
        path,
        base.atmosphere.sounding_time.clone(),
        base.atmosphere.strict,
    )
}

fn read(path: &std::path::Path, time: Option<String>, strict: bool) -> Result<Sounding, JobError> {
    let options = ReadOptions {
        sounding_time: time,
        strict,
    };
    read_sounding(path, &options).map_err(|source| {
        JobError::Atmosphere(std::sync::Arc::new(
            crate::atmosphere::AtmosphereError::Sounding {
                source_name: path.display().to_string(),
                source,
            },
        ))
    })
}

/// When a sounding was made: its nominal time, else the time it was asked for by, else its
/// launch time (the first of these that reads as a UTC time).
pub fn sounding_time(sounding: &Sounding, asked: Option<&str>) -> Option<UtcTime> {
    let meta = |k: &str| sounding.metadata.get(k).map(String::as_str);
    [meta("nominal_time_utc"), asked, meta("launch_time_utc")]
        .into_iter()
        .flatten()
        .find_map(|text| {
            let text = crate::sounding::time::readable_time(text.split(['(', ';']).next()?);
            UtcTime::parse(&text).ok()
        })
}

/// The scene's sounding and `to`, checked: both have times, `to` is later, and when both record
/// their station's position they agree within 0.05°.
fn sounding_pair(
    base: &Scene,
    to: &std::path::Path,
    to_time: Option<&str>,
) -> Result<SoundingPair, JobError> {
    if base.atmosphere.straight {
        return Err(JobError::Invalid(
            "a sweep between soundings needs curved rays (not --straight)".into(),
        ));
    }
    let first = scene_sounding(base)?;
    let second = read(to, to_time.map(str::to_string), base.atmosphere.strict)?;
    let time_of = |s: &Sounding, asked: Option<&str>| {
        sounding_time(s, asked).ok_or_else(|| {
            JobError::Invalid(format!(
                "{}: no time of the sounding could be read (nominal_time_utc or \
                 launch_time_utc)",
                s.source.display()
            ))
        })
    };
    let first_at = time_of(&first, base.atmosphere.sounding_time.as_deref())?;
    let second_at = time_of(&second, to_time)?;
    if second_at <= first_at {
        return Err(JobError::Invalid(format!(
            "the second sounding ({}, {second_at}) must be later than the scene's ({}, {first_at})",
            second.source.display(),
            first.source.display()
        )));
    }
    let position = |s: &Sounding| -> Option<(f64, f64)> {
        let n = |k: &str| {
            s.metadata
                .get(k)?
                .split_whitespace()
                .next()?
                .parse::<f64>()
                .ok()
        };
        Some((n("latitude")?, n("longitude")?))
    };
    if let (Some(a), Some(b)) = (position(&first), position(&second))
        && ((a.0 - b.0).abs() > 0.05 || (a.1 - b.1).abs() > 0.05)
    {
        return Err(JobError::Invalid(format!(
            "the two soundings are not of one station: {} is at {}°, {}° and {} at {}°, {}°",
            first.source.display(),
            a.0,
            a.1,
            second.source.display(),
            b.0,
            b.1
        )));
    }
    Ok(SoundingPair {
        second: AtmosphereSource::Sounding(to.to_path_buf()),
        second_time: to_time.map(str::to_string),
        first_at,
        second_at,
    })
}

/// Frames from the first sounding's time to the second's in steps of `step_min`.
fn sounding_frames(
    pair: &SoundingPair,
    step_min: f64,
    base: &Scene,
) -> Result<Vec<FramePlan>, JobError> {
    let span = TimeSpan::new(pair.first_at, pair.second_at, step_min).map_err(JobError::Invalid)?;
    let total = (pair.second_at.unix_s - pair.first_at.unix_s) as f64;
    Ok(span
        .times()
        .into_iter()
        .map(|t| {
            let weight = (t.unix_s - pair.first_at.unix_s) as f64 / total;
            FramePlan {
                scene: base.clone(),
                values: vec![t.iso(), weight.to_string()],
                weight: Some(weight),
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_spans_count_their_frames() {
        let span = TimeSpan::parse("2026-02-12T11:00Z/2026-02-12T12:00Z", 20.0).unwrap();
        let times: Vec<String> = span.times().iter().map(|t| t.iso()).collect();
        assert_eq!(
            times,
            [
                "2026-02-12T11:00:00Z",
                "2026-02-12T11:20:00Z",
                "2026-02-12T11:40:00Z",
                "2026-02-12T12:00:00Z"
            ]
        );
        // A span that is not a whole number of steps stops before TO.
        assert_eq!(
            TimeSpan::parse("2026-02-12T11:00Z/2026-02-12T11:50Z", 20.0)
                .unwrap()
                .times()
                .len(),
            3
        );
        for (text, step, message) in [
            ("2026-02-12T11:00Z", 1.0, "FROM/TO"),
            (
                "2026-02-12T12:00Z/2026-02-12T11:00Z",
                1.0,
                "before it starts",
            ),
            (
                "2026-02-12T11:00Z/2026-02-12T12:00Z",
                0.0,
                "at least 1 second",
            ),
            ("2026-02-12T11:00Z/2026-03-12T12:00Z", 1.0, "at most 10000"),
            ("2026-02-32T11:00Z/2026-03-12T12:00Z", 1.0, "FROM"),
        ] {
            let e = TimeSpan::parse(text, step).unwrap_err();
            assert!(e.contains(message), "{text}: {e}");
        }
    }

    #[test]
    fn key_sweeps_parse() {
        let SweepSpec::Key { key, range } = parse_key_sweep("camera.heading_deg=-2:2:0.5").unwrap()
        else {
            panic!("a key sweep");
        };
        assert_eq!(key.to_string(), "camera.heading_deg");
        assert_eq!(
            range.values(),
            [-2.0, -1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0]
        );
        assert!(
            parse_key_sweep("camera.heading_deg")
                .unwrap_err()
                .contains("KEY=FROM:TO:STEP")
        );
        assert!(
            parse_key_sweep("camera.width=1:2:1")
                .unwrap_err()
                .contains("not a numeric scene key")
        );
        assert!(
            parse_key_sweep("sun.azimuth_deg=2:1:1")
                .unwrap_err()
                .contains("TO must not be below FROM")
        );
    }
}
