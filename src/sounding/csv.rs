//! Stage 1 — ingest: CSV readers. In: the text of a normalised ghostship CSV or a University of
//! Wyoming TEXT:CSV file. Out: metadata and raw rows for [`super::validate`].
//!
//! Columns are found by header name (case-insensitive, surrounding spaces ignored), in any order;
//! other columns are ignored. Recognised names (the unit is the one in the name; bare names take
//! the radiosonde-usual unit shown):
//!
//! | quantity | names |
//! |---|---|
//! | pressure (hPa) | `pressure_hpa`, `pressure`, `pres`, `press`, `p` |
//! | pressure (Pa) | `pressure_pa` |
//! | height (m above mean sea level) | `height_m`, `height`, `hght`, `alt`, `altitude`, `altitude_m`, `gph`, `gph_m`, `geopotential_height_m`, `geopotential height_m` |
//! | temperature (°C) | `temperature_c`, `temperature`, `temp`, `temp_c`, `t` |
//! | temperature (K) | `temperature_k`, `temp_k` |
//! | dewpoint (°C) | `dewpoint_c`, `dewpoint`, `dwpt`, `td`, `dew_point_c`, `dew point temperature_c` |
//! | dewpoint (K) | `dewpoint_k` |
//! | relative humidity (%) | `relative_humidity_pct`, `relative_humidity`, `relh`, `rh`, `rh_pct`, `relative humidity_%` |
//! | vapour pressure (hPa) | `vapour_pressure_hpa`, `vapor_pressure_hpa` |
//!
//! Humidity priority per row: dewpoint, then relative humidity, then vapour pressure (the first
//! that is not empty). Empty fields are missing. Lines starting with `#` are comments; those of the
//! form `# key: value` become metadata. In a normalised CSV, the usual missing-value sentinels
//! (`-9999`, `-8888`, `99999`, `999.0` for temperatures, `9999` for pressure, `//`, `M`) are
//! errors: a missing value is an empty field.
//!
//! The Wyoming TEXT:CSV (`time,longitude,latitude,pressure_hPa,geopotential height_m,…`) uses the
//! same reader; its first row's `time`, `latitude` and `longitude` become metadata.
//!
//! The `csv` crate does the tokenising (quoting, comments, blank lines, line numbers).

use std::collections::BTreeMap;
use std::path::Path;

use super::error::SoundingError;
use super::validate::{ColumnNames, Quantity, RawHumidity, RawRow, parse_value};
use super::{HeightSource, SoundingFormat};

/// What a header name stands for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Role {
    Pressure,
    Height,
    Temperature,
    Dewpoint,
    RelativeHumidity,
    VapourPressure,
}

fn classify(name: &str) -> Option<(Role, Quantity)> {
    let n = name.trim().to_ascii_lowercase();
    Some(match n.as_str() {
        "pressure_hpa" | "pressure" | "pres" | "press" | "p" => {
            (Role::Pressure, Quantity::PressureHpa)
        }
        "pressure_pa" => (Role::Pressure, Quantity::PressurePa),
        "height_m"
        | "height"
        | "hght"
        | "alt"
        | "altitude"
        | "altitude_m"
        | "gph"
        | "gph_m"
        | "geopotential_height_m"
        | "geopotential height_m" => (Role::Height, Quantity::HeightM),
        "temperature_c" | "temperature" | "temp" | "temp_c" | "t" => {
            (Role::Temperature, Quantity::TemperatureC)
        }
        "temperature_k" | "temp_k" => (Role::Temperature, Quantity::TemperatureK),
        "dewpoint_c" | "dewpoint" | "dwpt" | "td" | "dew_point_c" | "dew point temperature_c" => {
            (Role::Dewpoint, Quantity::DewpointC)
        }
        "dewpoint_k" => (Role::Dewpoint, Quantity::DewpointK),
        "relative_humidity_pct"
        | "relative_humidity"
        | "relh"
        | "rh"
        | "rh_pct"
        | "relative humidity_%" => (Role::RelativeHumidity, Quantity::RelativeHumidityPct),
        "vapour_pressure_hpa" | "vapor_pressure_hpa" => {
            (Role::VapourPressure, Quantity::VapourPressureHpa)
        }
        _ => return None,
    })
}

