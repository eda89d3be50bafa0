//! Stage 1 — ingest of NCAR/EOL ESC soundings (`tests/data/soundings/raw/*.cls`, `*.cls.qc`;
//! provenance in that folder's README). The independent check is the hand conversion of the same
//! three files to normalised CSVs (`tests/data/soundings/*.csv`, their `# conversion:` lines say
//! what was done): the ESC reader must give the same levels. Quality-flag counts are recounted
//! here by splitting the raw lines, without ghostship; metadata is checked against the header
//! text.

use std::path::{Path, PathBuf};

use ghostship::sounding::{
    ReadOptions, Sounding, SoundingError, SoundingFormat, parse_sounding, read_sounding,
};
use proptest::prelude::*;

use crate::support::data::sounding;

/// (normalised CSV stem, raw ESC file) of the three soundings.
const FILES: [(&str, &str); 3] = [
    (
        "Bjornoya-01028_2024022611",
        "raw/Bjornoya-01028_2024022611_GTS_BUFR_Bjornoya_Norway_202402261120_05_SONDE.cls",
    ),
    (
        "NyAlesund-01004_2024022611",
        "raw/NyAlesund-01004_2024022611_GTS_BUFR_Ny-Alesund_Svalbard_Norway_202402261105_02_SONDE.cls.qc",
    ),
    (
        "TroisRivieres-UQAM_2022022222",
        "raw/TroisRivieres-UQAM_2022022222_UQAM_Trois_Rivieres_202202222200.cls",
    ),
];

fn raw_path(i: usize) -> PathBuf {
    sounding(FILES[i].1)
}

fn csv_path(i: usize) -> PathBuf {
    sounding(&format!("{}.csv", FILES[i].0))
}

