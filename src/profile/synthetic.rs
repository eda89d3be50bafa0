//! Stage 2 — synthetic (paper-style) atmospheres. In: a TOML description (surface, background,
//! humidity, layers). Out: a [`SyntheticAtmosphere`], an [`AirColumn`] with analytic T and dT/dh
//! and an accurate hydrostatic P.
//!
//! ```toml
//! description = "superior mirage"  # optional free text
//! surface_height_m = 0.0           # optional, default 0
//! surface_temperature_c = 0.0
//! surface_pressure_hpa = 1013.25
//! background = -0.0065             # lapse rate (K/m) up to `tropopause_m`, or "us1976"
//! tropopause_m = 11000.0           # optional with a lapse rate, default 11 000 m
//! relative_humidity_percent = 0.0  # optional, absent = dry air
//!
//! [[layers]]                        # smooth step: T += ΔT·½·(1 + tanh((h − centre)/(L/4)))
//! centre_m = 100.0                  # or base_m (centre = base + L/2)
//! thickness_m = 15.0                # L: 96 % of the change happens inside it
//! delta_t_k = 10.0
//!
//! [[layers]]                        # constant gradient: T += g·(clamp(h, from, to) − from)
//! from_m = 0.0
//! to_m = 100.0
//! gradient_k_per_m = 0.112
//! ```
//!
//! Temperature is the background plus every layer's contribution (layers add, so they may
//! overlap), offset by the layers' sum at the surface so that T(surface) is exactly the given
//! surface temperature (this only matters for a layer touching the ground). A lapse-rate background holds from the surface up to `tropopause_m`; above it the
//! temperature follows the shape of US1976, shifted to join continuously. `background = "us1976"`
//! is US1976's shape shifted to the surface temperature. Step layers are C^∞; a constant-gradient
//! layer is continuous in T with a jump in dT/dh at its ends (as the paper's layer is meant).
//! Pressure: d(ln P)/dh = −g₀/(R_d·T_v) integrated once at construction (RK4, 0.25 m nodes up to
//! 500 m above the highest layer, 10 m above) and interpolated in ln P by a cubic Hermite with
//! the exact hydrostatic slopes at the nodes. Vapour: e = RH·e_s(T) (Magnus, `units.rs`).

use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

use super::error::line_column;
use super::hydrostatic::{HydrostaticTable, virtual_temperature_k};
use super::us1976::us1976_temperature;
use super::{AirColumn, AirSample, MODEL_TOP_M, ProfileError};
use crate::units::{
    celsius_to_kelvin, hpa_to_pa, kelvin_to_celsius, saturation_vapour_pressure_pa,
};

/// The background temperature profile of a synthetic atmosphere.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Background {
    /// A constant lapse rate from the surface up to `tropopause_m`, the US1976 shape above.
    Lapse {
        /// dT/dh (K m⁻¹), e.g. −0.0065.
        lapse_rate_k_per_m: f64,
        /// Top of the constant lapse (m above mean sea level).
        tropopause_m: f64,
    },
    /// The US1976 shape, shifted to the surface temperature.
    Us1976,
}

/// One layer added to the background temperature.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SyntheticLayer {
    /// T += ΔT·½·(1 + tanh((h − centre)/(L/4))).
    Step {
        /// Centre of the step (m above mean sea level).
        centre_m: f64,
        /// Thickness L (m): 96 % of the change happens within centre ± L/2.
        thickness_m: f64,
        /// Temperature change across the layer (K); negative for a layer that cools upward.
        delta_t_k: f64,
    },
    /// T += g·(clamp(h, from, to) − from).
    Gradient {
        /// Bottom of the layer (m above mean sea level).
        from_m: f64,
        /// Top of the layer (m above mean sea level).
        to_m: f64,
        /// Extra dT/dh inside the layer (K m⁻¹), added to the background.
        gradient_k_per_m: f64,
    },
}

