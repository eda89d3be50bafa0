//! Verification, effects — what terrain, haze and the sun cost. In: a [`Scene`]. Out: the same
//! scene with some of those effects taken out ([`with_effects`]), so a bench can time the plain
//! frame, each effect alone and the scene as shipped through the same render API
//! (`examples/effects_cost.rs` → `docs/effects_cost.md`, and the `effects` group of
//! `cargo bench --bench render`).

use crate::scene::Scene;

/// The shipped scenes (file stems in `data/scenes/`) with terrain, haze or a sun, timed by the
/// effects bench (the spectral fig13 is timed by `bench accuracy`: its bands are RGB frames).
pub const EFFECT_SCENES: [&str; 6] = [
    "fig12_novaya_zemlya",
    "fig12b_novaya_zemlya_strips",
    "fig14_island_terrain",
    "fig15_calm_sea",
    "fig16_sun_glitter",
    "fig17_kauai_fata_morgana",
];

/// One effect a scene may have.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Effect {
    /// Aerial perspective (`sky.visibility_km`).
    Haze,
    /// The sun (`[sun]`): its disc, its light along its own ray, its glitter.
    Sun,
    /// Terrain from an elevation model (`[terrain]`).
    Terrain,
}

impl Effect {
    /// Every effect, in table order.
    pub const ALL: [Effect; 3] = [Effect::Haze, Effect::Sun, Effect::Terrain];

    /// Its name in tables.
    pub fn label(self) -> &'static str {
        match self {
            Effect::Haze => "haze",
            Effect::Sun => "sun",
            Effect::Terrain => "terrain",
        }
    }

    /// Whether `scene` has it.
    pub fn present(self, scene: &Scene) -> bool {
        match self {
            Effect::Haze => scene.sky.aerial.is_some(),
            Effect::Sun => scene.sun.is_some(),
            Effect::Terrain => scene.terrain.is_some(),
        }
    }

    fn remove(self, scene: &mut Scene) {
        match self {
            Effect::Haze => scene.sky.aerial = None,
            Effect::Sun => scene.sun = None,
            Effect::Terrain => scene.terrain = None,
        }
    }
}

/// The effects `scene` has, in [`Effect::ALL`] order.
pub fn effects_of(scene: &Scene) -> Vec<Effect> {
    Effect::ALL
        .into_iter()
        .filter(|e| e.present(scene))
        .collect()
}

/// `scene` at `width` × `height` with every effect but those in `keep` taken out (cards, the
/// sea and its reflections stay).
pub fn with_effects(scene: &Scene, (width, height): (u32, u32), keep: &[Effect]) -> Scene {
    let mut s = scene.clone();
    s.camera.width = width;
    s.camera.height = height;
    for e in Effect::ALL {
        if !keep.contains(&e) {
            e.remove(&mut s);
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    #[test]
    fn effects_are_taken_out_and_kept() {
        let text = "[camera]\nheight_m = 10\nhfov_deg = 1\nwidth = 40\nheight = 20\n\
                    [sky]\nvisibility_km = 20\n[sun]\nelevation_deg = 1\n";
        let scene = Scene::from_toml_str(text, Path::new("."), Path::new("t.toml")).unwrap();
        assert_eq!(effects_of(&scene), vec![Effect::Haze, Effect::Sun]);
        let plain = with_effects(&scene, (8, 4), &[]);
        assert!(effects_of(&plain).is_empty());
        assert_eq!((plain.camera.width, plain.camera.height), (8, 4));
        let haze = with_effects(&scene, (8, 4), &[Effect::Haze]);
        assert_eq!(effects_of(&haze), vec![Effect::Haze]);
    }
}
