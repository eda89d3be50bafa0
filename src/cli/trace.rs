//! `ghostship trace`: arguments → [`TraceOptions`] (a validated
//! [`TraceRequest`](ghostship::analysis::TraceRequest)) → load the atmosphere, trace the fan,
//! print the report (JSON or CSV) and optionally write the fan + transfer plot.

use std::path::PathBuf;

use anyhow::Context;
use ghostship::analysis::{TraceReport, TraceRequest, trace_plot_png, trace_report};
use ghostship::atmosphere::{
    AtmosphereOptions, AtmosphereSource, LoadedAtmosphere, UniformIndex, load_atmosphere,
};
use ghostship::output::write_atomic;
use ghostship::refractivity::DEFAULT_WAVELENGTH_NM;
use ghostship::tracer::{StratifiedIndex, TracerConfig};

/// Most rays a fan may have.
pub const MAX_RAYS: usize = ghostship::analysis::MAX_FAN_RAYS;

/// How the report is printed on stdout.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum TraceFormat {
    /// The whole report: rays, images, horizons, trapped rays.
    Json,
    /// One row per ray of the fan, with its height at every distance.
    Csv,
}

/// Arguments of `ghostship trace`.
#[derive(Debug, clap::Args)]
pub struct TraceArgs {
    /// The atmosphere: a sounding file, a synthetic layered atmosphere (*.toml) or `us1976`.
    #[arg(long, short, value_name = "SOUNDING|ATMOSPHERE.toml|us1976")]
    pub atmosphere: String,
    /// Observer (eye) height in metres above the atmosphere's surface level.
    #[arg(long, value_name = "M")]
    pub observer_height_m: f64,
    /// Apparent elevations of the rays, in degrees: one value (0.5), a comma-separated list in
    /// strictly ascending order (-0.1,0,0.25; refused if out of order), or a fan FROM:TO:STEP
    /// (-0.4:0.6:0.001: rays at FROM, FROM+STEP, … up to TO). 1 to 100 000 rays. Every ray is
    /// reported; images and apparent horizons need a fan of at least 3 rays (with fewer, the
    /// JSON has empty `images` and `horizons` and says so in `notes`).
    #[arg(
        long,
        value_name = "DEG|DEG,DEG,...|FROM:TO:STEP",
        allow_hyphen_values = true
    )]
    pub elevation_deg: String,
    /// Ground distances of the targets in metres, comma-separated (heights of every ray are
    /// reported there; images are searched there).
    #[arg(long, value_name = "M,...", value_delimiter = ',', default_values_t = [10_000.0, 20_000.0, 30_000.0])]
    pub distance_m: Vec<f64>,
    /// Heights of the targets standing at every distance, in metres, comma-separated: the images
    /// of [0, H] are found (erect or inverted, with magnification).
    #[arg(long, value_name = "M,...", value_delimiter = ',', default_values_t = [20.0])]
    pub target_height_m: Vec<f64>,
    /// Error tolerance on the ray heights at the requested distances, in metres (the paper used
    /// 1 cm per step; the default 1 mm is the knee of the time-against-error curve, see
    /// BENCHMARKS.md).
    #[arg(long, value_name = "M", default_value_t = 1e-3)]
    pub tolerance_m: f64,
    /// Vacuum wavelength for the refractive index, in nanometres (300–1700).
    #[arg(long, value_name = "NM", default_value_t = DEFAULT_WAVELENGTH_NM)]
    pub wavelength_nm: f64,
    /// Smoothing scale of the sounding fit, in metres (0 = none). Ignored for .toml and us1976.
    #[arg(long, value_name = "M", default_value_t = 20.0)]
    pub smooth_m: f64,
    /// Which sounding of a multi-sounding IGRA2 file: "YYYY-MM-DD HH" (UTC). Default: the first.
    #[arg(long, value_name = "YYYY-MM-DD HH")]
    pub igra2_time: Option<String>,
    /// Top of the atmosphere in metres above the surface: rays above it have escaped.
    #[arg(long, value_name = "M", default_value_t = 40_000.0)]
    pub top_m: f64,
    /// Safety limit on a ray's ground distance, in metres (default: none). Rays are traced to
    /// the ground or the top; one that provably oscillates in a duct past the last target
    /// distance ends `trapped` (Bouguer's invariant). A ray stopped at this limit ends
    /// `max_distance`, its fate undecided.
    #[arg(long, value_name = "M")]
    pub max_distance_m: Option<f64>,
    /// Straight rays: refractive index 1 everywhere (no refraction), for comparison.
    #[arg(long)]
    pub straight: bool,
    /// Output on stdout.
    #[arg(long, value_enum, default_value_t = TraceFormat::Json)]
    pub format: TraceFormat,
    /// Also draw the ray fan and the transfer curves into this PNG file.
    #[arg(long, value_name = "FILE.png")]
    pub plot: Option<PathBuf>,
}

