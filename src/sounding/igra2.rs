//! Stage 1 — ingest: IGRA version 2 readers (NOAA NCEI Integrated Global Radiosonde Archive).
//! In: the text of an IGRA2 sounding-data file (`*-data.txt`) or derived-parameter file
//! (`*-drvd.txt`), which may hold many soundings. Out: the metadata and raw rows of one sounding
//! (the first, or the one chosen by [`ReadOptions::sounding_time`](super::ReadOptions)).
//!
//! Fixed-width layouts (1-based columns, from the IGRA 2 format descriptions; checked against
//! the siphon reader and against the normalised CSVs converted from the same files):
//!
//! * Header, both kinds: `#` (1), ID 2–12, YEAR 14–17, MONTH 19–20, DAY 22–23, HOUR 25–26,
//!   RELTIME 28–31. Data files: NUMLEV 33–36, P_SRC 38–45, NP_SRC 47–54, LAT 56–62 and LON 64–71
//!   (degrees × 10000). Derived files: NUMLEV 32–36, then sounding indices.
//! * Data record: LVLTYP1 1, LVLTYP2 2, ETIME 4–8, PRESS 10–15 (Pa), PFLAG 16, GPH 17–21 (m,
//!   geopotential), ZFLAG 22, TEMP 23–27 (0.1 °C), TFLAG 28, RH 29–33 (0.1 %), DPDP 35–39
//!   (dewpoint depression, 0.1 °C), WDIR 41–45, WSPD 47–51. Missing −9999, removed by quality
//!   assurance −8888. The flags `A` (passed the climatological check) and `B` (passed the
//!   climatological and the tier-2 check) mark checked values, not bad ones, so values are used
//!   whatever their flag.
//! * Derived record: PRESS 1–7 (Pa), REPGPH 9–15 (reported geopotential height, m), CALCGPH 17–23
//!   (height NCEI computed hypsometrically, m), TEMP 25–31 (0.1 K), …, VAPPRESS 73–79 (vapour
//!   pressure, hPa × 1000), SATVAP 81–87, REPRH 89–95 (0.1 %), … Missing −99999. The height is
//!   REPGPH; where it is missing but CALCGPH is given, CALCGPH is used with
//!   [`HeightSource::Hypsometric`].
//!
//! Humidity: dewpoint = TEMP − DPDP when DPDP is given, else RH; derived files give the vapour
//! pressure directly.
//!
//! Hand-written: no crate reads IGRA2.

use std::collections::BTreeMap;
use std::path::Path;

use super::error::SoundingError;
use super::validate::{ColumnNames, Quantity, RawHumidity, RawRow, check_range};
use super::{HeightSource, SoundingFormat};
use crate::units;

/// A derived-file header is much longer (sounding indices) than a data-file header (71 chars).
const DERIVED_HEADER_MIN_LEN: usize = 120;

/// Whether `line` is an IGRA2 header record: `#`, an 11-character station ID, a space and a year.
fn is_header(line: &str) -> bool {
    let b = line.as_bytes();
    b.len() >= 26
        && b[0] == b'#'
        && b[1..12].iter().all(|c| c.is_ascii_alphanumeric())
        && b[12] == b' '
        && b[13..17].iter().all(u8::is_ascii_digit)
}

/// Which IGRA2 kind the text is, from its first non-blank line.
pub(crate) fn detect(text: &str) -> Option<SoundingFormat> {
    let first = text.lines().find(|l| !l.trim().is_empty())?;
    if !is_header(first) {
        return None;
    }
    Some(if first.trim_end().len() >= DERIVED_HEADER_MIN_LEN {
        SoundingFormat::Igra2Derived
    } else {
        SoundingFormat::Igra2Data
    })
}

/// 0-based byte range of a 1-based inclusive column span.
fn cols(line: &str, first: usize, last: usize) -> Option<&str> {
    if first > line.len() {
        return Some("");
    }
    line.get(first - 1..last.min(line.len()))
}

/// Parses an integer field; `None` if missing (blank or a missing code).
fn int_field(
    path: &Path,
    line_no: usize,
    line: &str,
    name: &str,
    span: (usize, usize),
    missing: &[i64],
) -> Result<Option<i64>, SoundingError> {
    let Some(text) = cols(line, span.0, span.1) else {
        return Err(SoundingError::field(
            path,
            line_no,
            name,
            format!("columns {}-{} are not plain ASCII text", span.0, span.1),
        ));
    };
    let text = text.trim();
    if text.is_empty() {
        return Ok(None);
    }
    let value: i64 = text.parse().map_err(|_| {
        SoundingError::field(
            path,
            line_no,
            name,
            format!("cannot parse \"{text}\" as an integer"),
        )
    })?;
    Ok((!missing.contains(&value)).then_some(value))
}