impl SyntheticLayer {
    /// The layer's temperature contribution and its derivative at `h`.
    fn at(&self, h: f64) -> (f64, f64) {
        match *self {
            SyntheticLayer::Step {
                centre_m,
                thickness_m,
                delta_t_k,
            } => {
                let scale = thickness_m / 4.0;
                let x = (h - centre_m) / scale;
                // tanh is ±1 exactly beyond |x| = 22 (1 − tanh 22 ≈ 1.6e-19 rounds away).
                let th = if x.abs() > 22.0 { x.signum() } else { x.tanh() };
                (
                    delta_t_k * 0.5 * (1.0 + th),
                    delta_t_k * 0.5 * (1.0 - th * th) / scale,
                )
            }
            SyntheticLayer::Gradient {
                from_m,
                to_m,
                gradient_k_per_m,
            } => {
                let inside = h >= from_m && h < to_m;
                (
                    gradient_k_per_m * (h.clamp(from_m, to_m) - from_m),
                    if inside { gradient_k_per_m } else { 0.0 },
                )
            }
        }
    }

    /// Height (m) above which the layer no longer changes T noticeably.
    fn upper_m(&self) -> f64 {
        match *self {
            SyntheticLayer::Step {
                centre_m,
                thickness_m,
                ..
            } => centre_m + 2.0 * thickness_m,
            SyntheticLayer::Gradient { to_m, .. } => to_m,
        }
    }
}

/// A paper-style layered atmosphere (see the module doc for the file format).
#[derive(Debug, Clone)]
pub struct SyntheticAtmosphere {
    source: PathBuf,
    description: Option<String>,
    surface_height_m: f64,
    surface_temperature_k: f64,
    surface_pressure_pa: f64,
    background: Background,
    relative_humidity: f64,
    layers: Vec<SyntheticLayer>,
    /// Sum of the layers' contributions at the surface, subtracted so that T(surface) is the
    /// given surface temperature.
    layer_offset_k: f64,
    pressure: HydrostaticTable,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAtmosphere {
    description: Option<String>,
    surface_height_m: Option<Spanned<f64>>,
    surface_temperature_c: Spanned<f64>,
    surface_pressure_hpa: Spanned<f64>,
    background: Option<Spanned<RawBackground>>,
    tropopause_m: Option<Spanned<f64>>,
    relative_humidity_percent: Option<Spanned<f64>>,
    #[serde(default)]
    layers: Vec<Spanned<RawLayer>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLayer {
    centre_m: Option<Spanned<f64>>,
    base_m: Option<Spanned<f64>>,
    thickness_m: Option<Spanned<f64>>,
    delta_t_k: Option<Spanned<f64>>,
    from_m: Option<Spanned<f64>>,
    to_m: Option<Spanned<f64>>,
    gradient_k_per_m: Option<Spanned<f64>>,
}

/// `background`: a number (lapse rate, K/m) or the string "us1976".
enum RawBackground {
    Lapse(f64),
    Us1976,
}

impl<'de> Deserialize<'de> for RawBackground {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl serde::de::Visitor<'_> for Visitor {
            type Value = RawBackground;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a lapse rate in K/m (e.g. -0.0065) or \"us1976\"")
            }
            fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<Self::Value, E> {
                Ok(RawBackground::Lapse(v))
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Self::Value, E> {
                Ok(RawBackground::Lapse(v as f64))
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Self::Value, E> {
                Ok(RawBackground::Lapse(v as f64))
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Self::Value, E> {
                if v == "us1976" {
                    Ok(RawBackground::Us1976)
                } else {
                    Err(E::invalid_value(serde::de::Unexpected::Str(v), &self))
                }
            }
        }
        d.deserialize_any(Visitor)
    }
}

/// Builds `Syntax` errors at a byte span of the text.
struct Reporter<'a> {
    text: &'a str,
    path: &'a Path,
}

impl Reporter<'_> {
    fn at(&self, offset: usize, message: impl Into<String>) -> ProfileError {
        let (line, column) = line_column(self.text, offset);
        ProfileError::Syntax {
            path: self.path.to_path_buf(),
            line,
            column,
            message: message.into(),
        }
    }

    /// The value of `field` if it lies in `range` (inclusive), else an error at the value.
    fn within(
        &self,
        field: &Spanned<f64>,
        name: &str,
        range: (f64, f64),
        unit: &str,
    ) -> Result<f64, ProfileError> {
        let v = *field.get_ref();
        if v.is_finite() && v >= range.0 && v <= range.1 {
            Ok(v)
        } else {
            Err(self.at(
                field.span().start,
                format!(
                    "{name} = {v} is outside the plausible range {} … {} {unit}",
                    range.0, range.1
                ),
            ))
        }
    }
}

