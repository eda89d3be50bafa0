//! Stage 1 — ingest: University of Wyoming TEXT:LIST reader. In: the text of a TEXT:LIST page
//! (HTML-wrapped or plain). Out: metadata and raw rows for [`super::validate`].
//!
//! Layout: a title line (`72681 BOI Boise Observations at 12Z 09 Dec 2010`), a dashed rule, the
//! header `PRES HGHT TEMP DWPT RELH MIXR DRCT SKNT THTA THTE THTV` (each name right-aligned in a
//! 7-character column), a units line, another rule, then one level per line in the same fixed
//! 7-character columns, blank where a value is missing. The table ends at `</PRE>` or a blank
//! line; the block "Station information and sounding indices" that follows holds
//! `name: value` lines (station, latitude, longitude, elevation, indices), kept as metadata.
//!
//! A page may hold several soundings (a request over several times): each starts at its title
//! line. One is read: the one whose observation time (`12Z 09 Dec 2010` → `2010-12-09 12`)
//! matches the requested time, else the first, with a note saying how many were ignored. A page
//! without any table ("Can't get … Observations at …") is an error that quotes the server.
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
    text.lines().any(is_header) || is_empty_page(text)
}

/// Whether the text is the archive's page for a sounding it does not have ("Can't get 72681
/// BOI Boise Observations at 01Z 09 Dec 2010.").
fn is_empty_page(text: &str) -> bool {
    text.lines()
        .any(|l| l.contains("Can't get") && l.contains(" Observations at "))
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

/// One sounding of a page: its title line (0-based index), observation time and the line range
/// (0-based, end exclusive) it spans.
struct Section {
    title_index: usize,
    station: String,
    time_text: String,
    time: Option<String>,
    lines: std::ops::Range<usize>,
}

/// The observation time of a title (`12Z 09 Dec 2010`) as `"YYYY-MM-DD HH"`.
fn canonical_observation_time(text: &str) -> Option<String> {
    const MONTHS: [&str; 12] = [
        "jan", "feb", "mar", "apr", "may", "jun", "jul", "aug", "sep", "oct", "nov", "dec",
    ];
    let mut words = text.split_whitespace();
    let hour: u32 = words.next()?.strip_suffix(['Z', 'z'])?.parse().ok()?;
    let day: u32 = words.next()?.parse().ok()?;
    let month_word = words.next()?.to_ascii_lowercase();
    let month = 1 + MONTHS.iter().position(|m| month_word.starts_with(m))?;
    let year: u32 = words.next()?.parse().ok()?;
    (hour < 24 && (1..=31).contains(&day))
        .then(|| format!("{year:04}-{month:02}-{day:02} {hour:02}"))
}

/// The soundings of a page, in page order.
fn sections(lines: &[&str]) -> Vec<Section> {
    let mut found: Vec<Section> = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        let plain = strip_tags(line);
        if let Some((station, time)) = plain.split_once(" Observations at ") {
            if let Some(last) = found.last_mut() {
                last.lines.end = i;
            }
            let time_text = time.trim().trim_end_matches('.').to_string();
            found.push(Section {
                title_index: i,
                station: station.trim().to_string(),
                time: canonical_observation_time(&time_text),
                time_text,
                lines: i..lines.len(),
            });
        }
    }
    found
}

/// The observation times (`"YYYY-MM-DD HH"`) of every sounding on a TEXT:LIST page, in page
/// order (titles whose time cannot be read are left out).
pub(crate) fn times(text: &str) -> Vec<String> {
    let lines: Vec<&str> = text.lines().collect();
    sections(&lines)
        .into_iter()
        .filter_map(|s| s.time)
        .collect()
}

