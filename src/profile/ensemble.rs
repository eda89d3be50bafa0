//! Stage 2 — fit: sensitivity ensembles of a sounding fit. In: a fitted [`Profile`] and
//! [`EnsembleOptions`] (number of members, bound, seed). Out: the member profiles — the same fit
//! with the temperature between levels moved within the bound — for the jobs layer to trace
//! (what is seen through them is not this stage's business).
//!
//! A significant-level sounding fixes the temperature at its levels only; between them WMO's
//! selection rule promises that linear interpolation in ln p stays within about 1 K of the
//! measured curve. Every member therefore adds, in every gap between two adjacent levels, a bump
//! a·sin(πu) with a drawn uniformly in ±[`EnsembleOptions::tolerance_k`] (u the gap's ln p
//! fraction): smooth inside the gap, zero at both levels, at most the bound away from the fit.
//! Which gaps ([`perturbed_gaps`]): all of them in a significant-level sounding; in a dense
//! ascent only gaps wider than [`AUTO_SPARSE_SPACING_M`] (where the sonde has no data, e.g.
//! levels dropped at ingest) — elsewhere its levels, a few metres apart, are the measured curve,
//! and a kelvin between two of them would be a departure the sonde measured against.
//!
//! The draws come from SplitMix64 seeded with the seed and the member's index, so every member
//! is the same whatever the order or thread it is built in. Written here because the crate has
//! no random-number dependency and the draws need to be reproducible, not cryptographic.

use super::temperature::AUTO_SPARSE_SPACING_M;
use super::{Profile, ProfileError};

/// The bound of the departure from the fit between levels (K): WMO's significant-level
/// criterion for temperature in the lower troposphere.
pub const WMO_TOLERANCE_K: f64 = 1.0;

/// The seed used when none is given.
pub const DEFAULT_SEED: u64 = 20_260_206;

/// Most members an ensemble may have.
pub const MAX_MEMBERS: usize = 500;

/// How to build an ensemble.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct EnsembleOptions {
    /// Number of member profiles (1 … [`MAX_MEMBERS`]).
    pub members: usize,
    /// Largest departure from the fit between levels (K), > 0 and ≤ 10.
    pub tolerance_k: f64,
    /// Seed of the draws.
    pub seed: u64,
}

impl Default for EnsembleOptions {
    /// 20 members, ±1 K, [`DEFAULT_SEED`].
    fn default() -> Self {
        EnsembleOptions {
            members: 20,
            tolerance_k: WMO_TOLERANCE_K,
            seed: DEFAULT_SEED,
        }
    }
}

impl EnsembleOptions {
    /// Check the member count and the bound.
    pub fn validate(&self) -> Result<(), ProfileError> {
        if !(1..=MAX_MEMBERS).contains(&self.members) {
            return Err(ProfileError::BadOption {
                name: "ensemble",
                message: format!("{} members is outside 1…{MAX_MEMBERS}", self.members),
            });
        }
        if !(self.tolerance_k.is_finite() && self.tolerance_k > 0.0 && self.tolerance_k <= 10.0) {
            return Err(ProfileError::BadOption {
                name: "tolerance_k",
                message: format!("{} K is outside (0, 10] K", self.tolerance_k),
            });
        }
        Ok(())
    }
}

/// Whether each gap between adjacent levels of `profile` is perturbed (see the module doc): all
/// of them for significant levels, else those wider than [`AUTO_SPARSE_SPACING_M`].
pub fn perturbed_gaps(profile: &Profile) -> Vec<bool> {
    let all = profile.fit_choice().significant_levels;
    profile
        .levels()
        .windows(2)
        .map(|w| all || w[1].height_m - w[0].height_m > AUTO_SPARSE_SPACING_M)
        .collect()
}

/// The bump amplitudes (K, one per gap) of member `member`: uniform in ±tolerance where `gaps`
/// says so, 0 elsewhere. Each gap has its own draw whether perturbed or not, so a gap's
/// amplitude does not depend on which other gaps are.
pub fn member_bumps_k(options: &EnsembleOptions, gaps: &[bool], member: usize) -> Vec<f64> {
    let mut rng =
        SplitMix64::new(options.seed ^ (member as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    gaps.iter()
        .map(|&on| {
            let a = options.tolerance_k * (2.0 * rng.unit() - 1.0);
            if on { a } else { 0.0 }
        })
        .collect()
}

/// The member profiles of `profile` (member i from [`member_bumps_k`] with index i).
pub fn ensemble_members(
    profile: &Profile,
    options: &EnsembleOptions,
) -> Result<Vec<Profile>, ProfileError> {
    options.validate()?;
    let gaps = perturbed_gaps(profile);
    (0..options.members)
        .map(|m| profile.perturbed(&member_bumps_k(options, &gaps, m)))
        .collect()
}

/// SplitMix64 (Steele, Lea & Flood 2014): a 64-bit state stepped by the golden-ratio constant
/// and mixed by two multiply–xorshift rounds.
struct SplitMix64 {
    state: u64,
}

impl SplitMix64 {
    fn new(seed: u64) -> Self {
        SplitMix64 { state: seed }
    }

    fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1) with 53 random bits.
    fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splitmix_matches_the_reference_sequence() {
        // First outputs of SplitMix64 from seed 0, as published with the algorithm (and in
        // Vigna's reference C code, splitmix64.c).
        let mut rng = SplitMix64::new(0);
        assert_eq!(rng.next_u64(), 0xE220_A839_7B1D_CDAF);
        assert_eq!(rng.next_u64(), 0x6E78_9E6A_A1B9_65F4);
        assert_eq!(rng.next_u64(), 0x06C4_5D18_8009_454F);
    }

    #[test]
    fn bumps_are_bounded_reproducible_and_per_member() {
        let options = EnsembleOptions::default();
        let gaps = [true, false, true, true];
        let a = member_bumps_k(&options, &gaps, 3);
        assert_eq!(a, member_bumps_k(&options, &gaps, 3));
        assert_ne!(a, member_bumps_k(&options, &gaps, 4));
        assert_eq!(a[1], 0.0);
        assert!(a.iter().all(|v| v.abs() <= 1.0));
        // A gap's draw does not depend on the others being perturbed.
        assert_eq!(member_bumps_k(&options, &[true; 4], 3)[2], a[2]);
        // Over many members the draws fill ±1 K.
        let all: Vec<f64> = (0..400)
            .flat_map(|m| member_bumps_k(&options, &[true], m))
            .collect();
        let (lo, hi) = all
            .iter()
            .fold((f64::MAX, f64::MIN), |(l, h), &v| (l.min(v), h.max(v)));
        assert!(lo < -0.95 && hi > 0.95, "{lo} {hi}");
        let mean = all.iter().sum::<f64>() / all.len() as f64;
        assert!(mean.abs() < 0.1, "{mean}");
        assert!(
            EnsembleOptions {
                members: 0,
                ..options
            }
            .validate()
            .is_err()
        );
    }
}
