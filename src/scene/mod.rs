//! Stage 5a — scene. In: a scene file (TOML) and the card images it names. Out: a validated
//! [`Scene`] in SI units (camera, atmosphere choice, Earth, sky, sea, cards with decoded textures,
//! optional sun) and its reproducibility hash.
//!
//! A scene file (every section but `[camera]` optional; paths relative to the scene file):
//!
//! ```toml
//! [camera]
//! height_m = 10.0            # above the surface; rendering needs it below the 40 km top
//! heading_deg = 0.0          # azimuth of the optical axis, clockwise from north
//! pitch_deg = 0.0            # elevation of the optical axis
//! hfov_deg = 1.0             # horizontal field of view
//! width = 400                # pixels
//! height = 200
//! samples_per_pixel = 4      # a square number ≤ 1024: n×n stratified jitter
//!
//! [atmosphere]               # exactly one of sounding / synthetic / standard (default us1976)
//! synthetic = "../superior_mirage.toml"   # or sounding = "x.csv", or standard = "us1976"
//! wavelength_nm = 550.0
//! straight = false           # true: n ≡ 1 (straight rays)
//! smooth_m = 0.0             # optional smoothing length for soundings
//! fit = "auto"               # optional: temperature between levels, "pchip" | "linear" | "auto"
//! sounding_time = "2024-01-15 12"   # optional: which sounding of a multi-sounding IGRA2 file
//! strict = false                 # optional: refuse levels that contradict those below them
//!
//! [earth]
//! radius_m = 6371000.0
//!
//! [sky]                      # see scene::sky
//! brightness = 1.0
//! rayleigh_optical_depth = 0.0975
//! aerosol_optical_depth = 0.02
//! visibility_km = 20.0       # optional: aerial perspective (haze) towards cards and the sea
//! aerosol_scale_height_m = 1000.0   # optional (default 1000); no effect without visibility_km
//!
//! [sea]                      # see scene::sea
//! water_rgb = [0.004, 0.012, 0.018]
//! refractive_index = 1.333
//! wind_speed_m_s = 0.0       # Cox–Munk wave slopes (or wave_slope_deg = 3.0, not both)
//! reflections = true         # mirror images of the cards and the sun's glitter
//!
//! [[cards]]
//! image = "../cards/ship.png"
//! distance_m = 20000.0       # ground distance
//! azimuth_deg = 0.0          # of the card's centre
//! width_m = 80.0
//! height_m = 20.0
//! base_m = 0.0               # bottom edge above the surface
//!
//! [sun]
//! elevation_deg = -2.0       # TRUE elevation of the centre; may be below 0
//! azimuth_deg = 0.0
//! angular_diameter_deg = 0.533   # default from 1 392 000 km at 149.6e6 km
//! limb_darkening = 0.6
//! intensity = 1.85e5         # disc-centre radiance above the atmosphere, 1 = horizon sky (default 1.85e5)
//!
//! [render]                   # optional
//! spectral_bands = 8         # 0/absent: RGB; 8…60: trace and shade per wavelength band
//!                            # across 400–700 nm, then CIE 1931 → Rec.709 (render::spectral)
//!
//! [terrain]                  # optional; see scene::terrain
//! dem = "island.tif"         # SRTM .hgt or geographic GeoTIFF
//! observer_lat_deg = 78.0
//! observer_lon_deg = 15.0
//! ```

/// Default radiance of the sun's disc centre above the atmosphere, in film units (1 = the white
/// horizon sky): the ratio of the sky model's own radiances. The optically thick horizon sky of
/// a uniformly lit, isotropically scattering atmosphere has radiance E/(4π) for a solar
/// irradiance E, and the disc has E/Ω with Ω = π(θ/2)² its solid angle, so the ratio is
/// 16/θ² = 1.85e5 for θ = 0.533°. The sun's light along its own path (often e^−7 and less for a
/// ducted Novaya Zemlya ray, see `sky`) then leaves a dim red sun where it should. EXR files
/// carry the linear values as rendered; the PNG compresses highlights keeping their hue.
pub const DEFAULT_SUN_INTENSITY: f64 = 1.85e5;

/// Fewest wavelength bands of a spectral render (`[render] spectral_bands`).
pub const MIN_SPECTRAL_BANDS: u32 = 8;
/// Most wavelength bands of a spectral render (5 nm wide across 400–700 nm).
pub const MAX_SPECTRAL_BANDS: u32 = 60;

pub mod assets;
pub mod camera;
pub mod card;
pub mod keys;
pub mod sea;
pub mod sky;
pub mod terrain;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::atmosphere::{
    AtmosphereError, AtmosphereOptions, AtmosphereSource, LoadedAtmosphere, load_atmosphere,
};
use crate::profile::TemperatureFit;
use sha2::{Digest, Sha256};

pub use camera::Camera;
pub use card::{Card, Texture};
pub use sea::Sea;
pub use sky::{AerialPerspective, Sky, Sun};
pub use terrain::{Dem, DemError, Palette, Terrain};

/// A scene file could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("cannot read scene {path}: {source}")]
    Read {
        /// The scene file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The file is not valid TOML or does not match the schema (the message has line and column).
    #[error("invalid scene {path}: {source}")]
    Parse {
        /// The scene file.
        path: PathBuf,
        /// The TOML error, with line and column.
        #[source]
        source: toml::de::Error,
    },
    /// A value is out of range or inconsistent.
    #[error("invalid scene {path}: {key}: {message}")]
    Invalid {
        /// The scene file.
        path: PathBuf,
        /// The offending key, e.g. `camera.hfov_deg` or `cards[2].distance_m`.
        key: String,
        /// What is wrong with it.
        message: String,
    },
    /// A card image could not be read.
    #[error("invalid scene {path}: {source}")]
    Texture {
        /// The scene file.
        path: PathBuf,
        /// The image error.
        #[source]
        source: card::TextureError,
    },
    /// The terrain's orthophoto could not be read.
    #[error("invalid scene {path}: terrain.orthophoto: cannot read image {image}: {source}")]
    Orthophoto {
        /// The scene file.
        path: PathBuf,
        /// The image file.
        image: PathBuf,
        /// The image error.
        #[source]
        source: image::ImageError,
    },
    /// The terrain's elevation model could not be read.
    #[error("invalid scene {path}: terrain.dem: {source}")]
    Terrain {
        /// The scene file.
        path: PathBuf,
        /// The reader's error (names the model file and the field).
        #[source]
        source: Box<terrain::DemError>,
    },
}

