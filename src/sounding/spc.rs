//! Stage 1 — ingest: SPC / SHARPpy `%RAW%` text reader. In: the text of a sounding file in the
//! format the Storm Prediction Center's tools and SHARPpy write and read (`*.OAX`, the SARS
//! analogue files). Out: metadata and raw rows for [`super::validate`].
//!
//! Layout:
//!
//! ```text
//! %TITLE%
//!  OAX   140616/1900            (station, then YYMMDD/HHMM in UTC; some files add "lat,lon")
//!
//!    LEVEL       HGHT       TEMP       DWPT       WDIR       WSPD
//! -------------------------------------------------------------------
//! %RAW%
//!  1000.00,    34.00,  -9999.00,  -9999.00,  -9999.00,  -9999.00
//!  965.00,    350.00,     27.80,     23.80,    150.00,     23.00
//! %END%
//! ```
//!
//! One level per line between `%RAW%` and `%END%`, comma-separated, in the order of the column
//! names on the line above the rule (LEVEL hPa, HGHT m above mean sea level, TEMP and DWPT °C;
//! WDIR, WSPD and any other column are not needed). `-9999` (written `-9999.00`) is the missing
//! value. Below-ground mandatory levels (1000 hPa under a higher surface) are listed without
//! temperature, sometimes after the surface (SARS files): they are skipped like every row
//! without temperature. SARS files carry a text report after `%END%`, which is not read. The
//! two-digit year follows SHARPpy's (Python's `%y`): 69–99 → 19xx, 00–68 → 20xx.
//!
//! Hand-written: no maintained Rust crate reads this format (crates.io has none for SPC or
//! SHARPpy files; sounding-bufkit reads BUFKIT, a different SPC product).

use std::collections::BTreeMap;
use std::path::Path;

use super::HeightSource;
use super::error::SoundingError;
use super::validate::{ColumnNames, Quantity, RawHumidity, RawRow, parse_value};

/// The format's missing value.
const MISSING: f64 = -9999.0;

/// Whether the text is an SPC / SHARPpy file: a `%TITLE%` line, then a `%RAW%` line.
pub(crate) fn detect(text: &str) -> bool {
    let mut lines = text.lines().map(str::trim);
    lines.any(|l| l == "%TITLE%") && lines.any(|l| l == "%RAW%")
}

/// `YYMMDD/HHMM` → `"YYYY-MM-DD HH"` and `"YYYY-MM-DD HH:MM UTC"`; `None` if malformed.
fn title_time(token: &str) -> Option<(String, String)> {
    let (date, time) = token.split_once('/')?;
    let digits = |s: &str, n: usize| s.len() == n && s.bytes().all(|b| b.is_ascii_digit());
    if !(digits(date, 6) && digits(time, 4)) {
        return None;
    }
    let yy: u32 = date[0..2].parse().ok()?;
    let year = if yy >= 69 { 1900 + yy } else { 2000 + yy };
    let (month, day, hour, minute) = (&date[2..4], &date[4..6], &time[0..2], &time[2..4]);
    let nominal = format!("{year}-{month}-{day} {hour}");
    let canonical = super::time::canonical_time(&nominal).ok()?;
    Some((
        canonical,
        format!("{year}-{month}-{day} {hour}:{minute} UTC"),
    ))
}

/// Reads the title line (`OAX   140616/1900`, optionally followed by `lat,lon`) into metadata.
fn read_title(path: &Path, number: usize, line: &str, metadata: &mut BTreeMap<String, String>) {
    let mut tokens = line.split_whitespace();
    if let Some(station) = tokens.next() {
        metadata.insert("station".into(), station.to_string());
    }
    if let Some((nominal, launch)) = tokens.next().and_then(title_time) {
        metadata.insert("nominal_time_utc".into(), nominal);
        metadata.insert("launch_time_utc".into(), launch);
    }
    if let Some((lat, lon)) = tokens.next().and_then(|t| t.split_once(','))
        && let (Ok(lat), Ok(lon)) = (lat.parse::<f64>(), lon.parse::<f64>())
        && lat.abs() <= 90.0
        && lon.abs() <= 360.0
    {
        metadata.insert("latitude".into(), lat.to_string());
        metadata.insert("longitude".into(), lon.to_string());
    }
    metadata.insert(
        "title".into(),
        format!("{} (line {number} of {})", line.trim(), path.display()),
    );
}

/// The column names of the line above the rule that precedes `%RAW%`, or the standard six.
fn column_names(lines: &[&str], raw_index: usize) -> Vec<String> {
    let standard = ["LEVEL", "HGHT", "TEMP", "DWPT", "WDIR", "WSPD"];
    lines[..raw_index]
        .iter()
        .rev()
        .map(|l| l.trim())
        .find(|l| l.split_whitespace().any(|t| t == "LEVEL"))
        .map(|l| l.split_whitespace().map(str::to_string).collect())
        .unwrap_or_else(|| standard.iter().map(|s| s.to_string()).collect())
}

/// One `%RAW%` cell: `-9999` is missing, anything else is parsed and range-checked.
fn cell(
    path: &Path,
    number: usize,
    name: &str,
    text: Option<&str>,
    quantity: Quantity,
) -> Result<Option<f64>, SoundingError> {
    let Some(text) = text else {
        return Err(SoundingError::field(
            path,
            number,
            name,
            "missing: the line has fewer comma-separated fields than the header has columns",
        ));
    };
    if text.trim().parse::<f64>() == Ok(MISSING) {
        return Ok(None);
    }
    if text.trim().is_empty() {
        return Err(SoundingError::field(
            path,
            number,
            name,
            "empty field (the format writes -9999.00 for a missing value)",
        ));
    }
    parse_value(path, number, name, text, quantity, false)
}

