//! Tests of pipeline files: defaults, matrices, globs, IGRA2 time ranges and the problems
//! reported at their line and column.

use super::*;

fn data(rel: &str) -> String {
    format!("{}/{rel}", env!("CARGO_MANIFEST_DIR"))
}

fn parse(text: &str) -> Result<ResolvedPipeline, PipelineError> {
    // Paths in the text are relative to the repository's pipelines/ folder.
    ResolvedPipeline::from_toml_str(text, Path::new(&data("pipelines/t.toml")))
}

fn problems(text: &str) -> Vec<Diagnostic> {
    match parse(text) {
        Err(PipelineError::Invalid { problems, .. }) => problems,
        other => panic!("expected problems, got {other:?}"),
    }
}

#[test]
fn resolves_defaults_names_and_matrix() {
    let text = r#"
[defaults]
sizes = ["40x20"]
smooth_m = 10.0
[[render]]
scene = "../data/scenes/fig04_superior_mirage.toml"
atmosphere = ["../data/Bjornoya-01028_2024022611.csv", "us1976"]
observer_height_m = [5.0, 10.0]
[[trace]]
atmosphere = "us1976"
observer_height_m = 10
elevation_deg = "-0.5:0.5:0.01"
distances_m = [1000.0]
"#;
    let p = parse(text).unwrap();
    assert_eq!(p.name, "t");
    let names: Vec<&str> = p.jobs.iter().map(|j| j.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "us1976_transfer",
            "fig04_superior_mirage_Bjornoya-01028_2024022611_5m",
            "fig04_superior_mirage_Bjornoya-01028_2024022611_10m",
            "fig04_superior_mirage_us1976_5m",
            "fig04_superior_mirage_us1976_10m",
        ]
    );
    let crate::jobs::JobRequest::Render(r) = &p.jobs[1].request else {
        panic!("a render job")
    };
    assert_eq!(r.settings.sizes, vec![Some((40, 20))]);
    assert_eq!(r.scene.camera.height_m, 5.0);
    // The trace job took smooth_m from [defaults]; render jobs have no such key.
    let crate::jobs::JobRequest::Trace(t) = &p.jobs[0].request else {
        panic!("a trace job")
    };
    assert_eq!(t.atmosphere.options.smooth_m, 10.0);
    // Labels are relative to the pipeline folder.
    assert!(
        p.jobs[1]
            .inputs
            .contains_key("../data/Bjornoya-01028_2024022611.csv"),
        "{:?}",
        p.jobs[1].inputs
    );
}

#[test]
fn globs_and_sounding_time_ranges_expand() {
    let p = parse(
        "[[profile]]\natmosphere = \"../tests/data/soundings/raw/USM00070026-data_*.txt\"\nsounding_time = \"all\"\n",
    )
    .unwrap();
    assert_eq!(p.jobs.len(), 3, "three soundings in the excerpt");
    assert!(
        p.jobs[0]
            .name
            .starts_with("USM00070026-data_2010-06-01_excerpt_2010060")
    );
    let p = parse(
        "[[profile]]\natmosphere = \"../tests/data/soundings/raw/USM00070026-data_*.txt\"\nsounding_time = \"..2010-06-01 00\"\n",
    )
    .unwrap();
    assert_eq!(p.jobs.len(), 1);
}

#[test]
fn every_problem_is_reported_with_line_and_column() {
    let text = "[[render]]\nscene = \"missing.toml\"\nsize = [\"1x1\"]\n[[trace]]\natmosphere = \"us1976\"\nobserver_height_m = -1\nelevation_deg = \"1:0:0.1\"\ndistances_m = [1.0]\n[[profile]]\natmosphere = \"us1976\"\nwavelength_nm = \"x\"\n";
    let found = problems(text);
    let at: Vec<(usize, usize)> = found.iter().map(|d| (d.line, d.column)).collect();
    assert_eq!(at, [(3, 1), (7, 17), (11, 17)], "{found:?}");
    assert!(found[0].message.contains("size"), "{found:?}");
    assert!(
        found[1].message.contains("TO must not be below FROM"),
        "{found:?}"
    );
}

