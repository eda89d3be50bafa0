//! Stage 1 — ingest: validation shared by every format. In: raw rows as a reader found them (SI
//! values or missing, each with its source line). Out: the validated, height-ordered [`Level`]s of
//! a [`Sounding`](super::Sounding), plus warnings for rows that were skipped or dropped.
//!
//! The rules, in order (all documented in `data/README.md` too):
//! 1. Every value is finite, not a missing-value sentinel, and in range (see `Quantity` in this file).
//! 2. Rows without temperature (wind-only levels, below-ground levels) are skipped, with one
//!    summary warning; they are not errors.
//! 3. A row with temperature but neither height nor pressure cannot be placed: error.
//! 4. Humidity becomes vapour pressure: e = e_s(T_d) from a dewpoint, RH·e_s(T) from relative
//!    humidity, or as given. A dewpoint may exceed the temperature by at most
//!    [`DEWPOINT_ROUNDING_TOLERANCE_K`] (both are rounded to 0.1 K in the sources); such a level is
//!    taken as saturated. More is an error.
//! 5. Heights must increase up the file. An exact duplicate row (same height, pressure,
//!    temperature and humidity) is merged; a conflicting duplicate or a height below an earlier
//!    one is an error — except in a continuous high-resolution ascent (see
//!    [`is_high_resolution`]), where rows that go backwards (height not above the highest so far,
//!    or pressure above the lowest so far) are dropped and counted in a warning, because 1-s
//!    radiosonde files do contain short GPS/balloon descents (Trois-Rivières 2022-02-22: five
//!    rows around 3.07 km).
//! 6. Pressure must not increase with height. Equal consecutive pressures are allowed between
//!    rows that have heights (1-s files repeat the 0.1 hPa value), not where a height has to be
//!    computed from them.
//! 7. Levels with pressure but no height get hypsometric heights ([`super::hypsometric`]).
//! 8. At least [`MIN_LEVELS`] levels must remain.
//! 9. Steps steeper than [`SUSPECT_TEMPERATURE_GRADIENT_K_PER_M`] between consecutive levels are
//!    kept but reported in a warning: they are almost certainly a height or temperature error and
//!    would be traced as an extreme duct.

use std::collections::HashMap;
use std::path::Path;

use super::error::SoundingError;
use super::hypsometric::{self, HypsometricLevel};
use super::{HeightSource, Level};
use crate::units;

/// Fewest usable levels a sounding may have.
pub const MIN_LEVELS: usize = 3;

/// Temperature change between consecutive levels (K/m) above which a warning names the levels.
/// The steepest step in the test soundings (`tests/data/soundings`, 1-s files included) is
/// 0.12 K/m and the paper's strongest layer 0.67 K/m; 10 K/m is 0.1 K of rounding over 1 cm. Not
/// an error: the first seconds of a 1-s ascent can legitimately carry sensor lag over a few
/// centimetres.
pub const SUSPECT_TEMPERATURE_GRADIENT_K_PER_M: f64 = 10.0;

/// How far (K) a dewpoint may sit above the temperature and still be accepted (as saturation):
/// both are reported to 0.1 K, so rounding alone can put a saturated dewpoint 0.1 K high.
pub const DEWPOINT_ROUNDING_TOLERANCE_K: f64 = 0.1;

/// Relative humidity above this (%) is rejected; up to it, the value is used as given (sensors
/// report slightly over 100 % in cloud).
pub const MAX_RELATIVE_HUMIDITY_PCT: f64 = 105.0;

/// A physical quantity as written in a file, with its unit. Knows its missing-value sentinels and
/// its plausible range, and converts to SI.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Quantity {
    PressureHpa,
    PressurePa,
    HeightM,
    TemperatureC,
    TemperatureK,
    DewpointC,
    DewpointK,
    RelativeHumidityPct,
    VapourPressureHpa,
}

impl Quantity {
    /// Value in SI (Pa, m, K, %, Pa).
    fn to_si(self, value: f64) -> f64 {
        match self {
            Quantity::PressureHpa | Quantity::VapourPressureHpa => units::hpa_to_pa(value),
            Quantity::TemperatureC | Quantity::DewpointC => units::celsius_to_kelvin(value),
            _ => value,
        }
    }