/// The rays to trace, as given on the command line.
#[derive(Debug, Clone, PartialEq)]
pub enum ElevationFan {
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
pub fn parse_elevation_fan(text: &str) -> Result<ElevationFan, String> {
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
        return Ok(ElevationFan::List(list));
    }
    let parts: Vec<&str> = text.split(':').collect();
    let [from, to, step] = parts.as_slice() else {
        return Err(format!(
            "elevation fan {text:?} is not FROM:TO:STEP in degrees (e.g. \"-0.4:0.6:0.001\")"
        ));
    };
    let num = |name: &str, s: &str| {
        s.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("elevation fan {text:?}: {name} {s:?} is not a number"))
    };
    let (from, to, step) = (num("FROM", from)?, num("TO", to)?, num("STEP", step)?);
    if step <= 0.0 {
        return Err(format!("elevation fan {text:?}: STEP must be > 0"));
    }
    if to < from {
        return Err(format!("elevation fan {text:?}: TO must not be below FROM"));
    }
    if !(inside(from) && inside(to)) {
        return Err(format!(
            "elevation fan {text:?}: elevations must lie strictly between -90° and 90°"
        ));
    }
    // A relative slack so that 0.6 reached by steps of 0.001 counts despite rounding.
    let intervals = ((to - from) / step * (1.0 + 1e-9)).floor();
    if intervals + 1.0 > MAX_RAYS as f64 {
        return Err(format!(
            "elevation fan {text:?} has {} rays; at most {MAX_RAYS} are allowed (use a larger STEP)",
            intervals + 1.0
        ));
    }
    let count = intervals as usize + 1;
    Ok(ElevationFan::Range {
        from_deg: from,
        to_deg: from + (count - 1) as f64 * step,
        count,
    })
}

/// Validated options of `trace` (also built by pipeline jobs).
#[derive(Debug, Clone, PartialEq)]
pub struct TraceOptions {
    /// What to load.
    pub source: AtmosphereSource,
    /// How to load it.
    pub atmosphere: AtmosphereOptions,
    /// What to trace.
    pub request: TraceRequest,
    /// Trace through n ≡ 1 instead of the atmosphere.
    pub straight: bool,
}

