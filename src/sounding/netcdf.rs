//! Stage 1 — ingest: netCDF sounding reader (cargo feature `netcdf`). In: the bytes of a netCDF
//! file (classic or netCDF-4) holding one radiosonde ascent, as ARM and GRUAN distribute them.
//! Out: metadata and raw rows for [`super::validate`].
//!
//! Two products are recognised, by their variable names:
//!
//! | product | pressure | temperature | height | humidity | file metadata |
//! |---|---|---|---|---|---|
//! | ARM `sondewnpn` (b1) | `pres` | `tdry` | `alt` | `rh`, else `dp` | `site_id`, `facility_id`, `base_time` + `time_offset`, `lat`/`lon`/`alt` of the first record |
//! | GRUAN RS92 / RS41 GDP | `press` | `temp` | `alt` | `rh` | `g.General.*`, `g.MeasuringSystem.*`, `g.Ascent.StartTime` / `StandardTime` |
//!
//! Every data variable is one-dimensional along the record dimension (`time`); a record is a
//! level, and its 1-based index is the level's "line" in messages. A value is missing when it is
//! NaN, equals the variable's `_FillValue` or `missing_value` attribute, or is netCDF's default
//! fill (about 9.97e36). Units come from each variable's `units` attribute (hPa/mb, kPa, Pa;
//! K, °C; m, km; %, fraction "1") and are converted to SI; a variable without a known unit is an
//! error. Relative humidity is preferred over ARM's dewpoint: the sensor measures humidity and
//! `dp` is derived from it. Heights are the files' `alt` (GPS altitude above mean sea level).
//!
//! The netCDF C library (through the `netcdf` crate) reads the file from memory, so the input
//! size limit of [`crate::input`] applies as for every other format.

use std::collections::BTreeMap;
use std::path::Path;

use ::netcdf::{AttributeValue, File};

use super::HeightSource;
use super::error::SoundingError;
use super::validate::{ColumnNames, Quantity, RawHumidity, RawRow, check_range};
use crate::units;

/// The two products read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Arm,
    Gruan,
}

/// The variables of one product.
struct Product {
    kind: Kind,
    /// Name for messages and the `product` metadata.
    name: &'static str,
    pressure: &'static str,
    temperature: &'static str,
    height: &'static str,
    /// Humidity variables, preferred first: relative humidity, then dewpoint.
    relative_humidity: &'static str,
    dewpoint: Option<&'static str>,
}

const ARM: Product = Product {
    kind: Kind::Arm,
    name: "ARM sondewnpn",
    pressure: "pres",
    temperature: "tdry",
    height: "alt",
    relative_humidity: "rh",
    dewpoint: Some("dp"),
};

const GRUAN: Product = Product {
    kind: Kind::Gruan,
    name: "GRUAN GDP",
    pressure: "press",
    temperature: "temp",
    height: "alt",
    relative_humidity: "rh",
    dewpoint: None,
};

/// Values above this magnitude are netCDF's default fill (`NC_FILL_FLOAT` = 9.9692e36).
const DEFAULT_FILL_ABOVE: f64 = 9.0e36;

/// One variable read in full: its name and its values in SI (`None` = missing).
struct Column {
    name: String,
    values_si: Vec<Option<f64>>,
}

