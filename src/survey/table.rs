//! Survey — the table. In: [`SurveyRow`]s and the [`SurveyOptions`] that made them. Out: one
//! flat table, one row per sounding, as CSV bytes and as Parquet bytes (the columnar format
//! pandas, polars and DuckDB read directly). Both come from one column list ([`columns`]), so
//! they cannot disagree; a missing value (an unusable sounding, no duct) is an empty CSV field
//! and a Parquet null.
//!
//! Parquet is written with the `parquet` crate's low-level column writers (no Arrow): the table
//! is small and flat, and that keeps the dependency lean.

use std::sync::Arc;

use parquet::basic::{LogicalType, Repetition, Type as PhysicalType};
use parquet::data_type::{BoolType, ByteArray, ByteArrayType, DoubleType, Int64Type};
use parquet::file::properties::WriterProperties;
use parquet::file::writer::SerializedFileWriter;
use parquet::schema::types::Type;

use super::{CaseFacts, ObserverFacts, SurveyError, SurveyOptions, SurveyRow};

/// One cell.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// Text.
    Text(Option<String>),
    /// A real number.
    Float(Option<f64>),
    /// A count.
    Int(Option<i64>),
    /// Yes or no.
    Bool(Option<bool>),
}

type Getter = Box<dyn Fn(&SurveyRow) -> Value + Send + Sync>;

/// One column: its name (units in it) and how a row gives its value.
pub struct Column {
    /// Column name.
    pub name: String,
    get: Getter,
}

impl Column {
    /// The column's value in `row`.
    pub fn value(&self, row: &SurveyRow) -> Value {
        (self.get)(row)
    }
}

fn col(
    name: impl Into<String>,
    get: impl Fn(&SurveyRow) -> Value + Send + Sync + 'static,
) -> Column {
    Column {
        name: name.into(),
        get: Box::new(get),
    }
}

/// `f` of the row's layers, or null for an unusable row.
fn used<T>(row: &SurveyRow, f: impl Fn(&SurveyRow) -> T) -> Option<T> {
    row.unusable.is_none().then(|| f(row))
}

fn float(
    f: impl Fn(&SurveyRow) -> Option<f64> + Send + Sync + 'static,
) -> impl Fn(&SurveyRow) -> Value {
    move |r| Value::Float(used(r, &f).flatten())
}

/// The columns of a survey made with `options`: identity, surface, inversions, ducts, then per
/// observer height (`_h<H>m`) the horizon and sun, then per observer height × distance
/// (`_h<H>m_d<D>m`) the target's images.
pub fn columns(options: &SurveyOptions) -> Vec<Column> {
    let mut c = identity_columns();
    c.extend(layer_columns());
    for (k, &h) in options.observer_heights_m.iter().enumerate() {
        c.extend(observer_columns(k, &format!("h{h}m")));
    }
    let n = options.distances_m.len();
    for (k, &h) in options.observer_heights_m.iter().enumerate() {
        for (j, &d) in options.distances_m.iter().enumerate() {
            c.extend(case_columns(k * n + j, &format!("h{h}m_d{d}m")));
        }
    }
    c
}

fn identity_columns() -> Vec<Column> {
    vec![
        col("origin", |r| Value::Text(Some(r.origin.clone()))),
        col("station", |r| Value::Text(r.station.clone())),
        col("time_utc", |r| Value::Text(r.time_utc.clone())),
        col("month", |r| Value::Int(r.month().map(i64::from))),
        col("unusable_reason", |r| Value::Text(r.unusable.clone())),
    ]
}