    /// Numbers that formats use for "missing" in this kind of column. In a normalised CSV they are
    /// errors (leave the field empty instead); readers of formats that use them as markers handle
    /// them before calling [`parse_value`].
    fn sentinels(self) -> &'static [f64] {
        match self {
            Quantity::PressureHpa => &[-9999.0, -8888.0, -99999.0, 9999.0, 99999.0, -999.0],
            Quantity::HeightM => &[-9999.0, -8888.0, -99999.0, 99999.0, 32767.0],
            Quantity::TemperatureC | Quantity::DewpointC => {
                &[-9999.0, -8888.0, -99999.0, 999.0, -999.0, 9999.0, 99999.0]
            }
            _ => &[-9999.0, -8888.0, -99999.0, 999.0, -999.0, 9999.0, 99999.0],
        }
    }

    /// Accepted SI range (inclusive) and a description of it in the file's unit.
    fn range_si(self) -> (f64, f64, &'static str) {
        match self {
            Quantity::PressureHpa | Quantity::PressurePa => (
                1e-3,
                110_000.0,
                "pressure must be above 0 and at most 1100 hPa",
            ),
            Quantity::HeightM => (-1000.0, 80_000.0, "height must be within -1000…80000 m"),
            Quantity::TemperatureC | Quantity::TemperatureK => (
                units::celsius_to_kelvin(-100.0),
                units::celsius_to_kelvin(60.0),
                "temperature must be within -100…+60 °C",
            ),
            Quantity::DewpointC | Quantity::DewpointK => (
                units::celsius_to_kelvin(-150.0),
                units::celsius_to_kelvin(60.0),
                "dewpoint must be within -150…+60 °C",
            ),
            Quantity::RelativeHumidityPct => (
                0.0,
                MAX_RELATIVE_HUMIDITY_PCT,
                "relative humidity must be within 0…105 %",
            ),
            Quantity::VapourPressureHpa => {
                (0.0, 20_000.0, "vapour pressure must be within 0…200 hPa")
            }
        }
    }
}

/// Parses one text field. Empty → `Ok(None)` (missing). Rejects the markers `//` and `M`,
/// non-numbers, NaN/inf, the quantity's sentinels (when `reject_sentinels`) and out-of-range
/// values, naming file, line and column. Returns the value in SI.
pub(crate) fn parse_value(
    path: &Path,
    line: usize,
    column: &str,
    text: &str,
    quantity: Quantity,
    reject_sentinels: bool,
) -> Result<Option<f64>, SoundingError> {
    let text = text.trim();
    if text.is_empty() {
        return Ok(None);
    }
    if text.chars().all(|c| c == '/') || text == "M" {
        return Err(SoundingError::field(
            path,
            line,
            column,
            format!(
                "\"{text}\" is a missing-value marker; leave the field empty for a missing value"
            ),
        ));
    }
    let value: f64 = text.parse().map_err(|_| {
        SoundingError::field(
            path,
            line,
            column,
            format!("cannot parse \"{text}\" as a number"),
        )
    })?;
    if !value.is_finite() {
        return Err(SoundingError::field(
            path,
            line,
            column,
            format!("\"{text}\" is not a finite number"),
        ));
    }
    if reject_sentinels && quantity.sentinels().contains(&value) {
        return Err(SoundingError::field(
            path,
            line,
            column,
            format!(
                "{text} looks like a missing-value sentinel; leave the field empty for a missing value"
            ),
        ));
    }
    check_range(path, line, column, quantity, quantity.to_si(value), text).map(Some)
}

/// Range check of an SI value; `shown` is how the value appears in the file.
pub(crate) fn check_range(
    path: &Path,
    line: usize,
    column: &str,
    quantity: Quantity,
    value_si: f64,
    shown: &str,
) -> Result<f64, SoundingError> {
    let (lo, hi, rule) = quantity.range_si();
    if !value_si.is_finite() || value_si < lo || value_si > hi {
        return Err(SoundingError::field(
            path,
            line,
            column,
            format!("{shown} is out of range: {rule}"),
        ));
    }
    Ok(value_si)
}

/// Humidity as a reader found it (SI).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum RawHumidity {
    /// No humidity: the level is treated as dry.
    None,
    /// Dewpoint (K).
    DewpointK(f64),
    /// Relative humidity over water (%).
    RelativeHumidityPct(f64),
    /// Water-vapour partial pressure (Pa).
    VapourPressurePa(f64),
}

/// One data row as a reader found it.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct RawRow {
    pub line: usize,
    pub height_m: Option<f64>,
    /// Where `height_m` came from when present (IGRA2 derived files may give a computed height).
    pub height_source: HeightSource,
    pub pressure_pa: Option<f64>,
    pub temperature_k: Option<f64>,
    pub humidity: RawHumidity,
}

/// The file's names for the columns, for error messages.
#[derive(Debug, Clone)]
pub(crate) struct ColumnNames {
    pub height: String,
    pub pressure: String,
    pub humidity: String,
}

