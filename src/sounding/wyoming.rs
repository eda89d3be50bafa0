//! Stage 1 — ingest: University of Wyoming TEXT:LIST reader. In: the text of a TEXT:LIST page
//! (HTML-wrapped or plain). Out: metadata and raw rows for [`super::validate`].
//!
//! Layout: a title line (`72681 BOI Boise Observations at 12Z 09 Dec 2010`), a dashed rule, the
//! header `PRES HGHT TEMP DWPT RELH MIXR DRCT SKNT THTA THTE THTV` (each name right-aligned in a
//! 7-character column), a units line, another rule, then one level per line in the same fixed
//! 7-character columns, blank where a value is missing. The table ends at `</PRE>` or a blank
//! line; the block "Station information and sounding indices" that follows holds
//! `name: value` lines (station, latitude, longitude, elevation, indices), kept as metadata. Only
//! the first table of a page is read.
//!
//! Column positions are taken from the header line itself (the 7 characters ending at each
//! name), so variants with extra columns (`FRPT`, `RELI`) read too. Units: PRES hPa, HGHT m
//! (geopotential), TEMP and DWPT °C, RELH %.
//!
//! Hand-written: fixed-width text with an HTML wrapper is not something a crate reads.

use std::collections::BTreeMap;
use std::path::Path;

use super::HeightSource;
use super::error::SoundingError;
use super::validate::{ColumnNames, Quantity, RawHumidity, RawRow, parse_value};

/// Width of every TEXT:LIST column.
const COLUMN_WIDTH: usize = 7;

/// Whether `line` is the TEXT:LIST column header.
pub(crate) fn is_header(line: &str) -> bool {
    let mut tokens = line.split_whitespace();
    tokens.next() == Some("PRES") && tokens.next() == Some("HGHT") && tokens.next() == Some("TEMP")
}

/// Whether the text holds a TEXT:LIST table.
pub(crate) fn detect(text: &str) -> bool {
    text.lines().any(is_header)
}

/// Removes HTML tags from a line.
fn strip_tags(line: &str) -> String {
    let mut out = String::with_capacity(line.len());
    let mut in_tag = false;
    for c in line.chars() {
        match c {
            '<' => in_tag = true,
            '>' if in_tag => in_tag = false,
            _ if !in_tag => out.push(c),
            _ => {}
        }
    }
    out
}

fn metadata_key(name: &str) -> String {
    match name.trim().to_ascii_lowercase().as_str() {
        "station latitude" => "latitude".into(),
        "station longitude" => "longitude".into(),
        "station elevation" => "station_elevation_m".into(),
        other => other
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
            .collect::<String>()
            .split('_')
            .filter(|s| !s.is_empty())
            .collect::<Vec<_>>()
            .join("_"),
    }
}

