//! Verification, small statistics shared by the benchmarks. In: measured values (times,
//! errors). Out: their median and 95th percentile (nearest rank).

/// The median of `values` (the upper one of the two middle values for an even count), sorting
/// them in place; `None` for no values. NaNs sort last ([`f64::total_cmp`]).
pub fn median(values: &mut [f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    Some(values[values.len() / 2])
}

/// The value below which 95 % of `values` lie (nearest rank), sorting them in place; `None` for
/// no values.
pub fn percentile_95(values: &mut [f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let rank = ((0.95 * values.len() as f64).ceil() as usize).clamp(1, values.len());
    Some(values[rank - 1])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentile_95_is_the_nearest_rank() {
        let mut v: Vec<f64> = (1..=100).map(f64::from).collect();
        v.reverse();
        assert_eq!(percentile_95(&mut v), Some(95.0));
        assert_eq!(percentile_95(&mut [7.0]), Some(7.0));
        assert_eq!(percentile_95(&mut []), None);
    }

    #[test]
    fn median_of_odd_even_and_no_values() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), Some(2.0));
        // A slow outlier (a busy spell of a shared machine) does not move it.
        assert_eq!(median(&mut [10.0, 11.0, 900.0]), Some(11.0));
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), Some(3.0));
        assert_eq!(median(&mut []), None);
    }
}
