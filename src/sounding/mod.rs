//! Stage 1 — ingest. In: a sounding file (normalised CSV, University of Wyoming TEXT:LIST or
//! TEXT:CSV, IGRA2 data or derived). Out: a validated [`Sounding`]: levels sorted by height, in SI
//! units, with every level carrying a height (measured or hypsometric) and its source line.

use std::collections::BTreeMap;
use std::path::PathBuf;

/// Where a level's height came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum HeightSource {
    /// Reported in the file.
    Measured,
    /// Computed from pressure and temperature with the hypsometric equation.
    Hypsometric,
}

/// One level of a sounding, in SI units.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Level {
    /// Height above mean sea level (m), as the source reports it (geopotential for most formats).
    pub height_m: f64,
    /// Pressure (Pa), if known.
    pub pressure_pa: Option<f64>,
    /// Air temperature (K).
    pub temperature_k: f64,
    /// Water-vapour partial pressure (Pa), if humidity is known (from dewpoint, RH or directly).
    pub vapour_pressure_pa: Option<f64>,
    /// Whether the height was measured or computed.
    pub height_source: HeightSource,
    /// 1-based line of the source file this level came from.
    pub line: usize,
}

/// The file format a sounding was read from (detected from content).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SoundingFormat {
    /// ghostship's normalised CSV (`pressure_hpa,height_m,temperature_c,dewpoint_c`, `#` metadata).
    NormalizedCsv,
    /// University of Wyoming TEXT:LIST.
    WyomingTextList,
    /// University of Wyoming TEXT:CSV.
    WyomingTextCsv,
    /// IGRA version 2 sounding data file.
    Igra2Data,
    /// IGRA version 2 derived-parameter file.
    Igra2Derived,
}

/// A validated sounding.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Sounding {
    /// The file it was read from (or a description for in-memory soundings).
    pub source: PathBuf,
    /// Detected format.
    pub format: SoundingFormat,
    /// `key: value` metadata (station, latitude, longitude, station_elevation_m, launch time …),
    /// as given in the file.
    pub metadata: BTreeMap<String, String>,
    /// Levels, strictly increasing in height.
    pub levels: Vec<Level>,
}

impl Sounding {
    /// The lowest level (the surface, for a sounding launched from the ground).
    pub fn surface(&self) -> &Level {
        &self.levels[0]
    }
}
