//! Stages 1–3 in one call — the atmosphere resolver every command uses. In: what the user named
//! (a sounding file, a synthetic atmosphere TOML or `us1976`) and the options that shape it
//! (smoothing scale, temperature fit, wavelength, IGRA2 launch time). Out: a [`LoadedAtmosphere`] holding the
//! sounding (if any), the air column and the [`RefractiveAtmosphere`] built on it, or one
//! [`AtmosphereError`] whose chain names the file and the place in it.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::profile::{
    AirColumn, FitOptions, Profile, StandardAtmosphere, SyntheticAtmosphere, TemperatureFit,
};
use crate::refractivity::{DEFAULT_WAVELENGTH_NM, RefractiveAtmosphere};
use crate::sounding::{ReadOptions, Sounding, read_sounding};

/// What the user named: a sounding file, a synthetic atmosphere TOML, or the standard atmosphere.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
pub enum AtmosphereSource {
    /// A radiosonde sounding (normalised CSV, Wyoming, IGRA2; the format is read from the content).
    Sounding(PathBuf),
    /// A synthetic layered atmosphere (`.toml`).
    Synthetic(PathBuf),
    /// The U.S. Standard Atmosphere 1976 (dry, surface at sea level).
    Us1976,
}

impl AtmosphereSource {
    /// `us1976` (any case) → [`Us1976`](Self::Us1976); a name ending in `.toml` (any case) →
    /// [`Synthetic`](Self::Synthetic); anything else → [`Sounding`](Self::Sounding).
    pub fn parse(text: &str) -> Self {
        let trimmed = text.trim();
        if trimmed.eq_ignore_ascii_case("us1976") {
            return AtmosphereSource::Us1976;
        }
        let path = PathBuf::from(text);
        let is_toml = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("toml"));
        if is_toml {
            AtmosphereSource::Synthetic(path)
        } else {
            AtmosphereSource::Sounding(path)
        }
    }

    /// The file behind the source, if any.
    pub fn path(&self) -> Option<&Path> {
        match self {
            AtmosphereSource::Sounding(p) | AtmosphereSource::Synthetic(p) => Some(p),
            AtmosphereSource::Us1976 => None,
        }
    }

    /// A short name for output folders: the file stem, or `us1976`.
    pub fn stem(&self) -> String {
        match self.path() {
            Some(p) => p
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .filter(|s| !s.is_empty())
                .unwrap_or_else(|| "atmosphere".into()),
            None => "us1976".into(),
        }
    }
}

impl std::fmt::Display for AtmosphereSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.path() {
            Some(p) => write!(f, "{}", p.display()),
            None => f.write_str("us1976"),
        }
    }
}

/// How to build the atmosphere.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AtmosphereOptions {
    /// Smoothing scale of the sounding fit (m); see [`FitOptions::smooth_m`]. Ignored for
    /// synthetic and standard atmospheres.
    pub smooth_m: f64,
    /// How the sounding's temperature is interpolated between levels; see
    /// [`FitOptions::temperature_fit`]. Ignored for synthetic and standard atmospheres. Always
    /// serialised: it is part of a pipeline job's key, and `auto` changed what earlier runs
    /// computed for significant-level soundings.
    pub fit: TemperatureFit,
    /// Vacuum wavelength the refractive index is computed for (nm, 300–1700).
    pub wavelength_nm: f64,
    /// Which sounding of a multi-sounding IGRA2 file (`"YYYY-MM-DD HH"`); `None`: the first.
    pub sounding_time: Option<String>,
    /// Refuse a sounding whose levels contradict each other in the lowest kilometres instead of
    /// dropping the offending levels (see [`ReadOptions::strict`]).
    #[serde(skip_serializing_if = "std::ops::Not::not", default)]
    pub strict: bool,
}

impl AtmosphereOptions {
    /// Check the wavelength (300–1700 nm) and the smoothing scale (finite, ≥ 0 m).
    pub fn validate(&self) -> Result<(), AtmosphereError> {
        let (lo, hi) = crate::refractivity::WAVELENGTH_RANGE_NM;
        if !(self.wavelength_nm >= lo && self.wavelength_nm <= hi) {
            return Err(AtmosphereError::InvalidOption(format!(
                "wavelength {} nm (wavelength_nm) is outside {lo}–{hi} nm",
                self.wavelength_nm
            )));
        }
        if !(self.smooth_m.is_finite() && self.smooth_m >= 0.0) {
            return Err(AtmosphereError::InvalidOption(format!(
                "smoothing scale {} m (smooth_m) must be finite and ≥ 0",
                self.smooth_m
            )));
        }
        Ok(())
    }

