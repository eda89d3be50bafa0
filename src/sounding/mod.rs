//! Stage 1 — ingest. In: a sounding file (normalised CSV, University of Wyoming TEXT:LIST or
//! TEXT:CSV, IGRA2 data or derived, SPC / SHARPpy `%RAW%`, NCAR/EOL ESC, WMO FM-35 TEMP). Out: a
//! validated [`Sounding`]: levels sorted by height, in SI
//! units, with every level carrying a height (measured or hypsometric) and its source line.
//!
//! Entry points: [`read_sounding`] (a file, plain, gzip or a one-file zip) and [`parse_sounding`]
//! (text already in memory). Files holding several soundings (IGRA2, Wyoming pages) give the one
//! chosen by [`ReadOptions::sounding_time`] (canonical form in [`time`]). The
//! format is detected from the content, never from the extension: IGRA2 header record first →
//! IGRA2 data or derived; a `PRES HGHT TEMP` table header → Wyoming TEXT:LIST; `%TITLE%` then
//! `%RAW%` lines → SPC / SHARPpy; a `Data Type:` line then a `Time Press Temp` column line →
//! NCAR/EOL ESC; a `TTAA` group followed by `YYGGId` → WMO TEMP; a CSV header with a
//! temperature column → Wyoming TEXT:CSV (has `time` and `geopotential height_m`) or normalised
//! CSV. Before any of these, a netCDF magic number ([`is_netcdf`]) sends the bytes to the
//! `netcdf` reader (cargo feature `netcdf`; without it, [`SoundingError::NetcdfNotBuilt`]).
//! Readers live in [`csv`], [`wyoming`], [`igra2`], [`spc`], [`esc`] and [`temp`]; the rules
//! every sounding must pass
//! are in [`validate`]; heights for pressure-only levels come from [`hypsometric`].

pub mod csv;
pub mod error;
pub mod esc;
pub mod hypsometric;
pub mod igra2;
#[cfg(feature = "netcdf")]
pub mod netcdf;
pub mod spc;
pub mod temp;
pub mod time;
pub mod validate;
pub mod wyoming;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

pub use error::SoundingError;

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
    /// 1-based line of the source file this level came from (for netCDF: the 1-based record,
    /// the index along the `time` dimension).
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
    /// SPC / SHARPpy `%TITLE%` / `%RAW%` text.
    SpcRaw,
    /// NCAR/EOL ESC (EOL Sounding Composite) text, `*.cls` / `*.cls.qc`.
    EolEsc,
    /// A WMO FM-35 TEMP message (`TTAA` / `TTBB` / `TTCC` / `TTDD` parts).
    WmoTemp,
    /// A netCDF sounding (ARM `sondewnpn`, GRUAN RS92/RS41 GDP); binary, read only by a build
    /// with the cargo feature `netcdf`.
    Netcdf,
}

impl SoundingFormat {
    /// The format's name for messages, e.g. "a University of Wyoming TEXT:LIST page".
    pub fn description(self) -> &'static str {
        match self {
            SoundingFormat::NormalizedCsv => "a normalised CSV",
            SoundingFormat::WyomingTextList => "a University of Wyoming TEXT:LIST page",
            SoundingFormat::WyomingTextCsv => "a University of Wyoming TEXT:CSV file",
            SoundingFormat::Igra2Data => "an IGRA2 data file",
            SoundingFormat::Igra2Derived => "an IGRA2 derived-parameter file",
            SoundingFormat::SpcRaw => "an SPC / SHARPpy %RAW% file",
            SoundingFormat::EolEsc => "an NCAR/EOL ESC sounding",
            SoundingFormat::WmoTemp => "a WMO FM-35 TEMP message",
            SoundingFormat::Netcdf => "an ARM sondewnpn or GRUAN GDP netCDF sounding",
        }
    }
}

/// A validated sounding.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Sounding {
    /// The file it was read from (or a description for in-memory soundings).
    pub source: PathBuf,
    /// Detected format.
    pub format: SoundingFormat,
    /// `key: value` metadata (station, latitude, longitude, station_elevation_m, launch time …),
    /// as given in the file. Keys every reader uses where the format has the information:
    /// `station`, `latitude`, `longitude` (degrees), `station_elevation_m`, `launch_time_utc`,
    /// `nominal_time_utc`; normalised CSVs keep all their `# key: value` lines, Wyoming TEXT:LIST
    /// its station block (snake_case keys), IGRA2 its header fields.
    pub metadata: BTreeMap<String, String>,
    /// Levels, strictly increasing in height.
    pub levels: Vec<Level>,
    /// What ingest skipped, merged or dropped (one line per kind, with the source lines), e.g.
    /// rows without temperature or the backward steps of a 1-s ascent. Empty for a clean file.
    pub warnings: Vec<String>,
}