impl SyntheticAtmosphere {
    /// Parse and validate a synthetic atmosphere. `source` names the text in errors (and is
    /// kept for provenance). Errors carry the 1-based line and column of the offending key,
    /// value or layer.
    pub fn from_toml_str(text: &str, source: &Path) -> Result<Self, ProfileError> {
        let rep = Reporter { text, path: source };
        let raw: RawAtmosphere = toml::from_str(text).map_err(|e| {
            let offset = e.span().map_or(0, |s| s.start);
            rep.at(offset, e.message().trim_end().to_string())
        })?;

        let surface_height_m = match &raw.surface_height_m {
            Some(v) => rep.within(v, "surface_height_m", (-500.0, 9000.0), "m")?,
            None => 0.0,
        };
        let surface_temperature_c = rep.within(
            &raw.surface_temperature_c,
            "surface_temperature_c",
            (-90.0, 60.0),
            "°C",
        )?;
        let surface_pressure_hpa = rep.within(
            &raw.surface_pressure_hpa,
            "surface_pressure_hpa",
            (100.0, 1100.0),
            "hPa",
        )?;
        // None = "us1976", Some(lapse) otherwise (default −0.0065 K/m).
        let lapse = match &raw.background {
            Some(b) => match b.get_ref() {
                RawBackground::Us1976 => None,
                RawBackground::Lapse(v) => Some(rep.within(
                    &Spanned::new(b.span(), *v),
                    "background",
                    (-0.0342, 0.03),
                    "K/m",
                )?),
            },
            None => Some(-0.0065),
        };
        let background = match lapse {
            None => {
                if let Some(t) = &raw.tropopause_m {
                    return Err(rep.at(
                        t.span().start,
                        "tropopause_m only applies to a lapse-rate background, not \"us1976\"",
                    ));
                }
                Background::Us1976
            }
            Some(lapse_rate_k_per_m) => {
                let tropopause_m = match &raw.tropopause_m {
                    Some(t) => rep.within(
                        t,
                        "tropopause_m",
                        (surface_height_m + 1000.0, 20_000.0),
                        "m",
                    )?,
                    None => 11_000.0f64.max(surface_height_m + 1000.0),
                };
                Background::Lapse {
                    lapse_rate_k_per_m,
                    tropopause_m,
                }
            }
        };
        let relative_humidity = match &raw.relative_humidity_percent {
            Some(v) => rep.within(v, "relative_humidity_percent", (0.0, 100.0), "%")? / 100.0,
            None => 0.0,
        };

        let mut layers = Vec::with_capacity(raw.layers.len());
        for spanned in &raw.layers {
            layers.push(parse_layer(&rep, spanned, surface_height_m)?);
        }

        let mut atmosphere = SyntheticAtmosphere {
            source: source.to_path_buf(),
            description: raw.description,
            surface_height_m,
            surface_temperature_k: celsius_to_kelvin(surface_temperature_c),
            surface_pressure_pa: hpa_to_pa(surface_pressure_hpa),
            background,
            relative_humidity,
            layer_offset_k: 0.0,
            layers,
            // Replaced below once the temperature is known to be plausible.
            pressure: HydrostaticTable::integrate(
                0.0,
                1.0,
                1.0,
                &[(f64::INFINITY, 1.0)],
                &|_, _| 1.0,
            ),
        };

        // A step centred near the ground (the inferior mirage) has part of its change below the
        // surface: offset the layers so that T(surface) is exactly the given surface temperature.
        atmosphere.layer_offset_k = atmosphere
            .layers
            .iter()
            .map(|l| l.at(surface_height_m).0)
            .sum();

        // Plausibility of the resulting temperature everywhere.
        let layer_top = atmosphere
            .layers
            .iter()
            .map(SyntheticLayer::upper_m)
            .fold(surface_height_m, f64::max);
        let fine_top = (layer_top + 500.0)
            .max(surface_height_m + 2000.0)
            .min(MODEL_TOP_M);
        let mut h = surface_height_m;
        while h <= MODEL_TOP_M {
            let t = atmosphere.temperature(h).0;
            if !(100.0..=400.0).contains(&t) {
                return Err(rep.at(
                    raw.surface_temperature_c.span().start,
                    format!(
                        "the temperature reaches {:.1} °C at {h:.0} m, outside the plausible \
                         range −173 … +127 °C: check the surface temperature, background and layers",
                        kelvin_to_celsius(t)
                    ),
                ));
            }
            h += if h < fine_top { 0.5 } else { 50.0 };
        }

        let grid = [(fine_top, 0.25), (f64::INFINITY, 10.0)];
        let p0 = atmosphere.surface_pressure_pa;
        let table = if relative_humidity > 0.0 {
            let tv = |h: f64, p: f64| {
                let (t, _) = atmosphere.temperature(h);
                let e = relative_humidity * saturation_vapour_pressure_pa(t);
                virtual_temperature_k(t, e, p)
            };
            HydrostaticTable::integrate(surface_height_m, p0, MODEL_TOP_M, &grid, &tv)
        } else {
            // Dry: T_v = T exactly (e = 0), no pressure needed.
            let t = |h: f64| atmosphere.temperature(h).0;
            HydrostaticTable::integrate_dry(surface_height_m, p0, MODEL_TOP_M, &grid, &t)
        };
        atmosphere.pressure = table;
        Ok(atmosphere)
    }

