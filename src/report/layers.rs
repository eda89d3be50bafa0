//! Stage 3 output (`profile` command) — `layers.json` and the readable summary. In: a
//! [`LayersReport`] (surface air, inversions, ducts and refractive regimes of one atmosphere).
//! Out: JSON bytes and summary text.

use std::fmt::Write;

use serde::Serialize;

use crate::profile::{InversionKind, InversionLayer};
use crate::refractivity::regimes::{AUTOCONVECTIVE_LAPSE_K_PER_M, SUPER_REFRACTION_DNDH_PER_KM};
use crate::refractivity::{
    RefractiveAtmosphere, RefractiveLayer, RegimeKind, TableError,
    critical_temperature_gradient_k_per_m,
};
use crate::units::{EARTH_RADIUS_M, kelvin_to_celsius, pa_to_hpa};

/// The air at the surface.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SurfaceReport {
    /// Surface height above mean sea level (m).
    pub height_m: f64,
    /// Temperature (K).
    pub temperature_k: f64,
    /// Pressure (hPa).
    pub pressure_hpa: f64,
    /// Water-vapour partial pressure (hPa).
    pub vapour_pressure_hpa: f64,
    /// dT/dh (K m⁻¹).
    pub dt_dh_k_per_m: f64,
    /// n − 1.
    pub n_minus_1: f64,
    /// dn/dh (m⁻¹).
    pub dn_dh_per_m: f64,
    /// Critical (ducting) temperature gradient for the surface air (K m⁻¹).
    pub critical_gradient_k_per_m: f64,
}

/// A duct in `layers.json`: the required `base_m`, `top_m`, `min_dndh_per_km`, and more.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DuctReport {
    /// Duct base above mean sea level (m).
    pub base_m: f64,
    /// Duct top (top of the trapping layer) above mean sea level (m).
    pub top_m: f64,
    /// Smallest dN/dh in the trapping layer (N-units per km).
    pub min_dndh_per_km: f64,
    /// Duct base above the surface (m).
    pub base_agl_m: f64,
    /// Duct top above the surface (m).
    pub top_agl_m: f64,
    /// Base of the trapping layer above mean sea level (m).
    pub trapping_base_m: f64,
    /// Duct strength: M deficit (M-units).
    pub m_deficit: f64,
    /// Whether the duct reaches the surface.
    pub surface_based: bool,
}

/// The thresholds the regimes were classified with.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Thresholds {
    /// Trapping: dN/dh below this (N/km) = −10⁹/R.
    pub trapping_dndh_per_km: f64,
    /// Super-refraction: dN/dh below this (N/km).
    pub super_refraction_dndh_per_km: f64,
    /// Inferior mirage (dry hydrostatic air): dT/dh below this (K m⁻¹) = −g/R_d.
    pub inferior_mirage_dtdh_k_per_m: f64,
    /// Earth radius used (m).
    pub earth_radius_m: f64,
}

/// Everything `layers.json` and the summary hold.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LayersReport {
    /// What the report was made from (source, station, time, levels read, ingest notes).
    pub input: InputReport,
    /// Surface air.
    pub surface: SurfaceReport,
    /// Vacuum wavelength (nm).
    pub wavelength_nm: f64,
    /// CO₂ content (ppm).
    pub co2_ppm: f64,
    /// Temperature inversions (from the profile fit).
    pub inversions: Vec<InversionLayer>,
    /// Ducts, one per trapping layer.
    pub ducts: Vec<DuctReport>,
    /// All refractive layers (trapping, super-refraction, inferior mirage).
    pub regimes: Vec<RefractiveLayer>,
    /// Classification thresholds.
    pub thresholds: Thresholds,
    /// Measured accuracy of the refractive-index table.
    pub table_error: TableError,
}

/// What a report was made from. For a sounding: its file, format, station, nominal time, the
/// number of levels read and every ingest note; for a model atmosphere only the source and its
/// description.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct InputReport {
    /// The source as given (a file path, a `.toml`, `us1976`).
    pub source: String,
    /// One line saying what it is (station and time, the TOML's description, …).
    pub description: String,
    /// The sounding's file format, for soundings.
    pub format: Option<crate::sounding::SoundingFormat>,
    /// Station, as the file names it.
    pub station: Option<String>,
    /// Nominal time (`"YYYY-MM-DD HH"`, UTC), when the file gives one.
    pub nominal_time_utc: Option<String>,
    /// Levels read from the file (after ingest dropped or merged what it had to).
    pub levels_read: Option<usize>,
    /// What ingest skipped, merged or dropped, one line per kind.
    pub notes: Vec<String>,
    /// The temperature fit between the levels and why it was chosen, for soundings.
    pub fit: Option<crate::profile::FitChoice>,
}

