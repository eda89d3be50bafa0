//! The reference pages `docs/scene.md` and `docs/atmosphere.md` against the real parsers, so the
//! pages cannot drift from the code:
//!
//! * every fenced TOML example parses (scene examples with `Scene::from_toml_str` as if the file
//!   sat in `data/scenes/`, their atmospheres loaded too; atmosphere examples with
//!   `SyntheticAtmosphere::from_toml_str`), and every sounding example parses with
//!   `parse_sounding` and is detected as the format its `<!-- sounding-format: … -->` marker names;
//! * the keys the pages' tables document are exactly the keys the deserializers accept. The
//!   accepted keys come from the parsers themselves: every section rejects unknown keys, and the
//!   rejection lists the fields it expects ("unknown field `x`, expected one of `a`, `b`");
//! * every scene table row's example value is accepted for its key, and every default a row gives
//!   as a plain value is the value the parser fills in when the key is absent (to the digits the
//!   page prints).

use std::collections::BTreeSet;
use std::path::Path;

use ghostship::atmosphere::AtmosphereOptions;
use ghostship::profile::SyntheticAtmosphere;
use ghostship::scene::Scene;
use ghostship::sounding::{ReadOptions, SoundingFormat, parse_sounding};

use super::support::data::{data_file, repo_file};

/// A fenced code block of a markdown page.
struct Block {
    /// The info string after the opening fence (`toml`, `csv`, …).
    info: String,
    text: String,
    /// 1-based line of the opening fence.
    line: usize,
    /// `X` of a `<!-- sounding-format: X -->` comment on the last non-blank line before the fence.
    format_marker: Option<String>,
}

fn read_page(rel: &str) -> String {
    let path = repo_file(rel);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn blocks(page: &str) -> Vec<Block> {
    let lines: Vec<&str> = page.lines().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let Some(info) = lines[i].strip_prefix("```") else {
            i += 1;
            continue;
        };
        let start = i;
        let format_marker = lines[..start]
            .iter()
            .rev()
            .find(|l| !l.trim().is_empty())
            .and_then(|l| l.trim().strip_prefix("<!-- sounding-format:"))
            .and_then(|l| l.strip_suffix("-->"))
            .map(|s| s.trim().to_string());
        let mut text = String::new();
        i += 1;
        while i < lines.len() && !lines[i].starts_with("```") {
            text.push_str(lines[i]);
            text.push('\n');
            i += 1;
        }
        assert!(i < lines.len(), "unclosed code block at line {}", start + 1);
        out.push(Block {
            info: info.trim().to_string(),
            text,
            line: start + 1,
            format_marker,
        });
        i += 1;
    }
    out
}

/// The table rows whose first cell is exactly one backticked key: (key, the row's cells).
fn key_rows(page: &str) -> Vec<(String, Vec<String>)> {
    page.lines()
        .filter_map(|line| {
            let inner = line.trim().strip_prefix('|')?.strip_suffix('|')?;
            let cells: Vec<String> = inner.split('|').map(|c| c.trim().to_string()).collect();
            let key = cells.first()?.strip_prefix('`')?.strip_suffix('`')?;
            (!key.contains('`')).then(|| (key.to_string(), cells.clone()))
        })
        .collect()
}

/// The field names an "unknown field" rejection lists as expected.
fn expected_fields(message: &str) -> BTreeSet<String> {
    let Some((_, list)) = message.split_once("expected") else {
        return BTreeSet::new();
    };
    let list = list.split('\n').next().unwrap_or("");
    list.split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_string)
        .collect()
}

const UNKNOWN: &str = "zz_not_a_key";
const CAMERA: &str = "[camera]\nheight_m = 10.0\nhfov_deg = 1.0\nwidth = 40\nheight = 20\n";

fn scenes_dir() -> std::path::PathBuf {
    data_file("scenes")
}

fn parse_scene(text: &str) -> Result<Scene, String> {
    Scene::from_toml_str(text, &scenes_dir(), Path::new("docs-test.toml")).map_err(|e| {
        // The whole chain: the TOML error (with the expected fields) is the source.
        let mut s = e.to_string();
        let mut source = std::error::Error::source(&e);
        while let Some(inner) = source {
            s.push_str(": ");
            s.push_str(&inner.to_string());
            source = inner.source();
        }
        s
    })
}