fn layer_columns() -> Vec<Column> {
    vec![
        col(
            "surface_height_m",
            float(|r| Some(r.layers.surface_height_m)),
        ),
        col(
            "surface_temperature_k",
            float(|r| Some(r.layers.surface_temperature_k)),
        ),
        col(
            "surface_pressure_hpa",
            float(|r| Some(r.layers.surface_pressure_hpa)),
        ),
        col(
            "surface_dt_dh_k_per_m",
            float(|r| Some(r.layers.surface_dt_dh_k_per_m)),
        ),
        col("inversion_count", |r| {
            Value::Int(used(r, |r| r.layers.inversion_count as i64))
        }),
        col("surface_inversion", |r| {
            Value::Bool(used(r, |r| r.layers.surface_inversion))
        }),
        col(
            "strongest_inversion_dt_k",
            float(|r| r.layers.strongest_inversion.map(|s| s.0)),
        ),
        col(
            "strongest_inversion_base_m",
            float(|r| r.layers.strongest_inversion.map(|s| s.1)),
        ),
        col(
            "strongest_inversion_top_m",
            float(|r| r.layers.strongest_inversion.map(|s| s.2)),
        ),
        col(
            "max_inversion_gradient_k_per_m",
            float(|r| r.layers.max_inversion_gradient_k_per_m),
        ),
        col("duct_count", |r| {
            Value::Int(used(r, |r| r.layers.duct_count as i64))
        }),
        col("surface_duct", |r| {
            Value::Bool(used(r, |r| r.layers.surface_duct))
        }),
        col(
            "strongest_duct_base_m",
            float(|r| r.layers.strongest_duct.map(|d| d.0)),
        ),
        col(
            "strongest_duct_top_m",
            float(|r| r.layers.strongest_duct.map(|d| d.1)),
        ),
        col(
            "strongest_duct_delta_m_units",
            float(|r| r.layers.strongest_duct.map(|d| d.2)),
        ),
        col("lowest_trapping_m", float(|r| r.layers.lowest_trapping_m)),
    ]
}

fn observer(r: &SurveyRow, k: usize) -> Option<&ObserverFacts> {
    r.observers.get(k)
}

fn observer_columns(k: usize, tag: &str) -> Vec<Column> {
    let f = |get: fn(&ObserverFacts) -> Option<f64>| {
        move |r: &SurveyRow| Value::Float(observer(r, k).and_then(get))
    };
    vec![
        col(format!("horizon_dip_deg_{tag}"), f(|o| o.horizon_dip_deg)),
        col(format!("dip_anomaly_deg_{tag}"), f(|o| o.dip_anomaly_deg)),
        col(format!("lowest_sun_deg_{tag}"), f(|o| o.lowest_sun_deg)),
        col(
            format!("sun_depth_anomaly_deg_{tag}"),
            f(|o| o.sun_depth_anomaly_deg),
        ),
        col(format!("trapped_rays_{tag}"), move |r| {
            Value::Int(observer(r, k).map(|o| o.trapped_rays as i64))
        }),
        col(format!("novaya_zemlya_{tag}"), move |r| {
            Value::Bool(observer(r, k).map(|o| o.novaya_zemlya))
        }),
    ]
}

fn case(r: &SurveyRow, k: usize) -> Option<&CaseFacts> {
    r.cases.get(k)
}

fn case_columns(k: usize, tag: &str) -> Vec<Column> {
    let b = |get: fn(&CaseFacts) -> bool| move |r: &SurveyRow| Value::Bool(case(r, k).map(get));
    vec![
        col(format!("images_{tag}"), move |r| {
            Value::Int(case(r, k).map(|c| c.images as i64))
        }),
        col(format!("inverted_{tag}"), b(|c| c.inverted)),
        col(format!("superior_{tag}"), b(|c| c.superior)),
        col(format!("inferior_{tag}"), b(|c| c.inferior)),
        col(format!("fata_morgana_{tag}"), b(|c| c.images >= 3)),
        col(format!("max_magnification_{tag}"), move |r| {
            Value::Float(case(r, k).and_then(|c| c.max_magnification))
        }),
    ]
}

/// The rows as CSV: a header of the column names, then one line per row.
pub fn to_csv(rows: &[SurveyRow], columns: &[Column]) -> Result<Vec<u8>, SurveyError> {
    let table = |e: csv::Error| SurveyError::Table(e.to_string());
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record(columns.iter().map(|c| c.name.as_str()))
        .map_err(table)?;
    for row in rows {
        let cells = columns.iter().map(|c| match c.value(row) {
            Value::Text(v) => v.unwrap_or_default(),
            Value::Float(v) => v.map(|x| format!("{x}")).unwrap_or_default(),
            Value::Int(v) => v.map(|x| x.to_string()).unwrap_or_default(),
            Value::Bool(v) => v.map(|x| x.to_string()).unwrap_or_default(),
        });
        w.write_record(cells).map_err(table)?;
    }
    w.into_inner()
        .map_err(|e| SurveyError::Table(e.to_string()))
}