    /// Read and parse a synthetic atmosphere file.
    pub fn from_file(path: &Path) -> Result<Self, ProfileError> {
        let text = crate::input::read_limited_text(path, crate::input::MAX_TOML_BYTES).map_err(
            |source| ProfileError::Io {
                path: path.to_path_buf(),
                source,
            },
        )?;
        Self::from_toml_str(&text, path)
    }

    /// The file (or description) the atmosphere was read from.
    pub fn source(&self) -> &Path {
        &self.source
    }

    /// The optional free-text description.
    pub fn description(&self) -> Option<&str> {
        self.description.as_deref()
    }

    /// The background profile.
    pub fn background(&self) -> Background {
        self.background
    }

    /// The layers, in file order.
    pub fn layers(&self) -> &[SyntheticLayer] {
        &self.layers
    }

    /// Surface temperature (K).
    pub fn surface_temperature_k(&self) -> f64 {
        self.surface_temperature_k
    }

    /// Surface pressure (Pa).
    pub fn surface_pressure_pa(&self) -> f64 {
        self.surface_pressure_pa
    }

    /// Relative humidity (fraction 0…1; 0 = dry).
    pub fn relative_humidity(&self) -> f64 {
        self.relative_humidity
    }

    /// T and dT/dh at `h` (no clamping).
    fn temperature(&self, h: f64) -> (f64, f64) {
        let (mut t, mut dt) = match self.background {
            Background::Lapse {
                lapse_rate_k_per_m,
                tropopause_m,
            } => {
                if h <= tropopause_m {
                    (
                        self.surface_temperature_k
                            + lapse_rate_k_per_m * (h - self.surface_height_m),
                        lapse_rate_k_per_m,
                    )
                } else {
                    let at_tropopause = self.surface_temperature_k
                        + lapse_rate_k_per_m * (tropopause_m - self.surface_height_m);
                    let (std_t, std_dt) = us1976_temperature(h);
                    (
                        at_tropopause + std_t - us1976_temperature(tropopause_m).0,
                        std_dt,
                    )
                }
            }
            Background::Us1976 => {
                let (std_t, std_dt) = us1976_temperature(h);
                (
                    self.surface_temperature_k + std_t
                        - us1976_temperature(self.surface_height_m).0,
                    std_dt,
                )
            }
        };
        for layer in &self.layers {
            let (lt, ldt) = layer.at(h);
            t += lt;
            dt += ldt;
        }
        (t - self.layer_offset_k, dt)
    }
}

