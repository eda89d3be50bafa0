//! Stage 1 — ingest of raw WMO FM-35 TEMP messages (`src/sounding/temp.rs`), against the six
//! real TEMP excerpts in `tests/data/soundings/raw/` and the independent hand decodings of the
//! same messages next to them (`<stem>.csv`: levels with a reported height; `pressure_levels/`:
//! Parts A and B merged), plus crafted damage and random mutations of the real files.

use std::path::Path;

use ghostship::sounding::{
    HeightSource, Level, ReadOptions, Sounding, SoundingError, SoundingFormat, parse_sounding,
    read_sounding,
};
use ghostship::units;
use proptest::prelude::*;

use crate::support::data::sounding;

/// (stem, station elevation in m above mean sea level from the CSV's `station_elevation_m`
/// line, latitude in degrees).
const STATIONS: [(&str, f64, f64); 6] = [
    ("Cherskiy-25123_2026020600", 32.0, 68.8),
    ("Danmarkshavn-04320_2026020523", 12.0, 76.77),
    ("Ittoqqortoormiit-04339_2026020523", 66.0, 70.48),
    ("SouthPole-89009_2026020600", 2830.0, -90.0),
    ("Tiksi-21824_2026020600", 8.0, 71.58),
    ("Utqiagvik-70026_2026020600", 12.0, 71.3),
];

fn raw_path(stem: &str) -> std::path::PathBuf {
    sounding(&format!("raw/{stem}_WMO-TEMP.txt"))
}

fn raw_text(stem: &str) -> String {
    std::fs::read_to_string(raw_path(stem)).unwrap()
}

fn read(stem: &str) -> Sounding {
    let s = read_sounding(&raw_path(stem), &ReadOptions::default())
        .unwrap_or_else(|e| panic!("{stem}: {e}"));
    assert_eq!(s.format, SoundingFormat::WmoTemp, "{stem}");
    s
}

/// A hand-decoded CSV read with a plain split (independent of the library): `#` lines as
/// `key: value`, then (pressure_hpa, height_m, temperature_c, dewpoint_c) rows.
struct HandCsv {
    meta: Vec<(String, String)>,
    rows: Vec<(f64, Option<f64>, f64, f64)>,
}

fn hand_csv(rel: &str) -> HandCsv {
    let text = std::fs::read_to_string(sounding(rel)).unwrap();
    let mut meta = Vec::new();
    let mut rows = Vec::new();
    for line in text.lines() {
        if let Some(m) = line.strip_prefix("# ") {
            let (k, v) = m.split_once(": ").unwrap();
            meta.push((k.to_string(), v.to_string()));
        } else if !line.starts_with("pressure_hpa") && !line.is_empty() {
            let f: Vec<&str> = line.split(',').collect();
            let num = |s: &str| s.parse::<f64>().unwrap();
            rows.push((
                num(f[0]),
                (!f[1].is_empty()).then(|| num(f[1])),
                num(f[2]),
                num(f[3]),
            ));
        }
    }
    HandCsv { meta, rows }
}

fn level_at(s: &Sounding, pressure_hpa: f64) -> &Level {
    s.levels
        .iter()
        .find(|l| l.pressure_pa == Some(units::hpa_to_pa(pressure_hpa)))
        .unwrap_or_else(|| panic!("{}: no level at {pressure_hpa} hPa", s.source.display()))
}

/// Temperature and dewpoint of `level` equal the hand decoding's (°C, 0.1 °C steps).
fn assert_same_air(level: &Level, t_c: f64, td_c: f64, what: &str) {
    assert!(
        (level.temperature_k - units::celsius_to_kelvin(t_c)).abs() < 1e-9,
        "{what}: temperature {} K vs {t_c} °C",
        level.temperature_k
    );
    let e = units::saturation_vapour_pressure_pa(units::celsius_to_kelvin(td_c));
    let got = level.vapour_pressure_pa.expect("dewpoint");
    assert!(
        (got - e).abs() <= 1e-9 * e,
        "{what}: vapour pressure {got} vs {e} (Td {td_c} °C)"
    );
}

