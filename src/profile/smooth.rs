//! Stage 2 — fit: noise smoothing for dense (1-second) soundings. In: levels (heights strictly
//! increasing) and one quantity per level. Out: the smoothed value at every level.
//!
//! Method: a local-linear regression (LOESS of degree 1) with the tricube kernel
//! w(d) = (1 − |d/s|³)³ of half-width `s = smooth_m`, evaluated at each level. Why this one:
//! * the kernel has compact support, so a level with no neighbour closer than `smooth_m` keeps its
//!   measured value exactly: sparse soundings (TEMP, IGRA2 significant levels) pass through
//!   untouched, only dense data is smoothed;
//! * local-linear (rather than a moving average) has no bias on a constant lapse rate and at the
//!   ends of the data (the surface, a data gap), so the ground value and the background lapse
//!   survive;
//! * any smoother that reproduces constants preserves the total temperature change across a
//!   layer: a 15 m, +3 K step keeps its +3 K and only widens by about the kernel's width
//!   (effective Gaussian σ ≈ 0.38·`smooth_m`), while white noise is averaged down by √(number of
//!   levels in the window);
//! * each result is clamped to the range of the values in its window, so smoothing cannot create
//!   a value that was not locally measured.
//!
//! Written by hand: it is a weighted 2×2 normal equation per level (about twenty lines), with the
//! compact-support and clamping rules above that a general LOESS implementation would not give.

/// Smooth `values` (at `heights`, strictly increasing) with the tricube local-linear regression
/// of half-width `half_width_m`. A half-width ≤ 0 (or non-finite) returns the input unchanged.
pub(crate) fn local_linear(heights: &[f64], values: &[f64], half_width_m: f64) -> Vec<f64> {
    local_linear_varying(heights, values, &|_| half_width_m)
}

/// As [`local_linear`], with a half-width that may differ per level (`half_width_m(i)` for the
/// estimate at level `i`).
pub(crate) fn local_linear_varying(
    heights: &[f64],
    values: &[f64],
    half_width_m: &dyn Fn(usize) -> f64,
) -> Vec<f64> {
    debug_assert_eq!(heights.len(), values.len());
    let n = heights.len();
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let half_width_m = half_width_m(i);
        if !(half_width_m > 0.0 && half_width_m.is_finite()) {
            out.push(values[i]);
            continue;
        }
        let x0 = heights[i];
        let lo = heights.partition_point(|&h| h <= x0 - half_width_m);
        let hi = heights.partition_point(|&h| h < x0 + half_width_m);
        if hi - lo <= 1 {
            out.push(values[i]);
            continue;
        }
        let (mut s0, mut sx, mut sy) = (0.0, 0.0, 0.0);
        let (mut vmin, mut vmax) = (f64::INFINITY, f64::NEG_INFINITY);
        for j in lo..hi {
            let d = heights[j] - x0;
            let q = 1.0 - (d.abs() / half_width_m).powi(3);
            let w = q * q * q;
            s0 += w;
            sx += w * d;
            sy += w * values[j];
            vmin = vmin.min(values[j]);
            vmax = vmax.max(values[j]);
        }
        let (xm, ym) = (sx / s0, sy / s0);
        let (mut sxx, mut sxy) = (0.0, 0.0);
        for j in lo..hi {
            let d = heights[j] - x0;
            let q = 1.0 - (d.abs() / half_width_m).powi(3);
            let w = q * q * q;
            sxx += w * (d - xm) * (d - xm);
            sxy += w * (d - xm) * (values[j] - ym);
        }
        // With (almost) all weight on one height the slope is undetermined: use the weighted mean.
        let value = if sxx > 1e-12 * half_width_m * half_width_m * s0 {
            ym - sxy / sxx * xm
        } else {
            ym
        };
        out.push(value.clamp(vmin, vmax));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sparse_levels_are_untouched() {
        let h = [0.0, 50.0, 120.0, 400.0];
        let v = [1.0, -3.0, 7.0, 2.0];
        assert_eq!(local_linear(&h, &v, 20.0), v.to_vec());
        assert_eq!(local_linear(&h, &v, 0.0), v.to_vec());
    }

    #[test]
    fn a_straight_line_is_reproduced() {
        // Local-linear regression is exact on a linear function, also at the ends and across
        // irregular spacing.
        let h: Vec<f64> = (0..200).map(|i| i as f64 * 5.0 + (i % 3) as f64).collect();
        let v: Vec<f64> = h.iter().map(|x| 270.0 - 0.0065 * x).collect();
        let s = local_linear(&h, &v, 20.0);
        for (a, b) in s.iter().zip(&v) {
            assert!((a - b).abs() < 1e-9, "{a} {b}");
        }
    }

    #[test]
    fn white_noise_is_reduced() {
        // Deterministic pseudo-noise (a linear congruential generator), σ = 0.1.
        let mut state: u64 = 12345;
        let mut noise = || {
            let mut sum = 0.0;
            for _ in 0..12 {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                sum += (state >> 11) as f64 / (1u64 << 53) as f64;
            }
            (sum - 6.0) * 0.1
        };
        let h: Vec<f64> = (0..2000).map(|i| i as f64 * 5.0).collect();
        let v: Vec<f64> = h.iter().map(|_| noise()).collect();
        let s = local_linear(&h, &v, 20.0);
        let rms = |x: &[f64]| (x.iter().map(|a| a * a).sum::<f64>() / x.len() as f64).sqrt();
        // Tricube weights at 0, ±5, ±10, ±15 m give an effective sample size of ≈5.6 for the
        // mean, so the residual noise should be near 0.1/√5.6 ≈ 0.042 (local-linear costs little
        // extra inside the data).
        let r = rms(&s);
        assert!(rms(&v) > 0.09 && r < 0.055 && r > 0.03, "{r}");
    }
}