fn read(path: &Path) -> Sounding {
    read_sounding(path, &ReadOptions::default())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The raw file split by hand: the column names and, per data line, (1-based line, fields).
struct RawTable {
    names: Vec<String>,
    rows: Vec<(usize, Vec<String>)>,
}

impl RawTable {
    fn of(text: &str) -> RawTable {
        let lines: Vec<&str> = text.lines().collect();
        // The column line starts with "Time"; the units line and a dashed rule follow.
        let at = lines
            .iter()
            .position(|l| l.split_whitespace().next() == Some("Time"))
            .expect("column line");
        assert!(lines[at + 2].starts_with("------"), "rule below the units");
        let names = lines[at].split_whitespace().map(String::from).collect();
        let rows = (at + 3..lines.len())
            .filter(|&i| !lines[i].trim().is_empty())
            .map(|i| {
                let fields = lines[i].split_whitespace().map(String::from).collect();
                (i + 1, fields)
            })
            .collect();
        RawTable { names, rows }
    }

    fn column(&self, name: &str) -> usize {
        self.names.iter().position(|n| n == name).expect(name)
    }

    /// The lines whose `flag` column holds 3.0 (bad).
    fn flagged_bad(&self, flag: &str) -> Vec<usize> {
        let c = self.column(flag);
        self.rows
            .iter()
            .filter(|(_, f)| f[c].parse::<f64>().unwrap() == 3.0)
            .map(|(line, _)| *line)
            .collect()
    }

    fn value(&self, line: usize, name: &str) -> f64 {
        let (_, fields) = self.rows.iter().find(|(l, _)| *l == line).unwrap();
        fields[self.column(name)].parse().unwrap()
    }
}

/// The number of rows the CSV's `# conversion:` line says were dropped for Qt = 3.
fn csv_says_dropped(csv: &str) -> usize {
    let line = csv
        .lines()
        .find(|l| l.starts_with("# conversion:"))
        .unwrap();
    let after = line.split("(bad) dropped (").nth(1).unwrap();
    after.split(' ').next().unwrap().parse().unwrap()
}

#[test]
fn qt_bad_rows_are_dropped_and_counted() {
    let mut counts = Vec::new();
    for (i, (name, _)) in FILES.iter().enumerate() {
        let text = std::fs::read_to_string(raw_path(i)).unwrap();
        let table = RawTable::of(&text);
        let bad = table.flagged_bad("Qt");
        let csv = std::fs::read_to_string(csv_path(i)).unwrap();
        assert_eq!(bad.len(), csv_says_dropped(&csv), "{name}");
        counts.push(bad.len());
        let s = read(&raw_path(i));
        let note = s
            .warnings
            .iter()
            .find(|w| w.contains("quality flag Qt is 3"));
        if bad.is_empty() {
            assert!(note.is_none(), "{:?}", s.warnings);
            continue;
        }
        let note = note.unwrap();
        assert!(
            note.starts_with(&format!("dropped {} row(s)", bad.len())),
            "{note}"
        );
        let first: Vec<String> = bad.iter().take(3).map(usize::to_string).collect();
        assert!(
            note.contains(&format!("lines {}", first.join(", "))),
            "{note}"
        );
        assert!(s.levels.iter().all(|l| !bad.contains(&l.line)));
    }
    // tests/data/soundings/README.md: 0 in Bjørnøya, 3 in Ny-Ålesund, 18 in Trois-Rivières.
    assert_eq!(counts, [0, 3, 18]);
}

#[test]
fn levels_equal_the_hand_converted_csvs() {
    for (i, (name, _)) in FILES.iter().enumerate() {
        let esc = read(&raw_path(i));
        let csv = read(&csv_path(i));
        assert_eq!(esc.format, SoundingFormat::EolEsc, "{name}");
        assert_eq!(esc.levels.len(), csv.levels.len(), "{name}");
        // The CSVs carry the ESC values to 0.1 (m, °C, hPa).
        for (e, c) in esc.levels.iter().zip(&csv.levels) {
            let at = format!("{name}: ESC line {} vs CSV line {}", e.line, c.line);
            assert!((e.height_m - c.height_m).abs() <= 0.05 + 1e-9, "{at}");
            assert!(
                (e.temperature_k - c.temperature_k).abs() <= 0.05 + 1e-9,
                "{at}"
            );
            match (e.pressure_pa, c.pressure_pa) {
                (Some(a), Some(b)) => assert!((a - b).abs() <= 5.0 + 1e-6, "{at}"),
                (a, b) => assert_eq!(a, b, "{at}"),
            }
            // 0.05 K of dewpoint changes the vapour pressure by under 2 % down to −95 °C.
            match (e.vapour_pressure_pa, c.vapour_pressure_pa) {
                (Some(a), Some(b)) => assert!((a / b - 1.0).abs() <= 0.02, "{at}"),
                (a, b) => assert_eq!(a, b, "{at}"),
            }
        }
    }
}

#[test]
fn each_level_points_at_its_raw_line() {
    for (i, (name, _)) in FILES.iter().enumerate() {
        let text = std::fs::read_to_string(raw_path(i)).unwrap();
        let table = RawTable::of(&text);
        for level in read(&raw_path(i)).levels {
            assert_eq!(
                level.height_m,
                table.value(level.line, "Alt"),
                "{name} line {}",
                level.line
            );
            let t = table.value(level.line, "Temp") + 273.15;
            assert!(
                (level.temperature_k - t).abs() < 1e-9,
                "{name} line {}",
                level.line
            );
        }
    }
}

#[test]
fn pressure_flagged_bad_is_missing() {
    // Trois-Rivières: Qp is 3 on rows whose Qt is not (the CSV leaves their pressure empty).
    let path = raw_path(2);
    let table = RawTable::of(&std::fs::read_to_string(&path).unwrap());
    let qt_bad = table.flagged_bad("Qt");
    let only_p: Vec<usize> = table
        .flagged_bad("Qp")
        .into_iter()
        .filter(|l| !qt_bad.contains(l))
        .collect();
    assert_eq!(only_p.len(), 4, "{only_p:?}");
    let s = read(&path);
    for line in &only_p {
        let level = s.levels.iter().find(|l| l.line == *line);
        // A row may also have been dropped as a backward step of the ascent; if kept, no pressure.
        if let Some(level) = level {
            assert_eq!(level.pressure_pa, None, "line {line}");
        }
    }
    let note = s
        .warnings
        .iter()
        .find(|w| w.contains("flag Qp is 3"))
        .unwrap();
    assert!(note.contains("of 4 row(s)"), "{note}");
}

/// The value of the header line starting with `label`.
fn header_value(text: &str, label: &str) -> String {
    let line = text.lines().find(|l| l.starts_with(label)).expect(label);
    line.split_once(':').unwrap().1.trim().to_string()
}

#[test]
fn metadata_comes_from_the_header() {
    for (i, (name, _)) in FILES.iter().enumerate() {
        let text = std::fs::read_to_string(raw_path(i)).unwrap();
        let s = read(&raw_path(i));
        let m = &s.metadata;
        // Release location: deg-min lon, lat, then decimal lon, lat and altitude.
        let location = header_value(&text, "Release Location (lon,lat,alt):");
        let parts: Vec<f64> = location
            .split(',')
            .skip(2)
            .map(|p| p.trim().parse().unwrap())
            .collect();
        assert_eq!(s.metadata_number("longitude"), Some(parts[0]), "{name}");
        assert_eq!(s.metadata_number("latitude"), Some(parts[1]), "{name}");
        assert_eq!(
            s.metadata_number("station_elevation_m"),
            Some(parts[2]),
            "{name}"
        );
        // The hand conversion read the same numbers.
        let csv = read(&csv_path(i));
        for key in ["latitude", "longitude", "station_elevation_m"] {
            assert_eq!(
                s.metadata_number(key),
                csv.metadata_number(key),
                "{name} {key}"
            );
        }
        assert_eq!(
            m["station"],
            header_value(&text, "Release Site Type/Site ID:")
        );
        assert_eq!(m["project"], header_value(&text, "Project ID:"));
        assert_eq!(
            m["radiosonde"],
            header_value(&text, "Radiosonde Type/RH Sensor Type:")
        );
        // "2024, 02, 26, 11:20:12" → "2024-02-26 11:20:12 UTC".
        let release = header_value(&text, "UTC Release Time (y,m,d,h,m,s):");
        let p: Vec<&str> = release.split(", ").collect();
        let launch = format!("{}-{}-{} {} UTC", p[0], p[1], p[2], p[3]);
        assert_eq!(m["launch_time_utc"], launch, "{name}");
        let nominal = header_value(&text, "Nominal Release Time (y,m,d,h,m,s):");
        let p: Vec<&str> = nominal.split(", ").collect();
        assert!(p[3].ends_with(":00:00"), "{nominal}");
        let hour = format!("{}-{}-{} {}", p[0], p[1], p[2], &p[3][..2]);
        assert_eq!(m["nominal_time_utc"], hour, "{name}");
    }
    // Values read off the headers by hand.
    let b = read(&raw_path(0)).metadata;
    assert_eq!(b["station"], "Bjornoya_Norway / 01028");
    assert_eq!(b["site_id"], "01028");
    assert_eq!(b["launch_time_utc"], "2024-02-26 11:20:12 UTC");
    assert_eq!(b["nominal_time_utc"], "2024-02-26 12");
    assert_eq!(b["temperature_qc"], "9 (missing): 1, 99 (unchecked): 2886");
    assert_eq!(b["ascension_number"], "56");
    let t = read(&raw_path(2)).metadata;
    assert_eq!(t["station"], "UQAM Trois Rivieres, QC");
    assert!(!t.contains_key("site_id"));
    assert_eq!(
        (t["latitude"].as_str(), t["longitude"].as_str()),
        ("46.349", "-72.581")
    );
    assert_eq!(
        t["radiosonde"],
        "iMet-4 radiosonde/thin-film capacitive polymer"
    );
}

#[test]
fn qc_summary_counts_every_flag() {
    let text = std::fs::read_to_string(raw_path(1)).unwrap();
    let table = RawTable::of(&text);
    let qt = table.column("Qt");
    let count = |v: f64| {
        table
            .rows
            .iter()
            .filter(|(_, f)| f[qt].parse::<f64>().unwrap() == v)
            .count()
    };
    let expected = format!(
        "1 (good): {}, 2 (maybe): {}, 3 (bad): {}, 9 (missing): {}",
        count(1.0),
        count(2.0),
        count(3.0),
        count(9.0)
    );
    assert_eq!(read(&raw_path(1)).metadata["temperature_qc"], expected);
    assert_eq!(
        count(1.0) + count(2.0) + count(3.0) + count(9.0),
        table.rows.len()
    );
}

#[test]
fn detected_from_content_not_extension() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read(raw_path(0)).unwrap();
    let renamed = dir.path().join("sounding.txt");
    std::fs::write(&renamed, &text).unwrap();
    assert_eq!(read(&renamed).format, SoundingFormat::EolEsc);
    let csv_as_cls = dir.path().join("x.cls");
    std::fs::copy(csv_path(0), &csv_as_cls).unwrap();
    assert_eq!(read(&csv_as_cls).format, SoundingFormat::NormalizedCsv);
    // A time is refused: the file holds one sounding.
    let e = read_sounding(&raw_path(0), &ReadOptions::with_time("2024-02-26 12")).unwrap_err();
    assert!(
        e.to_string()
            .contains("an NCAR/EOL ESC sounding and holds one sounding"),
        "{e}"
    );
}