/// Reads the netCDF sounding in `bytes` (the file `path`): metadata into `metadata`, one raw row
/// per record.
pub(crate) fn read(
    path: &Path,
    bytes: &[u8],
    metadata: &mut BTreeMap<String, String>,
) -> Result<(Vec<RawRow>, ColumnNames), SoundingError> {
    let file = ::netcdf::open_mem(None, bytes)
        .map_err(|e| SoundingError::file(path, format!("cannot open as netCDF: {e}")))?;
    let product = detect(path, &file)?;
    metadata.insert("product".into(), product_name(&file, &product));
    let pressure = column(path, &file, product.pressure, Quantity::PressurePa)?;
    let temperature = column(path, &file, product.temperature, Quantity::TemperatureK)?;
    let height = column(path, &file, product.height, Quantity::HeightM)?;
    let rh = optional_column(
        path,
        &file,
        product.relative_humidity,
        Quantity::RelativeHumidityPct,
    )?;
    let dewpoint = match product.dewpoint {
        Some(name) => optional_column(path, &file, name, Quantity::DewpointK)?,
        None => None,
    };
    let records = pressure.values_si.len();
    for c in [&temperature, &height]
        .into_iter()
        .chain(&rh)
        .chain(&dewpoint)
    {
        if c.values_si.len() != records {
            return Err(SoundingError::file(
                path,
                format!(
                    "variable {} has {} values but {} has {records}: they must share the record dimension",
                    c.name,
                    c.values_si.len(),
                    pressure.name
                ),
            ));
        }
    }
    if product.kind == Kind::Arm {
        arm_metadata(&file, &height, metadata);
    } else {
        gruan_metadata(&file, metadata);
    }
    let rows = (0..records)
        .map(|i| RawRow {
            line: i + 1,
            height_m: height.values_si[i],
            height_source: HeightSource::Measured,
            pressure_pa: pressure.values_si[i],
            temperature_k: temperature.values_si[i],
            humidity: humidity(i, rh.as_ref(), dewpoint.as_ref()),
        })
        .collect();
    let humidity_name = rh
        .or(dewpoint)
        .map_or(product.relative_humidity.into(), |c| c.name);
    Ok((
        rows,
        ColumnNames {
            height: height.name,
            pressure: pressure.name,
            humidity: humidity_name,
        },
    ))
}

/// Which product the file is, from its variable names.
fn detect(path: &Path, file: &File) -> Result<Product, SoundingError> {
    let has = |name: &str| file.variable(name).is_some();
    for product in [ARM, GRUAN] {
        if has(product.pressure) && has(product.temperature) && has(product.height) {
            return Ok(product);
        }
    }
    let mut names: Vec<String> = file.variables().map(|v| v.name()).collect();
    names.truncate(20);
    Err(SoundingError::file(
        path,
        format!(
            "a netCDF file, but not a known sounding product: expected the variables pres, tdry \
             and alt (ARM sondewnpn) or press, temp and alt (GRUAN GDP); the file has {}",
            names.join(", ")
        ),
    ))
}

/// `ARM sondewnpn-b1-2.1`, `GRUAN RS92-GDP version 2`, or the product's plain name.
fn product_name(file: &File, product: &Product) -> String {
    let text = |name: &str| global_text(file, name);
    if product.kind == Kind::Arm {
        return text("dod_version").map_or(product.name.into(), |v| format!("ARM {v}"));
    }
    match (text("g.Product.Code"), text("g.Product.Version")) {
        (Some(code), Some(version)) => format!("GRUAN {code} version {version}"),
        (Some(code), None) => format!("GRUAN {code}"),
        _ => product.name.into(),
    }
}

/// The variable `name`, or `None` if the file has no such variable.
fn optional_column(
    path: &Path,
    file: &File,
    name: &str,
    quantity: Quantity,
) -> Result<Option<Column>, SoundingError> {
    if file.variable(name).is_none() {
        return Ok(None);
    }
    column(path, file, name, quantity).map(Some)
}

