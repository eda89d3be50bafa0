//! Layered stress soundings: piecewise-linear temperature profiles written as normalised CSV
//! soundings (the way a user hands the program a layered atmosphere), each a hard case for the
//! integrator: kinks in dT/dh at every level, near-critical ducts, thin strong layers.
//!
//! In: nothing. Out: the atmospheres as CSV text, to be written to a file and read like any
//! sounding (they are meant for `smooth_m = 0`, which keeps the layer corners):
//!
//! * [`stress_soundings`] — the six of the accuracy study (`bench accuracy`, `BENCHMARKS.md`);
//! * [`stress_suite`] — those six and eight harder ones for the stress suite (`bench stress`,
//!   `tests/integration/stress.rs`): superadiabatic surface layers, 0.1 m layers with 30 K jumps,
//!   surface ducts at 0.105, 0.110, 0.115 and 0.120 K/m (either side of the critical gradient)
//!   and an elevated duct that carries a level ray for thousands of kilometres; each with its
//!   corner heights, for rays launched tangent to a layer top.

use std::fmt::Write as _;

/// One stress sounding: a name, what it is, and a temperature profile as (height above ground
/// m, °C) corners, linear between them, written every `spacing_m` (finer where the gradient
/// changes).
struct Corners {
    name: &'static str,
    what: &'static str,
    corners: &'static [(f64, f64)],
}

/// Above the last corner: −6.5 K/km up to 11 km, isothermal to 20 km (the standard's shape).
const LAPSE_K_PER_M: f64 = -0.0065;
const TROPOPAUSE_M: f64 = 11_000.0;
const TOP_M: f64 = 20_000.0;

/// The accuracy study's six.
const STRESS: &[Corners] = &[
    Corners {
        name: "novaya_zemlya_critical",
        what: "the Novaya Zemlya case: +0.112 K/m from the surface to 200 m (just critical at 0 °C)",
        corners: &[(0.0, 0.0), (200.0, 22.4)],
    },
    Corners {
        name: "arctic_surface_inversion",
        what: "an arctic surface inversion, +8 K over 300 m in three linear pieces",
        corners: &[(0.0, -25.0), (60.0, -21.0), (150.0, -18.5), (300.0, -17.0)],
    },
    Corners {
        name: "two_thin_layers",
        what: "two thin layers aloft: +6 K over 3 m at 40 m and +4 K over 3 m at 90 m",
        corners: &[
            (0.0, -10.0),
            (40.0, -10.26),
            (43.0, -4.26),
            (90.0, -4.57),
            (93.0, -0.57),
        ],
    },
    Corners {
        name: "hot_road",
        what: "a hot road: −8 K over the lowest 2 m (inferior mirage)",
        corners: &[(0.0, 38.0), (2.0, 30.0)],
    },
    Corners {
        name: "elevated_duct",
        what: "a strong elevated duct: +12 K over 20 m at 60 m",
        corners: &[(0.0, -5.0), (60.0, -5.39), (80.0, 6.61)],
    },
    Corners {
        name: "surface_duct",
        what: "a surface duct: +0.115 K/m over the lowest 150 m at −10 °C (super-critical)",
        corners: &[(0.0, -10.0), (150.0, 7.25)],
    },
];

/// The stress suite's eight harder ones (with [`STRESS`], the whole suite).
const EXTREME: &[Corners] = &[
    Corners {
        name: "superadiabatic_desert",
        what: "a sun-baked desert floor: −1.2 K/m over the lowest 5 m (120× the dry adiabatic \
               lapse rate), −0.05 K/m to 50 m, dry adiabatic to 300 m",
        corners: &[(0.0, 40.0), (5.0, 34.0), (50.0, 31.75), (300.0, 29.3)],
    },
    Corners {
        name: "superadiabatic_sea",
        what: "cold air over warm sea: −0.2 K/m over the lowest 30 m, −0.01 K/m to 200 m",
        corners: &[(0.0, 2.0), (30.0, -4.0), (200.0, -5.7)],
    },
    Corners {
        name: "thin_jumps_30k",
        what: "0.1 m layers with 30 K jumps (300 K/m): +30 K at 30 m, −30 K at 60 m, +30 K at \
               120 m",
        corners: &[
            (0.0, -10.0),
            (30.0, -10.2),
            (30.1, 19.8),
            (60.0, 19.6),
            (60.1, -10.4),
            (120.0, -10.8),
            (120.1, 19.2),
        ],
    },
    Corners {
        name: "near_critical_0105",
        what: "a surface layer of +0.105 K/m to 200 m at 0 °C (just sub-critical)",
        corners: &[(0.0, 0.0), (200.0, 21.0)],
    },
    Corners {
        name: "near_critical_0110",
        what: "a surface layer of +0.110 K/m to 200 m at 0 °C (a hair sub-critical)",
        corners: &[(0.0, 0.0), (200.0, 22.0)],
    },
    Corners {
        name: "near_critical_0115",
        what: "a surface layer of +0.115 K/m to 200 m at 0 °C (a hair super-critical)",
        corners: &[(0.0, 0.0), (200.0, 23.0)],
    },
    Corners {
        name: "near_critical_0120",
        what: "a surface layer of +0.120 K/m to 200 m at 0 °C (super-critical: a surface duct)",
        corners: &[(0.0, 0.0), (200.0, 24.0)],
    },
    Corners {
        name: "long_duct",
        what: "an elevated duct, +20 K over 40 m at 150 m (0.5 K/m): a level ray from 170 m \
               oscillates in it without touching the sea, for thousands of kilometres",
        corners: &[(0.0, -10.0), (150.0, -10.975), (190.0, 9.025)],
    },
];