/// Header fields of one sounding.
struct Header {
    line: usize,
    time: String,
    numlev: Option<i64>,
}

fn parse_header(
    path: &Path,
    line_no: usize,
    line: &str,
    format: SoundingFormat,
) -> Result<Header, SoundingError> {
    let get = |name: &str, a: usize, b: usize| int_field(path, line_no, line, name, (a, b), &[]);
    let year = get("YEAR", 14, 17)?;
    let month = get("MONTH", 19, 20)?;
    let day = get("DAY", 22, 23)?;
    let hour = get("HOUR", 25, 26)?;
    let (Some(year), Some(month), Some(day), Some(hour)) = (year, month, day, hour) else {
        return Err(SoundingError::line_error(
            path,
            line_no,
            "IGRA2 header lacks the date or hour",
        ));
    };
    let numlev = match format {
        SoundingFormat::Igra2Derived => get("NUMLEV", 32, 36)?,
        _ => get("NUMLEV", 33, 36)?,
    };
    Ok(Header {
        line: line_no,
        time: format!("{year:04}-{month:02}-{day:02} {hour:02}"),
        numlev,
    })
}

/// The nominal times (`"YYYY-MM-DD HH"`) of every sounding in an IGRA2 text, in file order;
/// `None` if the text is not IGRA2 or a header cannot be read.
pub(crate) fn times(path: &Path, text: &str) -> Result<Option<Vec<String>>, SoundingError> {
    let Some(format) = detect(text) else {
        return Ok(None);
    };
    let mut times = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.starts_with('#') && is_header(line) {
            times.push(parse_header(path, i + 1, line, format)?.time);
        }
    }
    Ok(Some(times))
}

/// Reads one sounding of an IGRA2 data or derived file.
pub(crate) fn read(
    path: &Path,
    text: &str,
    format: SoundingFormat,
    wanted_time: Option<&str>,
    metadata: &mut BTreeMap<String, String>,
    notes: &mut Vec<String>,
) -> Result<(Vec<RawRow>, ColumnNames), SoundingError> {
    let lines: Vec<&str> = text.lines().collect();
    let mut headers = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        if line.starts_with('#') {
            if !is_header(line) {
                return Err(SoundingError::line_error(
                    path,
                    i + 1,
                    "a line starting with # is not an IGRA2 header record",
                ));
            }
            headers.push(parse_header(path, i + 1, line, format)?);
        }
    }
    let available: Vec<String> = headers.iter().map(|h| h.time.clone()).collect();
    let wanted = wanted_time
        .map(|t| super::time::canonical_time(t).map_err(|m| SoundingError::file(path, m)))
        .transpose()?;
    let chosen = match &wanted {
        None => headers.first(),
        Some(t) => headers.iter().find(|h| &h.time == t),
    };
    let Some(header) = chosen else {
        let message = match &wanted {
            Some(t) => super::time::no_such_time(t, &available),
            None => "the file holds no IGRA2 sounding".to_string(),
        };
        return Err(SoundingError::file(path, message));
    };
    let twins: Vec<String> = headers
        .iter()
        .filter(|h| h.time == header.time && h.line != header.line)
        .map(|h| h.line.to_string())
        .collect();
    if !twins.is_empty() {
        notes.push(format!(
            "the file holds {} soundings at {}: read the first (header line {}), ignored the \
             one{} at line{} {}",
            twins.len() + 1,
            header.time,
            header.line,
            if twins.len() == 1 { "" } else { "s" },
            if twins.len() == 1 { "" } else { "s" },
            twins.join(", ")
        ));
    }
    read_block(path, &lines, header, format, &available, metadata)
}