/// Options for reading a sounding.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ReadOptions {
    /// Which sounding of a file holding several (IGRA2, a Wyoming TEXT:LIST page) to read: its
    /// nominal date and hour (UTC),
    /// in a form [`time::canonical_time`] accepts (`"YYYY-MM-DD HH"`, `"YYYY-MM-DDTHH:00Z"`…).
    /// `None`: the first in the file. Given for a file of one sounding, it is an error.
    pub sounding_time: Option<String>,
    /// Refuse the sounding when two levels within [`validate::STRICT_ZONE_M`] of the lowest
    /// contradict each other (height not increasing, pressure increasing, a duplicate with other
    /// values). Default (`false`): such a level is dropped with a note naming its line, wherever
    /// it is; the sounding is refused only when fewer than 3 usable levels remain.
    pub strict: bool,
}

impl ReadOptions {
    /// Options choosing the sounding at `time` (`"YYYY-MM-DD HH"`) of an IGRA2 file or a
    /// Wyoming page.
    pub fn with_time(time: impl Into<String>) -> Self {
        ReadOptions {
            sounding_time: Some(time.into()),
            ..ReadOptions::default()
        }
    }

    /// These options with [`strict`](Self::strict) set to `strict`.
    pub fn strict(self, strict: bool) -> Self {
        ReadOptions { strict, ..self }
    }
}

/// The bytes of the sounding file at `path`, read with the input size limit and inflated if the
/// file is gzip or a one-file zip archive (see [`crate::input::unpack`]).
fn read_bytes(path: &Path) -> Result<(Vec<u8>, crate::input::Packing), SoundingError> {
    let io = |source| SoundingError::Io {
        path: path.to_path_buf(),
        source,
    };
    let limit = crate::input::MAX_SOUNDING_BYTES;
    let bytes = crate::input::read_limited(path, limit).map_err(io)?;
    crate::input::unpack(bytes, limit).map_err(io)
}

/// Reads and validates the sounding in the file at `path` (any supported format, detected from
/// the content). Never panics, whatever the bytes; non-UTF-8 input is a
/// [`SoundingError::NotUtf8`] naming the line, except a netCDF file (see [`is_netcdf`]), which
/// is read when ghostship is built with the feature `netcdf` and is otherwise a
/// [`SoundingError::NetcdfNotBuilt`]. Gzip files and one-file zip archives are read
/// inflated (metadata `packed_as`); line numbers count lines of the inflated text.
pub fn read_sounding(path: &Path, options: &ReadOptions) -> Result<Sounding, SoundingError> {
    let (bytes, packing) = read_bytes(path)?;
    // Binary netCDF before the UTF-8 check: its header is not text.
    let mut sounding = if is_netcdf(&bytes) {
        read_netcdf(&bytes, path, options)?
    } else {
        parse_sounding(utf8(&bytes, path)?, path, options)?
    };
    if let Some(how) = packing.describe() {
        // Line numbers in messages count lines of the inflated text.
        sounding.metadata.insert("packed_as".into(), how);
    }
    Ok(sounding)
}

/// The magic numbers a netCDF file starts with: classic (`CDF` 1), 64-bit offset (`CDF` 2),
/// 64-bit data (`CDF` 5) and netCDF-4, which is HDF5.
const NETCDF_MAGIC: [&[u8]; 4] = [b"CDF\x01", b"CDF\x02", b"CDF\x05", b"\x89HDF\r\n\x1a\n"];

/// Whether `bytes` start like a netCDF file (classic or netCDF-4/HDF5).
pub fn is_netcdf(bytes: &[u8]) -> bool {
    NETCDF_MAGIC.iter().any(|magic| bytes.starts_with(magic))
}

/// Reads the netCDF sounding `bytes` of the file `path` ([`self::netcdf`] does the format).
#[cfg(feature = "netcdf")]
fn read_netcdf(
    bytes: &[u8],
    path: &Path,
    options: &ReadOptions,
) -> Result<Sounding, SoundingError> {
    let format = SoundingFormat::Netcdf;
    refuse_time(path, format, options)?;
    let mut metadata = BTreeMap::new();
    let (rows, names) = self::netcdf::read(path, bytes, &mut metadata)?;
    build(path, format, metadata, Vec::new(), rows, &names, options)
}

/// Without the `netcdf` feature a netCDF file is refused with a message saying how to rebuild.
#[cfg(not(feature = "netcdf"))]
fn read_netcdf(_: &[u8], path: &Path, _: &ReadOptions) -> Result<Sounding, SoundingError> {
    Err(SoundingError::NetcdfNotBuilt {
        path: path.to_path_buf(),
    })
}

