//! Image finding does not depend on fan density (issue 8, item 5): the integration noise between
//! neighbouring rays (up to ≈ 0.3 m at 60 km at the default 1 cm per step) must not be read as
//! folds, and real folds — however thin in elevation — must survive.
//!
//! For every paper atmosphere (data/*.toml) and shipped sounding (data/*.csv), from several
//! observer heights, at 5–60 km and for several target heights, `find_images` on a fan of 200
//! rays and on one of 20 000 rays over the same elevations gives the same images: same count,
//! same erect/inverted sequence, boundaries within [`ALPHA_TOL_DEG`] and [`HEIGHT_TOL_M`].

use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;

use ghostship::analysis::{FoldTest, Image, Reach, TransferCurve, find_images};
use ghostship::atmosphere::{AtmosphereOptions, AtmosphereSource, load_atmosphere};
use ghostship::refractivity::RefractiveAtmosphere;
use ghostship::tracer::{Tracer, TracerConfig};

/// The fan: −0.15° … +0.35°.
const LO_DEG: f64 = -0.15;
const HI_DEG: f64 = 0.35;
const COARSE: usize = 200;
const DENSE: usize = 20_000;
/// Boundaries of matching images agree to this in elevation. Band edges agree to ~1e-6°; a
/// fold's position is set by a flat extremum and moves by √(2δh/|h″|) for a height error δh
/// (measured: up to 3.3e-4° for the 0.3 m deep Fata Morgana fold at 60 km).
const ALPHA_TOL_DEG: f64 = 1e-3;
/// … and to this in height at the boundaries (the re-traced rays' error, up to 124 steps × 0.1 mm
/// at 60 km, plus bisection on their noise; measured ≤ 6 mm).
const HEIGHT_TOL_M: f64 = 0.02;

fn data_files(ext: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("data");
    let mut out: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == ext))
        .collect();
    out.sort();
    out
}

fn load(path: &Path) -> RefractiveAtmosphere {
    let source = if path.extension().is_some_and(|x| x == "toml") {
        AtmosphereSource::Synthetic(path.to_path_buf())
    } else {
        AtmosphereSource::Sounding(path.to_path_buf())
    };
    load_atmosphere(&source, &AtmosphereOptions::default())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .refractive
}

fn name(path: &Path) -> String {
    path.file_stem().unwrap().to_string_lossy().into_owned()
}

fn tracer(atm: &RefractiveAtmosphere) -> Tracer<'_, RefractiveAtmosphere> {
    Tracer::new(atm, TracerConfig::default()).unwrap()
}

/// The images of [0, H] for every (distance, H) in `jobs`, from a fan of `count` rays over
/// [`LO_DEG`, `HI_DEG`] launched at `h0` (one fan, the jobs in parallel).
fn images(
    tracer: &Tracer<'_, RefractiveAtmosphere>,
    h0: f64,
    count: usize,
    distances_m: &[f64],
    jobs: &[(usize, f64)],
) -> Vec<Vec<Image>> {
    let elevations: Vec<f64> = (0..count)
        .map(|i| (LO_DEG + (HI_DEG - LO_DEG) * i as f64 / (count - 1) as f64).to_radians())
        .collect();
    let records = tracer.trace_fan(h0, &elevations, distances_m).unwrap();
    jobs.par_iter()
        .map(|&(j, height)| {
            let curve = TransferCurve {
                distance_m: distances_m[j],
                elevations_rad: elevations.clone(),
                reach: records.iter().map(|r| Reach::from_record(r, j)).collect(),
            };
            find_images(tracer, h0, &curve, height)
        })
        .collect()
}

/// "EIE": the orientation sequence, lowest image first.
fn orientations(images: &[Image]) -> String {
    images
        .iter()
        .map(|im| if im.erect { 'E' } else { 'I' })
        .collect()
}

/// The largest boundary differences (deg, m) between two image lists of the same shape.
fn boundary_gap(a: &[Image], b: &[Image]) -> (f64, f64) {
    let (mut da, mut dh) = (0.0_f64, 0.0_f64);
    for (x, y) in a.iter().zip(b) {
        da = da
            .max((x.elevation_min_deg - y.elevation_min_deg).abs())
            .max((x.elevation_max_deg - y.elevation_max_deg).abs());
        dh = dh
            .max((x.height_at_min_m - y.height_at_min_m).abs())
            .max((x.height_at_max_m - y.height_at_max_m).abs());
    }
    (da, dh)
}

