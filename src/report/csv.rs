//! Stage 3 output (`profile` command) — `profile.csv`. In: a [`RefractiveAtmosphere`] (with its
//! fitted air column) and a [`ProfileGrid`]. Out: CSV bytes: the fitted air and the exact
//! refractive index on that height grid.

use std::fmt::Write;

use crate::refractivity::RefractiveAtmosphere;
use crate::units::pa_to_hpa;

/// The header line of `profile.csv` (exact column names and order).
pub const CSV_HEADER: &str =
    "height_m,temperature_k,pressure_hpa,vapour_pressure_hpa,n_minus_1,dn_dh_per_m,dt_dh_k_per_m";

/// One stretch of the output grid: rows every `step_m` up to `top_agl_m` above the surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridSegment {
    /// Row spacing (m).
    pub step_m: f64,
    /// Top of this stretch above the surface (m).
    pub top_agl_m: f64,
}

/// The heights of `profile.csv`: consecutive segments starting at the surface.
#[derive(Debug, Clone, PartialEq)]
pub struct ProfileGrid {
    /// Segments, bottom to top; each starts where the previous one ended.
    pub segments: Vec<GridSegment>,
}

impl Default for ProfileGrid {
    /// Every 1 m up to 2 km above the surface (where mirage layers live), every 10 m up to 20 km,
    /// every 100 m up to 40 km: 5 981 rows.
    fn default() -> Self {
        Self {
            segments: vec![
                GridSegment {
                    step_m: 1.0,
                    top_agl_m: 2_000.0,
                },
                GridSegment {
                    step_m: 10.0,
                    top_agl_m: 20_000.0,
                },
                GridSegment {
                    step_m: 100.0,
                    top_agl_m: 40_000.0,
                },
            ],
        }
    }
}

impl ProfileGrid {
    /// The heights above the surface (m), increasing, starting at 0. Segments with a non-positive
    /// or non-finite step, or that end below the previous one, are skipped.
    pub fn heights_agl_m(&self) -> Vec<f64> {
        let mut out = vec![0.0];
        let mut start = 0.0;
        for seg in &self.segments {
            if !(seg.step_m > 0.0 && seg.step_m.is_finite() && seg.top_agl_m.is_finite()) {
                continue;
            }
            let span = seg.top_agl_m - start;
            if span <= 0.0 {
                continue;
            }
            let n = (span / seg.step_m).round().min(1e7) as usize;
            out.extend((1..=n).map(|k| start + k as f64 * seg.step_m));
            start += n as f64 * seg.step_m;
        }
        out
    }
}

/// `profile.csv`: columns [`CSV_HEADER`], one row per grid height, heights above **mean sea
/// level**; n − 1 and dn/dh are the exact (not tabulated) values. Numbers are written with fixed
/// precision: height mm, temperature 10⁻⁴ K, pressures 10⁻⁵ hPa, n − 1 and dn/dh to 11 significant
/// digits, dT/dh 10⁻⁷ K/m. Formatted by hand: seven numbers per row need no quoting, and this
/// cannot fail, so no CSV writer is needed.
pub fn profile_csv(atm: &RefractiveAtmosphere, grid: &ProfileGrid) -> Vec<u8> {
    let heights = grid.heights_agl_m();
    let mut out = String::with_capacity(100 * (heights.len() + 1));
    out.push_str(CSV_HEADER);
    out.push('\n');
    for h in heights {
        let s = atm.sample_at(atm.surface_height_m() + h);
        // Writing to a String cannot fail.
        let _ = writeln!(
            out,
            "{:.3},{:.4},{:.5},{:.5},{:.10e},{:.10e},{:.7}",
            s.height_m,
            s.air.temperature_k,
            pa_to_hpa(s.air.pressure_pa),
            pa_to_hpa(s.air.vapour_pressure_pa),
            s.n_minus_1,
            s.dn_dh_per_m,
            s.air.dtemperature_dh_k_per_m
        );
    }
    out.into_bytes()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_grid_rows_and_spacing() {
        let h = ProfileGrid::default().heights_agl_m();
        assert_eq!(h.len(), 2001 + 1800 + 200);
        assert_eq!(&h[..3], &[0.0, 1.0, 2.0]);
        assert_eq!(h[2000], 2000.0);
        assert_eq!(h[2001], 2010.0);
        assert_eq!(*h.last().unwrap(), 40_000.0);
        assert!(h.windows(2).all(|w| w[1] > w[0]));
    }

    #[test]
    fn bad_segments_are_skipped() {
        let grid = ProfileGrid {
            segments: vec![
                GridSegment {
                    step_m: 0.0,
                    top_agl_m: 10.0,
                },
                GridSegment {
                    step_m: f64::NAN,
                    top_agl_m: 10.0,
                },
                GridSegment {
                    step_m: 2.0,
                    top_agl_m: 6.0,
                },
                GridSegment {
                    step_m: 1.0,
                    top_agl_m: 3.0,
                },
                GridSegment {
                    step_m: 5.0,
                    top_agl_m: 16.0,
                },
            ],
        };
        assert_eq!(grid.heights_agl_m(), vec![0.0, 2.0, 4.0, 6.0, 11.0, 16.0]);
    }
}
