//! Paths of the repository's own test inputs. Everything the tests read lies inside the
//! repository, so a fresh clone passes its own tests:
//!
//! * `tests/data/soundings/` — real radiosonde soundings (14 normalised CSVs, `pressure_levels/`,
//!   `raw/`), copied from the project's shared sounding collection with their provenance lines
//!   (see its README.md), and in `public/` real archive files from public projects' test suites
//!   (siphon, SHARPpy, sounding-wyoming-text-list), with their provenance and licences, and in
//!   `netcdf/` real ARM and GRUAN netCDF soundings (provenance in its README);
//! * `data/` — the soundings, paper atmospheres and scenes shipped with the program;
//! * `tests/fixtures/` — other crafted or captured inputs.
//!
//! Every helper asserts that its path exists and names the path when it does not.

use std::path::{Path, PathBuf};

/// The repository root (the crate's manifest directory).
pub const REPO_DIR: &str = env!("CARGO_MANIFEST_DIR");
/// The real soundings the tests read (a copy of the project's shared sounding collection).
pub const SOUNDINGS_DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/soundings");
/// The data shipped with the program (soundings, paper atmospheres, scenes, cards).
pub const DATA_DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/data");
/// Test fixtures that are not soundings of the collection.
pub const FIXTURES_DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures");

fn existing(path: PathBuf) -> PathBuf {
    assert!(path.exists(), "missing test input {}", path.display());
    path
}

/// `REL` relative to the repository root, e.g. `repo_file("data/fata_morgana.toml")`.
pub fn repo_file(rel: &str) -> PathBuf {
    existing(Path::new(REPO_DIR).join(rel))
}

/// `tests/data/soundings/REL`, e.g. `sounding("raw/USM00070026-data_2010-06-01_excerpt.txt")`.
pub fn sounding(rel: &str) -> PathBuf {
    existing(Path::new(SOUNDINGS_DIR).join(rel))
}

/// `tests/data/soundings/public/NAME`: a real archive file from a public project's tests.
pub fn public_sounding(name: &str) -> PathBuf {
    existing(Path::new(SOUNDINGS_DIR).join("public").join(name))
}

/// `data/REL`, a file shipped with the program.
pub fn data_file(rel: &str) -> PathBuf {
    existing(Path::new(DATA_DIR).join(rel))
}

/// `tests/fixtures/REL`.
pub fn fixture(rel: &str) -> PathBuf {
    existing(Path::new(FIXTURES_DIR).join(rel))
}

/// The `data/` folder itself (join names onto it; no existence check on the joined path).
pub fn data_dir() -> PathBuf {
    existing(PathBuf::from(DATA_DIR))
}

/// The `tests/data/soundings/` folder itself.
pub fn soundings_dir() -> PathBuf {
    existing(PathBuf::from(SOUNDINGS_DIR))
}
