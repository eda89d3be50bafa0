//! Stage 1 — ingest: NCAR/EOL ESC reader (EOL Sounding Composite, the CLASS-derived text
//! format of EOL's field-campaign sounding archives, `*.cls` and, after EOL's quality control,
//! `*.cls.qc`). In: the text of one ESC sounding. Out: metadata, ingest notes and raw rows for
//! [`super::validate`].
//!
//! Layout (EOL's format description, e.g. the CuPIDO 2006 addendum at
//! `data.eol.ucar.edu/datafile/nph-get/97.028/readme_cupido_mgaus_format_addendum.txt`): 15
//! header lines, then one whitespace-separated row per time step (1 s for modern radiosondes).
//!
//! ```text
//! Data Type:                         GTS BUFR Sounding Data/Ascending
//! Project ID:                        CAESAR_2024
//! Release Site Type/Site ID:         Bjornoya_Norway / 01028
//! Release Location (lon,lat,alt):    019 00.07'E, 74 30.23'N, 19.001, 74.504, 20.0
//! UTC Release Time (y,m,d,h,m,s):    2024, 02, 26, 11:20:12
//! …                                  (auxiliary `key: value` lines, `/` when unused)
//! Nominal Release Time (y,m,d,h,m,s):2024, 02, 26, 12:00:00
//!  Time  Press  Temp  Dewpt  RH    Ucmp   Vcmp   spd   dir   Wcmp     Lon     Lat   Ele   Azi    Alt    Qp   Qt   Qrh  Qu   Qv   QdZ
//!   sec    mb     C     C     %     m/s    m/s   m/s   deg   m/s      deg     deg   deg   deg     m    code code code code code code
//! ------ ------ ----- ----- ----- ------ ------ ----- ----- ----- -------- ------- ----- ----- ------- ---- ---- ---- ---- ---- ----
//!    0.0  990.5  -7.4  -8.8  89.7   -3.3   -1.7   3.7  62.0 999.0   19.001  74.504 999.0 999.0    20.0 99.0 99.0 99.0 99.0 99.0  9.0
//! ```
//!
//! Columns are found by their names on the column line (`Press` hPa, `Temp` and `Dewpt` °C,
//! `Alt` m, the height used, as EOL gives it; the flags `Qp`, `Qt`, `Qrh`), and their units
//! are checked on the line below. Missing values: `9999.0` (Press), `999.0` (Temp, Dewpt),
//! `99999.0` (Alt). Quality flags: 1 good, 2 maybe, 3 bad, 4 estimated, 9 missing, 99
//! unchecked. A row whose `Qt` is 3 is dropped; `Qp` = 3 makes its pressure missing and `Qrh`
//! = 3 its humidity (dewpoint); each kind is counted in one note naming its lines. Rows with a
//! temperature but no altitude are skipped with a note (a hypsometric height between 1-s GPS
//! altitudes would not fit them). Header metadata: `station` (and `site_id`), `latitude`,
//! `longitude`, `station_elevation_m` (the decimal values of the release location),
//! `launch_time_utc` (`YYYY-MM-DD HH:MM:SS UTC`), `nominal_time_utc` (`YYYY-MM-DD HH`),
//! `project`, `radiosonde`, `temperature_qc` (how many rows carry each `Qt` flag), and every
//! other header line under a snake_case key. The format has no end marker: a file cut at a line
//! boundary cannot be told from a short ascent; a row cut short is an error.
//!
//! Hand-written: no Rust crate reads EOL ESC or CLASS files (crates.io has none; the sounding
//! crates read BUFKIT and Wyoming text), and the format is plain columns.

use std::collections::BTreeMap;
use std::path::Path;

use super::HeightSource;
use super::error::SoundingError;
use super::time::CommaTime;
use super::validate::{ColumnNames, Quantity, RawHumidity, RawRow, describe_lines, parse_value};