/// A row that passed the per-row checks.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Row {
    line: usize,
    height_m: Option<f64>,
    height_source: HeightSource,
    pressure_pa: Option<f64>,
    temperature_k: f64,
    vapour_pressure_pa: Option<f64>,
}

impl Row {
    /// Same measurement (line and height source aside).
    fn same_values(&self, other: &Row) -> bool {
        self.height_m == other.height_m
            && self.pressure_pa == other.pressure_pa
            && self.temperature_k == other.temperature_k
            && self.vapour_pressure_pa == other.vapour_pressure_pa
    }
}

/// A continuous high-resolution ascent: at least this many rows with heights…
pub const HIGH_RESOLUTION_MIN_ROWS: usize = 200;
/// …whose median height step is at most this (m). 1-s soundings step about 5 m.
pub const HIGH_RESOLUTION_MAX_MEDIAN_STEP_M: f64 = 20.0;

/// Whether heights (in file order) look like a continuous 1-s-style ascent rather than a list of
/// reported levels.
pub fn is_high_resolution(heights_m: &[f64]) -> bool {
    if heights_m.len() < HIGH_RESOLUTION_MIN_ROWS {
        return false;
    }
    let mut steps: Vec<f64> = heights_m.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
    steps.sort_by(f64::total_cmp);
    steps[steps.len() / 2] <= HIGH_RESOLUTION_MAX_MEDIAN_STEP_M
}

/// In strict mode ([`crate::sounding::ReadOptions::strict`]) a conflict between levels this close
/// above the lowest level (m) refuses the sounding instead of dropping the level: the lowest
/// kilometres are where mirages form.
pub const STRICT_ZONE_M: f64 = 3000.0;

/// Levels that contradict the levels below them (height not increasing, pressure increasing, a
/// duplicate with other values): each is dropped with a note naming its line, or — in strict
/// mode, inside [`STRICT_ZONE_M`] — refuses the sounding.
struct Conflicts {
    strict: bool,
    notes: Vec<String>,
}

impl Conflicts {
    /// Drop the row `error` is about (at `height_m`, if known, above the lowest level's
    /// `surface_m`), or refuse the sounding with `error`.
    fn drop_or_refuse(
        &mut self,
        error: SoundingError,
        height_m: Option<f64>,
        surface_m: Option<f64>,
    ) -> Result<(), SoundingError> {
        let in_zone = match (height_m, surface_m) {
            (Some(h), Some(s)) => h - s <= STRICT_ZONE_M,
            _ => true,
        };
        if self.strict && in_zone {
            return Err(error);
        }
        self.notes.push(error.detail());
        Ok(())
    }

    fn report(self, warnings: &mut Vec<String>) {
        const SHOWN: usize = 5;
        if self.notes.is_empty() {
            return;
        }
        let mut text = format!(
            "dropped {} level(s) that contradict the levels below them: {}",
            self.notes.len(),
            self.notes[..self.notes.len().min(SHOWN)].join("; ")
        );
        if self.notes.len() > SHOWN {
            text.push_str(&format!("; … ({} more)", self.notes.len() - SHOWN));
        }
        warnings.push(text);
    }
}

/// `lines` for a note: the first ten, then how many more.
pub(crate) fn describe_lines(lines: &[usize]) -> String {
    const SHOWN: usize = 10;
    let mut s: Vec<String> = lines.iter().take(SHOWN).map(usize::to_string).collect();
    if lines.len() > SHOWN {
        s.push(format!("… ({} more)", lines.len() - SHOWN));
    }
    s.join(", ")
}