/// Levels of Parts A and B (pressure at least 100 hPa).
fn parts_a_b(s: &Sounding) -> Vec<&Level> {
    s.levels
        .iter()
        .filter(|l| l.pressure_pa.is_some_and(|p| p >= 10_000.0))
        .collect()
}

/// Every level with a reported height is the hand decoding's: same pressure, height,
/// temperature and dewpoint; no other level of Part A has a height; the surface (whose height the
/// CSV took from a station list) has the CSV's pressure, temperature and dewpoint and a computed
/// height.
#[test]
fn reported_heights_equal_the_hand_decoding() {
    for (stem, _, _) in STATIONS {
        let s = read(stem);
        let csv = hand_csv(&format!("{stem}.csv"));
        let (surface, standard) = csv.rows.split_first().unwrap();
        let first = &s.levels[0];
        assert_eq!(
            first.pressure_pa,
            Some(units::hpa_to_pa(surface.0)),
            "{stem}"
        );
        assert_eq!(first.height_source, HeightSource::Hypsometric, "{stem}");
        assert_same_air(first, surface.2, surface.3, stem);
        for &(p, h, t, td) in standard {
            let l = level_at(&s, p);
            assert_eq!(Some(l.height_m), h, "{stem} {p} hPa");
            assert_eq!(l.height_source, HeightSource::Measured, "{stem} {p} hPa");
            assert_same_air(l, t, td, &format!("{stem} {p} hPa"));
        }
        let measured = parts_a_b(&s)
            .iter()
            .filter(|l| l.height_source == HeightSource::Measured)
            .count();
        assert_eq!(
            measured,
            standard.len(),
            "{stem}: levels with a reported height"
        );
    }
}

/// Parts A and B equal the hand-merged `pressure_levels` CSV level for level (the hand decoder
/// used the first TTBB where a station sent two, as the reader does).
#[test]
fn parts_a_and_b_equal_the_hand_merged_levels() {
    for (stem, _, _) in STATIONS {
        let s = read(stem);
        let csv = hand_csv(&format!("pressure_levels/{stem}_all-levels.csv"));
        let ours = parts_a_b(&s);
        assert_eq!(ours.len(), csv.rows.len(), "{stem}: levels down to 100 hPa");
        for (l, &(p, h, t, td)) in ours.iter().zip(&csv.rows) {
            let what = format!("{stem} {p} hPa");
            assert_eq!(l.pressure_pa, Some(units::hpa_to_pa(p)), "{what}");
            assert_same_air(l, t, td, &what);
            if l.height_source == HeightSource::Measured {
                assert_eq!(Some(l.height_m), h, "{what}");
            }
        }
    }
}

/// Latitude-dependent normal gravity at sea level (m s⁻², Somigliana's formula with the WGS 84
/// constants), for turning a station elevation into geopotential metres like TEMP heights.
fn normal_gravity_m_s2(latitude_deg: f64) -> f64 {
    let s2 = latitude_deg.to_radians().sin().powi(2);
    9.780_325_335_9 * (1.0 + 0.001_931_852_652_41 * s2) / (1.0 - 0.006_694_379_990_13 * s2).sqrt()
}

/// The station elevation `z` (m) in geopotential metres: ∫ g dz / g₀ with g falling as
/// (R / (R + z))².
fn geopotential_m(z_m: f64, latitude_deg: f64) -> f64 {
    const R: f64 = 6_371_000.0;
    normal_gravity_m_s2(latitude_deg) / units::STANDARD_GRAVITY_M_S2 * z_m * R / (R + z_m)
}

