//! Stage 1 — ingest of archive files as users get them: real pages and files from public
//! projects' test suites (`tests/data/soundings/public/`, provenance in its README): levels that
//! contradict those below them, pages holding several soundings, a page without data, gzip and
//! zip archives, the choice of one sounding by its time, and SPC / SHARPpy `%RAW%` files.

use std::io::Write;
use std::path::{Path, PathBuf};

use ghostship::sounding::{HeightSource, ReadOptions, Sounding, read_sounding, sounding_times};

use crate::support::data::public_sounding;

fn read(path: &Path) -> Sounding {
    read_sounding(path, &ReadOptions::default())
        .unwrap_or_else(|e| panic!("{} failed to ingest: {e}", path.display()))
}

fn strict() -> ReadOptions {
    ReadOptions {
        strict: true,
        ..ReadOptions::default()
    }
}

fn at(time: &str) -> ReadOptions {
    ReadOptions::with_time(time)
}

/// The 1-based lines of `path` whose text (tags removed) starts like a TEXT:LIST level with a
/// temperature: read independently of the library, by splitting on whitespace.
fn table_lines_with_temperature(path: &Path, lines: std::ops::Range<usize>) -> Vec<usize> {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .enumerate()
        .filter(|(i, _)| lines.contains(&(i + 1)))
        .filter(|(_, l)| {
            let cells: Vec<&str> = l.split_whitespace().collect();
            cells.len() >= 3
                && cells[..3].iter().all(|c| c.parse::<f64>().is_ok())
                && l.len() > 20
                && !l[14..21].trim().is_empty()
        })
        .map(|(i, _)| i + 1)
        .collect()
}

#[test]
fn a_level_that_contradicts_the_one_below_is_dropped_with_a_note() {
    // SHARPpy's Norman 2018-12-22 12 UTC page: two 44.0 hPa rows, 21336 m (line 83) and
    // 21330 m (line 84).
    let path = public_sounding("wyoming_OUN_2018122212_sharppy.html");
    let s = read(&path);
    assert!(s.levels.iter().any(|l| l.line == 83));
    assert!(s.levels.iter().all(|l| l.line != 84));
    let note = s
        .warnings
        .iter()
        .find(|w| w.contains("contradict"))
        .expect("a note on the dropped level");
    assert!(
        note.contains("dropped 1 level(s)")
            && note
                .contains("line 84, column HGHT: height 21330 m is not above 21336 m at line 83"),
        "{note}"
    );
    // Every other level with a temperature was read, in file order.
    let expected: Vec<usize> = table_lines_with_temperature(&path, 1..200)
        .into_iter()
        .filter(|&l| l != 84)
        .collect();
    let got: Vec<usize> = s.levels.iter().map(|l| l.line).collect();
    assert_eq!(got, expected);
    // 21 km is far above the strict zone: strict mode reads it the same way.
    let strict_read = read_sounding(&path, &strict()).unwrap();
    assert_eq!(strict_read.levels, s.levels);

    // siphon's Boise page: two such pairs, at 15 km and 26 km.
    let boise = read(&public_sounding(
        "wyoming_BOI_2010120912_siphon_high_alt.html",
    ));
    let note = boise
        .warnings
        .iter()
        .find(|w| w.contains("contradict"))
        .unwrap();
    assert!(note.contains("dropped 2 level(s)"), "{note}");
    assert!(note.contains("line 81, column HGHT") && note.contains("line 127, column HGHT"));
}

#[test]
fn strict_mode_refuses_a_contradiction_in_the_lowest_kilometres() {
    // The real Norman page with its 850 hPa row's height moved below the level under it.
    let path = public_sounding("wyoming_OUN_2018122212_sharppy.html");
    let text = std::fs::read_to_string(&path).unwrap();
    let line = text
        .lines()
        .position(|l| l.starts_with("  850.0 "))
        .unwrap();
    let original = text.lines().nth(line).unwrap();
    let below_height: f64 = text.lines().nth(line - 1).unwrap()[7..14]
        .trim()
        .parse()
        .unwrap();
    let bad = format!("  850.0{:>7}{}", below_height - 1.0, &original[14..]);
    let dir = tempfile::tempdir().unwrap();
    let edited = dir.path().join("oun.html");
    std::fs::write(&edited, text.replacen(original, &bad, 1)).unwrap();
    let e = read_sounding(&edited, &strict()).unwrap_err();
    assert_eq!(e.line(), Some(line + 1), "{e}");
    assert!(e.to_string().contains("heights must increase"), "{e}");
    let lenient = read(&edited);
    assert!(lenient.levels.iter().all(|l| l.line != line + 1));
}