/// The atmosphere section of a scene.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AtmosphereSettings {
    /// The source of the air column (paths resolved against the scene file's folder).
    pub source: AtmosphereSource,
    /// Wavelength for the refractive index (nm).
    pub wavelength_nm: f64,
    /// Trace straight rays (n ≡ 1) instead.
    pub straight: bool,
    /// Optional smoothing length for soundings (m).
    pub smooth_m: Option<f64>,
    /// How a sounding's temperature is interpolated between levels (default auto).
    pub fit: TemperatureFit,
    /// Which sounding of a multi-sounding IGRA2 file (`"YYYY-MM-DD HH"`, UTC); `None`: the first.
    pub sounding_time: Option<String>,
    /// Refuse a sounding whose levels contradict each other in the lowest kilometres (see
    /// [`crate::sounding::ReadOptions::strict`]).
    pub strict: bool,
}

impl AtmosphereSettings {
    /// What the section names and how to load it, as every command loads atmospheres (source,
    /// wavelength, smoothing, IGRA2 time); `None` when the scene traces straight rays, which
    /// need no air.
    pub fn resolve(&self) -> Option<(AtmosphereSource, AtmosphereOptions)> {
        if self.straight {
            return None;
        }
        let options = AtmosphereOptions {
            smooth_m: self
                .smooth_m
                .unwrap_or(AtmosphereOptions::default().smooth_m),
            fit: self.fit,
            wavelength_nm: self.wavelength_nm,
            sounding_time: self.sounding_time.clone(),
            strict: self.strict,
        };
        Some((self.source.clone(), options))
    }

    /// Load the atmosphere [`resolve`](Self::resolve) names; `None` for straight rays.
    pub fn load(&self) -> Result<Option<LoadedAtmosphere>, AtmosphereError> {
        self.resolve()
            .map(|(source, options)| load_atmosphere(&source, &options))
            .transpose()
    }
}