/// The surface height computed down from the lowest reported height matches the station's
/// elevation (in geopotential metres) within an error budget built from what limits it:
/// * the anchor's rounding: ±0.5 m (reported in m up to 700 hPa) or ±5 m (dam above);
/// * the surface pressure's rounding to whole hPa: ±0.5 hPa × H/p, H = R_d T / g₀;
/// * the significant levels standing for the profile (the code selects them so that linear
///   interpolation stays within about 1 K): 0.25 % of the thickness, i.e. 0.6 K in the mean;
/// * the launch site and barometer against the listed station elevation: 3 m.
///
/// Measured (this test prints them): Cherskiy −5.6 m, Danmarkshavn −1.1 m, Ittoqqortoormiit
/// +8.8 m, South Pole +5.1 m, Tiksi −0.3 m, Utqiagvik +4.4 m.
#[test]
fn surface_heights_match_the_station_elevations() {
    for (stem, elevation_m, latitude) in STATIONS {
        let s = read(stem);
        let surface = &s.levels[0];
        let anchor = s
            .levels
            .iter()
            .find(|l| l.height_source == HeightSource::Measured)
            .unwrap();
        let expected_m = geopotential_m(elevation_m, latitude);
        let error_m = surface.height_m - expected_m;
        let p_hpa = units::pa_to_hpa(surface.pressure_pa.unwrap());
        let scale_height_m = units::DRY_AIR_GAS_CONSTANT_J_KG_K * surface.temperature_k
            / units::STANDARD_GRAVITY_M_S2;
        let anchor_rounding_m = if anchor.pressure_pa.unwrap() >= 70_000.0 {
            0.5
        } else {
            5.0
        };
        let budget_m = anchor_rounding_m
            + 0.5 * scale_height_m / p_hpa
            + 0.0025 * (anchor.height_m - surface.height_m)
            + 3.0;
        println!(
            "{stem}: surface {:.1} m, station {expected_m:.1} gpm ({elevation_m} m), error \
             {error_m:+.1} m, budget {budget_m:.1} m",
            surface.height_m
        );
        assert!(
            error_m.abs() <= budget_m,
            "{stem}: error {error_m:.1} m > {budget_m:.1} m"
        );
    }
}

/// Every computed height lies strictly between the reported heights around it.
#[test]
fn computed_heights_lie_between_the_reported_ones() {
    for (stem, _, _) in STATIONS {
        let s = read(stem);
        let reported: Vec<&Level> = s
            .levels
            .iter()
            .filter(|l| l.height_source == HeightSource::Measured)
            .collect();
        let mut computed = 0;
        for l in s
            .levels
            .iter()
            .filter(|l| l.height_source == HeightSource::Hypsometric)
        {
            let p = l.pressure_pa.unwrap();
            let below = reported.iter().rev().find(|r| r.pressure_pa.unwrap() > p);
            let above = reported.iter().find(|r| r.pressure_pa.unwrap() < p);
            if let Some(b) = below {
                assert!(
                    l.height_m > b.height_m,
                    "{stem} {p} Pa below {}",
                    b.height_m
                );
            }
            if let Some(a) = above {
                assert!(
                    l.height_m < a.height_m,
                    "{stem} {p} Pa above {}",
                    a.height_m
                );
            }
            computed += 1;
        }
        assert!(computed >= 15, "{stem}: {computed} computed heights");
    }
}

