//! Running the `ghostship` binary: exit status and output of one run, with the assertions every
//! command-line test makes (success, failure with status 1, usage error with status 2).

use std::path::Path;

use assert_cmd::cargo::cargo_bin_cmd;

/// The `ghostship` binary built for these tests.
pub fn ghostship() -> assert_cmd::Command {
    cargo_bin_cmd!("ghostship")
}

/// What a run of the binary printed and how it exited.
pub struct Run {
    /// Exit status (`None`: killed by a signal).
    pub code: Option<i32>,
    /// Standard output.
    pub stdout: String,
    /// Standard error.
    pub stderr: String,
}

/// Run `ghostship ARGS`.
pub fn run(args: &[&str]) -> Run {
    let out = ghostship().args(args).output().expect("binary runs");
    Run {
        code: out.status.code(),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

/// Run `ghostship ARGS`, which must succeed.
pub fn ok(args: &[&str]) -> Run {
    let r = run(args);
    assert_eq!(
        r.code,
        Some(0),
        "ghostship {args:?} failed:\nstdout: {}\nstderr: {}",
        r.stdout,
        r.stderr
    );
    r
}

/// `ghostship profile PATH --format json` (files written to a temporary folder), which must
/// succeed: the summary JSON printed on stdout.
pub fn profile_json(path: &Path) -> serde_json::Value {
    let dir = tempfile::tempdir().unwrap();
    let r = ok(&[
        "profile",
        path.to_str().unwrap(),
        "--out",
        dir.path().to_str().unwrap(),
        "--format",
        "json",
        "--quiet",
    ]);
    serde_json::from_str(&r.stdout).unwrap()
}

/// Run `ghostship ARGS`, which must fail with status 1, an `error:` line and no panic.
pub fn fails(args: &[&str]) -> Run {
    let r = run(args);
    assert_eq!(
        r.code,
        Some(1),
        "ghostship {args:?} should fail with status 1: {}",
        r.stderr
    );
    assert!(r.stderr.starts_with("error: "), "{}", r.stderr);
    assert!(!r.stderr.contains("panicked"), "{}", r.stderr);
    r
}

/// Run `ghostship ARGS`, which must be refused as a usage error: status 2, no panic.
pub fn usage_error(args: &[&str]) -> Run {
    let r = run(args);
    assert_eq!(
        r.code,
        Some(2),
        "ghostship {args:?} should be a usage error (status 2): {}",
        r.stderr
    );
    assert!(!r.stderr.contains("panicked"), "{}", r.stderr);
    r
}

/// A JSON file, parsed.
pub fn json_file(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Every file under `dir` (recursively) by its path relative to `dir`, with its bytes; empty
/// if `dir` does not exist.
pub fn output_tree(dir: &Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    let mut files = std::collections::BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(folder) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&folder) else {
            continue;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else {
                let rel = path
                    .strip_prefix(dir)
                    .unwrap()
                    .to_string_lossy()
                    .into_owned();
                files.insert(rel, std::fs::read(&path).unwrap());
            }
        }
    }
    files
}

/// `ghostship pipeline run PIPELINE --out OUT EXTRA…`, which must succeed.
pub fn pipeline_ok(pipeline: &Path, out: &Path, extra: &[&str]) -> Run {
    let r = pipeline_run(pipeline, out, extra);
    assert_eq!(
        r.code,
        Some(0),
        "pipeline run {extra:?} failed:\nstdout: {}\nstderr: {}",
        r.stdout,
        r.stderr
    );
    r
}

/// `ghostship pipeline run PIPELINE --out OUT EXTRA…`.
pub fn pipeline_run(pipeline: &Path, out: &Path, extra: &[&str]) -> Run {
    let mut args = vec![
        "pipeline",
        "run",
        pipeline.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    run(&args)
}

/// Path of the `ghostship` binary built for these tests (for spawning and killing it).
pub fn binary() -> &'static str {
    env!("CARGO_BIN_EXE_ghostship")
}

/// Assert that two output folders hold the same files with the same bytes (naming the files
/// that differ rather than printing their content).
pub fn assert_same_tree(a: &Path, b: &Path) {
    let (ta, tb) = (output_tree(a), output_tree(b));
    let names =
        |t: &std::collections::BTreeMap<String, Vec<u8>>| t.keys().cloned().collect::<Vec<_>>();
    assert_eq!(
        names(&ta),
        names(&tb),
        "{} and {} hold different files",
        a.display(),
        b.display()
    );
    let differing: Vec<&String> = ta
        .iter()
        .filter(|(k, v)| tb[*k] != **v)
        .map(|(k, _)| k)
        .collect();
    assert!(
        differing.is_empty(),
        "these files differ between {} and {}: {differing:?}",
        a.display(),
        b.display()
    );
}