/// Applies every rule of this module to the rows of one sounding. `warnings` receives one line
/// per kind of skipped or dropped row. `strict`: a conflict between levels inside
/// [`STRICT_ZONE_M`] refuses the sounding instead of dropping the level.
pub(crate) fn build_levels(
    path: &Path,
    rows: Vec<RawRow>,
    names: &ColumnNames,
    strict: bool,
    warnings: &mut Vec<String>,
) -> Result<Vec<Level>, SoundingError> {
    // Rules 2–4: per-row checks.
    let mut skipped_no_temperature = Vec::new();
    let mut checked = Vec::with_capacity(rows.len());
    for raw in rows {
        let Some(temperature_k) = raw.temperature_k else {
            skipped_no_temperature.push(raw.line);
            continue;
        };
        if raw.height_m.is_none() && raw.pressure_pa.is_none() {
            return Err(SoundingError::line_error(
                path,
                raw.line,
                format!(
                    "the row has a temperature but neither a height ({}) nor a pressure ({}), so it cannot be placed",
                    names.height, names.pressure
                ),
            ));
        }
        let vapour_pressure_pa = vapour_pressure(path, &raw, temperature_k, names)?;
        checked.push(Row {
            line: raw.line,
            height_m: raw.height_m,
            height_source: raw.height_source,
            pressure_pa: raw.pressure_pa,
            temperature_k,
            vapour_pressure_pa,
        });
    }
    if !skipped_no_temperature.is_empty() {
        warnings.push(format!(
            "skipped {} row(s) without temperature (e.g. wind-only or below-ground levels): lines {}",
            skipped_no_temperature.len(),
            describe_lines(&skipped_no_temperature)
        ));
    }

    // Rules 5–6: order, duplicates, pressure.
    let heights: Vec<f64> = checked.iter().filter_map(|r| r.height_m).collect();
    let high_resolution = is_high_resolution(&heights);
    let mut accepted: Vec<Row> = Vec::with_capacity(checked.len());
    let mut by_height: HashMap<u64, usize> = HashMap::new();
    let mut by_pressure: HashMap<u64, usize> = HashMap::new();
    let mut highest: Option<usize> = None; // index into accepted of the highest height so far
    let mut lowest_pressure: Option<usize> = None; // index into accepted
    let mut merged = Vec::new();
    let mut dropped = Vec::new();
    let mut conflicts = Conflicts {
        strict,
        notes: Vec::new(),
    };
    for row in checked {
        let surface_m = accepted.first().and_then(|r: &Row| r.height_m);
        let top_m = highest.and_then(|i| accepted[i].height_m);
        let at_m = row.height_m.or(top_m);
        // Exact duplicates and conflicts, keyed on the height (or on the pressure for rows
        // without height).
        let twin = match row.height_m {
            Some(h) => by_height.get(&h.to_bits()).copied(),
            None => row
                .pressure_pa
                .and_then(|p| by_pressure.get(&p.to_bits()).copied()),
        };
        if let Some(t) = twin {
            let other = accepted[t];
            let same = match row.height_m {
                Some(_) => row.same_values(&other),
                // A pressure-only row repeating a level that also has a height: same level.
                None => {
                    other.pressure_pa == row.pressure_pa
                        && other.temperature_k == row.temperature_k
                        && other.vapour_pressure_pa == row.vapour_pressure_pa
                }
            };
            if same {
                merged.push(row.line);
                continue;
            }
            if high_resolution && row.height_m.is_some() {
                dropped.push(row.line);
                continue;
            }
            let key = match row.height_m {
                Some(h) => format!("height {h} m"),
                None => format!(
                    "pressure {} hPa",
                    units::pa_to_hpa(row.pressure_pa.unwrap_or(f64::NAN))
                ),
            };
            let error = SoundingError::line_error(
                path,
                row.line,
                format!(
                    "conflicting duplicate: {key} is also at line {} with different values",
                    other.line
                ),
            );
            conflicts.drop_or_refuse(error, at_m, surface_m)?;
            continue;
        }
        if let (Some(h), Some(hi)) = (row.height_m, highest)
            && let Some(top) = accepted[hi].height_m
            && h <= top
        {
            if high_resolution {
                dropped.push(row.line);
                continue;
            }
            let error = SoundingError::field(
                path,
                row.line,
                names.height.clone(),
                format!(
                    "height {h} m is not above {top} m at line {}: heights must increase up the file",
                    accepted[hi].line
                ),
            );
            conflicts.drop_or_refuse(error, at_m, surface_m)?;
            continue;
        }
        if let (Some(p), Some(lo)) = (row.pressure_pa, lowest_pressure)
            && let Some(p_low) = accepted[lo].pressure_pa
        {
            let other = accepted[lo];
            if p > p_low && high_resolution {
                dropped.push(row.line);
                continue;
            }
            if p > p_low {
                let error = SoundingError::field(
                    path,
                    row.line,
                    names.pressure.clone(),
                    format!(
                        "pressure {} hPa is above {} hPa at line {} lower in the file: pressure must decrease with height",
                        units::pa_to_hpa(p),
                        units::pa_to_hpa(p_low),
                        other.line
                    ),
                );
                conflicts.drop_or_refuse(error, at_m, surface_m)?;
                continue;
            }
            if p == p_low && (row.height_m.is_none() || other.height_m.is_none()) {
                let error = SoundingError::field(
                    path,
                    row.line,
                    names.pressure.clone(),
                    format!(
                        "pressure {} hPa equals that of line {} and one of the two has no height, so no height can be computed for it",
                        units::pa_to_hpa(p),
                        other.line
                    ),
                );
                conflicts.drop_or_refuse(error, at_m, surface_m)?;
                continue;
            }
        }
        let index = accepted.len();
        if let Some(h) = row.height_m {
            by_height.insert(h.to_bits(), index);
            highest = Some(index);
        }
        if let Some(p) = row.pressure_pa {
            by_pressure.entry(p.to_bits()).or_insert(index);
            lowest_pressure = Some(index);
        }
        accepted.push(row);
    }
    if !merged.is_empty() {
        warnings.push(format!(
            "merged {} exact duplicate row(s): lines {}",
            merged.len(),
            describe_lines(&merged)
        ));
    }
    conflicts.report(warnings);
    if !dropped.is_empty() {
        warnings.push(format!(
            "dropped {} row(s) of a continuous high-resolution ascent whose height does not increase or whose pressure increases (the sonde briefly descended or its height/pressure jumped back): lines {}",
            dropped.len(),
            describe_lines(&dropped)
        ));
    }

    // Rule 7: hypsometric heights for pressure-only rows.
    if accepted.iter().any(|r| r.height_m.is_none()) {
        let chain: Vec<usize> = (0..accepted.len())
            .filter(|&i| accepted[i].pressure_pa.is_some())
            .collect();
        let mut column: Vec<HypsometricLevel> = chain
            .iter()
            .map(|&i| {
                let r = &accepted[i];
                let p = r.pressure_pa.unwrap_or(f64::NAN);
                HypsometricLevel {
                    pressure_pa: p,
                    virtual_temperature_k: hypsometric::virtual_temperature_k(
                        r.temperature_k,
                        r.vapour_pressure_pa,
                        p,
                    ),
                    height_m: r.height_m,
                }
            })
            .collect();
        let filled = hypsometric::fill_missing_heights(&mut column).map_err(|e| match e {
            hypsometric::HypsometricError::NoAnchor => SoundingError::file(
                path,
                "some levels have a pressure but no height, and no level has both a height and a pressure to compute their heights from",
            ),
            hypsometric::HypsometricError::BadColumn { index } => SoundingError::line_error(
                path,
                accepted[chain[index + 1]].line,
                "cannot compute hypsometric heights: pressure does not decrease here",
            ),
        })?;
        for k in filled {
            let row = &mut accepted[chain[k]];
            row.height_m = column[k].height_m;
            row.height_source = HeightSource::Hypsometric;
        }
    }

    // Final order check (hypsometric heights must fit between reported ones) and conversion.
    let mut levels: Vec<Level> = Vec::with_capacity(accepted.len());
    for row in accepted {
        let Some(height_m) = row.height_m.filter(|h| h.is_finite()) else {
            return Err(SoundingError::line_error(
                path,
                row.line,
                "no height could be determined for this row",
            ));
        };
        if let Some(prev) = levels.last()
            && height_m <= prev.height_m
        {
            return Err(SoundingError::line_error(
                path,
                row.line,
                format!(
                    "height {height_m:.1} m ({}) is not above {:.1} m at line {}: the file's heights and pressures disagree",
                    match row.height_source {
                        HeightSource::Measured => "reported",
                        HeightSource::Hypsometric => "computed from pressure",
                    },
                    prev.height_m,
                    prev.line
                ),
            ));
        }
        levels.push(Level {
            height_m,
            pressure_pa: row.pressure_pa,
            temperature_k: row.temperature_k,
            vapour_pressure_pa: row.vapour_pressure_pa,
            height_source: row.height_source,
            line: row.line,
        });
    }

    // Rule 9.
    let steep: Vec<usize> = levels
        .windows(2)
        .filter(|w| {
            let gradient =
                (w[1].temperature_k - w[0].temperature_k) / (w[1].height_m - w[0].height_m);
            gradient.abs() > SUSPECT_TEMPERATURE_GRADIENT_K_PER_M
        })
        .map(|w| w[1].line)
        .collect();
    if !steep.is_empty() {
        warnings.push(format!(
            "{} level(s) differ from the level below by more than {SUSPECT_TEMPERATURE_GRADIENT_K_PER_M} K/m in temperature (a height or temperature error?): lines {}",
            steep.len(),
            describe_lines(&steep)
        ));
    }

    // Rule 8.
    if levels.len() < MIN_LEVELS {
        return Err(SoundingError::file(
            path,
            format!(
                "only {} usable level(s) (with temperature and a height or pressure); at least {MIN_LEVELS} are needed",
                levels.len()
            ),
        ));
    }
    Ok(levels)
}