/// The Bjørnøya text with `line` (1-based) changed by `edit`.
fn edited(line: usize, edit: impl Fn(&str) -> String) -> String {
    let text = std::fs::read_to_string(raw_path(0)).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    lines[line - 1] = edit(&lines[line - 1]);
    lines.join("\n") + "\n"
}

#[test]
fn corrupt_and_truncated_files_name_line_and_field() {
    let source = Path::new("tests/data/soundings/raw/bjornoya-edited.cls");
    let parse = |text: &str| parse_sounding(text, source, &ReadOptions::default()).unwrap_err();
    // Line 200: the 185th data row. Replace its Temp field by a non-number.
    let text = std::fs::read_to_string(raw_path(0)).unwrap();
    let temp = RawTable::of(&text).column("Temp");
    let e = parse(&edited(200, |l| {
        let mut f: Vec<&str> = l.split_whitespace().collect();
        f[temp] = "-7.x";
        f.join(" ")
    }));
    assert!(matches!(e, SoundingError::Field { .. }), "{e}");
    assert_eq!((e.line(), e.column()), (Some(200), Some("Temp")));
    let message = e.to_string();
    assert!(
        message.starts_with("tests/data/soundings/raw/bjornoya-edited.cls: line 200, column Temp"),
        "{message}"
    );
    assert!(message.contains("cannot parse \"-7.x\""), "{message}");
    // Cut in the middle of line 300: the row lacks its last columns.
    let cut: String = {
        let full = edited(300, |l| l[..40].to_string());
        full.lines().take(300).map(|l| format!("{l}\n")).collect()
    };
    let e = parse(&cut);
    assert_eq!(e.line(), Some(300), "{e}");
    assert!(e.to_string().contains("truncated or corrupt row"), "{e}");
    // A header without Alt: the heights cannot be read.
    let e = parse(&edited(13, |l| l.replace(" Alt ", " Hgt ")));
    assert_eq!(e.line(), Some(13), "{e}");
    assert!(e.to_string().contains("no Alt column"), "{e}");
    // The header cut short before the table.
    let head: String = text.lines().take(13).map(|l| format!("{l}\n")).collect();
    assert!(parse(&head).to_string().contains("cut short"));
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// Whatever is deleted or inserted where, the reader answers with a sounding or an error
    /// naming the source, never a panic.
    #[test]
    fn mutated_esc_files_never_panic(
        edits in proptest::collection::vec((0usize..4000, 0usize..4, "[0-9 .x:\n-]{0,3}"), 1..5),
    ) {
        thread_local! {
            static TEXT: String = std::fs::read_to_string(raw_path(1)).unwrap();
        }
        // The header and the first hundred rows, edited.
        let mut text: String = TEXT.with(|t| t.lines().take(115).map(|l| format!("{l}\n")).collect());
        for (at, delete, insert) in edits {
            let mut at = at.min(text.len());
            while !text.is_char_boundary(at) {
                at -= 1;
            }
            let end = (at + delete).min(text.len());
            let end = (end..=text.len()).find(|&e| text.is_char_boundary(e)).unwrap();
            text.replace_range(at..end, &insert);
        }
        match parse_sounding(&text, Path::new("mutated"), &ReadOptions::default()) {
            Ok(s) => prop_assert!(s.levels.len() >= 3),
            Err(e) => prop_assert!(e.to_string().starts_with("mutated")),
        }
    }
}