/// A validated scene in SI units.
#[derive(Debug, Clone, Serialize)]
pub struct Scene {
    /// The scene file it came from (if any).
    pub source_path: Option<PathBuf>,
    /// The camera.
    pub camera: Camera,
    /// The atmosphere choice.
    pub atmosphere: AtmosphereSettings,
    /// Earth radius (m).
    pub earth_radius_m: f64,
    /// The clear sky.
    pub sky: Sky,
    /// The sea surface.
    pub sea: Sea,
    /// Cards, in file order.
    pub cards: Vec<Card>,
    /// The sun, if the scene has one.
    pub sun: Option<Sun>,
    /// Terrain from an elevation model, if the scene has one (left out of the hash's record
    /// when absent, so scenes without terrain keep their hash).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub terrain: Option<Terrain>,
    /// `[render] spectral_bands`: render in this many wavelength bands across 400–700 nm
    /// ([`crate::render::spectral`]); `None` (absent or 0): the RGB path. Left out of the hash's
    /// record when absent, so other scenes keep their hash.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub spectral_bands: Option<u32>,
    /// sha256 (hex) of the scene file content, the resolved parameters, the atmosphere file's
    /// content (sounding or synthetic) and the card images.
    #[serde(skip)]
    pub hash_hex: String,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScene {
    camera: RawCamera,
    #[serde(default)]
    atmosphere: RawAtmosphere,
    #[serde(default)]
    earth: RawEarth,
    #[serde(default)]
    sky: RawSky,
    #[serde(default)]
    sea: RawSea,
    #[serde(default)]
    cards: Vec<RawCard>,
    sun: Option<RawSun>,
    terrain: Option<RawTerrain>,
    #[serde(default)]
    render: RawRender,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRender {
    spectral_bands: Option<u32>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCamera {
    height_m: f64,
    #[serde(default)]
    heading_deg: f64,
    #[serde(default)]
    pitch_deg: f64,
    hfov_deg: f64,
    width: u32,
    height: u32,
    #[serde(default = "one")]
    samples_per_pixel: u32,
}

fn one() -> u32 {
    1
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAtmosphere {
    sounding: Option<PathBuf>,
    synthetic: Option<PathBuf>,
    standard: Option<String>,
    wavelength_nm: Option<f64>,
    #[serde(default)]
    straight: bool,
    smooth_m: Option<f64>,
    #[serde(default)]
    fit: TemperatureFit,
    #[serde(alias = "igra2_time")]
    sounding_time: Option<String>,
    #[serde(default)]
    strict: bool,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawEarth {
    radius_m: Option<f64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSky {
    brightness: Option<f64>,
    rayleigh_optical_depth: Option<f64>,
    aerosol_optical_depth: Option<f64>,
    visibility_km: Option<f64>,
    aerosol_scale_height_m: Option<f64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSea {
    water_rgb: Option<[f64; 3]>,
    refractive_index: Option<f64>,
    wave_slope_deg: Option<f64>,
    wind_speed_m_s: Option<f64>,
    reflections: Option<bool>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCard {
    image: PathBuf,
    distance_m: f64,
    #[serde(default)]
    azimuth_deg: f64,
    width_m: f64,
    height_m: f64,
    #[serde(default)]
    base_m: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSun {
    elevation_deg: f64,
    #[serde(default)]
    azimuth_deg: f64,
    angular_diameter_deg: Option<f64>,
    limb_darkening: Option<f64>,
    intensity: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTerrain {
    dem: PathBuf,
    observer_lat_deg: f64,
    observer_lon_deg: f64,
    snow_line_m: Option<f64>,
    ice_slope_deg: Option<f64>,
    rock_rgb: Option<[f64; 3]>,
    snow_rgb: Option<[f64; 3]>,
    ice_rgb: Option<[f64; 3]>,
    light_azimuth_deg: Option<f64>,
    light_elevation_deg: Option<f64>,
    fill_voids: Option<bool>,
    orthophoto: Option<PathBuf>,
    orthophoto_bounds_deg: Option<[f64; 4]>,
}

/// The sha256 of a terrain's elevation model file and of its orthophoto's, if any.
type TerrainDigests = ([u8; 32], Option<[u8; 32]>);

/// The `[terrain]` section checked and its elevation model (and orthophoto, at `photo_path`)
/// read, with the sha256 of the model file and of the orthophoto's.
fn terrain_section(
    c: &Checker<'_>,
    raw: &RawTerrain,
    dem_path: PathBuf,
    photo_path: Option<PathBuf>,
) -> Result<(Terrain, TerrainDigests), SceneError> {
    let lat = c.range(
        "terrain.observer_lat_deg",
        raw.observer_lat_deg,
        -90.0,
        90.0,
        "−90…90°",
    )?;
    let lon = c.range(
        "terrain.observer_lon_deg",
        raw.observer_lon_deg,
        -360.0,
        360.0,
        "−360…360°",
    )?;
    let d = Palette::default_palette();
    let rgb = |key: &str, v: Option<[f64; 3]>, default: [f64; 3]| {
        let v = v.unwrap_or(default);
        for x in v {
            c.range(key, x, 0.0, 1e6, "each 0…1e6")?;
        }
        Ok::<_, SceneError>(v)
    };
    let light_az = c.range(
        "terrain.light_azimuth_deg",
        raw.light_azimuth_deg.unwrap_or(180.0),
        -360.0,
        360.0,
        "−360…360°",
    )?;
    let light_el = c.range(
        "terrain.light_elevation_deg",
        raw.light_elevation_deg.unwrap_or(30.0),
        -90.0,
        90.0,
        "−90…90°",
    )?;
    let palette = Palette {
        rock_rgb: rgb("terrain.rock_rgb", raw.rock_rgb, d.rock_rgb)?,
        snow_rgb: rgb("terrain.snow_rgb", raw.snow_rgb, d.snow_rgb)?,
        ice_rgb: rgb("terrain.ice_rgb", raw.ice_rgb, d.ice_rgb)?,
        snow_line_m: c.range(
            "terrain.snow_line_m",
            raw.snow_line_m.unwrap_or(d.snow_line_m),
            -1e5,
            1e5,
            "−100000…100000 m",
        )?,
        ice_slope_rad: c
            .range(
                "terrain.ice_slope_deg",
                raw.ice_slope_deg.unwrap_or(d.ice_slope_rad.to_degrees()),
                0.0,
                90.0,
                "0…90°",
            )?
            .to_radians(),
        light_azimuth_rad: light_az.to_radians(),
        light_elevation_rad: light_el.to_radians(),
        light_enu: terrain::light_direction(light_az.to_radians(), light_el.to_radians()),
    };
    let bytes =
        crate::input::read_limited(&dem_path, terrain::dem::MAX_DEM_BYTES).map_err(|source| {
            SceneError::Terrain {
                path: c.path.to_path_buf(),
                source: Box::new(DemError::Read {
                    path: dem_path.clone(),
                    source,
                }),
            }
        })?;
    let dem = Dem::from_bytes(&dem_path, &bytes).map_err(|source| SceneError::Terrain {
        path: c.path.to_path_buf(),
        source: Box::new(source),
    })?;
    let digest: [u8; 32] = Sha256::digest(&bytes).into();
    let fill_voids = raw.fill_voids.unwrap_or(true);
    let terrain = Terrain::new(dem_path, dem, (lat, lon), palette, fill_voids);
    if raw.orthophoto.is_none() && raw.orthophoto_bounds_deg.is_some() {
        return Err(c.invalid(
            "terrain.orthophoto_bounds_deg",
            "bounds without terrain.orthophoto: give the image too".to_string(),
        ));
    }
    match photo_path {
        Some(image) => {
            let bounds = raw
                .orthophoto_bounds_deg
                .unwrap_or_else(|| terrain.model_area_deg());
            let (photo, photo_digest) = orthophoto(c, image, bounds)?;
            Ok((terrain.with_orthophoto(photo), (digest, Some(photo_digest))))
        }
        None => Ok((terrain, (digest, None))),
    }
}

/// The orthophoto at `image_path` over `bounds_deg` (south, west, north, east; checked), with
/// the image file's sha256.
fn orthophoto(
    c: &Checker<'_>,
    image_path: PathBuf,
    bounds_deg: [f64; 4],
) -> Result<(terrain::Orthophoto, [u8; 32]), SceneError> {
    let key = "terrain.orthophoto_bounds_deg";
    let [south, west, north, east] = bounds_deg;
    c.range(
        key,
        south,
        -90.0,
        90.0,
        "south, west, north, east: latitudes −90…90°",
    )?;
    c.range(
        key,
        north,
        -90.0,
        90.0,
        "south, west, north, east: latitudes −90…90°",
    )?;
    c.range(
        key,
        west,
        -360.0,
        360.0,
        "south, west, north, east: longitudes −360…360°",
    )?;
    c.range(
        key,
        east,
        -360.0,
        360.0,
        "south, west, north, east: longitudes −360…360°",
    )?;
    if !(south < north && west < east && east - west <= 360.0) {
        return Err(c.invalid(
            key,
            format!(
                "[{south}, {west}, {north}, {east}]: give south < north and west < east, at \
                 most 360° apart"
            ),
        ));
    }
    let (texture, digest) =
        card::Texture::from_file_with_digest(&image_path).map_err(|e| SceneError::Orthophoto {
            path: c.path.to_path_buf(),
            image: e.path,
            source: e.source,
        })?;
    if texture.width == 0 || texture.height == 0 {
        return Err(c.invalid("terrain.orthophoto", "the image has no pixels".to_string()));
    }
    let photo = terrain::Orthophoto {
        image_path,
        bounds_deg,
        texture: Arc::new(texture),
    };
    Ok((photo, digest))
}

/// The sea's rms facet slope (rad): `wave_slope_deg` if given, else Cox–Munk at
/// `wind_speed_m_s` (default 0 m/s); giving both is an error.
fn sea_wave_slope_rad(c: &Checker<'_>, raw: &RawSea) -> Result<f64, SceneError> {
    match (raw.wave_slope_deg, raw.wind_speed_m_s) {
        (Some(_), Some(_)) => Err(c.invalid(
            "sea.wind_speed_m_s",
            "give either sea.wave_slope_deg or sea.wind_speed_m_s, not both".to_string(),
        )),
        (Some(deg), None) => Ok(c
            .range("sea.wave_slope_deg", deg, 0.0, 45.0, "0…45°")?
            .to_radians()),
        (None, wind) => {
            let u = c.range(
                "sea.wind_speed_m_s",
                wind.unwrap_or(0.0),
                0.0,
                50.0,
                "0…50 m/s",
            )?;
            Ok(sea::cox_munk_rms_slope_rad(u))
        }
    }
}

/// Largest supported card distance (m): beyond a few hundred km the ray model is pointless.
pub const MAX_CARD_DISTANCE_M: f64 = 1_000_000.0;

struct Checker<'a> {
    path: &'a Path,
}

impl Checker<'_> {
    fn range(
        &self,
        key: &str,
        value: f64,
        lo: f64,
        hi: f64,
        what: &str,
    ) -> Result<f64, SceneError> {
        if value.is_finite() && value >= lo && value <= hi {
            Ok(value)
        } else {
            Err(self.invalid(key, format!("must be {what}, got {value}")))
        }
    }

    fn positive(&self, key: &str, value: f64, hi: f64) -> Result<f64, SceneError> {
        if value.is_finite() && value > 0.0 && value <= hi {
            Ok(value)
        } else {
            Err(self.invalid(key, format!("must be > 0 and ≤ {hi}, got {value}")))
        }
    }

    fn invalid(&self, key: &str, message: String) -> SceneError {
        SceneError::Invalid {
            path: self.path.to_path_buf(),
            key: key.to_string(),
            message,
        }
    }
}

/// `sky.visibility_km` and `sky.aerosol_scale_height_m` checked: `None` without a visibility
/// (a scale height alone is checked and has no effect). The visibility must stay below that of
/// the Rayleigh air alone ([`sky::rayleigh_visibility_m`]): it is the total extinction.
fn aerial_perspective(
    c: &Checker<'_>,
    raw: &RawSky,
    rayleigh_optical_depth: f64,
) -> Result<Option<AerialPerspective>, SceneError> {
    let aerosol_scale_height_m = c.positive(
        "sky.aerosol_scale_height_m",
        raw.aerosol_scale_height_m
            .unwrap_or(sky::DEFAULT_AEROSOL_SCALE_HEIGHT_M),
        1e12,
    )?;
    let Some(visibility_km) = raw.visibility_km else {
        return Ok(None);
    };
    let limit_km = sky::rayleigh_visibility_m(rayleigh_optical_depth) / 1000.0;
    let visibility_km = c.positive("sky.visibility_km", visibility_km, 1e6)?;
    if visibility_km > limit_km {
        return Err(c.invalid(
            "sky.visibility_km",
            format!(
                "must be ≤ {limit_km:.1} km, the visibility of Rayleigh air alone with \
                 sky.rayleigh_optical_depth = {rayleigh_optical_depth}, got {visibility_km}"
            ),
        ));
    }
    Ok(Some(AerialPerspective {
        visibility_m: visibility_km * 1000.0,
        aerosol_scale_height_m,
    }))
}

/// Largest number of samples per pixel (32 × 32). Without a bound a mistyped `--spp` (any
/// square up to 65535²) would keep the machine busy for days; the per-sample jitter hash also
/// keeps the sample index in 16 bits.
pub const MAX_SAMPLES_PER_PIXEL: u32 = 1024;

/// Check that `spp` is a square number from 1 to [`MAX_SAMPLES_PER_PIXEL`] and return its root.
pub fn samples_per_pixel_root(spp: u32) -> Option<u32> {
    if !(1..=MAX_SAMPLES_PER_PIXEL).contains(&spp) {
        return None;
    }
    let n = (spp as f64).sqrt().round() as u32;
    (n * n == spp).then_some(n)
}

impl Scene {
    /// Load a scene file; paths inside are relative to its folder.
    pub fn from_file(path: &Path) -> Result<Self, SceneError> {
        let text = crate::input::read_limited_text(path, crate::input::MAX_TOML_BYTES).map_err(
            |source| SceneError::Read {
                path: path.to_path_buf(),
                source,
            },
        )?;
        let base = path.parent().unwrap_or(Path::new("."));
        let mut scene = Self::from_toml_str(&text, base, path)?;
        scene.source_path = Some(path.to_path_buf());
        Ok(scene)
    }

    /// Parse scene text; relative paths are resolved against `base_dir`; `name` is used in errors.
    pub fn from_toml_str(text: &str, base_dir: &Path, name: &Path) -> Result<Self, SceneError> {
        let raw: RawScene = toml::from_str(text).map_err(|source| SceneError::Parse {
            path: name.to_path_buf(),
            source,
        })?;
        let c = Checker { path: name };
        let resolve = |p: &Path| {
            if p.is_absolute() {
                p.to_path_buf()
            } else {
                base_dir.join(p)
            }
        };

        let rc = &raw.camera;
        let spp = rc.samples_per_pixel;
        if samples_per_pixel_root(spp).is_none() {
            return Err(c.invalid(
                "camera.samples_per_pixel",
                format!(
                    "must be a square number (1, 4, 9, 16, …, {MAX_SAMPLES_PER_PIXEL}), got {spp}"
                ),
            ));
        }
        for (key, v) in [("camera.width", rc.width), ("camera.height", rc.height)] {
            if !(1..=16_384).contains(&v) {
                return Err(c.invalid(key, format!("must be 1…16384 pixels, got {v}")));
            }
        }
        let camera = Camera {
            height_m: c.range(
                "camera.height_m",
                rc.height_m,
                0.01,
                100_000.0,
                "0.01…100000 m",
            )?,
            heading_rad: c
                .range(
                    "camera.heading_deg",
                    rc.heading_deg,
                    -360.0,
                    360.0,
                    "−360…360°",
                )?
                .to_radians(),
            pitch_rad: c
                .range("camera.pitch_deg", rc.pitch_deg, -90.0, 90.0, "−90…90°")?
                .to_radians(),
            hfov_rad: c
                .range(
                    "camera.hfov_deg",
                    rc.hfov_deg,
                    1e-4,
                    179.0,
                    "between 0.0001° and 179°",
                )?
                .to_radians(),
            width: rc.width,
            height: rc.height,
            samples_per_pixel: spp,
        };

        let ra = &raw.atmosphere;
        let source = match (&ra.sounding, &ra.synthetic, &ra.standard) {
            (Some(p), None, None) => AtmosphereSource::Sounding(resolve(p)),
            (None, Some(p), None) => AtmosphereSource::Synthetic(resolve(p)),
            (None, None, Some(s)) if s.eq_ignore_ascii_case("us1976") => AtmosphereSource::Us1976,
            (None, None, Some(s)) => {
                return Err(c.invalid(
                    "atmosphere.standard",
                    format!("the only standard atmosphere is \"us1976\", got {s:?}"),
                ));
            }
            (None, None, None) => AtmosphereSource::Us1976,
            _ => {
                return Err(c.invalid(
                    "atmosphere",
                    "give only one of `sounding`, `synthetic` or `standard`".into(),
                ));
            }
        };
        let sounding_time = match (&ra.sounding_time, &source) {
            (None, _) => None,
            (Some(t), AtmosphereSource::Sounding(_)) => Some(t.clone()),
            (Some(_), _) => {
                return Err(c.invalid(
                    "atmosphere.sounding_time",
                    "only applies to a `sounding` (an IGRA2 file)".into(),
                ));
            }
        };
        let atmosphere = AtmosphereSettings {
            source,
            // The refractive-index model's range (Ciddor 1996), the same as every other command.
            wavelength_nm: {
                let (lo, hi) = crate::refractivity::WAVELENGTH_RANGE_NM;
                c.range(
                    "atmosphere.wavelength_nm",
                    ra.wavelength_nm.unwrap_or(550.0),
                    lo,
                    hi,
                    &format!("{lo}…{hi} nm"),
                )?
            },
            straight: ra.straight,
            smooth_m: ra
                .smooth_m
                .map(|s| c.range("atmosphere.smooth_m", s, 0.0, 10_000.0, "0…10000 m"))
                .transpose()?,
            fit: ra.fit,
            sounding_time,
            strict: ra.strict,
        };

        let earth_radius_m = c.positive(
            "earth.radius_m",
            raw.earth.radius_m.unwrap_or(crate::units::EARTH_RADIUS_M),
            1e9,
        )?;

        let d = Sky::default();
        let sky = Sky {
            brightness: c.range(
                "sky.brightness",
                raw.sky.brightness.unwrap_or(d.brightness),
                0.0,
                1e6,
                "0…1e6",
            )?,
            rayleigh_optical_depth: c.range(
                "sky.rayleigh_optical_depth",
                raw.sky
                    .rayleigh_optical_depth
                    .unwrap_or(d.rayleigh_optical_depth),
                0.0,
                10.0,
                "0…10",
            )?,
            aerosol_optical_depth: c.range(
                "sky.aerosol_optical_depth",
                raw.sky
                    .aerosol_optical_depth
                    .unwrap_or(d.aerosol_optical_depth),
                0.0,
                10.0,
                "0…10",
            )?,
            aerial: None,
            channel_wavelengths_nm: sky::CHANNEL_WAVELENGTHS_NM,
        };
        let sky = Sky {
            aerial: aerial_perspective(&c, &raw.sky, sky.rayleigh_optical_depth)?,
            ..sky
        };

        let d = Sea::default();
        let water_rgb = raw.sea.water_rgb.unwrap_or(d.water_rgb);
        for v in water_rgb {
            c.range("sea.water_rgb", v, 0.0, 1e6, "each 0…1e6")?;
        }
        let sea = Sea {
            water_rgb,
            refractive_index: c.range(
                "sea.refractive_index",
                raw.sea.refractive_index.unwrap_or(d.refractive_index),
                1.0,
                3.0,
                "1…3",
            )?,
            wave_slope_rad: sea_wave_slope_rad(&c, &raw.sea)?,
            wind_speed_m_s: raw
                .sea
                .wave_slope_deg
                .is_none()
                .then_some(raw.sea.wind_speed_m_s.unwrap_or(0.0)),
            reflections: raw.sea.reflections.unwrap_or(d.reflections),
        };

        let mut cards = Vec::with_capacity(raw.cards.len());
        let mut card_digests = Vec::with_capacity(raw.cards.len());
        for (i, rc) in raw.cards.iter().enumerate() {
            let key = |k: &str| format!("cards[{i}].{k}");
            let image_path = resolve(&rc.image);
            // Numbers first (cheap, and the error names the key), then the image.
            // Ground distances beyond half the circumference (πR) do not exist on the sphere
            // (the card would be nearer the other way round).
            let distance_m = c.positive(
                &key("distance_m"),
                rc.distance_m,
                MAX_CARD_DISTANCE_M.min(std::f64::consts::PI * earth_radius_m),
            )?;
            let azimuth_rad = c
                .range(
                    &key("azimuth_deg"),
                    rc.azimuth_deg,
                    -360.0,
                    360.0,
                    "−360…360°",
                )?
                .to_radians();
            let width_m = c.positive(&key("width_m"), rc.width_m, 100_000.0)?;
            let height_m = c.positive(&key("height_m"), rc.height_m, 100_000.0)?;
            let base_m = c.range(
                &key("base_m"),
                rc.base_m,
                -1_000.0,
                100_000.0,
                "−1000…100000 m",
            )?;
            let (texture, digest) =
                Texture::from_file_with_digest(&image_path).map_err(|source| {
                    SceneError::Texture {
                        path: name.to_path_buf(),
                        source,
                    }
                })?;
            card_digests.push(digest);
            cards.push(Card {
                image_path,
                distance_m,
                azimuth_rad,
                width_m,
                height_m,
                base_m,
                texture: Arc::new(texture),
            });
        }

        let sun = match &raw.sun {
            None => None,
            Some(rs) => Some(Sun {
                elevation_rad: c
                    .range(
                        "sun.elevation_deg",
                        rs.elevation_deg,
                        -90.0,
                        90.0,
                        "−90…90°",
                    )?
                    .to_radians(),
                azimuth_rad: c
                    .range(
                        "sun.azimuth_deg",
                        rs.azimuth_deg,
                        -360.0,
                        360.0,
                        "−360…360°",
                    )?
                    .to_radians(),
                angular_diameter_rad: match rs.angular_diameter_deg {
                    Some(v) => c
                        .range("sun.angular_diameter_deg", v, 1e-4, 20.0, "0.0001…20°")?
                        .to_radians(),
                    None => sky::sun_angular_diameter_rad(),
                },
                limb_darkening: c.range(
                    "sun.limb_darkening",
                    rs.limb_darkening.unwrap_or(0.6),
                    0.0,
                    1.0,
                    "0…1",
                )?,
                intensity: c.range(
                    "sun.intensity",
                    rs.intensity.unwrap_or(DEFAULT_SUN_INTENSITY),
                    0.0,
                    1e9,
                    "0…1e9",
                )?,
            }),
        };

        let (terrain, terrain_digests) = match &raw.terrain {
            Some(rt) => {
                let photo = rt.orthophoto.as_deref().map(resolve);
                let (t, digests) = terrain_section(&c, rt, resolve(&rt.dem), photo)?;
                (Some(t), Some(digests))
            }
            None => (None, None),
        };

        let spectral_bands = match raw.render.spectral_bands {
            None | Some(0) => None,
            Some(n) if (MIN_SPECTRAL_BANDS..=MAX_SPECTRAL_BANDS).contains(&n) => Some(n),
            Some(n) => {
                return Err(c.invalid(
                    "render.spectral_bands",
                    format!(
                        "give 0 (RGB) or {MIN_SPECTRAL_BANDS}…{MAX_SPECTRAL_BANDS} bands, got {n}"
                    ),
                ));
            }
        };
        let mut scene = Scene {
            source_path: None,
            camera,
            atmosphere,
            earth_radius_m,
            sky,
            sea,
            cards,
            sun,
            terrain,
            spectral_bands,
            hash_hex: String::new(),
        };
        scene.hash_hex = scene.compute_hash(text, &card_digests, terrain_digests);
        Ok(scene)
    }

    /// `card_digests`: the sha256 of each card's image file, in card order; `terrain_digests`:
    /// those of the elevation model file and of the orthophoto (if any), when there is terrain.
    fn compute_hash(
        &self,
        text: &str,
        card_digests: &[[u8; 32]],
        terrain_digests: Option<TerrainDigests>,
    ) -> String {
        let mut h = Sha256::new();
        h.update(b"ghostship-scene-v1\0");
        h.update(text.as_bytes());
        h.update(b"\0");
        // Resolved parameters (JSON of the validated scene; serde_json prints f64 exactly), with
        // paths reduced to file names so the hash does not depend on where the scene was loaded
        // from; the card images enter by content below.
        let mut view = self.clone();
        let file_name = |p: &Path| PathBuf::from(p.file_name().unwrap_or_default());
        for card in &mut view.cards {
            card.image_path = file_name(&card.image_path);
        }
        view.atmosphere.source = match &view.atmosphere.source {
            AtmosphereSource::Sounding(p) => AtmosphereSource::Sounding(file_name(p)),
            AtmosphereSource::Synthetic(p) => AtmosphereSource::Synthetic(file_name(p)),
            AtmosphereSource::Us1976 => AtmosphereSource::Us1976,
        };
        view.source_path = None;
        if let Some(t) = &mut view.terrain {
            t.dem_path = file_name(&t.dem_path);
            if let Some(photo) = &mut t.orthophoto {
                photo.image_path = file_name(&photo.image_path);
            }
        }
        h.update(serde_json::to_vec(&view).unwrap_or_default());
        // The atmosphere file enters by content too: editing a layer changes the image, so it
        // must change the hash. An unreadable file (the render will fail to load it anyway)
        // is marked as such.
        if let AtmosphereSource::Sounding(p) | AtmosphereSource::Synthetic(p) =
            &self.atmosphere.source
        {
            h.update(b"\0atmosphere\0");
            match crate::input::read_limited(p, crate::input::MAX_SOUNDING_BYTES) {
                Ok(bytes) => h.update(bytes),
                Err(_) => h.update(b"unreadable"),
            }
        }
        // The card images by the content of their files (what was decoded; hashing the
        // decoded linear texels instead costs more than rendering a small frame).
        for digest in card_digests {
            h.update(b"\0card\0");
            h.update(digest);
        }
        if let Some((digest, photo)) = terrain_digests {
            h.update(b"\0terrain\0");
            h.update(digest);
            if let Some(photo) = photo {
                h.update(b"\0orthophoto\0");
                h.update(photo);
            }
        }
        h.finalize().iter().map(|b| format!("{b:02x}")).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MINIMAL: &str = "[camera]\nheight_m = 10\nhfov_deg = 1\nwidth = 40\nheight = 20\n";

    fn parse(text: &str) -> Result<Scene, SceneError> {
        Scene::from_toml_str(text, Path::new("/base"), Path::new("test.toml"))
    }

    #[test]
    fn the_default_sun_is_the_sky_models_own_ratio_of_disc_to_horizon_radiance() {
        let theta = sky::sun_angular_diameter_rad();
        let ratio = 16.0 / (theta * theta);
        assert!(
            (DEFAULT_SUN_INTENSITY / ratio - 1.0).abs() < 5e-3,
            "{ratio}"
        );
    }

    #[test]
    fn defaults_fill_in() {
        let s = parse(MINIMAL).unwrap();
        assert_eq!(s.atmosphere.source, AtmosphereSource::Us1976);
        assert_eq!(s.atmosphere.wavelength_nm, 550.0);
        assert_eq!(s.earth_radius_m, 6_371_000.0);
        assert_eq!(s.camera.samples_per_pixel, 1);
        assert!(s.sun.is_none() && s.cards.is_empty());
        assert_eq!(s.hash_hex.len(), 64);
    }

    #[test]
    fn unknown_fields_report_line_and_column() {
        let text = format!("{MINIMAL}pich_deg = 3\n");
        let err = parse(&text).unwrap_err().to_string();
        assert!(err.contains("line 6") && err.contains("column 1"), "{err}");
        assert!(err.contains("pich_deg"), "{err}");
    }

    #[test]
    fn invalid_values_name_the_key() {
        let text = MINIMAL.replace("hfov_deg = 1", "hfov_deg = 200");
        let err = parse(&text).unwrap_err().to_string();
        assert!(
            err.contains("camera.hfov_deg") && err.contains("200"),
            "{err}"
        );
        let text = format!("{MINIMAL}samples_per_pixel = 3\n");
        let err = parse(&text).unwrap_err().to_string();
        assert!(err.contains("square"), "{err}");
        let text = format!("{MINIMAL}[atmosphere]\nsounding = \"a.csv\"\nstandard = \"us1976\"\n");
        let err = parse(&text).unwrap_err().to_string();
        assert!(err.contains("only one"), "{err}");
        let text = format!("{MINIMAL}[sun]\nelevation_deg = -95\n");
        assert!(
            parse(&text)
                .unwrap_err()
                .to_string()
                .contains("sun.elevation_deg")
        );
    }

    #[test]
    fn visibility_sets_the_aerial_perspective_and_is_checked() {
        assert_eq!(parse(MINIMAL).unwrap().sky.aerial, None);
        let scene = parse(&format!("{MINIMAL}[sky]\nvisibility_km = 12.5\n")).unwrap();
        let aerial = scene.sky.aerial.unwrap();
        assert_eq!(aerial.visibility_m, 12_500.0);
        assert_eq!(aerial.aerosol_scale_height_m, 1000.0);
        let text = format!("{MINIMAL}[sky]\nvisibility_km = 5\naerosol_scale_height_m = 1e9\n");
        assert_eq!(
            parse(&text)
                .unwrap()
                .sky
                .aerial
                .unwrap()
                .aerosol_scale_height_m,
            1e9
        );
        // Rayleigh air alone (τ_R = 0.0975) sees 3.912 × 8 km / 0.0975 = 321 km.
        for (bad, key) in [
            ("visibility_km = 0", "sky.visibility_km"),
            ("visibility_km = 330", "sky.visibility_km"),
            (
                "visibility_km = 5\naerosol_scale_height_m = -1",
                "sky.aerosol_scale_height_m",
            ),
            ("aerosol_scale_height_m = 0", "sky.aerosol_scale_height_m"),
        ] {
            let err = parse(&format!("{MINIMAL}[sky]\n{bad}\n"))
                .unwrap_err()
                .to_string();
            assert!(err.contains(key), "{bad}: {err}");
        }
        assert!(parse(&format!("{MINIMAL}[sky]\nvisibility_km = 320\n")).is_ok());
        let text = format!("{MINIMAL}[sky]\naerosol_scale_height_m = 500\n");
        assert_eq!(parse(&text).unwrap().sky.aerial, None);
    }

    #[test]
    fn wavelength_range_is_the_refractive_index_models() {
        // Ciddor (1996) holds for 300–1690 nm; the scene used to stop at 1100 nm while `profile`
        // and `trace` accept up to 1700 nm for the same atmosphere.
        let (lo, hi) = crate::refractivity::WAVELENGTH_RANGE_NM;
        for (wl, ok) in [
            (lo, true),
            (1500.0, true),
            (hi, true),
            (hi + 1.0, false),
            (2000.0, false),
        ] {
            let text = format!("{MINIMAL}[atmosphere]\nwavelength_nm = {wl}\n");
            match parse(&text) {
                Ok(s) => assert!(ok && s.atmosphere.wavelength_nm == wl, "{wl}"),
                Err(e) => assert!(!ok && e.to_string().contains("wavelength_nm"), "{wl}: {e}"),
            }
        }
    }

    #[test]
    fn samples_per_pixel_are_bounded_squares() {
        for n in 1..=32u32 {
            assert_eq!(samples_per_pixel_root(n * n), Some(n));
        }
        for spp in [0, 2, 3, 5, 1023, 1025, 33 * 33, 65_535 * 65_535, u32::MAX] {
            assert_eq!(samples_per_pixel_root(spp), None, "{spp}");
        }
        let text = format!("{MINIMAL}samples_per_pixel = 4096\n");
        let err = parse(&text).unwrap_err().to_string();
        assert!(err.contains("camera.samples_per_pixel"), "{err}");
    }

    #[test]
    fn atmosphere_paths_are_relative_to_the_scene() {
        let text =
            format!("{MINIMAL}[atmosphere]\nsynthetic = \"../fata.toml\"\nstraight = true\n");
        let s = parse(&text).unwrap();
        assert_eq!(
            s.atmosphere.source,
            AtmosphereSource::Synthetic(PathBuf::from("/base/../fata.toml"))
        );
        assert!(s.atmosphere.straight);
    }

    #[test]
    fn sun_defaults_and_hash_depends_on_content() {
        let text = format!("{MINIMAL}[sun]\nelevation_deg = -2\n");
        let s = parse(&text).unwrap();
        let sun = s.sun.unwrap();
        assert!((sun.angular_diameter_rad.to_degrees() - 0.533).abs() < 1e-3);
        assert_ne!(s.hash_hex, parse(MINIMAL).unwrap().hash_hex);
        assert_eq!(
            parse(MINIMAL).unwrap().hash_hex,
            parse(MINIMAL).unwrap().hash_hex
        );
    }

    #[test]
    fn hash_does_not_depend_on_the_folder() {
        let text = format!("{MINIMAL}[atmosphere]\nsynthetic = \"fata.toml\"\n");
        let a = Scene::from_toml_str(&text, Path::new("/one"), Path::new("a.toml")).unwrap();
        let b = Scene::from_toml_str(&text, Path::new("two/three"), Path::new("b.toml")).unwrap();
        assert_eq!(a.hash_hex, b.hash_hex);
    }

    #[test]
    fn hash_follows_the_atmosphere_file_content_not_its_folder() {
        let text = format!("{MINIMAL}[atmosphere]\nsynthetic = \"atm.toml\"\n");
        let hash_in = |dir: &Path, atmosphere: &str| {
            std::fs::write(dir.join("atm.toml"), atmosphere).unwrap();
            Scene::from_toml_str(&text, dir, Path::new("s.toml"))
                .unwrap()
                .hash_hex
        };
        let (one, two) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        let a = hash_in(one.path(), "surface_temperature_c = 0.0\n");
        let b = hash_in(one.path(), "surface_temperature_c = 5.0\n");
        let c = hash_in(two.path(), "surface_temperature_c = 0.0\n");
        assert_ne!(a, b, "editing the atmosphere must change the scene hash");
        assert_eq!(a, c, "the same files in another folder give the same hash");
    }

    #[test]
    fn hash_follows_the_card_image_content_not_its_folder() {
        let text = format!(
            "{MINIMAL}[[cards]]\nimage = \"card.png\"\ndistance_m = 1000\nwidth_m = 10\nheight_m = 5\n"
        );
        let hash_in = |dir: &Path, rgba: [u8; 4]| {
            let img = image::RgbaImage::from_pixel(4, 2, image::Rgba(rgba));
            img.save(dir.join("card.png")).unwrap();
            Scene::from_toml_str(&text, dir, Path::new("s.toml"))
                .unwrap()
                .hash_hex
        };
        let (one, two) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        let a = hash_in(one.path(), [10, 20, 30, 255]);
        let b = hash_in(one.path(), [10, 20, 31, 255]);
        let c = hash_in(two.path(), [10, 20, 30, 255]);
        assert_ne!(a, b, "editing a card image must change the scene hash");
        assert_eq!(a, c, "the same files in another folder give the same hash");
    }

    #[test]
    fn sounding_time_only_for_soundings() {
        let text = format!(
            "{MINIMAL}[atmosphere]\nsounding = \"a.txt\"\nsounding_time = \"2010-06-01 12\"\n"
        );
        let s = parse(&text).unwrap();
        assert_eq!(s.atmosphere.sounding_time.as_deref(), Some("2010-06-01 12"));
        let text = format!(
            "{MINIMAL}[atmosphere]\nsynthetic = \"a.toml\"\nsounding_time = \"2010-06-01 12\"\n"
        );
        let err = parse(&text).unwrap_err().to_string();
        assert!(err.contains("atmosphere.sounding_time"), "{err}");
    }

    #[test]
    fn card_distance_stays_within_half_the_circumference() {
        // The distance check comes before the image is read, so no card file is needed.
        let text = format!(
            "{MINIMAL}[earth]\nradius_m = 1000.0\n[[cards]]\nimage = \"nope.png\"\n\
             distance_m = 26000\nwidth_m = 10\nheight_m = 5\n"
        );
        let err = parse(&text).unwrap_err().to_string();
        assert!(err.contains("cards[0].distance_m"), "{err}");
    }

    #[test]
    fn missing_card_image_is_a_clear_error() {
        let text = format!(
            "{MINIMAL}[[cards]]\nimage = \"nope.png\"\ndistance_m = 1000\nwidth_m = 10\nheight_m = 5\n"
        );
        let err = parse(&text).unwrap_err().to_string();
        assert!(err.contains("nope.png"), "{err}");
    }
}