/// Every sounding of an IGRA2 text, in file order: its header line (1-based), its nominal time
/// (`"YYYY-MM-DD HH"`, `None` when the header cannot be read) and its rows or why they cannot be
/// read. One bad sounding (a malformed header or record, a wrong level count) is one `Err`; the
/// others are read as if each were alone in the file (line numbers count lines of the whole
/// text). A line starting with `#` that is not a header belongs to the sounding before it,
/// which it spoils. `None` if the text is not IGRA2.
pub(crate) fn read_all(path: &Path, text: &str) -> Option<Vec<BlockRead>> {
    let format = detect(text)?;
    let lines: Vec<&str> = text.lines().collect();
    let starts: Vec<usize> = (0..lines.len()).filter(|&i| is_header(lines[i])).collect();
    let headers: Vec<Result<Header, SoundingError>> = starts
        .iter()
        .map(|&i| parse_header(path, i + 1, lines[i], format))
        .collect();
    let available: Vec<String> = headers
        .iter()
        .filter_map(|h| h.as_ref().ok().map(|h| h.time.clone()))
        .collect();
    let blocks = starts
        .iter()
        .zip(headers)
        .enumerate()
        .map(|(k, (&i, header))| {
            let end = starts.get(k + 1).copied().unwrap_or(lines.len());
            let time = header.as_ref().ok().map(|h| h.time.clone());
            let result = header.and_then(|header| {
                let stray = (i + 1..end).find(|&j| lines[j].starts_with('#'));
                if let Some(j) = stray {
                    return Err(SoundingError::line_error(
                        path,
                        j + 1,
                        "a line starting with # is not an IGRA2 header record",
                    ));
                }
                let mut metadata = BTreeMap::new();
                let (rows, names) =
                    read_block(path, &lines, &header, format, &available, &mut metadata)?;
                Ok((rows, names, metadata))
            });
            BlockRead {
                header_line: i + 1,
                time,
                format,
                result,
            }
        });
    Some(blocks.collect())
}

/// A block's rows, column names and header metadata.
pub(crate) type BlockContent = (Vec<RawRow>, ColumnNames, BTreeMap<String, String>);

/// One sounding of a multi-sounding IGRA2 text, as [`read_all`] reads it.
pub(crate) struct BlockRead {
    /// Line of its header record (1-based).
    pub header_line: usize,
    /// Its nominal time, when the header could be read.
    pub time: Option<String>,
    /// Data or derived file.
    pub format: SoundingFormat,
    /// Its rows, column names and header metadata, or why they cannot be read.
    pub result: Result<BlockContent, SoundingError>,
}

/// The metadata and rows of the sounding whose header is `header`: its records run from the line
/// after the header to the next header. `available` lists every time in the file.
fn read_block(
    path: &Path,
    lines: &[&str],
    header: &Header,
    format: SoundingFormat,
    available: &[String],
    metadata: &mut BTreeMap<String, String>,
) -> Result<(Vec<RawRow>, ColumnNames), SoundingError> {
    let header_text = lines[header.line - 1];
    metadata.insert(
        "station".into(),
        cols(header_text, 2, 12).unwrap_or("").trim().to_string(),
    );
    metadata.insert("nominal_time_utc".into(), header.time.clone());
    if let Some(rel) = cols(header_text, 28, 31) {
        metadata.insert("release_time_utc_hhmm".into(), rel.trim().to_string());
    }
    metadata.insert(
        "soundings_in_file".into(),
        format!("{} ({})", available.len(), super::time::span(available)),
    );
    if format == SoundingFormat::Igra2Data {
        for (key, a, b) in [("latitude", 56, 62), ("longitude", 64, 71)] {
            if let Some(v) = int_field(path, header.line, header_text, key, (a, b), &[-99999])? {
                metadata.insert(key.into(), format!("{}", v as f64 / 10_000.0));
            }
        }
    }

    // The sounding's records run to the next header.
    let body_start = header.line; // 0-based index of the first record
    let body_end = lines[body_start..]
        .iter()
        .position(|l| l.starts_with('#'))
        .map_or(lines.len(), |n| body_start + n);
    let records = &lines[body_start..body_end];
    let count = records.iter().filter(|l| !l.trim().is_empty()).count();
    if let Some(n) = header.numlev
        && n as usize != count
    {
        return Err(SoundingError::line_error(
            path,
            header.line,
            format!("the header announces {n} levels but {count} records follow"),
        ));
    }
    let mut rows = Vec::with_capacity(records.len());
    for (k, line) in records.iter().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let line_no = body_start + k + 1;
        rows.push(match format {
            SoundingFormat::Igra2Derived => derived_record(path, line_no, line)?,
            _ => data_record(path, line_no, line)?,
        });
    }
    let names = match format {
        SoundingFormat::Igra2Derived => ColumnNames {
            height: "REPGPH".into(),
            pressure: "PRESS".into(),
            humidity: "VAPPRESS".into(),
        },
        _ => ColumnNames {
            height: "GPH".into(),
            pressure: "PRESS".into(),
            humidity: "DPDP".into(),
        },
    };
    Ok((rows, names))
}