/// The variable `name` read in full, in SI, with missing values as `None` and every present
/// value range-checked (an out-of-range value names its record and the variable).
fn column(
    path: &Path,
    file: &File,
    name: &str,
    quantity: Quantity,
) -> Result<Column, SoundingError> {
    let bad = |message: String| SoundingError::file(path, format!("variable {name}: {message}"));
    let var = file
        .variable(name)
        .ok_or_else(|| bad("missing from the file".into()))?;
    if var.dimensions().len() != 1 {
        return Err(bad(format!(
            "has {} dimensions; a sounding variable has one (the record dimension)",
            var.dimensions().len()
        )));
    }
    let units = match var.attribute_value("units") {
        Some(Ok(AttributeValue::Str(units))) => units,
        _ => return Err(bad("has no text `units` attribute".into())),
    };
    let to_si = conversion(quantity, &units).ok_or_else(|| {
        bad(format!(
            "unknown units {units:?} for {}",
            quantity_name(quantity)
        ))
    })?;
    let mut missing = Vec::new();
    for attribute in ["_FillValue", "missing_value"] {
        if let Some(Ok(value)) = var.attribute_value(attribute) {
            missing.extend(numbers(value));
        }
    }
    let raw: Vec<f64> = var
        .get_values::<f64, _>(..)
        .map_err(|e| bad(format!("cannot read the values: {e}")))?;
    let mut values_si = Vec::with_capacity(raw.len());
    for (i, value) in raw.into_iter().enumerate() {
        let is_missing =
            value.is_nan() || value.abs() > DEFAULT_FILL_ABOVE || missing.contains(&value);
        values_si.push(if is_missing {
            None
        } else {
            let shown = format!("{value} {units}");
            Some(check_range(
                path,
                i + 1,
                name,
                quantity,
                to_si(value),
                &shown,
            )?)
        });
    }
    Ok(Column {
        name: name.into(),
        values_si,
    })
}

/// What a quantity is, for messages.
fn quantity_name(quantity: Quantity) -> &'static str {
    match quantity {
        Quantity::PressurePa | Quantity::PressureHpa => "a pressure (expected hPa, mb, kPa or Pa)",
        Quantity::HeightM => "a height (expected m or km)",
        Quantity::RelativeHumidityPct => "a relative humidity (expected % or 1)",
        _ => "a temperature (expected K or degC)",
    }
}

/// The conversion from the file's `units` to SI (Pa, K, m, %), if the unit is known.
fn conversion(quantity: Quantity, units: &str) -> Option<fn(f64) -> f64> {
    let units = units.trim().to_ascii_lowercase().replace(['_', ' '], "");
    let units = units.trim_start_matches('°');
    match quantity {
        Quantity::PressurePa | Quantity::PressureHpa => match units {
            "hpa" | "mb" | "mbar" | "millibar" | "millibars" | "hectopascal" | "hectopascals" => {
                Some(units::hpa_to_pa)
            }
            "kpa" => Some(|v| v * 1000.0),
            "pa" | "pascal" | "pascals" => Some(|v| v),
            _ => None,
        },
        Quantity::TemperatureK | Quantity::DewpointK => match units {
            "k" | "degk" | "kelvin" | "degreesk" => Some(|v| v),
            "c" | "degc" | "celsius" | "degreecelsius" | "degreescelsius" | "degreesc" => {
                Some(units::celsius_to_kelvin)
            }
            _ => None,
        },
        Quantity::HeightM => match units {
            "m" | "meter" | "meters" | "metre" | "metres" | "gpm" => Some(|v| v),
            "km" => Some(|v| v * 1000.0),
            _ => None,
        },
        Quantity::RelativeHumidityPct => match units {
            "%" | "percent" => Some(|v| v),
            "1" | "" | "fraction" => Some(|v| v * 100.0),
            _ => None,
        },
        _ => None,
    }
}

/// The numbers of a numeric attribute (scalar or vector); empty for text.
fn numbers(value: AttributeValue) -> Vec<f64> {
    match value {
        AttributeValue::Floats(v) => v.into_iter().map(f64::from).collect(),
        AttributeValue::Doubles(v) => v,
        AttributeValue::Shorts(v) => v.into_iter().map(f64::from).collect(),
        AttributeValue::Ints(v) => v.into_iter().map(f64::from).collect(),
        AttributeValue::Schars(v) => v.into_iter().map(f64::from).collect(),
        AttributeValue::Uchars(v) => v.into_iter().map(f64::from).collect(),
        AttributeValue::Ushorts(v) => v.into_iter().map(f64::from).collect(),
        AttributeValue::Uints(v) => v.into_iter().map(f64::from).collect(),
        scalar => f64::try_from(scalar).into_iter().collect(),
    }
}