impl InputReport {
    /// The input report of a sounding read from `source`, described as `description`.
    pub fn of_sounding(
        source: &str,
        description: &str,
        sounding: &crate::sounding::Sounding,
    ) -> Self {
        InputReport {
            source: source.to_string(),
            description: description.to_string(),
            format: Some(sounding.format),
            station: sounding.metadata.get("station").cloned(),
            nominal_time_utc: sounding
                .metadata
                .get("nominal_time_utc")
                .or_else(|| sounding.metadata.get("launch_time_utc"))
                .map(|t| report_time(t)),
            levels_read: Some(sounding.levels.len()),
            notes: sounding.warnings.clone(),
            fit: None,
        }
    }
}

/// A metadata time as reports show it: NCAR/EOL's comma form (`2024, 02, 26, 12:00:00`, kept as
/// given by normalised CSVs converted from ESC files) becomes `2024-02-26 12` when on the hour,
/// else `2024-02-26 11:20:12 UTC`; any other text is kept.
fn report_time(text: &str) -> String {
    match crate::sounding::time::CommaTime::parse(text) {
        Some(t) => t.nominal().unwrap_or_else(|| t.readable()),
        None => text.to_string(),
    }
}

impl LayersReport {
    /// Collect the report from the atmosphere, the inversions found by the fit and the regimes
    /// found by [`detect_regimes`](crate::refractivity::detect_regimes) (with R = 6 371 km).
    pub fn new(
        atm: &RefractiveAtmosphere,
        inversions: &[InversionLayer],
        regimes: &[RefractiveLayer],
    ) -> Self {
        let s = atm.sample_at(atm.surface_height_m());
        let surface = SurfaceReport {
            height_m: s.height_m,
            temperature_k: s.air.temperature_k,
            pressure_hpa: pa_to_hpa(s.air.pressure_pa),
            vapour_pressure_hpa: pa_to_hpa(s.air.vapour_pressure_pa),
            dt_dh_k_per_m: s.air.dtemperature_dh_k_per_m,
            n_minus_1: s.n_minus_1,
            dn_dh_per_m: s.dn_dh_per_m,
            critical_gradient_k_per_m: critical_temperature_gradient_k_per_m(
                s.air.temperature_k,
                s.air.pressure_pa,
                s.air.vapour_pressure_pa,
                atm.wavelength_nm() * 1e-9,
                EARTH_RADIUS_M,
            ),
        };
        let ducts = regimes
            .iter()
            .filter_map(|l| l.duct.as_ref())
            .map(|d| DuctReport {
                base_m: d.base_m,
                top_m: d.top_m,
                min_dndh_per_km: d.min_dndh_per_km,
                base_agl_m: d.base_agl_m,
                top_agl_m: d.top_agl_m,
                trapping_base_m: d.trapping_base_m,
                m_deficit: d.m_deficit,
                surface_based: d.surface_based,
            })
            .collect();
        Self {
            input: InputReport::default(),
            surface,
            wavelength_nm: atm.wavelength_nm(),
            co2_ppm: atm.co2_ppm(),
            inversions: inversions.to_vec(),
            ducts,
            regimes: regimes.to_vec(),
            thresholds: Thresholds {
                trapping_dndh_per_km: -1e9 / EARTH_RADIUS_M,
                super_refraction_dndh_per_km: SUPER_REFRACTION_DNDH_PER_KM,
                inferior_mirage_dtdh_k_per_m: -AUTOCONVECTIVE_LAPSE_K_PER_M,
                earth_radius_m: EARTH_RADIUS_M,
            },
            table_error: atm.table_max_error(),
        }
    }
}