/// The section to read: the one at `wanted` (canonical), else the first; notes on the others.
fn choose(
    path: &Path,
    all: Vec<Section>,
    wanted: Option<&str>,
    notes: &mut Vec<String>,
) -> Result<Option<Section>, SoundingError> {
    let times: Vec<String> = all.iter().filter_map(|s| s.time.clone()).collect();
    let count = all.len();
    let index = match wanted {
        None => 0,
        Some(t) => all
            .iter()
            .position(|s| s.time.as_deref() == Some(t))
            .ok_or_else(|| SoundingError::file(path, super::time::no_such_time(t, &times)))?,
    };
    let Some(chosen) = all.into_iter().nth(index) else {
        return Ok(None);
    };
    if count > 1 {
        let how = if wanted.is_some() {
            "the one asked for"
        } else {
            "the first; choose another with --time (sounding_time in scene and pipeline files)"
        };
        notes.push(format!(
            "the page holds {count} soundings ({}); read {} at {} (line {}), {how}",
            super::time::span(&times),
            chosen.station,
            chosen.time_text,
            chosen.title_index + 1
        ));
    }
    Ok(Some(chosen))
}

/// Reads one sounding's table and station block: the one at `wanted_time` (canonical
/// `"YYYY-MM-DD HH"`), else the first; `notes` says what else the page held.
pub(crate) fn read(
    path: &Path,
    text: &str,
    wanted_time: Option<&str>,
    metadata: &mut BTreeMap<String, String>,
    notes: &mut Vec<String>,
) -> Result<(Vec<RawRow>, ColumnNames), SoundingError> {
    let all_lines: Vec<&str> = text.lines().collect();
    let all = sections(&all_lines);
    let range = match choose(path, all, wanted_time, notes)? {
        Some(section) => {
            metadata.insert("station".into(), section.station.clone());
            metadata.insert("observation_time".into(), section.time_text.clone());
            if let Some(t) = &section.time {
                metadata.insert("nominal_time_utc".into(), t.clone());
            }
            section.lines
        }
        None if wanted_time.is_some() => {
            return Err(SoundingError::file(
                path,
                "a sounding time was given, but the page has no \"Observations at\" title to \
                 match it with",
            ));
        }
        None => 0..all_lines.len(),
    };
    let offset = range.start;
    let lines = &all_lines[range];
    let Some(header_index) = lines.iter().position(|l| is_header(l)) else {
        let server = lines
            .iter()
            .map(|l| strip_tags(l))
            .find(|l| l.contains("Can't get"));
        return Err(SoundingError::file(
            path,
            match server {
                Some(said) => format!(
                    "the page holds no sounding: the server says {:?}",
                    said.trim()
                ),
                None => "no TEXT:LIST header (PRES HGHT TEMP …)".to_string(),
            },
        ));
    };
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
            offset + header_index + 1,
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
        let number = offset + index + 1;
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
    // Station information block (a browser-saved page may put its first entry on the line of
    // the block's heading).
    if let Some(start) = lines[index.saturating_sub(1)..]
        .iter()
        .position(|l| l.contains("Station information"))
    {
        let first = index.saturating_sub(1) + start;
        let heading = strip_tags(lines[first]);
        let after_heading = heading
            .split_once("sounding indices")
            .map_or(String::new(), |(_, rest)| rest.to_string());
        let block = std::iter::once((after_heading, false)).chain(
            lines[first + 1..]
                .iter()
                .map(|l| (strip_tags(l), l.contains("</PRE>") || l.contains("</pre>"))),
        );
        for (plain, closes) in block {
            if plain.trim().is_empty() && closes {
                break;
            }
            if let Some((k, v)) = plain.split_once(':') {
                let mut key = metadata_key(k);
                // The block's "Observation time: 130517/0000" must not replace the title's.
                if metadata.contains_key(&key) {
                    key = format!("station_block_{key}");
                }
                if !key.ends_with('_') && !key.is_empty() {
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
        let (rows, _) = read(Path::new("w.txt"), TABLE, None, &mut meta, &mut Vec::new()).unwrap();
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
        let e = read(
            Path::new("w.txt"),
            &text,
            None,
            &mut BTreeMap::new(),
            &mut Vec::new(),
        )
        .unwrap_err();
        assert_eq!((e.line(), e.column()), (Some(8), Some("TEMP")));
    }
}