/// Observer height (m) from which a level ray stays in the stress suite's `long_duct` for
/// thousands of kilometres (the middle of its inversion).
pub const LONG_DUCT_OBSERVER_M: f64 = 170.0;

/// One atmosphere of the stress suite.
#[derive(Debug, Clone, PartialEq)]
pub struct StressAtmosphere {
    /// Short name (file stem, table heading, plot legend).
    pub name: &'static str,
    /// What it is, in one line.
    pub description: &'static str,
    /// The sounding as normalised CSV text (heights and temperatures).
    pub csv_text: String,
    /// Heights above ground (m, ascending) of the layer corners above the surface, where dT/dh
    /// changes: the tops (and bases) of its layers.
    pub corner_heights_m: Vec<f64>,
    /// Whether it belongs to the accuracy study's six ([`stress_soundings`]).
    pub in_accuracy_study: bool,
}

/// Level spacing (m) of the written sounding at height `h` above ground.
fn spacing_m(h: f64) -> f64 {
    if h < 300.0 {
        0.5
    } else if h < 2_000.0 {
        10.0
    } else {
        250.0
    }
}

/// The CSV text of one profile: heights and temperatures only (pressures are hydrostatic from
/// the standard surface pressure), levels on the spacing grid plus every corner.
fn csv_text(name: &str, corners: &[(f64, f64)]) -> String {
    let mut heights: Vec<f64> = Vec::new();
    let mut h = 0.0;
    while h <= TOP_M {
        heights.push(h);
        h += spacing_m(h);
    }
    heights.extend(corners.iter().map(|c| c.0).chain([TROPOPAUSE_M]));
    heights.sort_by(f64::total_cmp);
    heights.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
    let mut text = format!(
        "# station: ghostship stress sounding {name}\n# source: generated by \
         ghostship::verify::stress (piecewise-linear temperature, corners exact)\n\
         height_m,temperature_c\n"
    );
    for h in heights {
        let _ = writeln!(text, "{h},{:.6}", temperature_c(corners, h));
    }
    text
}

/// Linear interpolation between the corners, the background above them.
fn temperature_c(corners: &[(f64, f64)], h: f64) -> f64 {
    let (last_h, last_t) = corners[corners.len() - 1];
    if h >= last_h {
        return last_t + LAPSE_K_PER_M * (h.min(TROPOPAUSE_M) - last_h);
    }
    let i = corners
        .partition_point(|c| c.0 <= h)
        .clamp(1, corners.len() - 1);
    let (h0, t0) = corners[i - 1];
    let (h1, t1) = corners[i];
    t0 + (t1 - t0) * (h - h0) / (h1 - h0)
}

/// The accuracy study's six stress soundings as `(name, CSV text)`.
pub fn stress_soundings() -> Vec<(&'static str, String)> {
    STRESS
        .iter()
        .map(|s| (s.name, csv_text(s.name, s.corners)))
        .collect()
}

/// Every atmosphere of the stress suite: the accuracy study's six, then the eight harder ones.
pub fn stress_suite() -> Vec<StressAtmosphere> {
    let study = STRESS.iter().map(|s| (s, true));
    let extreme = EXTREME.iter().map(|s| (s, false));
    study
        .chain(extreme)
        .map(|(s, in_accuracy_study)| StressAtmosphere {
            name: s.name,
            description: s.what,
            csv_text: csv_text(s.name, s.corners),
            corner_heights_m: s.corners.iter().map(|c| c.0).filter(|&h| h > 0.0).collect(),
            in_accuracy_study,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corners_are_levels_and_profiles_are_linear_between() {
        for s in stress_suite() {
            let (name, text) = (s.name, s.csv_text);
            let rows: Vec<(f64, f64)> = text
                .lines()
                .filter(|l| !l.starts_with('#') && !l.starts_with("height"))
                .map(|l| {
                    let (a, b) = l.split_once(',').unwrap();
                    (a.parse().unwrap(), b.parse().unwrap())
                })
                .collect();
            assert!(rows.windows(2).all(|w| w[1].0 > w[0].0), "{name}");
            assert_eq!(rows[0].0, 0.0, "{name}");
        }
        let nz = &STRESS[0];
        assert!((temperature_c(nz.corners, 100.0) - 11.2).abs() < 1e-12);
        assert_eq!(stress_soundings().len(), 6);
    }

    #[test]
    fn thin_jumps_are_levels_of_their_own() {
        let suite = stress_suite();
        let jumps = suite.iter().find(|s| s.name == "thin_jumps_30k").unwrap();
        assert!(jumps.csv_text.contains("\n30.1,19.800000\n"));
        assert!(jumps.csv_text.contains("\n60.1,-10.400000\n"));
        assert_eq!(jumps.corner_heights_m.len(), 6);
        let names: std::collections::HashSet<_> = suite.iter().map(|s| s.name).collect();
        assert_eq!(names.len(), 14);
    }
}