fn parse_layer(
    rep: &Reporter,
    spanned: &Spanned<RawLayer>,
    surface_height_m: f64,
) -> Result<SyntheticLayer, ProfileError> {
    let layer = spanned.get_ref();
    let at = spanned.span().start;
    let step_fields = layer.centre_m.is_some()
        || layer.base_m.is_some()
        || layer.thickness_m.is_some()
        || layer.delta_t_k.is_some();
    let gradient_fields =
        layer.from_m.is_some() || layer.to_m.is_some() || layer.gradient_k_per_m.is_some();
    const SHAPES: &str = "a layer is either { centre_m or base_m, thickness_m, delta_t_k } or \
                          { from_m, to_m, gradient_k_per_m }";
    let height_range = (surface_height_m - 10_000.0, 80_000.0);
    let parsed = match (step_fields, gradient_fields) {
        (true, false) => {
            let (Some(thickness), Some(delta)) = (&layer.thickness_m, &layer.delta_t_k) else {
                return Err(rep.at(
                    at,
                    format!("{SHAPES}: thickness_m and delta_t_k are required"),
                ));
            };
            let thickness_m = rep.within(thickness, "thickness_m", (0.01, 10_000.0), "m")?;
            let delta_t_k = rep.within(delta, "delta_t_k", (-50.0, 50.0), "K")?;
            let centre_m = match (&layer.centre_m, &layer.base_m) {
                (Some(c), None) => rep.within(c, "centre_m", height_range, "m")?,
                (None, Some(b)) => rep.within(b, "base_m", height_range, "m")? + thickness_m / 2.0,
                _ => {
                    return Err(rep.at(at, "give exactly one of centre_m and base_m"));
                }
            };
            if centre_m + thickness_m / 2.0 <= surface_height_m {
                return Err(rep.at(at, "the layer lies entirely below the surface"));
            }
            SyntheticLayer::Step {
                centre_m,
                thickness_m,
                delta_t_k,
            }
        }
        (false, true) => {
            let (Some(from), Some(to), Some(gradient)) =
                (&layer.from_m, &layer.to_m, &layer.gradient_k_per_m)
            else {
                return Err(rep.at(
                    at,
                    format!("{SHAPES}: from_m, to_m and gradient_k_per_m are required"),
                ));
            };
            let from_m = rep.within(from, "from_m", height_range, "m")?;
            let to_m = rep.within(to, "to_m", height_range, "m")?;
            let gradient_k_per_m = rep.within(gradient, "gradient_k_per_m", (-5.0, 5.0), "K/m")?;
            if to_m <= from_m {
                return Err(rep.at(to.span().start, "to_m must be above from_m"));
            }
            if to_m <= surface_height_m {
                return Err(rep.at(at, "the layer lies entirely below the surface"));
            }
            SyntheticLayer::Gradient {
                from_m,
                to_m,
                gradient_k_per_m,
            }
        }
        (true, true) => return Err(rep.at(at, format!("{SHAPES}, not both"))),
        (false, false) => return Err(rep.at(at, format!("{SHAPES}; this one is empty"))),
    };
    Ok(parsed)
}

impl AirColumn for SyntheticAtmosphere {
    fn surface_height_m(&self) -> f64 {
        self.surface_height_m
    }

    /// The air at `height_m`; below the surface the surface air, above 86 km the 86 km air, and
    /// an all-NaN sample for a NaN height.
    fn air_at(&self, height_m: f64) -> AirSample {
        if height_m.is_nan() {
            return AirSample::nan();
        }
        let h = height_m.clamp(self.surface_height_m, MODEL_TOP_M);
        let (t, dt) = self.temperature(h);
        let (lnp, dlnp) = self.pressure.ln_p_and_slope(h);
        let p = lnp.exp();
        let (e, de) = if self.relative_humidity > 0.0 {
            let es = saturation_vapour_pressure_pa(t);
            let tc = kelvin_to_celsius(t);
            // d e_s/dT for the Magnus form e_s = 610.94·exp(17.625 t/(t + 243.04)).
            let des_dt = es * 17.625 * 243.04 / ((tc + 243.04) * (tc + 243.04));
            (
                self.relative_humidity * es,
                self.relative_humidity * des_dt * dt,
            )
        } else {
            (0.0, 0.0)
        };
        AirSample {
            temperature_k: t,
            dtemperature_dh_k_per_m: dt,
            pressure_pa: p,
            dpressure_dh_pa_per_m: p * dlnp,
            vapour_pressure_pa: e,
            dvapour_pressure_dh_pa_per_m: de,
        }
    }