/// Whether the first data-bearing line (after `#` comments and blank lines) is a CSV header with
/// at least one recognised column name, and whether it is Wyoming TEXT:CSV or normalised.
pub(crate) fn detect(text: &str) -> Option<SoundingFormat> {
    let header = text
        .lines()
        .map(str::trim)
        .find(|l| !l.is_empty() && !l.starts_with('#'))?;
    if !header.contains(',') {
        return None;
    }
    let names: Vec<String> = header
        .split(',')
        .map(|s| s.trim().trim_matches('"').to_ascii_lowercase())
        .collect();
    // Any recognised column makes it a sounding CSV; a missing temperature, height or pressure
    // column is then reported by `read` with the header's line.
    if !names.iter().any(|n| classify(n).is_some()) {
        return None;
    }
    if names.iter().any(|n| n == "time") && names.iter().any(|n| n == "geopotential height_m") {
        Some(SoundingFormat::WyomingTextCsv)
    } else {
        Some(SoundingFormat::NormalizedCsv)
    }
}

/// `# key: value` lines → metadata (later keys override earlier ones).
pub(crate) fn comment_metadata(text: &str) -> BTreeMap<String, String> {
    let mut metadata = BTreeMap::new();
    for line in text.lines() {
        let Some(rest) = line.trim_start().strip_prefix('#') else {
            continue;
        };
        if let Some((key, value)) = rest.split_once(':') {
            let key = key.trim();
            if !key.is_empty() && !key.contains(char::is_whitespace) {
                metadata.insert(key.to_string(), value.trim().to_string());
            }
        }
    }
    metadata
}

/// 1-based line numbers of byte offsets, for offsets that never decrease.
struct LineCounter<'a> {
    bytes: &'a [u8],
    offset: usize,
    line: usize,
}

impl<'a> LineCounter<'a> {
    fn new(text: &'a str) -> Self {
        LineCounter {
            bytes: text.as_bytes(),
            offset: 0,
            line: 1,
        }
    }

    fn line_at(&mut self, byte: usize) -> usize {
        let byte = byte.min(self.bytes.len());
        if byte < self.offset {
            // Not expected; recount from the start rather than give a wrong line.
            self.offset = 0;
            self.line = 1;
        }
        self.line += self.bytes[self.offset..byte]
            .iter()
            .filter(|&&b| b == b'\n')
            .count();
        self.offset = byte;
        self.line
    }

    /// Line of the record whose reading started at `byte`: the csv crate reports where it began
    /// consuming input, which may be a comment or blank line before the record itself.
    fn record_line(&mut self, byte: usize) -> usize {
        let mut line = self.line_at(byte);
        let mut start = self.offset;
        while start < self.bytes.len() {
            let end = self.bytes[start..]
                .iter()
                .position(|&b| b == b'\n')
                .map_or(self.bytes.len(), |n| start + n);
            let content = &self.bytes[start..end];
            let skippable =
                content.first() == Some(&b'#') || content.iter().all(u8::is_ascii_whitespace);
            if !skippable || end == self.bytes.len() {
                break;
            }
            start = end + 1;
            line += 1;
        }
        line
    }
}