#[test]
fn rejects_bad_values() {
    for (text, needle) in [
        (
            "[[render]]\nscene = \"../data/scenes/fig04_superior_mirage.toml\"\nsizes = [\"400*200\"]\n",
            "WIDTHxHEIGHT",
        ),
        (
            "[[render]]\nscene = \"../data/scenes/fig04_superior_mirage.toml\"\nformats = [\"jpg\"]\n",
            "jpg",
        ),
        (
            "[[render]]\nscene = \"../data/scenes/fig04_superior_mirage.toml\"\nspp = 3\n",
            "square",
        ),
        (
            "[[render]]\nscene = \"../data/scenes/fig04_superior_mirage.toml\"\ntolerance_m = 0\n",
            "tolerance",
        ),
        ("[[render]]\nscene = \"missing.toml\"\n", "missing.toml"),
        (
            "[[render]]\nscene = \"../data/scenes/fig04_superior_mirage.toml\"\nsounding_time = \"2010-06-01 00\"\n",
            "needs an `atmosphere`",
        ),
        (
            "name = \"../x\"\n[[profile]]\natmosphere = \"us1976\"\n",
            "plain file name",
        ),
        ("name = \"x\"\n", "no jobs"),
        (
            "[defaults]\ncolour = 1\n[[profile]]\natmosphere = \"us1976\"\n",
            "unknown key `colour`",
        ),
        (
            "[[profile]]\natmosphere = \"../data/*.nothing\"\n",
            "no file matches",
        ),
        (
            "[[profile]]\natmosphere = \"us1976\"\nname = \"{what}\"\n",
            "placeholder",
        ),
        (
            "[[profile]]\natmosphere = \"us1976\"\n[[profile]]\natmosphere = \"us1976\"\n",
            "two jobs",
        ),
        (
            "[[profile]]\natmosphere = \"us1976\"\nsounding_time = \"tuesday\"\n",
            "sounding_time",
        ),
        (
            "[[trace]]\natmosphere = \"us1976\"\nobserver_height_m = 1\nelevation_deg = \"0:1:0.1\"\ndistances_m = [1.0]\ntarget_heights_m = [0.0]\n",
            "target_heights_m",
        ),
        ("[[profile\n", "unclosed"),
    ] {
        let found = problems(text);
        assert!(
            found.iter().any(|d| d.message.contains(needle)),
            "{text}: {found:?}"
        );
    }
}

#[test]
fn survey_problems_name_the_job_and_the_key_at_its_value() {
    let cases = [
        "observer_height_m = [40.0, 10.0]",
        "observer_height_m = 1e7",
        "distances_m = [-1.0]",
        "target_height_m = -3.0",
        "fan_step_deg = 1e-300",
        "layers_top_m = -5.0",
        "tolerance_m = 0.0",
        "wavelength_nm = 5.0",
        "smooth_m = -1.0",
        "strict = 3",
        "fit = \"cubic\"",
        "parts = 0",
        "to = \"2001-01-01\"",
        "from = \"2024-13\"",
    ];
    for bad in cases {
        let key = bad.split(' ').next().unwrap();
        // `from` is there so that a message merely mentioning "from" cannot catch the problem.
        let from = if key == "from" {
            ""
        } else {
            "from = \"2010-01-01\"\n"
        };
        let text = format!(
            "[[survey]]\nname = \"arctic\"\nsources = \"../tests/data/soundings/public/igra2_USM00070026-data.txt\"\n{from}{bad}\n"
        );
        let found = problems(&text);
        assert_eq!(found.len(), 1, "{bad}: {found:?}");
        let line = if from.is_empty() { 4 } else { 5 };
        let at = (found[0].line, found[0].column);
        assert_eq!(at, (line, key.len() + 4), "{bad}: {found:?}");
        let message = &found[0].message;
        assert!(
            message.contains("[[survey]] arctic") && message.contains(key),
            "{bad}: {message}"
        );
    }
}