impl TraceOptions {
    /// Build and check the request from its parts; `elevation_deg` is what
    /// [`parse_elevation_fan`] reads (one value, an ascending list or `FROM:TO:STEP`).
    #[allow(clippy::too_many_arguments)] // one argument per request field
    pub fn new(
        source: AtmosphereSource,
        atmosphere: AtmosphereOptions,
        observer_height_m: f64,
        elevation_deg: &str,
        mut distances_m: Vec<f64>,
        target_heights_m: Vec<f64>,
        tracer: TracerConfig,
        straight: bool,
    ) -> anyhow::Result<Self> {
        let fan = parse_elevation_fan(elevation_deg).map_err(anyhow::Error::msg)?;
        if !(observer_height_m.is_finite() && observer_height_m >= 0.0) {
            anyhow::bail!("observer height {observer_height_m} m must be ≥ 0 m above the surface");
        }
        if distances_m.is_empty() {
            anyhow::bail!("give at least one target distance");
        }
        distances_m.sort_by(f64::total_cmp);
        let (elevation_min_deg, elevation_max_deg, elevation_count, elevations_deg) = match fan {
            ElevationFan::Range {
                from_deg,
                to_deg,
                count,
            } => (from_deg, to_deg, count, Vec::new()),
            ElevationFan::List(list) => {
                let (lo, hi) = (list[0], list[list.len() - 1]);
                (lo, hi, list.len(), list)
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
            wavelength_nm: atmosphere.wavelength_nm,
            tracer,
        };
        request.validate()?;
        if observer_height_m >= request.tracer.top_m {
            anyhow::bail!(
                "observer height {observer_height_m} m is not below the top of the atmosphere ({} m)",
                request.tracer.top_m
            );
        }
        Ok(TraceOptions {
            source,
            atmosphere,
            request,
            straight,
        })
    }
}

/// Trace `options.request` through `atm` (or through n ≡ 1 when `options.straight`); with
/// `plot`, also draw the fan and transfer curves as PNG bytes.
pub fn trace_products(
    atm: &LoadedAtmosphere,
    options: &TraceOptions,
    plot: bool,
) -> anyhow::Result<(TraceReport, Option<Vec<u8>>)> {
    let index: &dyn StratifiedIndex = if options.straight {
        &UniformIndex
    } else {
        &atm.refractive
    };
    let report = trace_report(index, &options.request)
        .with_context(|| format!("cannot trace through {}", atm.source))?;
    let png = if plot {
        Some(
            trace_plot_png(index, &options.request, &report)
                .with_context(|| format!("cannot plot the trace through {}", atm.source))?,
        )
    } else {
        None
    };
    Ok((report, png))
}

/// Run `ghostship trace`.
pub fn run(args: TraceArgs, quiet: bool) -> anyhow::Result<()> {
    let tracer = TracerConfig {
        tolerance_m: args.tolerance_m,
        top_m: args.top_m,
        max_distance_m: args.max_distance_m,
        ..TracerConfig::default()
    };
    let options = TraceOptions::new(
        AtmosphereSource::parse(&args.atmosphere),
        AtmosphereOptions {
            smooth_m: args.smooth_m,
            wavelength_nm: args.wavelength_nm,
            igra2_time: args.igra2_time,
        },
        args.observer_height_m,
        &args.elevation_deg,
        args.distance_m,
        args.target_height_m,
        tracer,
        args.straight,
    )?;
    let atm = load_atmosphere(&options.source, &options.atmosphere)?;
    let (report, png) = trace_products(&atm, &options, args.plot.is_some())?;
    let text = match args.format {
        TraceFormat::Json => report.to_json()? + "\n",
        TraceFormat::Csv => String::from_utf8_lossy(&report.rays_csv()?).into_owned(),
    };
    super::print_stdout(&text)?;
    if let (Some(path), Some(png)) = (&args.plot, png) {
        write_atomic(path, &png)?;
        if !quiet {
            eprintln!("wrote {}", path.display());
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rays(text: &str) -> usize {
        match parse_elevation_fan(text).unwrap() {
            ElevationFan::Range { count, .. } => count,
            ElevationFan::List(v) => v.len(),
        }
    }

    #[test]
    fn fan_spec() {
        let ElevationFan::Range {
            from_deg,
            to_deg,
            count,
        } = parse_elevation_fan("-0.4:0.6:0.001").unwrap()
        else {
            panic!("a range")
        };
        assert_eq!((from_deg, count), (-0.4, 1001));
        assert!((to_deg - 0.6).abs() < 1e-12);
        let ElevationFan::Range { to_deg, count, .. } = parse_elevation_fan("0:1:0.3").unwrap()
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
            assert!(parse_elevation_fan(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn single_elevations_and_lists() {
        assert_eq!(
            parse_elevation_fan("0.5").unwrap(),
            ElevationFan::List(vec![0.5])
        );
        assert_eq!(
            parse_elevation_fan("-0.1,0, 0.25").unwrap(),
            ElevationFan::List(vec![-0.1, 0.0, 0.25])
        );
        let err = parse_elevation_fan("0.2,0.1").unwrap_err();
        assert!(err.contains("ascending"), "{err}");
        let err = parse_elevation_fan("0.1,0.1").unwrap_err();
        assert!(err.contains("ascending"), "{err}");
        for bad in ["", "0.1,", "x", "0.1,,0.2", "95", "nan", "inf"] {
            assert!(parse_elevation_fan(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn a_list_becomes_the_request_fan() {
        let options = TraceOptions::new(
            AtmosphereSource::Us1976,
            AtmosphereOptions::default(),
            10.0,
            "-0.1,0,0.25",
            vec![1000.0],
            vec![20.0],
            TracerConfig::default(),
            false,
        )
        .unwrap();
        assert_eq!(options.request.elevations_deg(), vec![-0.1, 0.0, 0.25]);
    }
}
