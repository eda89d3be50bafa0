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