/// Reads the SPC / SHARPpy file `text`: metadata from the title, raw rows from `%RAW%`.
pub(crate) fn read(
    path: &Path,
    text: &str,
    metadata: &mut BTreeMap<String, String>,
) -> Result<(Vec<RawRow>, ColumnNames), SoundingError> {
    let lines: Vec<&str> = text.lines().collect();
    let find = |tag: &str| lines.iter().position(|l| l.trim() == tag);
    let (Some(title), Some(raw)) = (find("%TITLE%"), find("%RAW%")) else {
        return Err(SoundingError::file(path, "no %TITLE% and %RAW% lines"));
    };
    if let Some(line) = lines.get(title + 1) {
        read_title(path, title + 2, line, metadata);
    }
    let names = column_names(&lines, raw);
    let column = |name: &str| names.iter().position(|n| n == name);
    let (Some(pres), Some(hght), Some(temp)) = (column("LEVEL"), column("HGHT"), column("TEMP"))
    else {
        return Err(SoundingError::line_error(
            path,
            raw,
            "the column names above %RAW% lack LEVEL, HGHT or TEMP",
        ));
    };
    let dwpt = column("DWPT");
    let mut rows = Vec::new();
    let mut ended = false;
    for (index, line) in lines.iter().enumerate().skip(raw + 1) {
        let number = index + 1;
        if line.trim() == "%END%" {
            ended = true;
            break;
        }
        if line.trim().is_empty() {
            continue;
        }
        let fields: Vec<&str> = line.split(',').collect();
        let get = |c: usize, q: Quantity| cell(path, number, &names[c], fields.get(c).copied(), q);
        // In the file's column order, so that a short line names its first missing column.
        let pressure_pa = get(pres, Quantity::PressureHpa)?;
        let height_m = get(hght, Quantity::HeightM)?;
        let temperature_k = get(temp, Quantity::TemperatureC)?;
        let humidity = match dwpt.map(|c| get(c, Quantity::DewpointC)).transpose()? {
            Some(Some(td)) => RawHumidity::DewpointK(td),
            _ => RawHumidity::None,
        };
        rows.push(RawRow {
            line: number,
            height_m,
            height_source: HeightSource::Measured,
            pressure_pa,
            temperature_k,
            humidity,
        });
    }
    if !ended {
        return Err(SoundingError::file(
            path,
            "the %RAW% table has no %END% line: the file is truncated",
        ));
    }
    Ok((
        rows,
        ColumnNames {
            height: "HGHT".into(),
            pressure: "LEVEL".into(),
            humidity: "DWPT".into(),
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str = "\
%TITLE%
 BNA 140728/0000 36.25,-86.56
     LEVEL       HGHT       TEMP       DWPT       WDIR       WSPD
-------------------------------------------------------------------
%RAW%
  994.00,     79.00,     23.60,     20.40,    100.00,      9.71
 1000.00,     32.00,  -9999.00,  -9999.00,  -9999.00,  -9999.00
  989.00,    123.14,     19.40,  -9999.00,    108.76,     10.47
%END%
----- Parcel Information-----
";

    #[test]
    fn reads_title_rows_and_missing_values() {
        assert!(detect(FILE));
        let mut meta = BTreeMap::new();
        let (rows, _) = read(Path::new("x.BNA"), FILE, &mut meta).unwrap();
        assert_eq!(rows.len(), 3);
        assert_eq!(rows[0].line, 6);
        assert_eq!(rows[0].pressure_pa, Some(99_400.0));
        assert_eq!(rows[0].height_m, Some(79.0));
        assert_eq!(rows[0].humidity, RawHumidity::DewpointK(273.15 + 20.4));
        assert_eq!(rows[1].temperature_k, None);
        assert_eq!(rows[2].humidity, RawHumidity::None);
        assert_eq!(meta["station"], "BNA");
        assert_eq!(meta["nominal_time_utc"], "2014-07-28 00");
        assert_eq!(meta["launch_time_utc"], "2014-07-28 00:00 UTC");
        assert_eq!(
            (meta["latitude"].as_str(), meta["longitude"].as_str()),
            ("36.25", "-86.56")
        );
    }

    #[test]
    fn two_digit_years_follow_sharppy() {
        assert_eq!(title_time("000330/0000").unwrap().0, "2000-03-30 00");
        assert_eq!(title_time("990330/1200").unwrap().0, "1999-03-30 12");
        assert_eq!(title_time("681231/2300").unwrap().0, "2068-12-31 23");
        assert!(title_time("001330/0000").is_none());
        assert!(title_time("0003300000").is_none());
    }

    #[test]
    fn bad_and_short_lines_name_line_and_column() {
        let text = FILE.replace("     19.40,", "     19.4x,");
        let e = read(Path::new("x"), &text, &mut BTreeMap::new()).unwrap_err();
        assert_eq!((e.line(), e.column()), (Some(8), Some("TEMP")));
        let text = FILE.replace(
            "  989.00,    123.14,     19.40,  -9999.00,    108.76,     10.47",
            "  989.00,    123.14",
        );
        let e = read(Path::new("x"), &text, &mut BTreeMap::new()).unwrap_err();
        assert_eq!((e.line(), e.column()), (Some(8), Some("TEMP")));
        let text = &FILE[..FILE.find("%END%").unwrap()];
        let e = read(Path::new("x"), text, &mut BTreeMap::new()).unwrap_err();
        assert!(e.to_string().contains("truncated"), "{e}");
    }
}