/// `layers.json`: pretty-printed JSON of the report (`surface`, `inversions`, `ducts` in the
/// documented shape, plus `wavelength_nm`, `co2_ppm`, `regimes`, `thresholds`, `table_error`).
/// Non-finite numbers become `null`.
pub fn layers_json(report: &LayersReport) -> Vec<u8> {
    // The report is plain structs of numbers, strings and enums: serialising cannot fail.
    let mut value = serde_json::to_value(report).expect("LayersReport serialises");
    tidy_numbers(&mut value);
    let mut bytes = serde_json::to_vec_pretty(&value).expect("a JSON value serialises");
    bytes.push(b'\n');
    bytes
}

/// Significant digits every number of the JSON report keeps: far more than any of them is known
/// to, and few enough that rounding noise (`966.0000000000001` hPa) is not printed.
const JSON_SIGNIFICANT_DIGITS: usize = 10;

/// Round every float in `value` to [`JSON_SIGNIFICANT_DIGITS`].
fn tidy_numbers(value: &mut serde_json::Value) {
    match value {
        serde_json::Value::Number(n) if n.is_f64() => {
            if let Some(x) = n.as_f64() {
                let rounded: f64 = format!("{x:.*e}", JSON_SIGNIFICANT_DIGITS - 1)
                    .parse()
                    .unwrap_or(x);
                if let Some(tidy) = serde_json::Number::from_f64(rounded) {
                    *n = tidy;
                }
            }
        }
        serde_json::Value::Array(items) => items.iter_mut().for_each(tidy_numbers),
        serde_json::Value::Object(map) => map.values_mut().for_each(tidy_numbers),
        _ => {}
    }
}

/// The summary for `--format json`: the same content as [`layers_json`].
pub fn summary_json(report: &LayersReport) -> Vec<u8> {
    layers_json(report)
}

fn kind_name(kind: RegimeKind) -> &'static str {
    match kind {
        RegimeKind::Trapping => "trapping",
        RegimeKind::SuperRefraction => "super-refraction",
        RegimeKind::InferiorMirage => "inferior mirage",
    }
}

