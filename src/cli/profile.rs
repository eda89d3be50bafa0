//! `ghostship profile`: arguments → [`ProfileOptions`] → load the atmosphere, find its layers,
//! print the summary and write `profile.csv`, `layers.json` and `profile.png`.

use std::path::{Path, PathBuf};

use anyhow::Context;
use ghostship::atmosphere::{
    AtmosphereOptions, AtmosphereSource, LoadedAtmosphere, load_atmosphere,
};
use ghostship::output::write_atomic;
use ghostship::profile::{InversionOptions, detect_inversions};
use ghostship::refractivity::{DEFAULT_WAVELENGTH_NM, RegimeOptions, detect_regimes};
use ghostship::report::{
    LayersReport, PlotOptions, ProfileGrid, ProfilePlot, layers_json, profile_csv, profile_png,
    summary_json, summary_text,
};

/// Default top of profile.png's height axis (m above the surface): where mirage layers live.
pub const DEFAULT_PLOT_TOP_M: f64 = 1_500.0;
/// Default top of the layer search (m above the surface).
pub const DEFAULT_LAYERS_TOP_M: f64 = 10_000.0;

/// How the summary is printed on stdout.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SummaryFormat {
    /// Readable text: surface air, inversions, ducts, refractive layers.
    Table,
    /// The same as JSON (the content of layers.json).
    Json,
}

/// Arguments of `ghostship profile`.
#[derive(Debug, clap::Args)]
pub struct ProfileArgs {
    /// The atmosphere: a sounding file (normalised CSV, Wyoming TEXT:LIST/TEXT:CSV, IGRA2), a
    /// synthetic layered atmosphere (*.toml), or `us1976`.
    #[arg(value_name = "SOUNDING|ATMOSPHERE.toml|us1976")]
    pub input: String,
    /// Vacuum wavelength for the refractive index, in nanometres (300–1700).
    #[arg(long, value_name = "NM", default_value_t = DEFAULT_WAVELENGTH_NM)]
    pub wavelength_nm: f64,
    /// Smoothing scale of the sounding fit, in metres (half-width of the local-linear smoother
    /// applied to temperature and humidity; 0 = none). Ignored for .toml and us1976.
    #[arg(long, value_name = "M", default_value_t = 20.0)]
    pub smooth_m: f64,
    /// Which sounding of a multi-sounding IGRA2 file to read: nominal date and hour (UTC),
    /// "YYYY-MM-DD HH". Default: the first in the file.
    #[arg(long, value_name = "YYYY-MM-DD HH")]
    pub igra2_time: Option<String>,
    /// Folder for profile.csv, layers.json and profile.png
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

/// Validated options of `profile` (also built by pipeline jobs).
#[derive(Debug, Clone, PartialEq)]
pub struct ProfileOptions {
    /// What to load.
    pub source: AtmosphereSource,
    /// How to load it.
    pub atmosphere: AtmosphereOptions,
    /// Top of the plot (m above the surface).
    pub plot_top_agl_m: f64,
    /// Top of the layer search (m above the surface).
    pub layers_top_agl_m: f64,
}

impl ProfileOptions {
    /// Check the numbers that the library would otherwise reject later with less context.
    pub fn validate(&self) -> anyhow::Result<()> {
        if !(self.plot_top_agl_m.is_finite() && self.plot_top_agl_m > 0.0) {
            anyhow::bail!(
                "--plot-top-m must be a height > 0 m above the surface (got {})",
                self.plot_top_agl_m
            );
        }
        if !(self.layers_top_agl_m.is_finite() && self.layers_top_agl_m > 0.0) {
            anyhow::bail!(
                "--layers-top-m must be a height > 0 m above the surface (got {})",
                self.layers_top_agl_m
            );
        }
        Ok(())
    }
}

/// The `profile` command's products, as bytes (nothing written yet).
pub struct ProfileProducts {
    /// The layers report (summary text and JSON are made from it).
    pub report: LayersReport,
    /// `profile.csv`.
    pub csv: Vec<u8>,
    /// `layers.json`.
    pub json: Vec<u8>,
    /// `profile.png`.
    pub png: Vec<u8>,
}

/// Find the layers of `atm` and make every product of the `profile` command.
pub fn profile_products(
    atm: &LoadedAtmosphere,
    options: &ProfileOptions,
) -> anyhow::Result<ProfileProducts> {
    let surface_m = atm.refractive.surface_height_m();
    let mut top_m = surface_m + options.layers_top_agl_m;
    if let Some(top_of_data) = atm.top_of_data_m {
        top_m = top_m.min(top_of_data);
    }
    let inversions = detect_inversions(atm.column.as_ref(), top_m, &InversionOptions::default());
    let regimes = detect_regimes(&atm.refractive, top_m, &RegimeOptions::default());
    let report = LayersReport::new(&atm.refractive, &inversions, &regimes);
    let csv = profile_csv(&atm.refractive, &ProfileGrid::default());
    let json = layers_json(&report);
    let levels = atm
        .sounding
        .as_ref()
        .map(|s| s.levels.as_slice())
        .unwrap_or(&[]);
    let title = atm.description.clone();
    let plot = ProfilePlot {
        atmosphere: &atm.refractive,
        levels,
        inversions: &inversions,
        regimes: &regimes,
        title: &title,
    };
    let plot_options = PlotOptions {
        top_agl_m: options.plot_top_agl_m,
        ..PlotOptions::default()
    };
    let png = profile_png(&plot, &plot_options)
        .with_context(|| format!("cannot draw the profile plot of {}", atm.source))?;
    Ok(ProfileProducts {
        report,
        csv,
        json,
        png,
    })
}

/// Write the products into `dir` (created if needed); returns the files written.
pub fn write_profile(dir: &Path, products: &ProfileProducts) -> anyhow::Result<Vec<PathBuf>> {
    let files = [
        ("profile.csv", &products.csv),
        ("layers.json", &products.json),
        ("profile.png", &products.png),
    ];
    let mut written = Vec::new();
    for (name, bytes) in files {
        let path = dir.join(name);
        write_atomic(&path, bytes)?;
        written.push(path);
    }
    Ok(written)
}

/// Run `ghostship profile`.
pub fn run(args: ProfileArgs, quiet: bool) -> anyhow::Result<()> {
    let source = AtmosphereSource::parse(&args.input);
    let out_dir = args
        .out
        .clone()
        .unwrap_or_else(|| Path::new("out").join("profile").join(source.stem()));
    let options = ProfileOptions {
        source,
        atmosphere: AtmosphereOptions {
            smooth_m: args.smooth_m,
            wavelength_nm: args.wavelength_nm,
            igra2_time: args.igra2_time,
        },
        plot_top_agl_m: args.plot_top_m,
        layers_top_agl_m: args.layers_top_m,
    };
    options.validate()?;
    let atm = load_atmosphere(&options.source, &options.atmosphere)?;
    let products = profile_products(&atm, &options)?;
    let text = match args.format {
        SummaryFormat::Table => {
            let summary = summary_text(&products.report);
            let mut text = format!("{}\n{}\n", atm.description, summary.trim_end());
            if let Some(s) = &atm.sounding {
                for w in &s.warnings {
                    text.push_str(&format!("Ingest note: {w}\n"));
                }
            }
            text
        }
        SummaryFormat::Json => {
            let json = summary_json(&products.report);
            format!("{}\n", String::from_utf8_lossy(&json).trim_end())
        }
    };
    super::print_stdout(&text)?;
    let written = write_profile(&out_dir, &products)?;
    if !quiet {
        for path in written {
            eprintln!("wrote {}", path.display());
        }
    }
    Ok(())
}