/// The first names of the column line.
const COLUMN_LINE_START: [&str; 3] = ["Time", "Press", "Temp"];
/// How many lines from the top the column line is looked for in (EOL's is the 13th).
const HEADER_MAX_LINES: usize = 40;
/// The quality flag for "bad".
const FLAG_BAD: f64 = 3.0;
/// Missing values of the columns read.
const MISSING_PRESSURE: f64 = 9999.0;
const MISSING_TEMPERATURE: f64 = 999.0;
const MISSING_ALTITUDE: f64 = 99999.0;

/// Whether the text is an ESC sounding: it starts with `Data Type:` and has a column line
/// beginning `Time Press Temp` near the top.
pub(crate) fn detect(text: &str) -> bool {
    let lines: Vec<&str> = text.lines().take(HEADER_MAX_LINES).collect();
    let first = lines.iter().find(|l| !l.trim().is_empty());
    first.is_some_and(|l| l.trim_start().starts_with("Data Type:")) && column_line(&lines).is_some()
}

/// The 0-based index of the column line among `lines`, if it is within [`HEADER_MAX_LINES`].
fn column_line(lines: &[&str]) -> Option<usize> {
    lines.iter().take(HEADER_MAX_LINES).position(|l| {
        let tokens: Vec<&str> = l.split_whitespace().take(3).collect();
        tokens == COLUMN_LINE_START
    })
}

/// Where the columns ingest needs sit in a row.
struct Columns {
    names: Vec<String>,
    press: usize,
    temp: usize,
    alt: usize,
    dewpt: Option<usize>,
    qp: Option<usize>,
    qt: Option<usize>,
    qrh: Option<usize>,
}

impl Columns {
    /// The columns of the column line at 0-based `index`, with the units line below checked.
    fn find(path: &Path, lines: &[&str], index: usize) -> Result<Columns, SoundingError> {
        let names: Vec<String> = lines[index].split_whitespace().map(String::from).collect();
        let at = |name: &str| names.iter().position(|n| n == name);
        let required = |name: &str, what: &str| {
            at(name).ok_or_else(|| {
                SoundingError::line_error(
                    path,
                    index + 1,
                    format!(
                        "the column line has no {name} column ({what}), which ghostship needs; \
                         columns: {}",
                        names.join(" ")
                    ),
                )
            })
        };
        let columns = Columns {
            press: required("Press", "pressure")?,
            temp: required("Temp", "temperature")?,
            alt: required("Alt", "altitude, the height of each level")?,
            dewpt: at("Dewpt"),
            qp: at("Qp"),
            qt: at("Qt"),
            qrh: at("Qrh"),
            names,
        };
        columns.check_units(path, lines, index + 1)?;
        Ok(columns)
    }