    /// The options of the sounding fit these options ask for.
    pub fn fit_options(&self) -> FitOptions {
        FitOptions {
            smooth_m: self.smooth_m,
            temperature_fit: self.fit,
            ..FitOptions::default()
        }
    }
}

impl Default for AtmosphereOptions {
    /// The fit's default smoothing (20 m) and temperature fit (auto), 550 nm, the first IGRA2
    /// sounding.
    fn default() -> Self {
        AtmosphereOptions {
            smooth_m: FitOptions::default().smooth_m,
            fit: TemperatureFit::Auto,
            wavelength_nm: DEFAULT_WAVELENGTH_NM,
            sounding_time: None,
            strict: false,
        }
    }
}

/// An atmosphere ready for the report, the tracer and the renderer.
pub struct LoadedAtmosphere {
    /// What it was loaded from.
    pub source: AtmosphereSource,
    /// The sounding, for measured atmospheres.
    pub sounding: Option<Sounding>,
    /// The fitted profile, for measured atmospheres (the same as `column`).
    pub profile: Option<Arc<Profile>>,
    /// The air column (fitted profile, synthetic layers or standard atmosphere).
    pub column: Arc<dyn AirColumn>,
    /// n(h) and dn/dh on the column.
    pub refractive: RefractiveAtmosphere,
    /// Height of the highest sounding level (m above mean sea level); `None` for model
    /// atmospheres (defined everywhere).
    pub top_of_data_m: Option<f64>,
    /// One line saying what this is (station and launch time, the TOML's description, …).
    pub description: String,
}

impl std::fmt::Debug for LoadedAtmosphere {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LoadedAtmosphere")
            .field("source", &self.source)
            .field("description", &self.description)
            .field("top_of_data_m", &self.top_of_data_m)
            .field("refractive", &self.refractive)
            .finish_non_exhaustive()
    }
}

/// Why an atmosphere could not be loaded. The source (the stage's own error) names the file and
/// says where in it and what, so the messages of the file stages do not repeat the file name.
#[derive(Debug, thiserror::Error)]
pub enum AtmosphereError {
    /// The options are out of range.
    #[error("invalid atmosphere option: {0}")]
    InvalidOption(String),
    /// The sounding could not be read.
    #[error("cannot load the atmosphere")]
    Sounding {
        /// The source as the user named it.
        source_name: String,
        /// Why (file, line, column).
        #[source]
        source: crate::sounding::SoundingError,
    },
    /// The sounding could not be fitted, or the synthetic atmosphere is invalid.
    #[error("cannot load the atmosphere")]
    Profile {
        /// The source as the user named it.
        source_name: String,
        /// Why.
        #[source]
        source: crate::profile::ProfileError,
    },
    /// The refractive index cannot be computed on the column.
    #[error("cannot compute the refractive index of atmosphere {source_name}")]
    Refractivity {
        /// The source as the user named it.
        source_name: String,
        /// Why.
        #[source]
        source: crate::refractivity::RefractivityError,
    },
}

/// Read, fit and refract the atmosphere `source` names.
pub fn load_atmosphere(
    source: &AtmosphereSource,
    options: &AtmosphereOptions,
) -> Result<LoadedAtmosphere, AtmosphereError> {
    options.validate()?;
    let source_name = source.to_string();
    let (sounding, profile, column, description): (
        Option<Sounding>,
        Option<Arc<Profile>>,
        Arc<dyn AirColumn>,
        String,
    ) = match source {
        AtmosphereSource::Sounding(path) => {
            let read = ReadOptions {
                sounding_time: options.sounding_time.clone(),
                strict: options.strict,
            };
            let sounding =
                read_sounding(path, &read).map_err(|source| AtmosphereError::Sounding {
                    source_name: source_name.clone(),
                    source,
                })?;
            let profile =
                Profile::from_sounding(&sounding, &options.fit_options()).map_err(|source| {
                    AtmosphereError::Profile {
                        source_name: source_name.clone(),
                        source,
                    }
                })?;
            let description = sounding_description(&sounding);
            let profile = Arc::new(profile);
            (Some(sounding), Some(profile.clone()), profile, description)
        }
        AtmosphereSource::Synthetic(path) => {
            let synthetic = SyntheticAtmosphere::from_file(path).map_err(|source| {
                AtmosphereError::Profile {
                    source_name: source_name.clone(),
                    source,
                }
            })?;
            let description = match synthetic.description() {
                Some(d) if !d.trim().is_empty() => d.trim().to_string(),
                _ => format!("synthetic atmosphere {}", path.display()),
            };
            (None, None, Arc::new(synthetic), description)
        }
        AtmosphereSource::Us1976 => (
            None,
            None,
            Arc::new(StandardAtmosphere::default()),
            "U.S. Standard Atmosphere 1976 (dry, surface at sea level)".to_string(),
        ),
    };
    let mut loaded = atmosphere_from_column(source, column, description, options.wavelength_nm)?;
    loaded.sounding = sounding;
    loaded.top_of_data_m = profile.as_ref().map(|p| p.top_of_data_m());
    loaded.profile = profile;
    Ok(loaded)
}