/// Humidity of record `i`: relative humidity if present there, else the dewpoint.
fn humidity(i: usize, rh: Option<&Column>, dewpoint: Option<&Column>) -> RawHumidity {
    let at = |c: Option<&Column>| c.and_then(|c| c.values_si[i]);
    match (at(rh), at(dewpoint)) {
        (Some(rh_pct), _) => RawHumidity::RelativeHumidityPct(rh_pct),
        (None, Some(td_k)) => RawHumidity::DewpointK(td_k),
        (None, None) => RawHumidity::None,
    }
}

/// A global text attribute, trimmed; `None` if absent, empty or not text.
fn global_text(file: &File, name: &str) -> Option<String> {
    match file.attribute(name)?.value().ok()? {
        AttributeValue::Str(s) => Some(s.trim().to_string()).filter(|s| !s.is_empty()),
        _ => None,
    }
}

/// The first non-missing value of the variable `name` (in the file's units), if any.
fn first_value(file: &File, name: &str) -> Option<f64> {
    let var = file.variable(name)?;
    let mut missing = Vec::new();
    for attribute in ["_FillValue", "missing_value"] {
        if let Some(Ok(value)) = var.attribute_value(attribute) {
            missing.extend(numbers(value));
        }
    }
    var.get_values::<f64, _>(..)
        .ok()?
        .into_iter()
        .find(|v| v.is_finite() && v.abs() <= DEFAULT_FILL_ABOVE && !missing.contains(v))
}

/// `value` rounded to `1 / per_unit` (per_unit = 10: one decimal).
fn round_to(value: f64, per_unit: f64) -> f64 {
    (value * per_unit).round() / per_unit
}

/// ARM metadata: site and facility, the position of the first record, the launch time.
fn arm_metadata(file: &File, height: &Column, metadata: &mut BTreeMap<String, String>) {
    let station = [
        global_text(file, "site_id"),
        global_text(file, "facility_id"),
    ];
    let station: Vec<String> = station.into_iter().flatten().collect();
    if !station.is_empty() {
        metadata.insert("station".into(), station.join(" "));
    }
    // Rounded to 1e-5° and 0.1 m (about a metre or less): the files store float32, whose
    // decimal expansion (36.61000061035156) is noise.
    for (key, variable) in [("latitude", "lat"), ("longitude", "lon")] {
        if let Some(v) = first_value(file, variable) {
            metadata.insert(key.into(), round_to(v, 1e5).to_string());
        }
    }
    if let Some(&h) = height.values_si.iter().flatten().next() {
        metadata.insert(
            "station_elevation_m".into(),
            format!("{} (altitude of the first record)", round_to(h, 10.0)),
        );
    }
    if let Some(serial) = global_text(file, "serial_number") {
        metadata.insert("sonde_serial_number".into(), serial);
    }
    if let Some(launch) = arm_launch_time(file) {
        metadata.insert("launch_time_utc".into(), launch);
    }
}

/// `base_time` (seconds since 1970-01-01 UTC) plus the first `time_offset`, as
/// `YYYY-MM-DD HH:MM:SS UTC`; `None` if either is missing or `base_time` has another epoch.
fn arm_launch_time(file: &File) -> Option<String> {
    let base = file.variable("base_time")?;
    let units = match base.attribute_value("units")?.ok()? {
        AttributeValue::Str(s) => s,
        _ => return None,
    };
    let epoch = units.trim().strip_prefix("seconds since ")?;
    if !(epoch.starts_with("1970-1-1 0:00:00") || epoch.starts_with("1970-01-01 00:00:00")) {
        return None;
    }
    let base_s = base.get_value::<f64, _>(..).ok()?;
    let offset_s = first_value(file, "time_offset").unwrap_or(0.0);
    let seconds = (base_s + offset_s).round();
    if !seconds.is_finite() || seconds.abs() > 1e11 {
        return None;
    }
    let time = jiff::Timestamp::from_second(seconds as i64).ok()?;
    Some(time.strftime("%Y-%m-%d %H:%M:%S UTC").to_string())
}

