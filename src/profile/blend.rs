//! Stage 2 (fit), an atmosphere between two soundings. In: two fitted air columns of one
//! station (e.g. its 00 and 12 UTC soundings) and a weight w in [0, 1] (the time elapsed
//! between them as a fraction). Out: [`TimeBlend`], an [`AirColumn`] whose air at every height
//! is interpolated linearly in time between the two: temperature, vapour pressure and their
//! height derivatives as (1 − w)·a + w·b, pressure log-linearly, P = Pa^(1−w)·Pb^w. The
//! interpolation is at fixed heights (the fitted profiles are continuous, so this is the
//! interpolation on every level of both): an inversion that rises between the soundings fades
//! out at its old height and in at its new one, it is not followed. The log-linear pressure is
//! hydrostatic to second order in the temperature difference: d ln P/dh blends 1/Tv, where
//! hydrostatic balance of the blended air would ask for 1/(blended Tv).

use std::sync::Arc;

use super::{AirColumn, AirSample, FineZone, normalise_breaks};

/// Two air columns interpolated in time (module docs).
pub struct TimeBlend {
    first: Arc<dyn AirColumn>,
    second: Arc<dyn AirColumn>,
    weight: f64,
    breaks_m: Vec<f64>,
    fine_zones_m: Vec<FineZone>,
}

impl TimeBlend {
    /// The air `weight` of the way from `first` to `second` (0: `first`, 1: `second`; clamped to
    /// that range). The surface is the higher of the two surfaces.
    pub fn new(first: Arc<dyn AirColumn>, second: Arc<dyn AirColumn>, weight: f64) -> Self {
        let mut breaks = first.breaks_m();
        breaks.extend(second.breaks_m());
        let mut fine_zones_m = first.fine_zones_m();
        fine_zones_m.extend(second.fine_zones_m());
        TimeBlend {
            fine_zones_m,
            first,
            second,
            weight: weight.clamp(0.0, 1.0),
            breaks_m: normalise_breaks(breaks),
        }
    }

    /// The weight of the second column.
    pub fn weight(&self) -> f64 {
        self.weight
    }
}

impl AirColumn for TimeBlend {
    fn surface_height_m(&self) -> f64 {
        self.first
            .surface_height_m()
            .max(self.second.surface_height_m())
    }

    fn air_at(&self, height_m: f64) -> AirSample {
        let (a, b) = (self.first.air_at(height_m), self.second.air_at(height_m));
        let w = self.weight;
        let mix = |x: f64, y: f64| (1.0 - w) * x + w * y;
        let pressure_pa = ((1.0 - w) * a.pressure_pa.ln() + w * b.pressure_pa.ln()).exp();
        let dlnp = mix(
            a.dpressure_dh_pa_per_m / a.pressure_pa,
            b.dpressure_dh_pa_per_m / b.pressure_pa,
        );
        AirSample {
            temperature_k: mix(a.temperature_k, b.temperature_k),
            dtemperature_dh_k_per_m: mix(a.dtemperature_dh_k_per_m, b.dtemperature_dh_k_per_m),
            pressure_pa,
            dpressure_dh_pa_per_m: pressure_pa * dlnp,
            vapour_pressure_pa: mix(a.vapour_pressure_pa, b.vapour_pressure_pa),
            dvapour_pressure_dh_pa_per_m: mix(
                a.dvapour_pressure_dh_pa_per_m,
                b.dvapour_pressure_dh_pa_per_m,
            ),
        }
    }

    fn breaks_m(&self) -> Vec<f64> {
        self.breaks_m.clone()
    }

    fn fine_zones_m(&self) -> Vec<FineZone> {
        self.fine_zones_m.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::profile::StandardAtmosphere;

    /// The standard atmosphere warmed by `dt_k` at every height (pressure scaled by `p_scale`).
    struct Shifted {
        dt_k: f64,
        p_scale: f64,
    }

    impl AirColumn for Shifted {
        fn surface_height_m(&self) -> f64 {
            0.0
        }
        fn air_at(&self, h: f64) -> AirSample {
            let s = StandardAtmosphere::default().air_at(h);
            AirSample {
                temperature_k: s.temperature_k + self.dt_k,
                pressure_pa: s.pressure_pa * self.p_scale,
                dpressure_dh_pa_per_m: s.dpressure_dh_pa_per_m * self.p_scale,
                vapour_pressure_pa: self.dt_k,
                ..s
            }
        }
        fn breaks_m(&self) -> Vec<f64> {
            vec![100.0 * self.dt_k]
        }
    }

    #[test]
    fn halfway_is_the_mean_temperature_and_the_geometric_mean_pressure() {
        let a: Arc<dyn AirColumn> = Arc::new(Shifted {
            dt_k: 0.0,
            p_scale: 1.0,
        });
        let b: Arc<dyn AirColumn> = Arc::new(Shifted {
            dt_k: 10.0,
            p_scale: 1.21,
        });
        let blend = TimeBlend::new(a.clone(), b.clone(), 0.5);
        let (x, y, m) = (a.air_at(500.0), b.air_at(500.0), blend.air_at(500.0));
        assert!((m.temperature_k - (x.temperature_k + 5.0)).abs() < 1e-12);
        assert!((m.vapour_pressure_pa - 5.0).abs() < 1e-12);
        assert!((m.pressure_pa / (x.pressure_pa * 1.1) - 1.0).abs() < 1e-12);
        // Both columns' breaks.
        assert_eq!(blend.breaks_m(), vec![0.0, 1000.0]);
        // The ends are the columns themselves.
        let end = TimeBlend::new(a, b, 1.0).air_at(500.0);
        assert!((end.temperature_k - y.temperature_k).abs() < 1e-12);
        assert!((end.pressure_pa / y.pressure_pa - 1.0).abs() < 1e-12);
    }
}