    /// Checks the units line (0-based `index`) under the columns read and the dashed rule
    /// under it.
    fn check_units(&self, path: &Path, lines: &[&str], index: usize) -> Result<(), SoundingError> {
        // Errors about the lines below name the column line (1-based: `index`).
        let rule = lines.get(index + 1).map(|l| l.trim_start());
        let (Some(units), Some(true)) = (lines.get(index), rule.map(|l| l.starts_with('-'))) else {
            return Err(SoundingError::line_error(
                path,
                index,
                "the column line must be followed by a units line and a dashed rule \
                 (the header is cut short or not laid out as ESC's)",
            ));
        };
        let units: Vec<&str> = units.split_whitespace().collect();
        let expected: [(usize, &[&str]); 3] = [
            (self.press, &["mb", "hPa"]),
            (self.temp, &["C"]),
            (self.alt, &["m"]),
        ];
        let dewpt = self.dewpt.map(|c| (c, &["C"][..]));
        for (column, allowed) in expected.into_iter().chain(dewpt) {
            let unit = units.get(column).copied().unwrap_or("");
            if !allowed.contains(&unit) {
                return Err(SoundingError::field(
                    path,
                    index + 1,
                    self.names[column].clone(),
                    format!(
                        "unit \"{unit}\" on the units line; expected {}",
                        allowed.join(" or ")
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// One value: the column's missing value gives `None`, anything else is parsed and
/// range-checked.
fn cell(
    path: &Path,
    number: usize,
    name: &str,
    text: &str,
    quantity: Quantity,
    missing: f64,
) -> Result<Option<f64>, SoundingError> {
    if text.parse::<f64>() == Ok(missing) {
        return Ok(None);
    }
    parse_value(path, number, name, text, quantity, false)
}

/// A quality flag's value; not a number is an error.
fn flag(path: &Path, number: usize, name: &str, text: &str) -> Result<f64, SoundingError> {
    text.parse().map_err(|_| {
        SoundingError::field(
            path,
            number,
            name,
            format!("cannot parse \"{text}\" as a quality flag"),
        )
    })
}

/// What one data row gave.
enum Parsed {
    /// A row for validation, with the kinds of values its flags made missing.
    Row {
        row: RawRow,
        pressure_bad: bool,
        humidity_bad: bool,
    },
    /// Temperature flagged bad (`Qt` = 3): the row is dropped.
    TemperatureBad,
    /// A temperature but no altitude: the row is skipped.
    NoAltitude,
}

/// One data row: what it gave and its `Qt` flag, if the file has that column.
struct ParsedRow {
    kind: Parsed,
    qt_flag: Option<f64>,
}

/// The values of one row (SI, `None` where missing) and its flags, before the flags are applied.
struct Values {
    pressure_pa: Option<f64>,
    temperature_k: Option<f64>,
    dewpoint_k: Option<f64>,
    height_m: Option<f64>,
    qp: Option<f64>,
    qt: Option<f64>,
    qrh: Option<f64>,
}

/// Parses the fields of the data row `line` (1-based `number`), in the order of the columns read.
fn values(path: &Path, number: usize, line: &str, c: &Columns) -> Result<Values, SoundingError> {
    let fields: Vec<&str> = line.split_whitespace().collect();
    if fields.len() != c.names.len() {
        let column = &c.names[fields.len().min(c.names.len() - 1)];
        return Err(SoundingError::field(
            path,
            number,
            column.clone(),
            format!(
                "the row has {} fields, the column line names {} (a truncated or corrupt row)",
                fields.len(),
                c.names.len()
            ),
        ));
    }
    let get = |i: usize, q: Quantity, missing: f64| {
        cell(path, number, &c.names[i], fields[i], q, missing)
    };
    let flag_at = |i: Option<usize>| {
        i.map(|i| flag(path, number, &c.names[i], fields[i]))
            .transpose()
    };
    Ok(Values {
        pressure_pa: get(c.press, Quantity::PressureHpa, MISSING_PRESSURE)?,
        temperature_k: get(c.temp, Quantity::TemperatureC, MISSING_TEMPERATURE)?,
        dewpoint_k: c
            .dewpt
            .map(|i| get(i, Quantity::DewpointC, MISSING_TEMPERATURE))
            .transpose()?
            .flatten(),
        height_m: get(c.alt, Quantity::HeightM, MISSING_ALTITUDE)?,
        qp: flag_at(c.qp)?,
        qt: flag_at(c.qt)?,
        qrh: flag_at(c.qrh)?,
    })
}

/// Parses the data row `line` (1-based `number`) and applies its quality flags.
fn parse_row(
    path: &Path,
    number: usize,
    line: &str,
    c: &Columns,
) -> Result<ParsedRow, SoundingError> {
    let v = values(path, number, line, c)?;
    let bad = |f: Option<f64>| f == Some(FLAG_BAD);
    let kind = if bad(v.qt) {
        Parsed::TemperatureBad
    } else if v.temperature_k.is_some() && v.height_m.is_none() {
        Parsed::NoAltitude
    } else {
        let (pressure_bad, humidity_bad) = (bad(v.qp), bad(v.qrh));
        let humidity = match v.dewpoint_k {
            Some(td) if !humidity_bad => RawHumidity::DewpointK(td),
            _ => RawHumidity::None,
        };
        Parsed::Row {
            row: RawRow {
                line: number,
                height_m: v.height_m,
                height_source: HeightSource::Measured,
                pressure_pa: v.pressure_pa.filter(|_| !pressure_bad),
                temperature_k: v.temperature_k,
                humidity,
            },
            // Noted only where it matters: a row without temperature is skipped anyway.
            pressure_bad: pressure_bad && v.pressure_pa.is_some() && v.temperature_k.is_some(),
            humidity_bad: humidity_bad && v.dewpoint_k.is_some() && v.temperature_k.is_some(),
        }
    };
    Ok(ParsedRow {
        kind,
        qt_flag: v.qt,
    })
}

/// The lines of each kind of row the reader dropped or changed, for the notes.
#[derive(Default)]
struct Notes {
    temperature_bad: Vec<usize>,
    pressure_bad: Vec<usize>,
    humidity_bad: Vec<usize>,
    no_altitude: Vec<usize>,
}

impl Notes {
    /// One note per kind of row, with its lines; one if the file has no `Qt` column.
    fn report(&self, columns: &Columns, warnings: &mut Vec<String>) {
        let kinds = [
            (
                &self.temperature_bad,
                "dropped {n} row(s) whose temperature quality flag Qt is 3 (bad)",
            ),
            (
                &self.pressure_bad,
                "used the pressure of {n} row(s) as missing: flag Qp is 3 (bad)",
            ),
            (
                &self.humidity_bad,
                "used the dewpoint of {n} row(s) as missing (dry air): flag Qrh is 3 (bad)",
            ),
            (
                &self.no_altitude,
                "skipped {n} row(s) with a temperature but no altitude (Alt 99999.0)",
            ),
        ];
        for (lines, text) in kinds {
            if !lines.is_empty() {
                let head = text.replace("{n}", &lines.len().to_string());
                warnings.push(format!("{head}: lines {}", describe_lines(lines)));
            }
        }
        if columns.qt.is_none() {
            warnings.push(
                "the file has no Qt column: temperatures were used without EOL's quality flags"
                    .into(),
            );
        }
    }
}

/// The quality-flag codes and what they mean.
const FLAG_MEANINGS: [(f64, &str); 6] = [
    (1.0, "good"),
    (2.0, "maybe"),
    (3.0, "bad"),
    (4.0, "estimated"),
    (9.0, "missing"),
    (99.0, "unchecked"),
];

/// `temperature_qc` metadata: how many data rows carry each `Qt` flag, e.g.
/// `1 (good): 3261, 2 (maybe): 2, 3 (bad): 3, 9 (missing): 1`.
fn qc_summary(flags: &[f64]) -> String {
    let mut counts: Vec<(f64, usize)> = Vec::new();
    for &flag in flags {
        match counts.iter_mut().find(|(code, _)| *code == flag) {
            Some((_, n)) => *n += 1,
            None => counts.push((flag, 1)),
        }
    }
    counts.sort_by(|a, b| a.0.total_cmp(&b.0));
    let parts: Vec<String> = counts
        .iter()
        .map(
            |&(code, n)| match FLAG_MEANINGS.iter().find(|(c, _)| *c == code) {
                Some((_, meaning)) => format!("{code} ({meaning}): {n}"),
                None => format!("{code}: {n}"),
            },
        )
        .collect();
    parts.join(", ")
}

/// Reads the ESC sounding `text`: metadata from the header, raw rows from the table; notes on
/// rows dropped or changed by the quality flags go to `warnings`.
/// Metres between the release altitude and the lowest level kept beyond which a note says so.
const SURFACE_NOTE_M: f64 = 5.0;

/// A note when the lowest level kept (the sounding's surface for every height "above the
/// surface") lies well above the release altitude of the header, e.g. because the first rows'
/// temperatures are flagged bad.
fn note_raised_surface(
    rows: &[RawRow],
    metadata: &BTreeMap<String, String>,
    warnings: &mut Vec<String>,
) {
    let release_m = metadata
        .get("station_elevation_m")
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse::<f64>().ok());
    let lowest = rows
        .iter()
        .filter(|r| r.temperature_k.is_some())
        .filter_map(|r| r.height_m.map(|h| (h, r.line)))
        .min_by(|a, b| a.0.total_cmp(&b.0));
    if let (Some(release_m), Some((h, line))) = (release_m, lowest)
        && (h - release_m).abs() > SURFACE_NOTE_M
    {
        warnings.push(format!(
            "the lowest level kept (line {line}, {h} m) is {:.1} m from the release altitude \
             ({release_m} m): heights above the surface count from {h} m",
            h - release_m
        ));
    }
}

pub(crate) fn read(
    path: &Path,
    text: &str,
    metadata: &mut BTreeMap<String, String>,
    warnings: &mut Vec<String>,
) -> Result<(Vec<RawRow>, ColumnNames), SoundingError> {
    let lines: Vec<&str> = text.lines().collect();
    let Some(names_index) = column_line(&lines) else {
        return Err(SoundingError::file(
            path,
            "no column line beginning \"Time Press Temp\" in the header",
        ));
    };
    read_header(&lines[..names_index], metadata, warnings);
    let columns = Columns::find(path, &lines, names_index)?;
    let table = read_table(path, &lines, names_index + 3, &columns)?;
    table.notes.report(&columns, warnings);
    if !table.qt_flags.is_empty() {
        metadata.insert("temperature_qc".into(), qc_summary(&table.qt_flags));
    }
    note_raised_surface(&table.rows, metadata, warnings);
    let dewpt = columns.dewpt.map_or("Dewpt", |i| columns.names[i].as_str());
    let names = ColumnNames {
        height: columns.names[columns.alt].clone(),
        pressure: columns.names[columns.press].clone(),
        humidity: dewpt.to_string(),
    };
    Ok((table.rows, names))
}

/// The data rows of a file, with the notes on them and every row's `Qt` flag.
struct Table {
    rows: Vec<RawRow>,
    notes: Notes,
    qt_flags: Vec<f64>,
}

/// Reads the data rows from 0-based line `start` on.
fn read_table(
    path: &Path,
    lines: &[&str],
    start: usize,
    columns: &Columns,
) -> Result<Table, SoundingError> {
    let mut table = Table {
        rows: Vec::new(),
        notes: Notes::default(),
        qt_flags: Vec::new(),
    };
    for (index, line) in lines.iter().enumerate().skip(start) {
        let number = index + 1;
        if line.trim().is_empty() {
            continue;
        }
        if line.trim_start().starts_with("Data Type:") {
            return Err(SoundingError::line_error(
                path,
                number,
                "a second sounding's header starts here; ghostship reads files of one ESC \
                 sounding (split the file at its \"Data Type:\" lines)",
            ));
        }
        let parsed = parse_row(path, number, line, columns)?;
        let notes = &mut table.notes;
        table.qt_flags.extend(parsed.qt_flag);
        match parsed.kind {
            Parsed::Row {
                row,
                pressure_bad,
                humidity_bad,
            } => {
                if pressure_bad {
                    notes.pressure_bad.push(number);
                }
                if humidity_bad {
                    notes.humidity_bad.push(number);
                }
                table.rows.push(row);
            }
            Parsed::TemperatureBad => notes.temperature_bad.push(number),
            Parsed::NoAltitude => notes.no_altitude.push(number),
        }
    }
    Ok(table)
}

/// What a header line is, by its label.
#[derive(Debug, PartialEq, Eq)]
enum HeaderKey {
    Site,
    Location,
    LaunchTime,
    NominalTime,
    Project,
    Radiosonde,
    /// Any other label, as its snake_case metadata key.
    Other(String),
}

impl HeaderKey {
    fn of(label: &str) -> HeaderKey {
        let label = label.trim();
        if label.ends_with("Site Type/Site ID") {
            HeaderKey::Site
        } else if label.starts_with("Release Location") || label.starts_with("Launch Location") {
            HeaderKey::Location
        } else if label.starts_with("Nominal") && label.contains("Time") {
            HeaderKey::NominalTime
        } else if label.contains("Release Time") || label.contains("Launch Time") {
            HeaderKey::LaunchTime
        } else if label == "Project ID" {
            HeaderKey::Project
        } else if label.starts_with("Radiosonde Type") || label.starts_with("Sonde Type") {
            HeaderKey::Radiosonde
        } else {
            HeaderKey::Other(snake_case(label))
        }
    }
}

/// `Ground Station Software` → `ground_station_software`; a parenthesised part is left out.
fn snake_case(label: &str) -> String {
    let label = label.split('(').next().unwrap_or(label);
    let words: Vec<String> = label
        .split(|c: char| !c.is_ascii_alphanumeric())
        .filter(|w| !w.is_empty())
        .map(str::to_ascii_lowercase)
        .collect();
    words.join("_")
}

/// Reads the header lines (those above the column line) into metadata; a location or time that
/// cannot be read is kept as given under a raw key, with a note.
fn read_header(
    lines: &[&str],
    metadata: &mut BTreeMap<String, String>,
    warnings: &mut Vec<String>,
) {
    for (index, line) in lines.iter().enumerate() {
        let Some((label, value)) = line.split_once(':') else {
            continue; // `/` placeholders and empty lines
        };
        let value = value.trim();
        match header_entries(label, value) {
            Ok(entries) => metadata.extend(entries),
            Err((what, raw_key)) => {
                warnings.push(format!(
                    "line {}: cannot read the {what} \"{value}\"; kept as metadata {raw_key}",
                    index + 1
                ));
                metadata.insert(raw_key.to_string(), value.to_string());
            }
        }
    }
}

/// The metadata entries of the header line `label: value`; when the value cannot be read, what
/// it should hold and the key its text is kept under.
fn header_entries(
    label: &str,
    value: &str,
) -> Result<Vec<(String, String)>, (&'static str, &'static str)> {
    let entry = |key: &str, text: &str| (key.to_string(), text.to_string());
    Ok(match HeaderKey::of(label) {
        HeaderKey::Site => {
            let id = value.rsplit_once(" / ").map(|(_, id)| id.trim());
            let id = id
                .filter(|id| !id.is_empty())
                .map(|id| entry("site_id", id));
            std::iter::once(entry("station", value)).chain(id).collect()
        }
        HeaderKey::Location => {
            let [lon, lat, alt] =
                location(value).ok_or(("release location", "release_location"))?;
            vec![
                entry("longitude", &lon),
                entry("latitude", &lat),
                entry("station_elevation_m", &alt),
            ]
        }
        HeaderKey::LaunchTime => {
            let t = CommaTime::parse(value).ok_or(("release time", "release_time"))?;
            vec![entry("launch_time_utc", &t.readable())]
        }
        HeaderKey::NominalTime => {
            let t =
                CommaTime::parse(value).ok_or(("nominal release time", "nominal_release_time"))?;
            match t.nominal() {
                Some(hour) => vec![entry("nominal_time_utc", &hour)],
                None => vec![entry("nominal_release_time_utc", &t.readable())],
            }
        }
        HeaderKey::Project => vec![entry("project", value)],
        HeaderKey::Radiosonde => vec![entry("radiosonde", value)],
        HeaderKey::Other(key) if !key.is_empty() => vec![(key, value.to_string())],
        HeaderKey::Other(_) => Vec::new(),
    })
}

/// The decimal longitude, latitude and altitude (m) of a release location — the last three
/// comma-separated numbers (`019 00.07'E, 74 30.23'N, 19.001, 74.504, 20.0`) — as written;
/// `None` if they are not numbers in range.
fn location(value: &str) -> Option<[String; 3]> {
    let parts: Vec<&str> = value.split(',').map(str::trim).collect();
    let [.., lon, lat, alt] = parts.as_slice() else {
        return None;
    };
    let number = |s: &str, limit: f64| s.parse::<f64>().ok().filter(|v| v.abs() <= limit);
    number(lon, 360.0)?;
    number(lat, 90.0)?;
    number(alt, 10_000.0)?;
    Some([lon.to_string(), lat.to_string(), alt.to_string()])
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str = "\
Data Type:                         GTS BUFR Sounding Data/Ascending
Project ID:                        CAESAR_2024
Release Site Type/Site ID:         Bjornoya_Norway / 01028
Release Location (lon,lat,alt):    019 00.07'E, 74 30.23'N, 19.001, 74.504, 20.0
UTC Release Time (y,m,d,h,m,s):    2024, 02, 26, 11:20:12
Radiosonde Type/RH Sensor Type:    Vaisala RS41
/
Nominal Release Time (y,m,d,h,m,s):2024, 02, 26, 12:00:00
 Time  Press  Temp  Dewpt  RH    Alt    Qp   Qt   Qrh
  sec    mb     C     C     %     m    code code code
------ ------ ----- ----- ----- ------- ---- ---- ----
   0.0  990.5  -7.4  -8.8  89.7    20.0  3.0  3.0  3.0
   2.0  989.2  -7.4  -8.0  95.9    30.4  3.0  1.0  3.0
   4.0  988.0  -7.3  -7.8  96.1    40.1  1.0  1.0  1.0
   6.0  986.6 999.0 999.0 999.0 99999.0  1.0  9.0  9.0
   8.0  985.1  -7.4  -7.9  96.1 99999.0  1.0  1.0  1.0
  10.0 9999.0  -7.4  -7.9  96.4    74.2  9.0  1.0 99.0
";

    type Metadata = BTreeMap<String, String>;

    fn read_file(text: &str) -> Result<(Vec<RawRow>, Vec<String>, Metadata), SoundingError> {
        let (mut meta, mut warnings) = (BTreeMap::new(), Vec::new());
        read(Path::new("x.cls"), text, &mut meta, &mut warnings).map(|(r, _)| (r, warnings, meta))
    }

    #[test]
    fn flags_drop_rows_and_values() {
        assert!(detect(FILE));
        let (rows, warnings, meta) = read_file(FILE).unwrap();
        // Line 12 (Qt 3) dropped, line 16 (no Alt) skipped; line 15 (no Temp) left to validation.
        let lines: Vec<usize> = rows.iter().map(|r| r.line).collect();
        assert_eq!(lines, [13, 14, 15, 17]);
        assert_eq!(rows[0].pressure_pa, None, "Qp 3");
        assert_eq!(rows[0].humidity, RawHumidity::None, "Qrh 3");
        assert_eq!(rows[0].temperature_k, Some(273.15 - 7.4));
        assert_eq!(rows[0].height_m, Some(30.4));
        assert_eq!(rows[1].pressure_pa, Some(98_800.0));
        assert_eq!(rows[1].humidity, RawHumidity::DewpointK(273.15 - 7.8));
        assert_eq!((rows[2].temperature_k, rows[2].height_m), (None, None));
        assert_eq!(rows[3].pressure_pa, None, "9999.0 is missing");
        let joined = warnings.join("\n");
        assert!(
            joined.contains(
                "dropped 1 row(s) whose temperature quality flag Qt is 3 (bad): lines 12"
            ),
            "{joined}"
        );
        assert!(
            joined.contains("pressure of 1 row(s) as missing: flag Qp is 3 (bad): lines 13"),
            "{joined}"
        );
        assert!(
            joined.contains(
                "dewpoint of 1 row(s) as missing (dry air): flag Qrh is 3 (bad): lines 13"
            ),
            "{joined}"
        );
        assert!(
            joined.contains(
                "skipped 1 row(s) with a temperature but no altitude (Alt 99999.0): lines 16"
            ),
            "{joined}"
        );
        assert_eq!(
            meta["temperature_qc"],
            "1 (good): 4, 3 (bad): 1, 9 (missing): 1"
        );
    }

    #[test]
    fn header_metadata() {
        let (_, _, meta) = read_file(FILE).unwrap();
        assert_eq!(meta["station"], "Bjornoya_Norway / 01028");
        assert_eq!(meta["site_id"], "01028");
        assert_eq!(
            (meta["longitude"].as_str(), meta["latitude"].as_str()),
            ("19.001", "74.504")
        );
        assert_eq!(meta["station_elevation_m"], "20.0");
        assert_eq!(meta["launch_time_utc"], "2024-02-26 11:20:12 UTC");
        assert_eq!(meta["nominal_time_utc"], "2024-02-26 12");
        assert_eq!(meta["project"], "CAESAR_2024");
        assert_eq!(meta["radiosonde"], "Vaisala RS41");
        assert_eq!(meta["data_type"], "GTS BUFR Sounding Data/Ascending");
        let text = FILE
            .replace("2024, 02, 26, 11:20:12", "yesterday")
            .replace("12:00:00", "12:30:00");
        let (_, warnings, meta) = read_file(&text).unwrap();
        assert_eq!(meta["release_time"], "yesterday");
        assert!(!meta.contains_key("launch_time_utc"));
        assert!(
            warnings
                .iter()
                .any(|w| w.contains("line 5: cannot read the release time")),
            "{warnings:?}"
        );
        assert_eq!(meta["nominal_release_time_utc"], "2024-02-26 12:30:00 UTC");
    }

    #[test]
    fn errors_name_line_and_column() {
        let e = read_file(&FILE.replace("  -7.3  -7.8", "  -7.x  -7.8")).unwrap_err();
        assert_eq!((e.line(), e.column()), (Some(14), Some("Temp")));
        assert!(e.to_string().contains("cannot parse \"-7.x\""), "{e}");
        let e = read_file(&FILE.replace("    40.1  1.0  1.0  1.0", "    40.1  1.0")).unwrap_err();
        assert_eq!((e.line(), e.column()), (Some(14), Some("Qt")));
        let e = read_file(&FILE.replace("    40.1  1.0  1.0", "    40.1  1.0  ok")).unwrap_err();
        assert_eq!((e.line(), e.column()), (Some(14), Some("Qt")));
        let e = read_file(&FILE.replace("Alt ", "Hgt ")).unwrap_err();
        assert_eq!(e.line(), Some(9));
        assert!(e.to_string().contains("no Alt column"), "{e}");
        let e = read_file(&FILE.replace("    mb  ", "    Pa  ")).unwrap_err();
        assert_eq!((e.line(), e.column()), (Some(10), Some("Press")));
        let cut: String = FILE.lines().take(10).map(|l| format!("{l}\n")).collect();
        let e = read_file(&cut).unwrap_err();
        assert!(e.to_string().contains("cut short"), "{e}");
        let e = read_file(&format!("{FILE}{FILE}")).unwrap_err();
        assert_eq!(e.line(), Some(18));
        assert!(e.to_string().contains("second sounding"), "{e}");
    }

    #[test]
    fn detection_needs_both_lines() {
        assert!(!detect(&FILE.replace("Data Type:", "Data type")));
        assert!(!detect(&FILE.replace(" Time  Press", " Press  Time")));
        assert!(!detect("pressure_hpa,height_m,temperature_c\n"));
        assert_eq!(
            HeaderKey::of("GMT Launch Time (y,m,d,h,m,s)"),
            HeaderKey::LaunchTime
        );
        assert_eq!(HeaderKey::of("Launch Site Type/Site ID"), HeaderKey::Site);
        assert_eq!(
            HeaderKey::of("Balloon Lot Number/Weight"),
            HeaderKey::Other("balloon_lot_number_weight".into())
        );
        assert_eq!(
            location("-97.298,32.835,195.0"),
            Some(["-97.298".into(), "32.835".into(), "195.0".into()])
        );
        assert_eq!(
            location("097 17.88'W, 32 50.10'N, -97.298, 95.0, 195.0"),
            None
        );
    }
}