/// The keys the scene parser accepts in `section` ("" for the top level), from its rejection of
/// an unknown key there.
fn scene_accepted(section: &str) -> BTreeSet<String> {
    let text = match section {
        "" => format!("{UNKNOWN} = 1\n{CAMERA}"),
        "camera" => format!("{CAMERA}{UNKNOWN} = 1\n"),
        "cards" => format!("{CAMERA}[[cards]]\n{UNKNOWN} = 1\n"),
        s => format!("{CAMERA}[{s}]\n{UNKNOWN} = 1\n"),
    };
    let err = parse_scene(&text).expect_err("an unknown key must be rejected");
    assert!(err.contains(UNKNOWN), "section {section:?}: {err}");
    let fields = expected_fields(&err);
    assert!(
        !fields.is_empty(),
        "section {section:?}: no expected fields in the rejection: {err}"
    );
    fields
}

/// Documented scene keys by section: `camera.height_m` → ("camera", "height_m").
fn scene_doc_keys(page: &str) -> Vec<(String, String, Vec<String>)> {
    key_rows(page)
        .into_iter()
        .map(|(key, cells)| {
            let (section, name) = key
                .split_once('.')
                .unwrap_or_else(|| panic!("scene.md key {key:?} is not section.key"));
            (section.to_string(), name.to_string(), cells)
        })
        .collect()
}

#[test]
fn scene_page_documents_exactly_the_keys_the_parser_accepts() {
    let page = read_page("docs/scene.md");
    let keys = scene_doc_keys(&page);
    let sections: BTreeSet<String> = keys.iter().map(|(s, _, _)| s.clone()).collect();
    assert_eq!(
        sections,
        scene_accepted(""),
        "docs/scene.md sections vs the scene file's top-level tables"
    );
    for section in &sections {
        let documented: BTreeSet<String> = keys
            .iter()
            .filter(|(s, _, _)| s == section)
            .map(|(_, k, _)| k.clone())
            .collect();
        assert_eq!(
            documented,
            scene_accepted(section),
            "docs/scene.md keys of [{section}] vs the keys the parser accepts"
        );
    }
}

/// A scene with every section present (one card, a sun, a sounding when `with_sounding`), as a
/// TOML table to put one key into.
fn base_scene(with_sounding: bool) -> toml::Table {
    let mut text = format!(
        "{CAMERA}[atmosphere]\n[earth]\n[sky]\n[sea]\n[[cards]]\nimage = \"../cards/ship.png\"\n\
         distance_m = 10000.0\nwidth_m = 50.0\nheight_m = 20.0\n[sun]\nelevation_deg = 1.0\n\
         [terrain]\ndem = \"terrain/island.tif\"\nobserver_lat_deg = 78.0\nobserver_lon_deg = 15.0\n\
         orthophoto = \"terrain/island_photo.png\"\n\
         [render]\n"
    );
    if with_sounding {
        text = text.replace(
            "[atmosphere]\n",
            "[atmosphere]\nsounding = \"../../tests/data/soundings/raw/USM00070026-data_2010-06-01_excerpt.txt\"\n",
        );
    }
    toml::from_str(&text).expect("base scene is TOML")
}

fn section_of<'a>(table: &'a mut toml::Table, section: &str) -> &'a mut toml::Table {
    let value = table.get_mut(section).expect("base has every section");
    match value {
        toml::Value::Array(cards) => cards[0].as_table_mut().expect("a card table"),
        v => v.as_table_mut().expect("a section table"),
    }
}

/// The first backticked token of a cell, if the cell starts with one, as a TOML value.
fn cell_value(cell: &str) -> Option<(String, toml::Value)> {
    let inner = cell.strip_prefix('`')?;
    let token = &inner[..inner.find('`')?];
    let value: toml::Table = toml::from_str(&format!("v = {token}")).ok()?;
    Some((token.to_string(), value["v"].clone()))
}

#[test]
fn scene_table_examples_are_accepted() {
    let page = read_page("docs/scene.md");
    let keys = scene_doc_keys(&page);
    assert!(!keys.is_empty());
    for (section, name, cells) in &keys {
        let example = cells
            .get(4)
            .and_then(|c| cell_value(c))
            .unwrap_or_else(|| panic!("{section}.{name}: the example cell is not a TOML value"));
        // Keys that choose the source replace the base's sounding; the sounding options need one.
        let with_sounding = !matches!(name.as_str(), "sounding" | "synthetic" | "standard");
        let mut table = base_scene(section == "atmosphere" && with_sounding);
        section_of(&mut table, section).insert(name.clone(), example.1.clone());
        let text = toml::to_string(&table).unwrap();
        if let Err(e) = parse_scene(&text) {
            panic!("{section}.{name} = {}: {e}\n{text}", example.0);
        }
    }
}