/// Reads rows (and, for Wyoming TEXT:CSV, metadata from the first row).
pub(crate) fn read(
    path: &Path,
    text: &str,
    format: SoundingFormat,
    metadata: &mut BTreeMap<String, String>,
) -> Result<(Vec<RawRow>, ColumnNames), SoundingError> {
    if format == SoundingFormat::NormalizedCsv {
        metadata.extend(comment_metadata(text));
    }
    let mut reader = ::csv::ReaderBuilder::new()
        .has_headers(false)
        .comment(Some(b'#'))
        .flexible(true)
        .trim(::csv::Trim::All)
        .from_reader(text.as_bytes());
    let mut records = reader.records();
    // The csv crate's line counter skips comment lines, so lines are counted here from the byte
    // offset of each record (records come in order, so the count runs forward).
    let mut counter = LineCounter::new(text);
    let csv_error = |e: ::csv::Error, counter: &mut LineCounter| {
        let line = e
            .position()
            .map_or(1, |p| counter.record_line(p.byte() as usize));
        SoundingError::line_error(path, line, format!("malformed CSV: {e}"))
    };
    let header = match records.next() {
        Some(r) => r.map_err(|e| csv_error(e, &mut counter))?,
        None => return Err(SoundingError::file(path, "no CSV header line")),
    };
    let header_line = header
        .position()
        .map_or(1, |p| counter.record_line(p.byte() as usize));

    // Map columns to roles.
    let mut columns: Vec<Option<(Role, Quantity)>> = Vec::with_capacity(header.len());
    let mut seen: Vec<(Role, usize)> = Vec::new();
    for (i, name) in header.iter().enumerate() {
        let c = classify(name);
        if let Some((role, _)) = c {
            if let Some(&(_, j)) = seen.iter().find(|(r, _)| *r == role) {
                return Err(SoundingError::line_error(
                    path,
                    header_line,
                    format!(
                        "columns \"{}\" and \"{}\" both give the {:?}; keep one",
                        &header[j], name, role
                    ),
                ));
            }
            seen.push((role, i));
        }
        columns.push(c);
    }
    let find = |role: Role| seen.iter().find(|(r, _)| *r == role).map(|&(_, i)| i);
    let temperature = find(Role::Temperature);
    let height = find(Role::Height);
    let pressure = find(Role::Pressure);
    let Some(temperature) = temperature else {
        return Err(SoundingError::line_error(
            path,
            header_line,
            "no temperature column (expected temperature_c or temperature_k, or an alias such as temp)",
        ));
    };
    if height.is_none() && pressure.is_none() {
        return Err(SoundingError::line_error(
            path,
            header_line,
            "neither a height column (height_m…) nor a pressure column (pressure_hpa…); at least one is needed",
        ));
    }
    let humidity_columns: Vec<usize> =
        [Role::Dewpoint, Role::RelativeHumidity, Role::VapourPressure]
            .into_iter()
            .filter_map(find)
            .collect();
    let name_of = |i: Option<usize>, fallback: &str| {
        i.map_or_else(|| fallback.to_string(), |i| header[i].to_string())
    };
    let names = ColumnNames {
        height: name_of(height, "height_m"),
        pressure: name_of(pressure, "pressure_hpa"),
        humidity: name_of(humidity_columns.first().copied(), "dewpoint_c"),
    };
    let reject_sentinels = format == SoundingFormat::NormalizedCsv;
    let wyoming = format == SoundingFormat::WyomingTextCsv;
    let meta_columns: Vec<(usize, &str)> = if wyoming {
        [
            ("time", "launch_time_utc"),
            ("latitude", "latitude"),
            ("longitude", "longitude"),
        ]
        .into_iter()
        .filter_map(|(col, key)| {
            header
                .iter()
                .position(|h| h.eq_ignore_ascii_case(col))
                .map(|i| (i, key))
        })
        .collect()
    } else {
        Vec::new()
    };

    let mut rows = Vec::new();
    for record in records {
        let record = record.map_err(|e| csv_error(e, &mut counter))?;
        let line = record
            .position()
            .map_or(1, |p| counter.record_line(p.byte() as usize));
        if record.len() > header.len() {
            return Err(SoundingError::line_error(
                path,
                line,
                format!(
                    "{} fields but the header has {}",
                    record.len(),
                    header.len()
                ),
            ));
        }
        if rows.is_empty() {
            for &(i, key) in &meta_columns {
                if let Some(v) = record.get(i).filter(|v| !v.is_empty()) {
                    metadata
                        .entry(key.to_string())
                        .or_insert_with(|| v.to_string());
                }
            }
        }
        let value = |i: usize| -> Result<Option<f64>, SoundingError> {
            let Some((_, quantity)) = columns[i] else {
                return Ok(None);
            };
            parse_value(
                path,
                line,
                &header[i],
                record.get(i).unwrap_or(""),
                quantity,
                reject_sentinels,
            )
        };
        let mut humidity = RawHumidity::None;
        for &i in &humidity_columns {
            // Every humidity field is checked, the first non-empty one is used.
            if let Some(v) = value(i)?
                && matches!(humidity, RawHumidity::None)
            {
                humidity = match columns[i].map(|c| c.0) {
                    Some(Role::Dewpoint) => RawHumidity::DewpointK(v),
                    Some(Role::RelativeHumidity) => RawHumidity::RelativeHumidityPct(v),
                    _ => RawHumidity::VapourPressurePa(v),
                };
            }
        }
        rows.push(RawRow {
            line,
            height_m: height.map(value).transpose()?.flatten(),
            height_source: HeightSource::Measured,
            pressure_pa: pressure.map(value).transpose()?.flatten(),
            temperature_k: value(temperature)?,
            humidity,
        });
    }
    Ok((rows, names))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn detects_normalised_and_wyoming_headers() {
        assert_eq!(
            detect("# station: x\npressure_hpa,height_m,temperature_c,dewpoint_c\n"),
            Some(SoundingFormat::NormalizedCsv)
        );
        assert_eq!(
            detect("time,longitude,latitude,pressure_hPa,geopotential height_m,temperature_C\n"),
            Some(SoundingFormat::WyomingTextCsv)
        );
        assert_eq!(detect("a,b,c\n1,2,3\n"), None);
        assert_eq!(
            detect("height_m,wind\n"),
            Some(SoundingFormat::NormalizedCsv)
        );
        assert_eq!(detect("PRES HGHT TEMP\n"), None);
    }

    #[test]
    fn metadata_from_comment_lines() {
        let m = comment_metadata(
            "# station: Danmarkshavn; WMO 04320\n#latitude: 76.77\n# free text without key\npressure_hpa\n",
        );
        assert_eq!(m["station"], "Danmarkshavn; WMO 04320");
        assert_eq!(m["latitude"], "76.77");
        assert_eq!(m.len(), 2);
    }

    #[test]
    fn aliases_any_order_and_kelvin() {
        let mut meta = BTreeMap::new();
        let text = "TEMP,hght,Pres,relh\n-1.0,10,1000,50\n";
        let (rows, names) = read(
            Path::new("a.csv"),
            text,
            SoundingFormat::NormalizedCsv,
            &mut meta,
        )
        .unwrap();
        assert_eq!(names.pressure, "Pres");
        assert_eq!(rows[0].line, 2);
        assert_eq!(rows[0].height_m, Some(10.0));
        assert_eq!(rows[0].pressure_pa, Some(100_000.0));
        assert_eq!(rows[0].temperature_k, Some(272.15));
        assert_eq!(rows[0].humidity, RawHumidity::RelativeHumidityPct(50.0));
        let text = "temperature_k,pressure_pa\n250.5,85000\n";
        let (rows, _) = read(
            Path::new("a.csv"),
            text,
            SoundingFormat::NormalizedCsv,
            &mut meta,
        )
        .unwrap();
        assert_eq!(rows[0].temperature_k, Some(250.5));
        assert_eq!(rows[0].pressure_pa, Some(85_000.0));
        assert_eq!(rows[0].height_m, None);
    }

    #[test]
    fn header_problems() {
        let mut meta = BTreeMap::new();
        let p = Path::new("a.csv");
        let e = read(
            p,
            "# c\nheight_m,dewpoint_c\n1,2\n",
            SoundingFormat::NormalizedCsv,
            &mut meta,
        )
        .unwrap_err();
        assert_eq!(e.line(), Some(2));
        assert!(e.to_string().contains("no temperature column"));
        let e = read(
            p,
            "temperature_c,dewpoint_c\n1,2\n",
            SoundingFormat::NormalizedCsv,
            &mut meta,
        )
        .unwrap_err();
        assert!(e.to_string().contains("neither a height column"));
        let e = read(
            p,
            "temp,temperature_c,height_m\n1,2,3\n",
            SoundingFormat::NormalizedCsv,
            &mut meta,
        )
        .unwrap_err();
        assert!(e.to_string().contains("both give"));
    }
}
