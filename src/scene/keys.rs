//! Stage 5a (scene), numeric keys by name. In: a dotted key of the scene format
//! (`camera.heading_deg`, `cards[0].distance_m`, `sun.azimuth_deg`, …), a scene file's text and a
//! value. Out: the scene text with that key set to the value, which [`Scene::from_toml_str`]
//! then checks like any scene file — what a sequence's `--sweep KEY=FROM:TO:STEP` renders.
//!
//! [`Scene::from_toml_str`]: super::Scene::from_toml_str

use toml::{Table, Value};

/// The keys a sweep may set: every number of the scene format that is not a count or a size in
/// pixels (`cards[]` stands for `cards[0]`, `cards[1]`, …).
pub const SWEEPABLE_KEYS: &[&str] = &[
    "camera.height_m",
    "camera.heading_deg",
    "camera.pitch_deg",
    "camera.hfov_deg",
    "atmosphere.wavelength_nm",
    "atmosphere.smooth_m",
    "earth.radius_m",
    "sky.brightness",
    "sky.rayleigh_optical_depth",
    "sky.aerosol_optical_depth",
    "sky.visibility_km",
    "sky.aerosol_scale_height_m",
    "sea.refractive_index",
    "sea.wave_slope_deg",
    "sea.wind_speed_m_s",
    "cards[].distance_m",
    "cards[].azimuth_deg",
    "cards[].width_m",
    "cards[].height_m",
    "cards[].base_m",
    "sun.elevation_deg",
    "sun.azimuth_deg",
    "sun.angular_diameter_deg",
    "sun.limb_darkening",
    "sun.intensity",
    "terrain.observer_lat_deg",
    "terrain.observer_lon_deg",
    "terrain.snow_line_m",
    "terrain.ice_slope_deg",
    "terrain.light_azimuth_deg",
    "terrain.light_elevation_deg",
];

/// Sections a scene may leave out whose keys still have defaults (setting one adds the section).
const DEFAULTED_SECTIONS: &[&str] = &["camera", "atmosphere", "earth", "sky", "sea"];

/// A numeric scene key: `section.field` or `cards[INDEX].field`.
#[derive(Debug, Clone, PartialEq, Eq, Hash, serde::Serialize)]
pub struct SceneKey {
    /// `camera`, `sky`, `cards`, …
    pub section: String,
    /// The card's index for `cards[i]`.
    pub index: Option<usize>,
    /// The field, e.g. `distance_m`.
    pub field: String,
}

impl SceneKey {
    /// Read a key and check that it is one of [`SWEEPABLE_KEYS`] (the message lists them).
    pub fn parse(text: &str) -> Result<Self, String> {
        let t = text.trim();
        let unknown = || {
            format!(
                "{t:?} is not a numeric scene key; sweepable keys are {} (cards[] with an index, \
                 e.g. cards[0].distance_m)",
                SWEEPABLE_KEYS.join(", ")
            )
        };
        let (head, field) = t.split_once('.').ok_or_else(unknown)?;
        let (section, index) = match head.strip_prefix("cards[") {
            Some(rest) => {
                let digits = rest.strip_suffix(']').ok_or_else(unknown)?;
                let index = digits.parse::<usize>().map_err(|_| {
                    format!("{t:?}: the card index {digits:?} is not a whole number ≥ 0")
                })?;
                ("cards", Some(index))
            }
            None => (head, None),
        };
        let pattern = match index {
            Some(_) => format!("cards[].{field}"),
            None => format!("{section}.{field}"),
        };
        if !SWEEPABLE_KEYS.contains(&pattern.as_str()) {
            return Err(unknown());
        }
        Ok(SceneKey {
            section: section.to_string(),
            index,
            field: field.to_string(),
        })
    }

    /// Set this key to `value` in the scene text `text`. Errors (naming the key) when the
    /// scene has no such card or no such optional section (`[sun]`, `[terrain]`), or the text is
    /// not a TOML table.
    pub fn set_in(&self, text: &str, value: f64) -> Result<String, String> {
        let mut table: Table = text
            .parse()
            .map_err(|e: toml::de::Error| format!("{self}: the scene is not valid TOML: {e}"))?;
        let section = match self.index {
            Some(i) => {
                let cards = table
                    .get_mut("cards")
                    .and_then(Value::as_array_mut)
                    .map(|a| a.as_mut_slice())
                    .unwrap_or_default();
                let count = cards.len();
                cards
                    .get_mut(i)
                    .and_then(Value::as_table_mut)
                    .ok_or_else(|| format!("{self}: the scene has {count} card(s)"))?
            }
            None => {
                let name = self.section.as_str();
                if !table.contains_key(name) && !DEFAULTED_SECTIONS.contains(&name) {
                    return Err(format!("{self}: the scene has no [{name}] section"));
                }
                table
                    .entry(name)
                    .or_insert_with(|| Value::Table(Table::new()))
                    .as_table_mut()
                    .ok_or_else(|| format!("{self}: [{name}] is not a table"))?
            }
        };
        section.insert(self.field.clone(), Value::Float(value));
        toml::to_string(&table).map_err(|e| format!("{self}: cannot write the scene: {e}"))
    }
}

impl std::fmt::Display for SceneKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.index {
            Some(i) => write!(f, "{}[{i}].{}", self.section, self.field),
            None => write!(f, "{}.{}", self.section, self.field),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SCENE: &str = "[camera]\nheight_m = 10\nhfov_deg = 1\nwidth = 40\nheight = 20\n\n\
                         [[cards]]\nimage = \"a.png\"\ndistance_m = 5000.0\nwidth_m = 5\nheight_m = 2\n";

    #[test]
    fn keys_parse_and_print() {
        for key in [
            "camera.heading_deg",
            "cards[1].distance_m",
            "sun.azimuth_deg",
        ] {
            assert_eq!(SceneKey::parse(key).unwrap().to_string(), key);
        }
        for bad in [
            "camera.width",
            "heading_deg",
            "cards.distance_m",
            "cards[x].base_m",
        ] {
            let e = SceneKey::parse(bad).unwrap_err();
            assert!(e.contains(bad.split('.').next().unwrap_or(bad)), "{e}");
        }
        assert!(
            SceneKey::parse("camera.width")
                .unwrap_err()
                .contains("camera.pitch_deg")
        );
    }

    #[test]
    fn setting_a_key_changes_only_that_value() {
        let key = SceneKey::parse("cards[0].distance_m").unwrap();
        let text = key.set_in(SCENE, 12_500.0).unwrap();
        let table: Table = text.parse().unwrap();
        assert_eq!(table["cards"][0]["distance_m"].as_float(), Some(12_500.0));
        assert_eq!(table["camera"]["height_m"].as_integer(), Some(10));
        // A defaulted section is added; a missing optional one or card is an error.
        let text = SceneKey::parse("sky.brightness")
            .unwrap()
            .set_in(SCENE, 0.5)
            .unwrap();
        assert!(text.contains("brightness = 0.5"), "{text}");
        let e = SceneKey::parse("sun.azimuth_deg")
            .unwrap()
            .set_in(SCENE, 3.0)
            .unwrap_err();
        assert!(e.contains("no [sun]"), "{e}");
        let e = SceneKey::parse("cards[2].base_m")
            .unwrap()
            .set_in(SCENE, 3.0)
            .unwrap_err();
        assert!(e.contains("1 card(s)"), "{e}");
    }
}