/// Reads the first table and the station block.
pub(crate) fn read(
    path: &Path,
    text: &str,
    metadata: &mut BTreeMap<String, String>,
) -> Result<(Vec<RawRow>, ColumnNames), SoundingError> {
    let lines: Vec<&str> = text.lines().collect();
    let Some(header_index) = lines.iter().position(|l| is_header(l)) else {
        return Err(SoundingError::file(
            path,
            "no TEXT:LIST header (PRES HGHT TEMP …)",
        ));
    };
    // Title: the last non-rule, non-empty line before the header that says "Observations at".
    for line in lines[..header_index].iter().rev() {
        let plain = strip_tags(line);
        if let Some((station, time)) = plain.split_once(" Observations at ") {
            metadata.insert("station".into(), station.trim().to_string());
            metadata.insert("observation_time".into(), time.trim().to_string());
            break;
        }
    }
    // Column ranges from the header.
    let header = lines[header_index];
    let mut columns: Vec<(String, usize, usize)> = Vec::new();
    let mut search_from = 0;
    for name in header.split_whitespace() {
        let Some(offset) = header[search_from..].find(name) else {
            break;
        };
        let end = search_from + offset + name.len();
        columns.push((name.to_string(), end.saturating_sub(COLUMN_WIDTH), end));
        search_from = end;
    }
    let find = |name: &str| columns.iter().position(|c| c.0 == name);
    let (Some(pres), Some(hght), Some(temp)) = (find("PRES"), find("HGHT"), find("TEMP")) else {
        return Err(SoundingError::line_error(
            path,
            header_index + 1,
            "header lacks PRES, HGHT or TEMP",
        ));
    };
    let dwpt = find("DWPT");
    let relh = find("RELH");

    let mut rows = Vec::new();
    let mut index = header_index + 1;
    // Units line and rule.
    while index < lines.len() {
        let t = lines[index].trim();
        if t.starts_with("hPa") || t.chars().all(|c| c == '-') && !t.is_empty() {
            index += 1;
        } else {
            break;
        }
    }
    while index < lines.len() {
        let line = lines[index];
        let number = index + 1;
        index += 1;
        let t = line.trim();
        if t.is_empty() || t.starts_with('<') {
            break;
        }
        if t.chars().all(|c| c == '-') {
            continue;
        }
        let field = |c: usize, quantity: Quantity| -> Result<Option<f64>, SoundingError> {
            let (name, start, end) = &columns[c];
            let cell = if line.len() <= *start {
                Some("")
            } else {
                line.get(*start..(*end).min(line.len()))
            };
            let Some(cell) = cell else {
                return Err(SoundingError::field(
                    path,
                    number,
                    name.clone(),
                    "not a fixed-width TEXT:LIST cell (the line is not plain ASCII in this column)",
                ));
            };
            parse_value(path, number, name, cell, quantity, false)
        };
        let mut humidity = RawHumidity::None;
        if let Some(c) = dwpt
            && let Some(td) = field(c, Quantity::DewpointC)?
        {
            humidity = RawHumidity::DewpointK(td);
        }
        if let Some(c) = relh
            && let Some(rh) = field(c, Quantity::RelativeHumidityPct)?
            && matches!(humidity, RawHumidity::None)
        {
            humidity = RawHumidity::RelativeHumidityPct(rh);
        }
        rows.push(RawRow {
            line: number,
            height_m: field(hght, Quantity::HeightM)?,
            height_source: HeightSource::Measured,
            pressure_pa: field(pres, Quantity::PressureHpa)?,
            temperature_k: field(temp, Quantity::TemperatureC)?,
            humidity,
        });
    }
    // Station information block.
    if let Some(start) = lines[index.saturating_sub(1)..]
        .iter()
        .position(|l| l.contains("Station information"))
    {
        for line in &lines[index.saturating_sub(1) + start + 1..] {
            let plain = strip_tags(line);
            if plain.trim().is_empty() && line.contains("</PRE>") {
                break;
            }
            if let Some((k, v)) = plain.split_once(':') {
                let key = metadata_key(k);
                if !key.is_empty() {
                    metadata.insert(key, v.trim().to_string());
                }
            }
        }
    }
    Ok((
        rows,
        ColumnNames {
            height: "HGHT".into(),
            pressure: "PRES".into(),
            humidity: if dwpt.is_some() { "DWPT" } else { "RELH" }.into(),
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    const TABLE: &str = "\
<H2>72681 BOI Boise Observations at 12Z 09 Dec 2010</H2>
<PRE>
-----------------------------------------------------------------------------
   PRES   HGHT   TEMP   DWPT   RELH   MIXR   DRCT   SKNT   THTA   THTE   THTV
    hPa     m      C      C      %    g/kg    deg   knot     K      K      K 
-----------------------------------------------------------------------------
 1000.0    112                                                               
  919.0    874   -0.1   -0.2     99   4.10    240      3  273.9  285.3  274.6
  909.0    962    1.2                                  4  276.0              
</PRE><H3>Station information and sounding indices</H3><PRE>
                         Station identifier: BOI
                           Station latitude: 43.56
                          Station elevation: 874.0
</PRE>
";

    #[test]
    fn reads_fixed_columns_blank_cells_and_station_block() {
        let mut meta = BTreeMap::new();
        let (rows, _) = read(Path::new("w.txt"), TABLE, &mut meta).unwrap();
        assert_eq!(rows.len(), 3);
        assert_eq!(rows[0].temperature_k, None);
        assert_eq!(rows[0].height_m, Some(112.0));
        assert_eq!(rows[1].line, 8);
        assert_eq!(rows[1].pressure_pa, Some(91_900.0));
        assert_eq!(rows[1].humidity, RawHumidity::DewpointK(273.15 - 0.2));
        assert_eq!(rows[2].humidity, RawHumidity::None);
        assert_eq!(meta["station"], "72681 BOI Boise");
        assert_eq!(meta["observation_time"], "12Z 09 Dec 2010");
        assert_eq!(meta["station_identifier"], "BOI");
        assert_eq!(meta["latitude"], "43.56");
        assert_eq!(meta["station_elevation_m"], "874.0");
    }

    #[test]
    fn bad_cell_names_line_and_column() {
        let text = TABLE.replace("  919.0    874   -0.1", "  919.0    874   -x.1");
        let e = read(Path::new("w.txt"), &text, &mut BTreeMap::new()).unwrap_err();
        assert_eq!((e.line(), e.column()), (Some(8), Some("TEMP")));
    }
}