fn too_short(path: &Path, line_no: usize, what: &str, need: usize) -> SoundingError {
    SoundingError::line_error(
        path,
        line_no,
        format!("too short for an IGRA2 {what} record (needs {need} columns)"),
    )
}

fn data_record(path: &Path, line_no: usize, line: &str) -> Result<RawRow, SoundingError> {
    const MISSING: &[i64] = &[-9999, -8888];
    if line.len() < 39 {
        return Err(too_short(path, line_no, "data", 39));
    }
    let f = |name: &str, a: usize, b: usize| int_field(path, line_no, line, name, (a, b), MISSING);
    let press = f("PRESS", 10, 15)?;
    let gph = f("GPH", 17, 21)?;
    let temp = f("TEMP", 23, 27)?;
    let rh = f("RH", 29, 33)?;
    let dpdp = f("DPDP", 35, 39)?;
    let range = |name: &str, q: Quantity, v: f64, raw: i64| {
        check_range(path, line_no, name, q, v, &raw.to_string())
    };
    let pressure_pa = press
        .map(|p| range("PRESS", Quantity::PressurePa, p as f64, p))
        .transpose()?;
    let height_m = gph
        .map(|h| range("GPH", Quantity::HeightM, h as f64, h))
        .transpose()?;
    let temperature_k = temp
        .map(|t| {
            range(
                "TEMP",
                Quantity::TemperatureK,
                units::celsius_to_kelvin(t as f64 / 10.0),
                t,
            )
        })
        .transpose()?;
    let humidity = match (temperature_k, dpdp, rh) {
        (Some(t), Some(d), _) => {
            if d < 0 {
                return Err(SoundingError::field(
                    path,
                    line_no,
                    "DPDP",
                    format!("negative dewpoint depression {d}"),
                ));
            }
            RawHumidity::DewpointK(range("DPDP", Quantity::DewpointK, t - d as f64 / 10.0, d)?)
        }
        (Some(_), None, Some(r)) => RawHumidity::RelativeHumidityPct(range(
            "RH",
            Quantity::RelativeHumidityPct,
            r as f64 / 10.0,
            r,
        )?),
        _ => RawHumidity::None,
    };
    Ok(RawRow {
        line: line_no,
        height_m,
        height_source: HeightSource::Measured,
        pressure_pa,
        temperature_k,
        humidity,
    })
}