    /// Edges of constant-gradient layers, the tropopause of a lapse-rate background and the
    /// US1976 layer bases above it (dT/dh jumps at each); step layers are smooth.
    fn breaks_m(&self) -> Vec<f64> {
        let mut breaks: Vec<f64> = self
            .layers
            .iter()
            .filter_map(|layer| match *layer {
                SyntheticLayer::Gradient { from_m, to_m, .. } => Some([from_m, to_m]),
                SyntheticLayer::Step { .. } => None,
            })
            .flatten()
            .collect();
        let standard_from = match self.background {
            Background::Lapse { tropopause_m, .. } => {
                breaks.push(tropopause_m);
                tropopause_m
            }
            Background::Us1976 => self.surface_height_m,
        };
        breaks.extend(super::us1976::layer_bases_geometric_m().filter(|&h| h > standard_from));
        breaks.push(MODEL_TOP_M);
        breaks.retain(|&h| h > self.surface_height_m);
        super::normalise_breaks(breaks)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> SyntheticAtmosphere {
        SyntheticAtmosphere::from_toml_str(text, Path::new("test")).unwrap()
    }

    #[test]
    fn step_layer_follows_the_tanh_formula() {
        let a = parse(
            "surface_temperature_c = 0\nsurface_pressure_hpa = 1000\nbackground = 0\n\
             [[layers]]\nbase_m = 50\nthickness_m = 20\ndelta_t_k = 8\n",
        );
        // base 50 m + L/2 → centre 60 m; scale L/4 = 5 m.
        for h in [40.0, 55.0, 60.0, 63.0, 90.0] {
            let z: f64 = (h - 60.0) / 5.0;
            let offset = 4.0 * (1.0 + (-12.0f64).tanh());
            let expected = 273.15 + 4.0 * (1.0 + z.tanh()) - offset;
            let s = a.air_at(h);
            assert!((s.temperature_k - expected).abs() < 1e-12, "{h}");
            let slope = 8.0 * 0.5 * (1.0 - z.tanh().powi(2)) / 5.0;
            assert!((s.dtemperature_dh_k_per_m - slope).abs() < 1e-12, "{h}");
        }
        // 96 % of the change lies inside the layer (tanh(2) = 0.964).
        let inside = a.air_at(70.0).temperature_k - a.air_at(50.0).temperature_k;
        assert!((inside / 8.0 - 2.0f64.tanh()).abs() < 1e-12);
    }

    #[test]
    fn gradient_layer_and_tropopause() {
        let a = parse(
            "surface_temperature_c = -10\nsurface_pressure_hpa = 1000\ntropopause_m = 9000\n\
             [[layers]]\nfrom_m = 0\nto_m = 50\ngradient_k_per_m = 0.1\n",
        );
        let t0 = 263.15;
        assert!((a.air_at(20.0).temperature_k - (t0 + 20.0 * 0.0935)).abs() < 1e-12);
        assert!((a.air_at(20.0).dtemperature_dh_k_per_m - 0.0935).abs() < 1e-15);
        assert!((a.air_at(100.0).temperature_k - (t0 + 5.0 - 0.65)).abs() < 1e-12);
        // Above the tropopause: the US1976 shape (isothermal from 11 km geopotential).
        let above = a.air_at(10_000.0);
        let trop = t0 + 5.0 - 0.0065 * 9000.0;
        let shape = us1976_temperature(10_000.0).0 - us1976_temperature(9000.0).0;
        assert!((above.temperature_k - (trop + shape)).abs() < 1e-9);
        assert!(matches!(
            a.background(),
            Background::Lapse { tropopause_m, .. } if tropopause_m == 9000.0
        ));
        assert_eq!(a.layers().len(), 1);
    }

    #[test]
    fn implausible_columns_are_rejected() {
        // A −0.03 K/m lapse from −80 °C reaches far below 100 K by 11 km.
        let e = SyntheticAtmosphere::from_toml_str(
            "surface_temperature_c = -80\nsurface_pressure_hpa = 1000\nbackground = -0.03\n",
            Path::new("cold"),
        )
        .unwrap_err();
        assert!(e.to_string().contains("plausible"), "{e}");
        let e = SyntheticAtmosphere::from_toml_str(
            "surface_temperature_c = 0\nsurface_pressure_hpa = 1000\nbackground = \"us1976\"\n\
             tropopause_m = 9000\n",
            Path::new("t"),
        )
        .unwrap_err();
        assert!(e.to_string().contains("tropopause_m"), "{e}");
        let e = SyntheticAtmosphere::from_toml_str(
            "surface_temperature_c = 0\nsurface_pressure_hpa = 1000\n\
             [[layers]]\ncentre_m = -100\nthickness_m = 10\ndelta_t_k = 3\n",
            Path::new("t"),
        )
        .unwrap_err();
        assert!(e.to_string().contains("below the surface"), "{e}");
    }
}