/// The Parquet schema of `columns`: every column optional; text as UTF-8 strings.
fn schema(columns: &[Column], sample: &[SurveyRow; 1]) -> Result<Type, SurveyError> {
    let fields = columns
        .iter()
        .map(|c| {
            let kind = kind_of(c, sample);
            let builder =
                Type::primitive_type_builder(&c.name, kind.0).with_repetition(Repetition::OPTIONAL);
            let builder = match kind.1 {
                true => builder.with_logical_type(Some(LogicalType::String)),
                false => builder,
            };
            builder.build().map(Arc::new)
        })
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| SurveyError::Table(e.to_string()))?;
    Type::group_type_builder("survey")
        .with_fields(fields)
        .build()
        .map_err(|e| SurveyError::Table(e.to_string()))
}

/// The physical type of a column (and whether it is text), from what its getter returns.
fn kind_of(column: &Column, sample: &[SurveyRow; 1]) -> (PhysicalType, bool) {
    match column.value(&sample[0]) {
        Value::Float(_) => (PhysicalType::DOUBLE, false),
        Value::Int(_) => (PhysicalType::INT64, false),
        Value::Bool(_) => (PhysicalType::BOOLEAN, false),
        Value::Text(_) => (PhysicalType::BYTE_ARRAY, true),
    }
}

/// The rows as a Parquet file (one row group, uncompressed).
pub fn to_parquet(rows: &[SurveyRow], columns: &[Column]) -> Result<Vec<u8>, SurveyError> {
    let table = |e: parquet::errors::ParquetError| SurveyError::Table(e.to_string());
    let placeholder = [placeholder_row()];
    let schema = Arc::new(schema(columns, &placeholder)?);
    let kinds: Vec<PhysicalType> = columns.iter().map(|c| kind_of(c, &placeholder).0).collect();
    let props = Arc::new(
        WriterProperties::builder()
            .set_created_by("ghostship".into())
            .build(),
    );
    let mut out = Vec::new();
    let mut writer = SerializedFileWriter::new(&mut out, schema, props).map_err(table)?;
    let mut group = writer.next_row_group().map_err(table)?;
    let mut k = 0;
    while let Some(mut column) = group.next_column().map_err(table)? {
        let values: Vec<Value> = rows.iter().map(|r| columns[k].value(r)).collect();
        write_column(&mut column, &values, kinds[k]).map_err(table)?;
        column.close().map_err(table)?;
        k += 1;
    }
    group.close().map_err(table)?;
    writer.close().map_err(table)?;
    Ok(out)
}

/// A row whose getters show each column's type (values do not matter).
fn placeholder_row() -> SurveyRow {
    SurveyRow {
        origin: String::new(),
        station: None,
        time_utc: None,
        unusable: None,
        layers: Default::default(),
        observers: Vec::new(),
        cases: Vec::new(),
    }
}

/// Write one column's values with definition levels (1 present, 0 null).
fn write_column(
    column: &mut parquet::file::writer::SerializedColumnWriter<'_>,
    values: &[Value],
    kind: PhysicalType,
) -> Result<(), parquet::errors::ParquetError> {
    let defs: Vec<i16> = values.iter().map(|v| i16::from(!is_null(v))).collect();
    macro_rules! put {
        ($ty:ty, $variant:ident, $map:expr) => {{
            let present: Vec<_> = values
                .iter()
                .filter_map(|v| match v {
                    Value::$variant(Some(x)) => Some($map(x)),
                    _ => None,
                })
                .collect();
            column
                .typed::<$ty>()
                .write_batch(&present, Some(&defs), None)?;
        }};
    }
    match kind {
        PhysicalType::DOUBLE => put!(DoubleType, Float, |x: &f64| *x),
        PhysicalType::INT64 => put!(Int64Type, Int, |x: &i64| *x),
        PhysicalType::BOOLEAN => put!(BoolType, Bool, |x: &bool| *x),
        _ => put!(ByteArrayType, Text, |x: &String| ByteArray::from(
            x.as_str()
        )),
    }
    Ok(())
}

fn is_null(v: &Value) -> bool {
    matches!(
        v,
        Value::Text(None) | Value::Float(None) | Value::Int(None) | Value::Bool(None)
    )
}