fn derived_record(path: &Path, line_no: usize, line: &str) -> Result<RawRow, SoundingError> {
    const MISSING: &[i64] = &[-99999];
    if line.len() < 79 {
        return Err(too_short(path, line_no, "derived", 79));
    }
    let f = |name: &str, a: usize, b: usize| int_field(path, line_no, line, name, (a, b), MISSING);
    let press = f("PRESS", 1, 7)?;
    let repgph = f("REPGPH", 9, 15)?;
    let calcgph = f("CALCGPH", 17, 23)?;
    let temp = f("TEMP", 25, 31)?;
    let vappress = f("VAPPRESS", 73, 79)?;
    let range = |name: &str, q: Quantity, v: f64, raw: i64| {
        check_range(path, line_no, name, q, v, &raw.to_string())
    };
    let pressure_pa = press
        .map(|p| range("PRESS", Quantity::PressurePa, p as f64, p))
        .transpose()?;
    let (height, height_source, height_name) = match (repgph, calcgph) {
        (Some(h), _) => (Some(h), HeightSource::Measured, "REPGPH"),
        (None, Some(h)) => (Some(h), HeightSource::Hypsometric, "CALCGPH"),
        (None, None) => (None, HeightSource::Measured, "REPGPH"),
    };
    let height_m = height
        .map(|h| range(height_name, Quantity::HeightM, h as f64, h))
        .transpose()?;
    let temperature_k = temp
        .map(|t| range("TEMP", Quantity::TemperatureK, t as f64 / 10.0, t))
        .transpose()?;
    let humidity = match vappress {
        // hPa × 1000 → Pa.
        Some(v) => RawHumidity::VapourPressurePa(range(
            "VAPPRESS",
            Quantity::VapourPressureHpa,
            v as f64 / 10.0,
            v,
        )?),
        None => RawHumidity::None,
    };
    Ok(RawRow {
        line: line_no,
        height_m,
        height_source,
        pressure_pa,
        temperature_k,
        humidity,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const DATA: &str = "\
#USM00070026 2010 06 01 00 2303    3 ncdc6301 ncdc6301  712889 -1567833
21     0 100980B   12     0B 1000     0    20    51 
10    12 100000    90B   -7B  936     9 -9999 -9999 
30  9800  -9999 28544 -9999 -9999 -9999   116    46 
#USM00070026 2010 06 01 12 1100    1 ncdc6301 ncdc6301  712889 -1567833
21     0 100840B   12   -17B 1000     0    20    72 
";

    #[test]
    fn detects_both_kinds() {
        assert_eq!(detect(DATA), Some(SoundingFormat::Igra2Data));
        // The first header of the real derived excerpt (157 characters).
        let derived = "#USM00070026 2014 09 10 00 2304  120    721-99999-99999-99999 94615   606100321   141 97903   335 97903   335 93776   676    20    12    -4    39     8     0\n";
        assert_eq!(detect(derived), Some(SoundingFormat::Igra2Derived));
        assert_eq!(detect("# station: x\n"), None);
    }

    #[test]
    fn reads_columns_and_missing_codes() {
        let mut meta = BTreeMap::new();
        let (rows, _) = read(
            Path::new("i.txt"),
            DATA,
            SoundingFormat::Igra2Data,
            None,
            &mut meta,
            &mut Vec::new(),
        )
        .unwrap();
        assert_eq!(rows.len(), 3);
        assert_eq!(rows[0].pressure_pa, Some(100_980.0));
        assert_eq!(rows[0].height_m, Some(12.0));
        assert_eq!(rows[0].temperature_k, Some(273.15));
        assert_eq!(rows[0].humidity, RawHumidity::DewpointK(273.15));
        assert_eq!(rows[1].line, 3);
        assert_eq!(rows[1].humidity, RawHumidity::DewpointK(273.15 - 0.7 - 0.9));
        assert_eq!(rows[2].pressure_pa, None);
        assert_eq!(rows[2].temperature_k, None);
        assert_eq!(meta["latitude"], "71.2889");
        assert_eq!(meta["longitude"], "-156.7833");
        assert_eq!(meta["nominal_time_utc"], "2010-06-01 00");

        let (rows, _) = read(
            Path::new("i.txt"),
            DATA,
            SoundingFormat::Igra2Data,
            Some("2010-06-01 12"),
            &mut meta,
            &mut Vec::new(),
        )
        .unwrap();
        assert_eq!(rows.len(), 1);
        assert_eq!(rows[0].line, 6);
        let e = read(
            Path::new("i.txt"),
            DATA,
            SoundingFormat::Igra2Data,
            Some("2010-06-02 00"),
            &mut meta,
            &mut Vec::new(),
        )
        .unwrap_err();
        assert!(
            e.to_string().contains("2010-06-01 00, 2010-06-01 12"),
            "{e}"
        );
    }

    #[test]
    fn derived_record_fields_and_calculated_height_fallback() {
        // Real 12 UTC surface record of the derived excerpt, then the same with REPGPH missing.
        let line = " 101890      15      15    2742     -60    2727      40    2748    2733    6273    6598     950     951    -139     -64    -219     -43     265     320";
        let row = derived_record(Path::new("d.txt"), 5, line).unwrap();
        assert_eq!(row.pressure_pa, Some(101_890.0));
        assert_eq!(row.height_m, Some(15.0));
        assert_eq!(row.height_source, HeightSource::Measured);
        assert_eq!(row.temperature_k, Some(274.2));
        assert_eq!(row.humidity, RawHumidity::VapourPressurePa(627.3));
        let missing = line.replacen("      15      15", "  -99999      17", 1);
        let row = derived_record(Path::new("d.txt"), 5, &missing).unwrap();
        assert_eq!(row.height_m, Some(17.0));
        assert_eq!(row.height_source, HeightSource::Hypsometric);
        let e = derived_record(Path::new("d.txt"), 5, &line[..60]).unwrap_err();
        assert!(e.to_string().contains("too short"), "{e}");
    }

    #[test]
    fn level_count_mismatch_and_garbage_are_located() {
        let text = DATA.replace("2303    3", "2303    4");
        let e = read(
            Path::new("i.txt"),
            &text,
            SoundingFormat::Igra2Data,
            None,
            &mut BTreeMap::new(),
            &mut Vec::new(),
        )
        .unwrap_err();
        assert_eq!(e.line(), Some(1));
        let text = DATA.replace("   90B   -7B", "   9xB   -7B");
        let e = read(
            Path::new("i.txt"),
            &text,
            SoundingFormat::Igra2Data,
            None,
            &mut BTreeMap::new(),
            &mut Vec::new(),
        )
        .unwrap_err();
        assert_eq!((e.line(), e.column()), (Some(3), Some("GPH")));
    }
}