/// GRUAN metadata from the `g.*` global attributes.
fn gruan_metadata(file: &File, metadata: &mut BTreeMap<String, String>) {
    let text = |name: &str| global_text(file, name);
    let station = match (text("g.General.SiteName"), text("g.General.SiteCode")) {
        (Some(name), Some(code)) => Some(format!("{name} ({code})")),
        (name, code) => name.or(code),
    };
    if let Some(station) = station {
        metadata.insert("station".into(), station);
    }
    if let Some(wmo) = text("g.General.SiteWmoId") {
        metadata.insert("wmo_id".into(), wmo);
    }
    // "46.81 °", "491.0 m": the number, without its unit.
    for (key, attribute) in [
        ("latitude", "g.MeasuringSystem.Latitude"),
        ("longitude", "g.MeasuringSystem.Longitude"),
        ("station_elevation_m", "g.MeasuringSystem.Altitude"),
    ] {
        let number = text(attribute)
            .and_then(|v| v.split_whitespace().next().map(str::to_string))
            .filter(|v| v.parse::<f64>().is_ok_and(f64::is_finite));
        if let Some(number) = number {
            metadata.insert(key.into(), number);
        }
    }
    if let Some(start) = text("g.Ascent.StartTime") {
        metadata.insert(
            "launch_time_utc".into(),
            format!("{} UTC", start.replacen('T', " ", 1)),
        );
    }
    if let Some(nominal) =
        text("g.Ascent.StandardTime").and_then(|t| super::time::canonical_time(&t).ok())
    {
        metadata.insert("nominal_time_utc".into(), nominal);
    }
    if let Some(instrument) = text("g.Instrument.Type") {
        metadata.insert("instrument".into(), instrument);
    }
    if let Some(serial) = text("g.Instrument.SerialNumber") {
        metadata.insert("sonde_serial_number".into(), serial);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_convert_to_si() {
        let p = |u| conversion(Quantity::PressurePa, u).map(|f| f(1.5));
        assert_eq!(p("hPa"), Some(150.0));
        assert_eq!(p("mb"), Some(150.0));
        assert_eq!(p("kPa"), Some(1500.0));
        assert_eq!(p("Pa"), Some(1.5));
        assert_eq!(p("psi"), None);
        let t = |u| conversion(Quantity::TemperatureK, u).map(|f| f(10.0));
        assert_eq!(t("C"), Some(283.15));
        assert_eq!(t("degC"), Some(283.15));
        assert_eq!(t("°C"), Some(283.15));
        assert_eq!(t("degree_Celsius"), Some(283.15));
        assert_eq!(t("K"), Some(10.0));
        assert_eq!(t("F"), None);
        let rh = |u| conversion(Quantity::RelativeHumidityPct, u).map(|f| f(0.5));
        assert_eq!(rh("1"), Some(50.0));
        assert_eq!(rh("%"), Some(0.5));
        let h = |u| conversion(Quantity::HeightM, u).map(|f| f(2.0));
        assert_eq!((h("m"), h("km"), h("ft")), (Some(2.0), Some(2000.0), None));
    }

    #[test]
    fn attribute_numbers_are_read_from_scalars_and_vectors() {
        assert_eq!(numbers(AttributeValue::Float(-9999.0)), vec![-9999.0]);
        assert_eq!(
            numbers(AttributeValue::Doubles(vec![1.0, 2.0])),
            vec![1.0, 2.0]
        );
        assert_eq!(numbers(AttributeValue::Short(-99)), vec![-99.0]);
        assert!(numbers(AttributeValue::Str("x".into())).is_empty());
    }
}