/// `bytes` as text, or a [`SoundingError::NotUtf8`] naming the line of the first invalid byte.
fn utf8<'b>(bytes: &'b [u8], path: &Path) -> Result<&'b str, SoundingError> {
    std::str::from_utf8(bytes).map_err(|e| {
        let byte_offset = e.valid_up_to();
        let line = 1 + bytes[..byte_offset].iter().filter(|&&b| b == b'\n').count();
        SoundingError::NotUtf8 {
            path: path.to_path_buf(),
            line,
            byte_offset,
        }
    })
}

/// The nominal times (`"YYYY-MM-DD HH"`, UTC) of every sounding in the IGRA2 file or Wyoming
/// TEXT:LIST page at `path`, in file order (the values [`ReadOptions::sounding_time`] accepts); `None` for a file in another
/// format (which holds one sounding).
pub fn sounding_times(path: &Path) -> Result<Option<Vec<String>>, SoundingError> {
    let (bytes, _) = read_bytes(path)?;
    if is_netcdf(&bytes) {
        return Ok(None);
    }
    let text = String::from_utf8_lossy(&bytes);
    if let Some(times) = igra2::times(path, &text)? {
        return Ok(Some(times));
    }
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    Ok(wyoming::detect(text)
        .then(|| wyoming::times(text))
        .filter(|t| !t.is_empty()))
}

/// Parses and validates a sounding from `text`; `source` names it in errors and in
/// [`Sounding::source`].
pub fn parse_sounding(
    text: &str,
    source: &Path,
    options: &ReadOptions,
) -> Result<Sounding, SoundingError> {
    // A UTF-8 byte-order mark is not part of the first header.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let format = detect_format(text).ok_or_else(|| {
        SoundingError::file(
            source,
            "cannot recognise the format: expected a normalised CSV (header such as \
             pressure_hpa,height_m,temperature_c,dewpoint_c), a University of Wyoming TEXT:LIST \
             or TEXT:CSV page, an IGRA2 data or derived file, an SPC / SHARPpy %RAW% file, \
             an NCAR/EOL ESC sounding or a WMO TEMP message (TTAA …)",
        )
    })?;
    let mut metadata = BTreeMap::new();
    let mut warnings = Vec::new();
    let time = refuse_time(source, format, options)?;
    let time = time.as_deref();
    let (rows, names) = match format {
        SoundingFormat::NormalizedCsv | SoundingFormat::WyomingTextCsv => {
            csv::read(source, text, format, &mut metadata)?
        }
        SoundingFormat::WyomingTextList => {
            wyoming::read(source, text, time, &mut metadata, &mut warnings)?
        }
        SoundingFormat::Igra2Data | SoundingFormat::Igra2Derived => {
            igra2::read(source, text, format, time, &mut metadata, &mut warnings)?
        }
        SoundingFormat::SpcRaw => spc::read(source, text, &mut metadata)?,
        SoundingFormat::EolEsc => esc::read(source, text, &mut metadata, &mut warnings)?,
        SoundingFormat::WmoTemp => temp::read(source, text, &mut metadata, &mut warnings)?,
        // Never detected in text: netCDF is binary and read from its bytes by read_sounding.
        SoundingFormat::Netcdf => {
            return Err(SoundingError::file(
                source,
                "a netCDF sounding is binary; read it from its file",
            ));
        }
    };
    build(source, format, metadata, warnings, rows, &names, options)
}

/// The canonical [`ReadOptions::sounding_time`], if given; an error if it is malformed or if
/// `format` holds one sounding (only IGRA2 files and Wyoming pages hold several).
fn refuse_time(
    source: &Path,
    format: SoundingFormat,
    options: &ReadOptions,
) -> Result<Option<String>, SoundingError> {
    let time = options.sounding_time.as_deref();
    let time = time
        .map(|t| time::canonical_time(t).map_err(|m| SoundingError::file(source, m)))
        .transpose()?;
    let selectable = matches!(
        format,
        SoundingFormat::Igra2Data | SoundingFormat::Igra2Derived | SoundingFormat::WyomingTextList
    );
    if let (Some(t), false) = (&time, selectable) {
        return Err(SoundingError::file(
            source,
            format!(
                "a sounding time ({t:?}) was given, but the file is {} and holds one sounding; \
                 leave the time out",
                format.description()
            ),
        ));
    }
    Ok(time)
}

/// The validated [`Sounding`] from a reader's raw rows ([`validate::build_levels`]).
fn build(
    source: &Path,
    format: SoundingFormat,
    metadata: BTreeMap<String, String>,
    mut warnings: Vec<String>,
    rows: Vec<validate::RawRow>,
    names: &validate::ColumnNames,
    options: &ReadOptions,
) -> Result<Sounding, SoundingError> {
    let levels = validate::build_levels(source, rows, names, options.strict, &mut warnings)?;
    Ok(Sounding {
        source: source.to_path_buf(),
        format,
        metadata,
        levels,
        warnings,
    })
}