/// Station, day and hour, launch time and the parts read; repeated parts are named.
#[test]
fn metadata_and_repeated_parts() {
    for (stem, _, _) in STATIONS {
        let s = read(stem);
        let csv = hand_csv(&format!("{stem}.csv"));
        let meta = |k: &str| csv.meta.iter().find(|(key, _)| key == k).unwrap().1.clone();
        let wmo = stem.split(['-', '_']).nth(1).unwrap();
        assert_eq!(s.metadata["station"], wmo);
        // "2026-02-06 00 UTC (…)" and "2026-02-05 23:30 UTC (31313 group 82330)".
        let nominal = meta("nominal_time_utc");
        let day_hour = format!("{} {}", &nominal[8..10], &nominal[11..13]);
        assert_eq!(s.metadata["nominal_day_hour_utc"], day_hour, "{stem}");
        assert_eq!(
            s.metadata["launch_hour_minute_utc"],
            meta("launch_time_utc")[11..16]
        );
        assert!(
            !s.metadata.contains_key("nominal_time_utc"),
            "{stem}: no year in TEMP"
        );
    }
    let s = read("Ittoqqortoormiit-04339_2026020523");
    assert_eq!(
        s.metadata["parts_read"],
        "TTAA (line 2), TTBB (line 8), TTCC (line 30)"
    );
    let joined = s.warnings.join("\n");
    assert!(
        joined.contains("TTBB appears 2 times (lines 8, 17): read the one at line 8"),
        "{joined}"
    );
    // The first TTCC holds only 88999 77999: the second is read.
    assert!(
        joined.contains("TTCC appears 2 times (lines 27, 30): read the one at line 30"),
        "{joined}"
    );
    assert_eq!(level_at(&s, 70.0).height_m, 17_820.0);
    let s = read("Danmarkshavn-04320_2026020523");
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("TTBB appears 2 times (lines 8, 20)"))
    );
    // Only the first TTBB's 668 hPa level; the second has 651 hPa instead.
    level_at(&s, 668.0);
    assert!(s.levels.iter().all(|l| l.pressure_pa != Some(65_100.0)));
    // After 51515 the regional groups 11600 18964 are not a 600 hPa level.
    assert!(s.levels.iter().all(|l| l.pressure_pa != Some(60_000.0)));
    let s = read("SouthPole-89009_2026020600");
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("skipped 4 standard surface(s) under the ground")),
        "{:?}",
        s.warnings
    );
    assert_eq!(s.surface().pressure_pa, Some(68_300.0));
}

/// Parts C and D: standard heights above 100 hPa (Danmarkshavn's TTCC read by hand: 70770 →
/// 17 700 m, 50970 → 19 700 m, 30272 → 22 720 m, 20515 → 25 150 m, 10953 → 29 530 m) and the
/// significant levels in tenths of hPa (TTDD 11788 67777 → 78.8 hPa, −67.7 °C).
#[test]
fn parts_c_and_d_above_100_hpa() {
    let s = read("Danmarkshavn-04320_2026020523");
    for (p, h, t) in [
        (70.0, 17_700.0, -66.9),
        (50.0, 19_700.0, -71.3),
        (30.0, 22_720.0, -70.9),
        (20.0, 25_150.0, -65.7),
        (10.0, 29_530.0, -52.3),
    ] {
        let l = level_at(&s, p);
        assert_eq!(
            (l.height_m, l.height_source),
            (h, HeightSource::Measured),
            "{p} hPa"
        );
        assert!(
            (l.temperature_k - units::celsius_to_kelvin(t)).abs() < 1e-9,
            "{p} hPa"
        );
    }
    let l = level_at(&s, 78.8);
    assert_eq!(l.height_source, HeightSource::Hypsometric);
    assert!((l.temperature_k - units::celsius_to_kelvin(-67.7)).abs() < 1e-9);
    assert!(
        l.height_m > 15_530.0 && l.height_m < 17_700.0,
        "{}",
        l.height_m
    );
    // 6.2 hPa, above the last standard surface: integrated up from 10 hPa.
    assert!(level_at(&s, 6.2).height_m > 29_530.0);
}

fn parse(text: &str) -> Result<Sounding, SoundingError> {
    parse_sounding(text, Path::new("t.txt"), &ReadOptions::default())
}