#[test]
fn profile_reports_the_esc_input() {
    let v = crate::support::cli::profile_json(&raw_path(0));
    let input = &v["input"];
    assert_eq!(input["format"], "eol_esc");
    assert_eq!(input["nominal_time_utc"], "2024-02-26 12");
    assert_eq!(input["levels_read"], read(&csv_path(0)).levels.len());
    let description = input["description"].as_str().unwrap();
    assert!(
        description.contains("launched 2024-02-26 11:20:12 UTC"),
        "{description}"
    );
}

/// The surface is the lowest level kept; when flagged-bad first rows lift it off the release
/// altitude of the header, a note says by how much (Trois-Rivières: release 59.0 m, first good
/// row 91.3 m; Bjørnøya's first row is the release).
#[test]
fn a_surface_above_the_release_altitude_is_noted() {
    let note = |s: &Sounding| {
        s.warnings
            .iter()
            .find(|w| w.contains("from the release altitude"))
            .cloned()
    };
    let bjornoya = read(&raw_path(0));
    assert_eq!(note(&bjornoya), None, "{:?}", bjornoya.warnings);
    let trois = read(&raw_path(2));
    let release_m = trois.metadata_number("station_elevation_m").unwrap();
    let lift = trois.levels[0].height_m - release_m;
    assert!(lift > 30.0, "{lift}");
    let text = note(&trois).expect("a note");
    assert!(text.contains(&format!("{lift:.1} m")), "{text}");
}