/// Where the parsed scene keeps `section.name`, as a JSON pointer, and whether the stored value
/// is in radians while the key is in degrees.
fn scene_field(section: &str, name: &str) -> (String, bool) {
    let (stored, radians) = match name.strip_suffix("_deg") {
        Some(stem) => (format!("{stem}_rad"), true),
        None => (name.to_string(), false),
    };
    let pointer = match section {
        "earth" => format!("/earth_{stored}"),
        "cards" => format!("/cards/0/{stored}"),
        "render" => format!("/{stored}"),
        s => format!("/{s}/{stored}"),
    };
    (pointer, radians)
}

/// Half a unit in the last digit `token` prints (0.5 for integers).
fn printed_precision(token: &str) -> f64 {
    let decimals = token.split_once('.').map_or(0, |(_, d)| d.len());
    0.5 * 10f64.powi(-(decimals as i32))
}

#[test]
fn scene_table_defaults_are_the_parsers() {
    let page = read_page("docs/scene.md");
    let parsed = parse_scene(&toml::to_string(&base_scene(false)).unwrap()).unwrap();
    let json = serde_json::to_value(&parsed).unwrap();
    let mut checked = 0;
    for (section, name, cells) in scene_doc_keys(&page) {
        let Some((token, default)) = cells.get(2).and_then(|c| cell_value(c)) else {
            continue; // "required", "—" or a sentence
        };
        let key = format!("{section}.{name}");
        let (pointer, radians) = scene_field(&section, &name);
        let stored = match json.pointer(&pointer) {
            Some(serde_json::Value::Null) if key == "atmosphere.smooth_m" => {
                // Absent in the scene: the atmosphere loader's default applies.
                serde_json::json!(AtmosphereOptions::default().smooth_m)
            }
            Some(v) => v.clone(),
            None if key == "atmosphere.standard" => continue, // stored as the source, below
            None => panic!("{key}: no field {pointer} in the parsed scene"),
        };
        let close = |doc: f64, got: f64| {
            let got = if radians { got.to_degrees() } else { got };
            (doc - got).abs() <= printed_precision(&token)
        };
        let ok = match (&default, &stored) {
            (toml::Value::Float(d), serde_json::Value::Number(n)) => close(*d, n.as_f64().unwrap()),
            (toml::Value::Integer(d), serde_json::Value::Number(n)) => {
                close(*d as f64, n.as_f64().unwrap())
            }
            (toml::Value::Boolean(d), serde_json::Value::Bool(b)) => d == b,
            (toml::Value::String(d), serde_json::Value::String(s)) => d == s,
            (toml::Value::Array(d), serde_json::Value::Array(s)) => {
                d.len() == s.len()
                    && d.iter().zip(s).all(|(d, s)| {
                        let d = d.as_float().or(d.as_integer().map(|i| i as f64));
                        d.zip(s.as_f64())
                            .is_some_and(|(d, s)| (d - s).abs() <= 0.5e-3)
                    })
            }
            _ => false,
        };
        assert!(
            ok,
            "{key}: docs/scene.md says default {token}, the parser gives {stored}"
        );
        checked += 1;
    }
    // The standard atmosphere is the default source.
    assert_eq!(
        json.pointer("/atmosphere/source"),
        Some(&serde_json::json!("Us1976"))
    );
    assert!(
        checked >= 10,
        "only {checked} defaults found in docs/scene.md"
    );
}

#[test]
fn scene_page_examples_parse_and_load() {
    let page = read_page("docs/scene.md");
    let toml_blocks: Vec<Block> = blocks(&page)
        .into_iter()
        .filter(|b| b.info == "toml")
        .collect();
    assert!(toml_blocks.len() >= 2, "docs/scene.md has no TOML examples");
    for block in toml_blocks {
        let scene = parse_scene(&block.text)
            .unwrap_or_else(|e| panic!("docs/scene.md line {}: {e}", block.line));
        scene
            .atmosphere
            .load()
            .unwrap_or_else(|e| panic!("docs/scene.md line {}: atmosphere: {e:?}", block.line));
    }
}

fn synthetic(text: &str) -> Result<SyntheticAtmosphere, String> {
    SyntheticAtmosphere::from_toml_str(text, Path::new("docs-test.toml")).map_err(|e| e.to_string())
}