/// A readable summary: surface air, critical gradient, inversions, ducts and regimes.
pub fn summary_text(report: &LayersReport) -> String {
    let mut o = String::new();
    let input = &report.input;
    if let (Some(levels), Some(format)) = (input.levels_read, input.format) {
        let _ = writeln!(
            o,
            "Read {levels} levels from {} ({}), {} ingest note{}",
            input.source,
            format.description(),
            input.notes.len(),
            if input.notes.len() == 1 { "" } else { "s" }
        );
    }
    if let Some(fit) = &input.fit {
        let name = match fit.used {
            crate::profile::TemperatureFit::Linear => "linear in ln p",
            _ => "PCHIP",
        };
        let _ = writeln!(o, "Temperature fit: {name} ({})", fit.reason);
    }
    let s = &report.surface;
    // Writing to a String cannot fail; results are ignored.
    let _ = writeln!(
        o,
        "Surface {:.1} m: {:.2} °C, {:.2} hPa, vapour {:.2} hPa, dT/dh {:+.4} K/m",
        s.height_m,
        kelvin_to_celsius(s.temperature_k),
        s.pressure_hpa,
        s.vapour_pressure_hpa,
        s.dt_dh_k_per_m
    );
    let _ = writeln!(
        o,
        "  n − 1 = {:.3e} at {} nm, dN/dh = {:.1} N/km; critical gradient for ducting {:.4} K/m",
        s.n_minus_1,
        report.wavelength_nm,
        s.dn_dh_per_m * 1e9,
        s.critical_gradient_k_per_m
    );
    let _ = writeln!(o, "Inversions: {}", report.inversions.len());
    for inv in &report.inversions {
        let kind = match inv.kind {
            InversionKind::Surface => "surface",
            InversionKind::Elevated => "elevated",
        };
        let _ = writeln!(
            o,
            "  {kind:8} {:7.1}–{:7.1} m AGL: +{:.2} K, max {:.4} K/m",
            inv.base_agl_m, inv.top_agl_m, inv.delta_t_k, inv.max_gradient_k_per_m
        );
    }
    let _ = writeln!(o, "Ducts: {}", report.ducts.len());
    for d in &report.ducts {
        let _ = writeln!(
            o,
            "  {:7.1}–{:7.1} m AGL ({}; trapping from {:.1} m AGL), min dN/dh {:.0} N/km, ΔM {:.2}",
            d.base_agl_m,
            d.top_agl_m,
            if d.surface_based {
                "surface-based"
            } else {
                "elevated"
            },
            d.trapping_base_m - s.height_m,
            d.min_dndh_per_km,
            d.m_deficit
        );
    }
    let _ = writeln!(o, "Refractive layers: {}", report.regimes.len());
    for l in &report.regimes {
        let _ = writeln!(
            o,
            "  {:16} {:7.1}–{:7.1} m AGL: dN/dh {:.0}…{:.0} N/km, dT/dh {:+.4}…{:+.4} K/m",
            kind_name(l.kind),
            l.base_agl_m,
            l.top_agl_m,
            l.min_dndh_per_km,
            l.max_dndh_per_km,
            l.min_dtdh_k_per_m,
            l.max_dtdh_k_per_m
        );
    }
    let t = &report.table_error;
    let _ = writeln!(
        o,
        "Index table: max |Δn| {:.1e}, max |Δdn/dh| {:.1e} /m, {} of {} cells exact, {} cut at a \
         break (a level, layer edge or layer base)",
        t.max_abs_dn(),
        t.max_abs_ddndh_per_m(),
        t.exact_cells(),
        t.fine.cells + t.coarse.cells,
        t.fine.cut_cells + t.coarse.cut_cells
    );
    o
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::refractivity::columns::LapseRateColumn;
    use std::sync::Arc;

    #[test]
    fn input_report_shows_eol_comma_times_as_dates() {
        let mut sounding = crate::sounding::Sounding {
            source: "b.csv".into(),
            format: crate::sounding::SoundingFormat::NormalizedCsv,
            metadata: Default::default(),
            levels: Vec::new(),
            warnings: Vec::new(),
        };
        // The `#` lines of tests/data/soundings/Bjornoya-01028_2024022611.csv.
        let m = &mut sounding.metadata;
        m.insert("launch_time_utc".into(), "2024, 02, 26, 11:20:12".into());
        let time =
            |s: &crate::sounding::Sounding| InputReport::of_sounding("b", "", s).nominal_time_utc;
        assert_eq!(time(&sounding).as_deref(), Some("2024-02-26 11:20:12 UTC"));
        let m = &mut sounding.metadata;
        m.insert("nominal_time_utc".into(), "2024, 02, 26, 12:00:00".into());
        assert_eq!(time(&sounding).as_deref(), Some("2024-02-26 12"));
        let m = &mut sounding.metadata;
        m.insert("nominal_time_utc".into(), "2010-06-01 00".into());
        assert_eq!(time(&sounding).as_deref(), Some("2010-06-01 00"));
    }

    #[test]
    fn summary_lists_surface_and_inversions_and_json_round_trips() {
        let atm = RefractiveAtmosphere::new(
            Arc::new(LapseRateColumn {
                surface_height_m: 5.0,
                surface_temperature_k: 253.15,
                surface_pressure_pa: 102_000.0,
                gradient_k_per_m: 0.02,
                vapour_pressure_pa: 50.0,
                isothermal_above_agl_m: 300.0,
            }),
            550.0,
        )
        .unwrap();
        let inv = InversionLayer {
            base_m: 5.0,
            top_m: 305.0,
            base_agl_m: 0.0,
            top_agl_m: 300.0,
            delta_t_k: 6.0,
            max_gradient_k_per_m: 0.02,
            kind: InversionKind::Surface,
        };
        let report = LayersReport::new(&atm, &[inv], &[]);
        let text = summary_text(&report);
        assert!(
            text.contains("Surface 5.0 m: -20.00 °C, 1020.00 hPa"),
            "{text}"
        );
        assert!(
            text.contains("  surface ") && text.contains("0.0–  300.0 m AGL: +6.00 K"),
            "{text}"
        );
        assert!(text.contains("Ducts: 0"), "{text}");
        let v: serde_json::Value = serde_json::from_slice(&summary_json(&report)).unwrap();
        assert_eq!(v["inversions"][0]["kind"], "surface");
        assert_eq!(v["surface"]["pressure_hpa"], 1020.0);
        // Critical gradient at −20 °C, 1020 hPa: docs/references.md gives 0.0915 K/m at
        // 1013.25 hPa; higher pressure lowers it slightly (n − 1 ∝ P).
        let g = v["surface"]["critical_gradient_k_per_m"].as_f64().unwrap();
        assert!(g > 0.089 && g < 0.0915, "{g}");
    }
}