/// A model atmosphere built in memory (e.g. the layers fitted to a sounding), refracted at
/// `wavelength_nm`; `source` names it in messages and outputs. No sounding, defined everywhere.
pub fn atmosphere_from_column(
    source: &AtmosphereSource,
    column: Arc<dyn AirColumn>,
    description: String,
    wavelength_nm: f64,
) -> Result<LoadedAtmosphere, AtmosphereError> {
    let refractive = RefractiveAtmosphere::new(column.clone(), wavelength_nm).map_err(|e| {
        AtmosphereError::Refractivity {
            source_name: source.to_string(),
            source: e,
        }
    })?;
    Ok(LoadedAtmosphere {
        source: source.clone(),
        sounding: None,
        column,
        refractive,
        top_of_data_m: None,
        profile: None,
        description,
    })
}

/// "station, launched time" from the sounding's metadata, or the file name. The station keeps
/// its first two `;`-separated parts (name and WMO number); the time drops parenthesised notes,
/// and NCAR/EOL's comma form (`2024, 02, 26, 11:20:12`, kept as given by normalised CSVs
/// converted from ESC files) is shown as `2024-02-26 11:20:12 UTC`.
fn sounding_description(sounding: &Sounding) -> String {
    let m = &sounding.metadata;
    let station = m
        .get("station")
        .map(|s| s.split(';').take(2).collect::<Vec<_>>().join(";"))
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty());
    let time = |key: &str| {
        m.get(key)
            .map(|s| crate::sounding::time::readable_time(s.split('(').next().unwrap_or("")))
            // A time must start with its year ("not given in this file" is no time).
            .filter(|s| s.starts_with(|c: char| c.is_ascii_digit()))
            .map(|t| {
                if t.contains("UTC") {
                    t
                } else {
                    format!("{t} UTC")
                }
            })
    };
    let name = station.unwrap_or_else(|| format!("sounding {}", sounding.source.display()));
    match (time("launch_time_utc"), time("nominal_time_utc")) {
        (Some(t), _) => format!("{name}, launched {t}"),
        (None, Some(t)) => format!("{name}, {t} (nominal)"),
        (None, None) => name,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn data(name: &str) -> PathBuf {
        PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/data")).join(name)
    }

    #[test]
    fn a_launch_time_that_is_not_a_time_falls_back_to_the_nominal_one() {
        let mut metadata = std::collections::BTreeMap::new();
        metadata.insert("station".into(), "NKX".into());
        metadata.insert(
            "launch_time_utc".into(),
            "not given in this file (valid time 2023-06-30 12 UTC)".into(),
        );
        metadata.insert("nominal_time_utc".into(), "2023-06-30 12 UTC".into());
        let s = Sounding {
            source: PathBuf::from("s.csv"),
            format: crate::sounding::SoundingFormat::NormalizedCsv,
            metadata,
            levels: Vec::new(),
            warnings: Vec::new(),
        };
        assert_eq!(sounding_description(&s), "NKX, 2023-06-30 12 UTC (nominal)");
    }

    #[test]
    fn eol_comma_times_are_shown_as_dates() {
        let sounding = |pairs: &[(&str, &str)]| Sounding {
            source: PathBuf::from("b.csv"),
            format: crate::sounding::SoundingFormat::NormalizedCsv,
            metadata: pairs
                .iter()
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect(),
            levels: Vec::new(),
            warnings: Vec::new(),
        };
        // The `#` lines of tests/data/soundings/Bjornoya-01028_2024022611.csv.
        let s = sounding(&[
            (
                "station",
                "Bjornoya (Bear Island), Norway; WMO 01028; IGRA2 SVM00001028",
            ),
            ("launch_time_utc", "2024, 02, 26, 11:20:12"),
            ("nominal_time_utc", "2024, 02, 26, 12:00:00"),
        ]);
        assert_eq!(
            sounding_description(&s),
            "Bjornoya (Bear Island), Norway; WMO 01028, launched 2024-02-26 11:20:12 UTC"
        );
        let s = sounding(&[("nominal_time_utc", "2024, 02, 26, 12:00:00 (nominal)")]);
        assert_eq!(
            sounding_description(&s),
            "sounding b.csv, 2024-02-26 12:00:00 UTC (nominal)"
        );
        // Other spellings are kept, with "UTC" added when absent.
        let s = sounding(&[("station", "X"), ("launch_time_utc", "2026-02-05 23:29")]);
        assert_eq!(sounding_description(&s), "X, launched 2026-02-05 23:29 UTC");
    }

    #[test]
    fn parse_names() {
        assert_eq!(AtmosphereSource::parse("US1976"), AtmosphereSource::Us1976);
        assert_eq!(
            AtmosphereSource::parse("a/b.TOML"),
            AtmosphereSource::Synthetic("a/b.TOML".into())
        );
        assert_eq!(
            AtmosphereSource::parse("x.csv"),
            AtmosphereSource::Sounding("x.csv".into())
        );
        assert_eq!(AtmosphereSource::parse("x.csv").stem(), "x");
        assert_eq!(AtmosphereSource::Us1976.stem(), "us1976");
    }

    #[test]
    fn loads_each_kind() {
        let opts = AtmosphereOptions::default();
        let s = load_atmosphere(
            &AtmosphereSource::Sounding(data("Utqiagvik-70026_2026020600_all-levels.csv")),
            &opts,
        )
        .unwrap();
        assert!(s.sounding.is_some());
        // The data README: surface at 12 m (station elevation).
        assert!((s.refractive.surface_height_m() - 12.0).abs() < 1e-9);
        assert!(s.top_of_data_m.unwrap() > 1000.0);
        let t = load_atmosphere(
            &AtmosphereSource::Synthetic(data("superior_mirage.toml")),
            &opts,
        )
        .unwrap();
        assert!(t.sounding.is_none() && t.top_of_data_m.is_none());
        assert!(
            t.description.contains("superior mirage"),
            "{}",
            t.description
        );
        let u = load_atmosphere(&AtmosphereSource::Us1976, &opts).unwrap();
        // US1976 at sea level: 288.15 K (the standard's defining value).
        let air = u.column.air_at(0.0);
        assert!((air.temperature_k - 288.15).abs() < 1e-9);
    }

    #[test]
    fn errors_name_the_file_and_line() {
        let dir = tempfile::tempdir().unwrap();
        let bad = dir.path().join("bad.csv");
        std::fs::write(
            &bad,
            "pressure_hpa,height_m,temperature_c,dewpoint_c\n1000,10,abc,\n990,100,-5,\n980,200,-6,\n",
        )
        .unwrap();
        let err = load_atmosphere(
            &AtmosphereSource::Sounding(bad.clone()),
            &AtmosphereOptions::default(),
        )
        .unwrap_err();
        let chain = format!("{:#}", anyhow::Error::new(err));
        assert!(chain.contains("cannot load the atmosphere"), "{chain}");
        // The file is named once, by the stage that read it.
        assert_eq!(chain.matches("bad.csv").count(), 1, "{chain}");
        assert!(chain.contains("line 2"), "{chain}");
        let err = load_atmosphere(
            &AtmosphereSource::Sounding(dir.path().join("missing.csv")),
            &AtmosphereOptions::default(),
        )
        .unwrap_err();
        assert!(format!("{:#}", anyhow::Error::new(err)).contains("missing.csv"));
        let err = load_atmosphere(
            &AtmosphereSource::Us1976,
            &AtmosphereOptions {
                wavelength_nm: 100.0,
                ..Default::default()
            },
        )
        .unwrap_err();
        assert!(err.to_string().contains("wavelength"), "{err}");
    }
}