/// The Cherskiy TTAA alone (its first four lines).
fn cherskiy_ttaa() -> String {
    raw_text("Cherskiy-25123_2026020600")
        .lines()
        .take(4)
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn a_message_of_only_ttaa_is_read() {
    let s = parse(&cherskiy_ttaa()).unwrap();
    assert_eq!(s.format, SoundingFormat::WmoTemp);
    assert_eq!(s.levels.len(), 9, "surface and eight standard surfaces");
    assert!(
        s.levels[1..]
            .iter()
            .all(|l| l.height_source == HeightSource::Measured)
    );
    assert_eq!(s.metadata["parts_read"], "TTAA (line 2)");
    assert!(
        !s.metadata.contains_key("launch_hour_minute_utc"),
        "31313 is in the TTBB"
    );
}

#[test]
fn a_corrupt_group_names_file_line_and_group() {
    let text = raw_text("Cherskiy-25123_2026020600").replace("99020 34148", "9902A 34148");
    let e = parse(&text).unwrap_err();
    assert!(matches!(e, SoundingError::Field { .. }), "{e}");
    assert_eq!(
        (e.line(), e.column()),
        (Some(2), Some("TTAA group 9902A")),
        "{e}"
    );
    assert!(e.to_string().starts_with("t.txt: line 2"), "{e}");
    // A level group out of order (850 hPa after 700 hPa) in the TTAA's line 3.
    let text = raw_text("Cherskiy-25123_2026020600").replace("70817 19970", "85817 19970");
    let e = parse(&text).unwrap_err();
    assert_eq!(
        (e.line(), e.column()),
        (Some(3), Some("TTAA group 85817")),
        "{e}"
    );
    // Dewpoint depression 52 is not a code figure; a significant level out of sequence.
    let text = raw_text("Tiksi-21824_2026020600").replace("22926 22342", "22926 22352");
    let e = parse(&text).unwrap_err();
    assert_eq!(
        (e.line(), e.column()),
        (Some(8), Some("TTBB group 22352")),
        "{e}"
    );
    let text = raw_text("Tiksi-21824_2026020600").replace("33882 21734", "44882 21734");
    let e = parse(&text).unwrap_err();
    assert!(e.to_string().contains("nn = 33"), "{e}");
}

#[test]
fn a_truncated_message_is_an_error_or_a_warning() {
    // Cut inside the 1000 hPa level (before its wind group): an error at its last group.
    let text = "USRA02 RUHB 060000\nTTAA 06002 25123 99020 34148 32001 00165 33745\n";
    let e = parse(text).unwrap_err();
    assert_eq!(
        (e.line(), e.column()),
        (Some(2), Some("TTAA group 33745")),
        "{e}"
    );
    assert!(e.to_string().contains("truncated"), "{e}");
    // Cut between two levels, without '=': read, with a warning.
    let ttaa = cherskiy_ttaa();
    let cut = &ttaa[..ttaa.find(" 30861").unwrap()];
    let s = parse(cut).unwrap();
    assert_eq!(s.levels.len(), 7);
    assert!(
        s.warnings.iter().any(|w| w.contains("may be truncated")),
        "{:?}",
        s.warnings
    );
    // Nothing after TTAA.
    assert!(parse("TTAA 06002").is_err());
}

#[test]
fn other_stations_are_named_and_not_read() {
    let text = format!(
        "{}\n\n{}",
        raw_text("Tiksi-21824_2026020600"),
        raw_text("Cherskiy-25123_2026020600")
    );
    let s = parse(&text).unwrap();
    assert_eq!(s.metadata["station"], "21824");
    let w = s.warnings.join("\n");
    // Tiksi's 24 lines, two blank ones, Cherskiy's heading, then its TTAA.
    assert!(
        w.contains("1 other station(s), not read: 25123 (from line 28)"),
        "{w}"
    );
    assert_eq!(s.levels.len(), read("Tiksi-21824_2026020600").levels.len());
}

#[test]
fn a_time_is_refused_and_the_format_is_described() {
    let e = read_sounding(
        &raw_path("Tiksi-21824_2026020600"),
        &ReadOptions::with_time("2026-02-06 00"),
    )
    .unwrap_err();
    assert!(
        e.to_string()
            .contains("a WMO FM-35 TEMP message and holds one sounding"),
        "{e}"
    );
    // A TTBB alone is not recognised as TEMP (detection needs TTAA and YYGGId).
    let ttbb: String = raw_text("Tiksi-21824_2026020600")
        .lines()
        .skip(6)
        .take(8)
        .collect::<Vec<_>>()
        .join("\n");
    assert!(ttbb.contains("TTBB") && !ttbb.contains("TTAA"));
    assert!(
        parse(&ttbb)
            .unwrap_err()
            .to_string()
            .contains("cannot recognise the format")
    );
}

/// One damage to a TEMP file: a group replaced, a group or line deleted, or the text cut.
#[derive(Debug, Clone)]
enum Damage {
    ReplaceGroup(usize, String),
    DeleteGroup(usize),
    DeleteLine(usize),
    Cut(usize),
}

fn damage() -> impl Strategy<Value = Damage> {
    prop_oneof![
        (any::<usize>(), "[0-9/A =]{0,6}").prop_map(|(i, s)| Damage::ReplaceGroup(i, s)),
        any::<usize>().prop_map(Damage::DeleteGroup),
        any::<usize>().prop_map(Damage::DeleteLine),
        any::<usize>().prop_map(Damage::Cut),
    ]
}

fn apply(text: &str, damage: &Damage) -> String {
    if text.is_empty() {
        return String::new();
    }
    let groups: Vec<&str> = text.split(' ').collect();
    let n = groups.len();
    match damage {
        Damage::ReplaceGroup(i, s) => {
            let mut g: Vec<&str> = groups.clone();
            g[i % n] = s;
            g.join(" ")
        }
        Damage::DeleteGroup(i) => {
            let mut g = groups.clone();
            g.remove(i % n);
            g.join(" ")
        }
        Damage::DeleteLine(i) => {
            let mut lines: Vec<&str> = text.lines().collect();
            if !lines.is_empty() {
                lines.remove(i % lines.len());
            }
            lines.join("\n")
        }
        Damage::Cut(i) => {
            let k = i % text.len();
            text[..(0..=k)
                .rev()
                .find(|&j| text.is_char_boundary(j))
                .unwrap_or(0)]
                .to_string()
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// Damaged real TEMP files never panic: they are read (well-formed) or refused with an error
    /// naming the file.
    #[test]
    fn damaged_temp_files_never_panic(
        which in 0usize..6,
        damages in proptest::collection::vec(damage(), 1..5),
    ) {
        let mut text = raw_text(STATIONS[which].0);
        for d in &damages {
            text = apply(&text, d);
        }
        match parse_sounding(&text, Path::new("damaged"), &ReadOptions::default()) {
            Ok(s) => {
                prop_assert!(s.levels.len() >= 3);
                prop_assert!(s.levels.windows(2).all(|w| w[1].height_m > w[0].height_m));
            }
            Err(e) => prop_assert!(e.to_string().starts_with("damaged"), "{}", e),
        }
    }
}

/// Two parts on one line (`…= TTBB …=`, as some archives join a report): the second is read,
/// not dropped with the rest of the line. The same report, each part on its own line, gives the
/// same levels.
#[test]
fn a_part_after_an_equals_sign_on_the_same_line_is_read() {
    let text = raw_text("Cherskiy-25123_2026020600");
    let apart = parse(&text).unwrap();
    // The whole bulletin on one line: only the `=` separate the parts.
    let joined = text.replace('\n', " ");
    assert_ne!(joined, text);
    let together = parse(&joined).unwrap();
    let air = |s: &Sounding| -> Vec<(Option<f64>, f64)> {
        s.levels
            .iter()
            .map(|l| (l.pressure_pa, l.temperature_k))
            .collect()
    };
    assert_eq!(air(&together), air(&apart));
}