#[test]
fn a_page_of_several_soundings_reads_the_one_asked_for() {
    let path = public_sounding("wyoming_OUN_201305_multi12_rnleach.html");
    let times = sounding_times(&path).unwrap().unwrap();
    assert_eq!(times.len(), 12);
    assert_eq!(times[0], "2013-05-17 00");
    assert_eq!(times[6], "2013-05-19 18");
    assert_eq!(times[11], "2013-05-22 00");

    let first = read(&path);
    assert_eq!(first.metadata["nominal_time_utc"], "2013-05-17 00");
    assert_eq!(first.metadata["observation_time"], "00Z 17 May 2013");
    assert!(first.levels.iter().all(|l| l.line < 158));
    let note = first
        .warnings
        .iter()
        .find(|w| w.contains("soundings"))
        .unwrap();
    assert!(
        note.contains("the page holds 12 soundings (2013-05-17 00 … 2013-05-22 00)"),
        "{note}"
    );
    // The station block's first entry sits on the line of its heading in this browser-saved page.
    assert_eq!(first.metadata["station_identifier"], "OUN");

    // The 18 UTC special of 19 May, asked for in ISO form: its title is line 1009, its first
    // level with a temperature line 1015 (964.0 hPa, 345 m, 27.4 °C).
    let special = read_sounding(&path, &at("2013-05-19T18:00Z")).unwrap();
    assert_eq!(special.metadata["nominal_time_utc"], "2013-05-19 18");
    let lines: Vec<usize> = special.levels.iter().map(|l| l.line).collect();
    assert_eq!(lines[0], 1015);
    assert_eq!(special.levels[0].height_m, 345.0);
    assert!((special.levels[0].temperature_k - (27.4 + 273.15)).abs() < 1e-9);
    let mut expected = table_lines_with_temperature(&path, 1009..1163);
    let dropped: Vec<usize> = expected
        .iter()
        .copied()
        .filter(|l| !lines.contains(l))
        .collect();
    expected.retain(|l| lines.contains(l));
    assert_eq!(lines, expected);
    // Whatever was not read is accounted for by a note naming its line.
    for l in dropped {
        assert!(
            special
                .warnings
                .iter()
                .any(|w| w.contains(&format!("line {l}"))),
            "line {l} dropped silently: {:?}",
            special.warnings
        );
    }

    let e = read_sounding(&path, &at("2013-05-20 00"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("holds 12 soundings"), "{e}");
    assert!(
        e.contains("nearest: 2013-05-19 18, 2013-05-19 12, 2013-05-20 12"),
        "{e}"
    );
}

#[test]
fn a_page_without_data_quotes_the_server() {
    let e = read_sounding(
        &public_sounding("wyoming_BOI_2010120901_siphon_no_data.html"),
        &ReadOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("the page holds no sounding: the server says \"Can't get 72681 BOI Boise Observations at 01Z 09 Dec 2010.\""),
        "{e}"
    );
}

#[test]
fn a_page_with_missing_station_fields_reads() {
    let s = read(&public_sounding(
        "wyoming_82244_2012010100_siphon_missing_station_info.html",
    ));
    assert_eq!(s.metadata["station"], "82244  Santarem");
    assert_eq!(s.metadata["nominal_time_utc"], "2012-01-01 00");
    // The surface row (1002.0 hPa, 29.0 °C, no height) gets a hypsometric height below the
    // 1000.0 hPa level at 74 m: Δz = R_d·T_v/g·ln(1002/1000), T_v ≈ 302.1 K·(1 + 0.61·0.0194).
    assert_eq!(s.levels[0].height_source, HeightSource::Hypsometric);
    let tv = (29.0 + 273.15) * (1.0 + 0.61 * 0.0194);
    let expected = 74.0 - 287.05 * tv / 9.80665 * (1002.0f64 / 1000.0).ln();
    assert!(
        (s.levels[0].height_m - expected).abs() < 0.3,
        "{} vs {expected}",
        s.levels[0].height_m
    );
    assert_eq!(s.levels[1].height_m, 74.0);
}

fn gzip_of(data: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    e.write_all(data).unwrap();
    e.finish().unwrap()
}

fn zip_of(members: &[(&str, &[u8])]) -> Vec<u8> {
    let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    for (name, data) in members {
        w.start_file(*name, zip::write::SimpleFileOptions::default())
            .unwrap();
        w.write_all(data).unwrap();
    }
    w.finish().unwrap().into_inner()
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

#[test]
fn gzip_and_zip_archives_read_as_the_file_they_hold() {
    // siphon's IGRA2 record came as a .txt.zip; here the real text is packed both ways.
    let path = public_sounding("igra2_USM00070026-data.txt");
    let text = std::fs::read(&path).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let gz = write(dir.path(), "USM00070026-data.txt.gz", &gzip_of(&text));
    let zipped = write(
        dir.path(),
        "USM00070026-data.txt.zip",
        &zip_of(&[("USM00070026-data.txt", &text)]),
    );
    let plain = read(&path);
    for (packed, how) in [(&gz, "gzip"), (&zipped, "zip member USM00070026-data.txt")] {
        let s = read(packed);
        assert_eq!(s.levels, plain.levels, "{how}");
        assert_eq!(s.metadata["packed_as"], how);
        assert_eq!(
            sounding_times(packed).unwrap(),
            sounding_times(&path).unwrap()
        );
    }
    let times = sounding_times(&path).unwrap().unwrap();
    let second = read_sounding(&zipped, &at(&times[1])).unwrap();
    assert_eq!(second.metadata["nominal_time_utc"], times[1]);
    // siphon's excerpt ends with the header of a third sounding and none of its records.
    let e = read_sounding(&zipped, &at(&times[2]))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("line 318: the header announces 147 levels but 0 records follow"),
        "{e}"
    );

    let two = write(
        dir.path(),
        "two.zip",
        &zip_of(&[("a-data.txt", &text), ("b-data.txt", &text)]),
    );
    let e = read_sounding(&two, &ReadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("a zip archive of 2 files (a-data.txt, b-data.txt)"),
        "{e}"
    );
    let mut cut = gzip_of(&text);
    cut.truncate(cut.len() / 2);
    let broken = write(dir.path(), "cut.txt.gz", &cut);
    let e = read_sounding(&broken, &ReadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("cut.txt.gz") && e.contains("cannot be inflated"),
        "{e}"
    );
}

#[test]
fn sounding_times_are_checked_and_duplicates_flagged() {
    let path = public_sounding("igra2_USM00070026-data.txt");
    let text = std::fs::read_to_string(&path).unwrap();
    let times = sounding_times(&path).unwrap().unwrap();
    // ISO spellings choose the same sounding.
    let a = read_sounding(&path, &at(&times[1])).unwrap();
    let iso = format!("{}T{}:00Z", &times[1][..10], &times[1][11..]);
    assert_eq!(read_sounding(&path, &at(&iso)).unwrap().levels, a.levels);
    let e = read_sounding(&path, &at("June 1st"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("not a nominal time"), "{e}");
    // A time on a file of one sounding is an error, not silently ignored; a one-sounding page
    // reads at its own time and names it when asked for another.
    let csv = crate::support::data::sounding("Norman-72357_1999050400.csv");
    let e = read_sounding(&csv, &at("1999-05-04 00"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("is a normalised CSV and holds one sounding"),
        "{e}"
    );
    let page = public_sounding("wyoming_OUN_2018122212_sharppy.html");
    assert_eq!(
        read_sounding(&page, &at("2018-12-22T12Z")).unwrap().levels,
        read(&page).levels
    );
    let e = read_sounding(&page, &at("2018-12-23 00"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("holds 1 sounding (2018-12-22 12)"), "{e}");
    // The same record twice: the first is read and the second named.
    let first_header = text.lines().position(|l| l.starts_with('#')).unwrap();
    let second_header = first_header
        + 1
        + text
            .lines()
            .skip(first_header + 1)
            .position(|l| l.starts_with('#'))
            .unwrap();
    let block: Vec<&str> = text
        .lines()
        .skip(first_header)
        .take(second_header - first_header)
        .collect();
    let doubled = format!("{}\n{text}", block.join("\n"));
    let dir = tempfile::tempdir().unwrap();
    let twice = write(dir.path(), "twice-data.txt", doubled.as_bytes());
    let s = read_sounding(&twice, &at(&times[0])).unwrap();
    let note = s
        .warnings
        .iter()
        .find(|w| w.contains("soundings at"))
        .unwrap();
    assert!(
        note.contains(&format!("the file holds 2 soundings at {}", times[0]))
            && note.contains(&format!("line {}", block.len() + 1)),
        "{note}"
    );
}

/// The number tokens of a JSON text, as printed (not re-parsed: parsing and printing again could
/// itself add digits).
fn number_tokens(json: &str) -> Vec<&str> {
    json.split(|c: char| !(c.is_ascii_digit() || "eE.+-".contains(c)))
        .filter(|t| {
            t.chars()
                .next()
                .is_some_and(|c| c.is_ascii_digit() || c == '-')
        })
        .filter(|t| t.chars().any(|c| c.is_ascii_digit()))
        .collect()
}

#[test]
fn the_profile_json_says_what_was_read_and_what_ingest_did() {
    let path = public_sounding("wyoming_OUN_2018122212_sharppy.html");
    let dir = tempfile::tempdir().unwrap();
    let r = crate::support::cli::ok(&[
        "profile",
        path.to_str().unwrap(),
        "--out",
        dir.path().to_str().unwrap(),
        "--format",
        "json",
        "--quiet",
    ]);
    let v: serde_json::Value = serde_json::from_str(&r.stdout).unwrap();
    let input = &v["input"];
    let s = read(&path);
    assert_eq!(input["source"], path.to_str().unwrap());
    assert_eq!(input["format"], "wyoming_text_list");
    assert_eq!(input["station"], "72357 OUN Norman");
    assert_eq!(input["nominal_time_utc"], "2018-12-22 12");
    assert_eq!(input["levels_read"], s.levels.len());
    let notes: Vec<&str> = input["notes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_str().unwrap())
        .collect();
    assert_eq!(notes, s.warnings);
    assert!(notes.iter().any(|n| n.contains("line 84")));
    // No rounding noise: every number is printed with at most 10 significant digits. (Numbers
    // inside the notes' text are integers and line numbers.)
    let numbers = number_tokens(&r.stdout);
    assert!(numbers.len() > 30, "{numbers:?}");
    for text in numbers {
        let mantissa = text.split(['e', 'E']).next().unwrap();
        let digits: String = mantissa.chars().filter(char::is_ascii_digit).collect();
        let significant = digits.trim_start_matches('0').trim_end_matches('0').len();
        assert!(significant <= 10, "{text}");
    }
    assert_eq!(v["surface"]["pressure_hpa"], 966.0);
    // The table says how many levels were read and from where.
    let text = crate::support::cli::ok(&[
        "profile",
        path.to_str().unwrap(),
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert!(
        text.stdout.contains(&format!(
            "Read {} levels from {} (a University of Wyoming TEXT:LIST page), 2 ingest notes",
            s.levels.len(),
            path.display()
        )),
        "{}",
        text.stdout
    );
}

/// The `%RAW%` rows of an SPC / SHARPpy file that have a temperature, split independently of the
/// library: (line, pressure hPa, height m, temperature °C, dewpoint °C or None).
fn spc_rows_with_temperature(path: &Path) -> Vec<(usize, f64, f64, f64, Option<f64>)> {
    let text = std::fs::read_to_string(path).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let start = lines.iter().position(|l| l.trim() == "%RAW%").unwrap() + 1;
    let end = lines.iter().position(|l| l.trim() == "%END%").unwrap();
    (start..end)
        .filter_map(|i| {
            let v: Vec<f64> = lines[i]
                .split(',')
                .map(|c| c.trim().parse().unwrap())
                .collect();
            (v[2] != -9999.0).then(|| (i + 1, v[0], v[1], v[2], (v[3] != -9999.0).then_some(v[3])))
        })
        .collect()
}

#[test]
fn spc_sharppy_raw_files_read_every_level_with_a_temperature() {
    for (name, station, time, levels) in [
        ("sharppy_14061619.OAX", "OAX", "2014-06-16 19", 150),
        ("sharppy_14072800.BNA", "BNA", "2014-07-28 00", 86),
        ("sharppy_sars_hail_00033000.SHV", "SHV", "2000-03-30 00", 92),
        ("sharppy_sars_hail_01040400.LZK", "LZK", "2001-04-04 00", 83),
    ] {
        let path = public_sounding(name);
        let s = read(&path);
        let expected = spc_rows_with_temperature(&path);
        assert_eq!(
            s.format,
            ghostship::sounding::SoundingFormat::SpcRaw,
            "{name}"
        );
        assert_eq!(s.metadata["station"], station, "{name}");
        assert_eq!(s.metadata["nominal_time_utc"], time, "{name}");
        assert_eq!(expected.len(), levels, "{name}: rows with temperature");
        assert_eq!(s.levels.len(), levels, "{name}: {:?}", s.warnings);
        for (level, &(line, p, h, t, td)) in s.levels.iter().zip(&expected) {
            assert_eq!(level.line, line, "{name}");
            assert_eq!(level.pressure_pa, Some(p * 100.0), "{name} line {line}");
            assert_eq!(level.height_m, h, "{name} line {line}");
            assert!(
                (level.temperature_k - (t + 273.15)).abs() < 1e-9,
                "{name} line {line}"
            );
            assert_eq!(
                level.vapour_pressure_pa.is_some(),
                td.is_some(),
                "{name} line {line}"
            );
            assert_eq!(level.height_source, HeightSource::Measured);
        }
    }
    // A BNA title carries the position; the SARS surface (994 hPa, 79 m) precedes the
    // below-ground 1000 hPa row, which has no temperature and is skipped.
    let bna = read(&public_sounding("sharppy_14072800.BNA"));
    assert_eq!(bna.metadata["latitude"], "36.25");
    assert_eq!(bna.metadata["longitude"], "-86.56");
    let shv = read(&public_sounding("sharppy_sars_hail_00033000.SHV"));
    assert_eq!((shv.surface().line, shv.surface().height_m), (7, 79.0));
}
