//! `ghostship profile`: arguments → [`ProfileRequest`] → its products (through the jobs layer)
//! → the summary on stdout and `profile.csv`, `layers.json`, `profile.png` (and, for a sounding,
//! `fitted_layers.toml`) in the output folder.

use std::path::{Path, PathBuf};

use ghostship::atmosphere::{AtmosphereOptions, AtmosphereSource};
use ghostship::jobs::cache::AtmosphereRequest;
use ghostship::jobs::profile::{DEFAULT_LAYERS_TOP_M, DEFAULT_PLOT_TOP_M};
use ghostship::jobs::{AtmosphereCache, ProfileRequest};
use ghostship::profile::TemperatureFit;
use ghostship::refractivity::DEFAULT_WAVELENGTH_NM;
use ghostship::report::{summary_json, summary_text};

/// How the summary is printed on stdout.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SummaryFormat {
    /// Readable text: surface air, inversions, ducts, refractive layers.
    Table,
    /// The same as JSON (the content of layers.json).
    Json,
}

/// `--fit`: `pchip`, `linear` or `auto`.
pub(super) fn parse_fit(text: &str) -> Result<TemperatureFit, String> {
    text.parse()
}

/// The options shaping an atmosphere, shared by `profile` and `trace`.
#[derive(Debug, Clone, clap::Args)]
pub struct AtmosphereArgs {
    /// Vacuum wavelength for the refractive index, in nanometres (300–1700).
    #[arg(long, value_name = "NM", default_value_t = DEFAULT_WAVELENGTH_NM)]
    pub wavelength_nm: f64,
    /// Smoothing scale of the sounding fit, in metres (half-width of the local-linear smoother
    /// applied to temperature and humidity; 0 = none). Ignored for .toml and us1976.
    #[arg(long, value_name = "M", default_value_t = 20.0)]
    pub smooth_m: f64,
    /// Temperature between sounding levels: `pchip` (monotone cubic in height, for dense 1-s
    /// ascents), `linear` (linear in ln p, what significant levels are chosen for) or `auto`
    /// (linear when the median level spacing in the lowest 3 km exceeds 25 m, else pchip).
    /// Ignored for .toml and us1976.
    #[arg(long, value_name = "pchip|linear|auto", default_value = "auto", value_parser = parse_fit)]
    pub fit: TemperatureFit,
    /// Which sounding of a file holding several (IGRA2, a Wyoming TEXT:LIST page) to read:
    /// nominal date and hour (UTC), "YYYY-MM-DD HH" or "YYYY-MM-DDTHH:00Z". Default: the first.
    #[arg(long = "time", visible_aliases = ["sounding-time"], alias = "igra2-time", value_name = "YYYY-MM-DD HH")]
    pub sounding_time: Option<String>,
    /// Refuse a sounding whose levels contradict each other (height not increasing, pressure
    /// increasing) within 3 km of its lowest level, instead of dropping those levels with a note.
    #[arg(long)]
    pub strict: bool,
}

impl AtmosphereArgs {
    /// The atmosphere request for `source` with these options.
    pub fn request(&self, source: &str) -> AtmosphereRequest {
        AtmosphereRequest {
            source: AtmosphereSource::parse(source),
            options: AtmosphereOptions {
                smooth_m: self.smooth_m,
                fit: self.fit,
                wavelength_nm: self.wavelength_nm,
                sounding_time: self.sounding_time.clone(),
                strict: self.strict,
            },
        }
    }
}

/// Arguments of `ghostship profile`.
#[derive(Debug, clap::Args)]
pub struct ProfileArgs {
    /// The atmosphere: a sounding file (normalised CSV, Wyoming TEXT:LIST/TEXT:CSV, IGRA2), a
    /// synthetic layered atmosphere (*.toml), or `us1976`.
    #[arg(value_name = "SOUNDING|ATMOSPHERE.toml|us1976")]
    pub input: String,
    /// How to build the atmosphere.
    #[command(flatten)]
    pub atmosphere: AtmosphereArgs,
    /// Folder for profile.csv, layers.json and profile.png (relative to the current folder)
    /// [default: out/profile/<input file stem>/ (out/profile/us1976/ for us1976)].
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Summary printed on stdout.
    #[arg(long, value_enum, default_value_t = SummaryFormat::Table)]
    pub format: SummaryFormat,
    /// Top of profile.png's height axis, in metres above the surface.
    #[arg(long, value_name = "M", default_value_t = DEFAULT_PLOT_TOP_M)]
    pub plot_top_m: f64,
    /// Inversions, ducts and refractive layers are searched from the surface up to this many
    /// metres above it (and never above the highest sounding level).
    #[arg(long, value_name = "M", default_value_t = DEFAULT_LAYERS_TOP_M)]
    pub layers_top_m: f64,
}

/// Run `ghostship profile`.
pub fn run(args: ProfileArgs, quiet: bool) -> anyhow::Result<()> {
    let request = ProfileRequest::new(
        args.atmosphere.request(&args.input),
        args.plot_top_m,
        args.layers_top_m,
    )?;
    let out_dir = args.out.clone().unwrap_or_else(|| {
        Path::new("out")
            .join("profile")
            .join(request.atmosphere.source.stem())
    });
    let atm = AtmosphereCache::new().get(&request.atmosphere)?;
    let products = request.products(&atm)?;
    let text = match args.format {
        SummaryFormat::Table => {
            let summary = summary_text(&products.report);
            let mut text = format!("{}\n{}\n", atm.description, summary.trim_end());
            if let Some(line) = products.layer_fit_line() {
                text.push_str(&format!("{line}\n"));
            }
            for w in atm.sounding.iter().flat_map(|s| &s.warnings) {
                text.push_str(&format!("Ingest note: {w}\n"));
            }
            text
        }
        SummaryFormat::Json => {
            let json = summary_json(&products.report);
            format!("{}\n", String::from_utf8_lossy(&json).trim_end())
        }
    };
    super::print_stdout(&text)?;
    super::write_into(&out_dir, &products.into_products(), quiet)
}