/// Rule 4: humidity → vapour pressure (Pa).
fn vapour_pressure(
    path: &Path,
    raw: &RawRow,
    temperature_k: f64,
    names: &ColumnNames,
) -> Result<Option<f64>, SoundingError> {
    let saturation = units::saturation_vapour_pressure_pa(temperature_k);
    let e = match raw.humidity {
        RawHumidity::None => return Ok(None),
        RawHumidity::DewpointK(td) => {
            if td > temperature_k + DEWPOINT_ROUNDING_TOLERANCE_K + 1e-9 {
                return Err(SoundingError::field(
                    path,
                    raw.line,
                    names.humidity.clone(),
                    format!(
                        "dewpoint {:.2} °C is above the temperature {:.2} °C by more than the {DEWPOINT_ROUNDING_TOLERANCE_K} K rounding tolerance",
                        units::kelvin_to_celsius(td),
                        units::kelvin_to_celsius(temperature_k)
                    ),
                ));
            }
            units::saturation_vapour_pressure_pa(td.min(temperature_k))
        }
        RawHumidity::RelativeHumidityPct(rh) => rh / 100.0 * saturation,
        RawHumidity::VapourPressurePa(e) => {
            if e > saturation * MAX_RELATIVE_HUMIDITY_PCT / 100.0 {
                return Err(SoundingError::field(
                    path,
                    raw.line,
                    names.humidity.clone(),
                    format!(
                        "vapour pressure {:.3} hPa exceeds {MAX_RELATIVE_HUMIDITY_PCT} % of saturation ({:.3} hPa) at {:.2} °C",
                        units::pa_to_hpa(e),
                        units::pa_to_hpa(saturation),
                        units::kelvin_to_celsius(temperature_k)
                    ),
                ));
            }
            e
        }
    };
    if !e.is_finite() || e < 0.0 {
        return Err(SoundingError::field(
            path,
            raw.line,
            names.humidity.clone(),
            "humidity gives no finite, non-negative vapour pressure",
        ));
    }
    if let Some(p) = raw.pressure_pa
        && e >= p
    {
        return Err(SoundingError::field(
            path,
            raw.line,
            names.humidity.clone(),
            "vapour pressure is not below the total pressure",
        ));
    }
    Ok(Some(e))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names() -> ColumnNames {
        ColumnNames {
            height: "height_m".into(),
            pressure: "pressure_hpa".into(),
            humidity: "dewpoint_c".into(),
        }
    }

    fn row(line: usize, h: Option<f64>, p_hpa: Option<f64>, t_c: Option<f64>) -> RawRow {
        RawRow {
            line,
            height_m: h,
            height_source: HeightSource::Measured,
            pressure_pa: p_hpa.map(units::hpa_to_pa),
            temperature_k: t_c.map(units::celsius_to_kelvin),
            humidity: RawHumidity::None,
        }
    }

    fn build(rows: Vec<RawRow>) -> Result<(Vec<Level>, Vec<String>), SoundingError> {
        let mut w = Vec::new();
        build_levels(Path::new("t.csv"), rows, &names(), true, &mut w).map(|l| (l, w))
    }

    #[test]
    fn parse_value_rejects_bad_text_with_location() {
        let p = Path::new("x.csv");
        let e =
            parse_value(p, 7, "temperature_c", "abc", Quantity::TemperatureC, true).unwrap_err();
        assert_eq!(
            e.to_string(),
            "x.csv: line 7, column temperature_c: cannot parse \"abc\" as a number"
        );
        for bad in [
            "NaN", "inf", "-inf", "//", "M", "-9999", "999.0", "-8888", "61", "-100.5",
        ] {
            let e = parse_value(p, 3, "temperature_c", bad, Quantity::TemperatureC, true);
            assert!(e.is_err(), "{bad} accepted");
        }
        assert!(parse_value(p, 3, "pressure_hpa", "9999.0", Quantity::PressureHpa, true).is_err());
        // 999 hPa and 999 m are real values, not sentinels.
        assert_eq!(
            parse_value(p, 3, "pressure_hpa", "999.0", Quantity::PressureHpa, true).unwrap(),
            Some(99_900.0)
        );
        assert_eq!(
            parse_value(p, 3, "height_m", "999", Quantity::HeightM, true).unwrap(),
            Some(999.0)
        );
        assert_eq!(
            parse_value(p, 3, "temperature_c", "  ", Quantity::TemperatureC, true).unwrap(),
            None
        );
        assert_eq!(
            parse_value(p, 3, "temperature_c", "-100", Quantity::TemperatureC, true).unwrap(),
            Some(173.14999999999998)
        );
    }

    #[test]
    fn impossible_temperature_steps_are_reported() {
        // 5 K over 0.1 mm (50 000 K/m): a height typo, not air.
        let (_, warnings) = build(vec![
            row(2, Some(0.0), Some(1000.0), Some(0.0)),
            row(3, Some(0.0001), Some(999.9), Some(-5.0)),
            row(4, Some(1800.0), Some(800.0), Some(-10.0)),
        ])
        .unwrap();
        assert_eq!(warnings.len(), 1, "{warnings:?}");
        assert!(
            warnings[0].contains("K/m") && warnings[0].contains("lines 3"),
            "{warnings:?}"
        );
        // The paper's strongest layer (+10 K over 15 m) is no warning.
        let (_, warnings) = build(vec![
            row(2, Some(0.0), Some(1000.0), Some(0.0)),
            row(3, Some(92.5), Some(988.5), Some(-0.6)),
            row(4, Some(107.5), Some(986.7), Some(9.3)),
            row(5, Some(1800.0), Some(800.0), Some(-10.0)),
        ])
        .unwrap();
        assert!(warnings.is_empty(), "{warnings:?}");
    }

    #[test]
    fn rows_without_temperature_are_skipped_and_counted() {
        let (levels, warnings) = build(vec![
            row(2, Some(0.0), Some(1000.0), Some(10.0)),
            row(3, Some(50.0), Some(994.0), None),
            row(4, Some(100.0), Some(988.0), Some(9.5)),
            row(5, Some(200.0), Some(976.0), Some(9.0)),
        ])
        .unwrap();
        assert_eq!(levels.len(), 3);
        assert!(warnings[0].contains("skipped 1 row") && warnings[0].contains("lines 3"));
    }

    #[test]
    fn row_with_neither_height_nor_pressure_is_rejected() {
        let e = build(vec![
            row(2, Some(0.0), Some(1000.0), Some(10.0)),
            row(3, None, None, Some(9.0)),
        ])
        .unwrap_err();
        assert_eq!(e.line(), Some(3));
        assert!(e.to_string().contains("cannot be placed"));
    }

    #[test]
    fn duplicates_merged_or_rejected() {
        let (levels, warnings) = build(vec![
            row(2, Some(0.0), Some(1000.0), Some(10.0)),
            row(3, Some(100.0), Some(988.0), Some(9.5)),
            row(4, Some(100.0), Some(988.0), Some(9.5)),
            row(5, Some(200.0), Some(976.0), Some(9.0)),
        ])
        .unwrap();
        assert_eq!(levels.len(), 3);
        assert!(
            warnings
                .iter()
                .any(|w| w.contains("merged 1 exact duplicate"))
        );
        let e = build(vec![
            row(2, Some(0.0), Some(1000.0), Some(10.0)),
            row(3, Some(100.0), Some(988.0), Some(9.5)),
            row(4, Some(100.0), Some(988.0), Some(9.4)),
            row(5, Some(200.0), Some(976.0), Some(9.0)),
        ])
        .unwrap_err();
        assert_eq!(e.line(), Some(4));
        assert!(e.to_string().contains("conflicting duplicate"), "{e}");
    }

    #[test]
    fn pressure_only_repeat_of_a_reported_level_is_merged() {
        // A Part B level repeating a Part A level (same pressure and temperature, no height).
        let (levels, warnings) = build(vec![
            row(2, Some(0.0), Some(1000.0), Some(10.0)),
            row(3, Some(100.0), Some(988.0), Some(9.5)),
            row(4, None, Some(988.0), Some(9.5)),
            row(5, None, Some(980.0), Some(9.0)),
        ])
        .unwrap();
        assert_eq!(levels.len(), 3);
        assert_eq!(levels[2].height_source, HeightSource::Hypsometric);
        assert!(
            warnings
                .iter()
                .any(|w| w.contains("merged 1") && w.contains("lines 4"))
        );
        // With a different temperature it is a conflict.
        let e = build(vec![
            row(2, Some(0.0), Some(1000.0), Some(10.0)),
            row(3, Some(100.0), Some(988.0), Some(9.5)),
            row(4, None, Some(988.0), Some(9.0)),
        ])
        .unwrap_err();
        assert_eq!(e.line(), Some(4));
    }

    #[test]
    fn decreasing_height_and_increasing_pressure_are_errors() {
        let e = build(vec![
            row(2, Some(0.0), Some(1000.0), Some(10.0)),
            row(3, Some(100.0), Some(988.0), Some(9.5)),
            row(4, Some(90.0), Some(987.0), Some(9.4)),
        ])
        .unwrap_err();
        assert_eq!((e.line(), e.column()), (Some(4), Some("height_m")));
        let e = build(vec![
            row(2, Some(0.0), Some(1000.0), Some(10.0)),
            row(3, Some(100.0), Some(988.0), Some(9.5)),
            row(4, Some(190.0), Some(989.0), Some(9.4)),
        ])
        .unwrap_err();
        assert_eq!((e.line(), e.column()), (Some(4), Some("pressure_hpa")));
        assert!(e.to_string().contains("pressure must decrease"), "{e}");
    }

    #[test]
    fn contradicting_levels_are_dropped_with_a_note_unless_strict_and_low() {
        let rows = |h_bad: f64| {
            vec![
                row(2, Some(0.0), Some(1000.0), Some(10.0)),
                row(3, Some(h_bad), Some(500.0), Some(-20.0)),
                row(4, Some(h_bad - 6.0), Some(499.0), Some(-20.1)),
                row(5, Some(h_bad + 100.0), Some(490.0), Some(-21.0)),
                row(6, Some(h_bad + 200.0), Some(491.0), Some(-21.5)),
            ]
        };
        let lenient = |rows| {
            let mut w = Vec::new();
            build_levels(Path::new("t.csv"), rows, &names(), false, &mut w).map(|l| (l, w))
        };
        // Lenient: the two contradicting levels go, each named in one note.
        let (levels, w) = lenient(rows(500.0)).unwrap();
        assert_eq!(levels.iter().map(|l| l.line).collect::<Vec<_>>(), [2, 3, 5]);
        let note = w.iter().find(|n| n.contains("contradict")).unwrap();
        assert!(note.starts_with("dropped 2 level(s)"), "{note}");
        assert!(
            note.contains("line 4, column height_m: height 494 m is not above 500 m at line 3"),
            "{note}"
        );
        assert!(note.contains("line 6, column pressure_hpa"), "{note}");
        // Strict: refused inside the lowest 3 km, dropped above it.
        let e = build(rows(500.0)).unwrap_err();
        assert_eq!((e.line(), e.column()), (Some(4), Some("height_m")));
        let (levels, w) = build(rows(STRICT_ZONE_M + 10.0)).unwrap();
        assert_eq!(levels.len(), 3);
        assert!(w.iter().any(|n| n.contains("dropped 2 level(s)")), "{w:?}");
        // Fewer than three usable levels left: refused whatever the mode.
        let e = lenient(rows(500.0)[..3].to_vec()).unwrap_err();
        assert!(e.to_string().contains("at least 3"), "{e}");
    }

    #[test]
    fn dewpoint_tolerance() {
        let mut r = row(2, Some(0.0), Some(1000.0), Some(10.0));
        r.humidity = RawHumidity::DewpointK(units::celsius_to_kelvin(10.1));
        let (levels, _) = build(vec![
            r.clone(),
            row(3, Some(100.0), Some(988.0), Some(9.5)),
            row(4, Some(200.0), Some(976.0), Some(9.0)),
        ])
        .unwrap();
        // Taken as saturated at the temperature.
        let es = units::saturation_vapour_pressure_pa(units::celsius_to_kelvin(10.0));
        assert_eq!(levels[0].vapour_pressure_pa, Some(es));
        r.humidity = RawHumidity::DewpointK(units::celsius_to_kelvin(10.2));
        let e = build(vec![r]).unwrap_err();
        assert_eq!((e.line(), e.column()), (Some(2), Some("dewpoint_c")));
    }

    #[test]
    fn too_few_levels() {
        let e = build(vec![
            row(2, Some(0.0), Some(1000.0), Some(10.0)),
            row(3, Some(100.0), Some(988.0), Some(9.5)),
        ])
        .unwrap_err();
        assert!(e.to_string().contains("at least 3"), "{e}");
    }

    #[test]
    fn high_resolution_descents_are_dropped_with_a_warning() {
        let mut rows: Vec<RawRow> = (0..300)
            .map(|i| {
                row(
                    i + 2,
                    Some(5.0 * i as f64),
                    Some(1000.0 - 0.6 * i as f64),
                    Some(0.0),
                )
            })
            .collect();
        // The sonde drops back 12 m for two seconds.
        rows.insert(101, row(999, Some(488.0), Some(940.7), Some(0.0)));
        rows.insert(102, row(1000, Some(493.0), Some(940.5), Some(0.0)));
        let (levels, warnings) = build(rows.clone()).unwrap();
        assert_eq!(levels.len(), 300);
        assert!(
            warnings
                .iter()
                .any(|w| w.contains("dropped 2 row") && w.contains("999, 1000"))
        );
        // The same glitch in a short list of reported levels is an error.
        let short: Vec<RawRow> = rows[95..110].to_vec();
        assert!(build(short).is_err());
    }

    #[test]
    fn high_resolution_detection() {
        let dense: Vec<f64> = (0..300).map(|i| 5.0 * i as f64).collect();
        assert!(is_high_resolution(&dense));
        let sparse: Vec<f64> = (0..300).map(|i| 100.0 * i as f64).collect();
        assert!(!is_high_resolution(&sparse));
        assert!(!is_high_resolution(&dense[..50]));
    }
}