/// The same image list from a fan of 200 and of 20 000 rays, everywhere.
#[test]
fn image_lists_do_not_depend_on_fan_density() {
    let t = Instant::now();
    let distances = [5_000.0, 10_000.0, 20_000.0, 40_000.0, 60_000.0];
    let heights = [20.0, 250.0];
    let jobs: Vec<(usize, f64)> = (0..distances.len())
        .flat_map(|j| heights.iter().map(move |&h| (j, h)))
        .collect();
    let files: Vec<PathBuf> = [data_files("toml"), data_files("csv")].concat();
    assert!(
        files.len() >= 8,
        "paper atmospheres and soundings: {files:?}"
    );
    let (mut cases, mut folds, mut worst) = (0, 0, (0.0_f64, 0.0_f64));
    for path in &files {
        let atm = load(path);
        let tracer = tracer(&atm);
        for h0 in [2.0, 10.0, 80.0] {
            let coarse = images(&tracer, h0, COARSE, &distances, &jobs);
            let dense = images(&tracer, h0, DENSE, &distances, &jobs);
            for ((a, b), &(j, height)) in coarse.iter().zip(&dense).zip(&jobs) {
                let label = format!(
                    "{} from {h0} m, [0, {height} m] at {} km",
                    name(path),
                    distances[j] / 1000.0
                );
                let (sa, sb) = (orientations(a), orientations(b));
                assert_eq!(sa, sb, "{label}: {COARSE} vs {DENSE} rays");
                let (da, dh) = boundary_gap(a, b);
                assert!(
                    da < ALPHA_TOL_DEG && dh < HEIGHT_TOL_M,
                    "{label}: boundaries differ by {da:.2e}° / {dh:.2e} m: {a:?} vs {b:?}"
                );
                if sa.len() > 1 {
                    eprintln!("{label}: {sa} (Δα {da:.1e}°, Δh {dh:.1e} m)");
                }
                cases += 1;
                folds += sa.len().saturating_sub(1);
                worst = (worst.0.max(da), worst.1.max(dh));
            }
        }
    }
    eprintln!(
        "{cases} cases, {folds} folds between images, identical at {COARSE} and {DENSE} rays; \
         worst boundary gap {:.1e}° / {:.1e} m; {:.1} s",
        worst.0,
        worst.1,
        t.elapsed().as_secs_f64()
    );
    assert!(
        folds >= 20,
        "the matrix should contain mirages: {folds} folds"
    );
}

/// The command (`trace -a data/fata_morgana.toml --observer-height-m 10
/// --elevation-deg=-0.15:0.35:0.000025 --distance-m 5000 --target-height-m 20`): one image, as
/// with 200 rays. Also the Danmarkshavn sounding from 10 m, which before the fold test showed 17
/// images of a 20 m target at 5 km on 20 001 rays (1 on 201).
#[test]
fn a_20_m_target_at_5_km_has_one_image_on_a_dense_fan() {
    for file in [
        "fata_morgana.toml",
        "Danmarkshavn-04320_2026020523_all-levels.csv",
    ] {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("data")
            .join(file);
        let atm = load(&path);
        let tracer = tracer(&atm);
        for count in [201, 20_001] {
            let found = images(&tracer, 10.0, count, &[5_000.0], &[(0, 20.0)]).remove(0);
            assert_eq!(orientations(&found), "E", "{file}, {count} rays: {found:?}");
            let im = &found[0];
            assert!(im.height_at_min_m.abs() < 1e-3 && (im.height_at_max_m - 20.0).abs() < 1e-3);
        }
    }
}

/// Three images (erect, inverted, erect) that a dense fan used to split into many: the inferior
/// mirage from 10 m at 20 km (19 images on 20 001 rays before the fold test), and the superior
/// mirage from 80 m at 10 km, whose fold pair is only 0.32 m deep: thin, but three times the
/// fold threshold (0.1 m) and ≈ 50 times the re-traced rays' error bound, so it must be kept.
#[test]
fn three_images_stay_three_on_a_dense_fan() {
    let cases = [
        ("inferior_mirage.toml", 10.0, 20_000.0, 250.0, None),
        ("superior_mirage.toml", 80.0, 10_000.0, 250.0, Some(0.324)),
    ];
    for (file, h0, d, height, depth) in cases {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("data")
            .join(file);
        let atm = load(&path);
        let tracer = tracer(&atm);
        for count in [201, 20_001] {
            let found = images(&tracer, h0, count, &[d], &[(0, height)]).remove(0);
            assert_eq!(
                orientations(&found),
                "EIE",
                "{file}, {count} rays: {found:?}"
            );
            if let Some(depth) = depth {
                let got = found[1].height_at_min_m - found[1].height_at_max_m;
                assert!((got - depth).abs() < 0.01, "{file}: fold depth {got} m");
                assert!(got > 3.0 * FoldTest::default().threshold_m(0.01));
            }
        }
    }
}