/// The format of `text`, from its content; `None` if it is none of the supported ones.
pub fn detect_format(text: &str) -> Option<SoundingFormat> {
    igra2::detect(text)
        .or_else(|| wyoming::detect(text).then_some(SoundingFormat::WyomingTextList))
        .or_else(|| spc::detect(text).then_some(SoundingFormat::SpcRaw))
        .or_else(|| esc::detect(text).then_some(SoundingFormat::EolEsc))
        .or_else(|| temp::detect(text).then_some(SoundingFormat::WmoTemp))
        .or_else(|| csv::detect(text))
}

impl Sounding {
    /// The number at the start of a metadata value, e.g. `20.0` from
    /// `station_elevation_m: 20.0 (release altitude from file header)`; `None` if the key is
    /// absent or its value does not start with a finite number.
    pub fn metadata_number(&self, key: &str) -> Option<f64> {
        let value = self.metadata.get(key)?;
        let token = value
            .split(|c: char| c.is_whitespace() || c == ',' || c == ';' || c == '(')
            .find(|t| !t.is_empty())?;
        token.parse::<f64>().ok().filter(|v| v.is_finite())
    }

    /// The lowest level (the surface, for a sounding launched from the ground).
    pub fn surface(&self) -> &Level {
        &self.levels[0]
    }
}

/// One sounding of a file that may hold many, as [`read_soundings`] reads it.
#[derive(Debug)]
pub struct SoundingEntry {
    /// Where it is: the file, and for a multi-sounding file the line of its header (1-based).
    pub line: Option<usize>,
    /// Its nominal time (`"YYYY-MM-DD HH"`, UTC) when the file says it before the data.
    pub time: Option<String>,
    /// The validated sounding, or why it cannot be used.
    pub result: Result<Sounding, SoundingError>,
}

/// Every sounding in the file at `path`, in file order, each read and validated on its own: all
/// soundings of an IGRA2 data or derived file (read once, not once per sounding), every
/// sounding of a Wyoming TEXT:LIST page, or the one sounding of any other format. A bad
/// sounding in the middle of a record is one entry with its error; the others are unaffected.
/// `Err` only when the file itself cannot be read (missing, too large, not text).
/// `options.sounding_time` is ignored (every sounding is read).
pub fn read_soundings(
    path: &Path,
    options: &ReadOptions,
) -> Result<Vec<SoundingEntry>, SoundingError> {
    let limit = crate::input::MAX_SOUNDING_BYTES;
    let bytes = crate::input::read_limited(path, limit).map_err(|source| SoundingError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    soundings_in(path, bytes, options)
}

/// [`read_soundings`] of a file's bytes as read from `path` (still packed, if it is; the caller
/// read them, e.g. to hash them too); `path` names the file in entries and errors.
pub fn soundings_in(
    path: &Path,
    bytes: Vec<u8>,
    options: &ReadOptions,
) -> Result<Vec<SoundingEntry>, SoundingError> {
    let single = ReadOptions {
        sounding_time: None,
        ..options.clone()
    };
    let (bytes, packing) =
        crate::input::unpack(bytes, crate::input::MAX_SOUNDING_BYTES).map_err(|source| {
            SoundingError::Io {
                path: path.to_path_buf(),
                source,
            }
        })?;
    if is_netcdf(&bytes) {
        let result = read_netcdf(&bytes, path, &single);
        return Ok(vec![SoundingEntry {
            line: None,
            time: None,
            result,
        }]);
    }
    let text = utf8(&bytes, path)?;
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut entries = if let Some(blocks) = igra2::read_all(path, text) {
        blocks
            .into_iter()
            .map(|b| SoundingEntry {
                line: Some(b.header_line),
                time: b.time,
                result: b.result.and_then(|(rows, names, metadata)| {
                    build(path, b.format, metadata, Vec::new(), rows, &names, &single)
                }),
            })
            .collect()
    } else if wyoming::detect(text) && wyoming::times(text).len() > 1 {
        wyoming::times(text)
            .into_iter()
            .map(|t| SoundingEntry {
                line: None,
                result: parse_sounding(
                    text,
                    path,
                    &ReadOptions::with_time(&t).strict(single.strict),
                ),
                time: Some(t),
            })
            .collect()
    } else {
        vec![SoundingEntry {
            line: None,
            time: None,
            result: parse_sounding(text, path, &single),
        }]
    };
    if let Some(how) = packing.describe() {
        for entry in &mut entries {
            if let Ok(s) = &mut entry.result {
                s.metadata.insert("packed_as".into(), how.clone());
            }
        }
    }
    Ok(entries)
}
