//! Renderer: scene geometry against closed forms, fan vs exact tracing, exporters, determinism,
//! and the committed card images and scene files.

use std::path::{Path, PathBuf};

use ghostship::output::{exr, png};
use ghostship::render::{
    ConstantCurvatureRays, FanEnd, FanRay, RayTracer, RenderOptions, StraightRays, render_scene,
};
use ghostship::scene::{Scene, assets};

const R: f64 = 6_371_000.0;

fn data_dir() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/data"))
}

#[test]
fn committed_card_images_equal_freshly_drawn_ones() {
    let dir = data_dir().join("cards");
    if std::env::var_os("GHOSTSHIP_WRITE_CARDS").is_some() {
        assets::write_card_images(&dir).unwrap();
    }
    for (name, fresh) in assets::card_images() {
        let path = dir.join(name);
        let committed = image::open(&path)
            .unwrap_or_else(|e| {
                panic!(
                    "{}: {e} (regenerate with GHOSTSHIP_WRITE_CARDS=1)",
                    path.display()
                )
            })
            .to_rgba8();
        assert_eq!(committed.dimensions(), fresh.dimensions(), "{name}");
        assert!(
            committed.as_raw() == fresh.as_raw(),
            "{name} differs from the drawing code"
        );
    }
}