#[test]
fn atmosphere_page_documents_exactly_the_synthetic_keys() {
    let page = read_page("docs/atmosphere.md");
    let rows = key_rows(&page);
    let top: BTreeSet<String> = rows
        .iter()
        .filter(|(k, _)| !k.contains('.'))
        .map(|(k, _)| k.clone())
        .collect();
    let layer: BTreeSet<String> = rows
        .iter()
        .filter_map(|(k, _)| k.strip_prefix("layers."))
        .map(str::to_string)
        .collect();
    let surface = "surface_temperature_c = 0.0\nsurface_pressure_hpa = 1013.25\n";
    let accepted = |text: String| {
        let err = synthetic(&text).expect_err("an unknown key must be rejected");
        assert!(err.contains(UNKNOWN), "{err}");
        let fields = expected_fields(&err);
        assert!(!fields.is_empty(), "no expected fields in: {err}");
        fields
    };
    assert_eq!(
        top,
        accepted(format!("{UNKNOWN} = 1\n{surface}")),
        "docs/atmosphere.md top-level keys vs the synthetic parser's"
    );
    assert_eq!(
        layer,
        accepted(format!("{surface}[[layers]]\n{UNKNOWN} = 1\n")),
        "docs/atmosphere.md layer keys vs the synthetic parser's"
    );
}

/// Sounding formats without a text example in docs/atmosphere.md, with their serde names:
/// netCDF files are binary (their reader is tested on real files in `ingest_netcdf.rs`).
const BINARY_FORMATS: [(SoundingFormat, &str); 1] = [(SoundingFormat::Netcdf, "netcdf")];

#[test]
fn atmosphere_page_examples_parse() {
    let page = read_page("docs/atmosphere.md");
    let all = blocks(&page);
    let mut synthetic_examples = 0;
    let mut formats = BTreeSet::new();
    for block in &all {
        if block.info == "toml" {
            synthetic(&block.text)
                .unwrap_or_else(|e| panic!("docs/atmosphere.md line {}: {e}", block.line));
            synthetic_examples += 1;
        }
        if let Some(format) = &block.format_marker {
            let name = format!("docs/atmosphere.md line {}", block.line);
            let sounding = parse_sounding(&block.text, Path::new(&name), &ReadOptions::default())
                .unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(
                serde_json::to_value(sounding.format).unwrap(),
                serde_json::json!(format),
                "{name}: detected format"
            );
            assert!(
                sounding.levels.len() >= 3,
                "{name}: {} levels",
                sounding.levels.len()
            );
            formats.insert(format.clone());
        }
    }
    assert!(synthetic_examples >= 1, "no synthetic TOML example");
    // Binary formats have no example (a page cannot show their bytes), but a section whose
    // heading names them.
    for (format, name) in BINARY_FORMATS {
        assert_eq!(
            serde_json::to_value(format).unwrap(),
            serde_json::json!(name)
        );
        assert!(
            !formats.contains(name),
            "{name} is binary, yet has a text example"
        );
        assert!(
            page.lines()
                .any(|l| l.starts_with("###") && l.to_lowercase().contains(name)),
            "docs/atmosphere.md has no section heading naming the binary format {name}"
        );
    }
    // One example per text format ingest reads (SoundingFormat's other variants).
    let expected: BTreeSet<String> = [
        "normalized_csv",
        "wyoming_text_list",
        "wyoming_text_csv",
        "igra2_data",
        "igra2_derived",
        "spc_raw",
        "eol_esc",
        "wmo_temp",
    ]
    .map(String::from)
    .into();
    assert_eq!(formats, expected, "sounding examples in docs/atmosphere.md");
}

#[test]
fn extractors_find_what_they_should() {
    // The helpers above must be able to fail: a misspelt key is not accepted, an undocumented key
    // is noticed, and the expected-field list is read from a real rejection.
    let err = parse_scene(&format!("{CAMERA}pich_deg = 3\n")).unwrap_err();
    assert!(expected_fields(&err).contains("pitch_deg"), "{err}");
    assert!(!expected_fields(&err).contains("pich_deg"), "{err}");
    let page = "| `camera.height_m` | m |\n| not a key | x |\n| `a` and more | y |\n";
    let keys: Vec<String> = key_rows(page).into_iter().map(|(k, _)| k).collect();
    assert_eq!(keys, ["camera.height_m"]);
    let md = "x\n<!-- sounding-format: igra2_data -->\n```text\nabc\n```\n```toml\na = 1\n```\n";
    let b = blocks(md);
    assert_eq!(b.len(), 2);
    assert_eq!(b[0].format_marker.as_deref(), Some("igra2_data"));
    assert_eq!((b[0].text.as_str(), b[1].info.as_str()), ("abc\n", "toml"));
    assert_eq!(b[1].format_marker, None);
}
