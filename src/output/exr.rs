//! Output — OpenEXR exporter. In: a [`Film`] (linear f32 RGBA) and provenance. Out: the bytes of
//! an EXR file: linear Rec.709 primaries with D65 white (the `chromaticities` attribute), f32 RGBA,
//! ZIP compression in increasing line order (`Encoding::SMALL_LOSSLESS`), so the same film gives
//! byte-identical files whatever the thread count.
//!
//! Provenance: `software` = `"ghostship VERSION"`, `comments` = the scene hash, and ONE extra
//! attribute `ghostship` (a string vector of `key=value` lines: program version, scene sha256,
//! observer height, wavelength, fan tolerance, tracer tolerance, …). One attribute, because `exr` keeps extra
//! attributes in a `HashMap` and writes them in its (per-process random) iteration order: several
//! would break byte reproducibility.

use std::io::Cursor;

use exr::meta::attribute::{AttributeValue, Chromaticities, Text};
use exr::prelude::{
    Encoding, Image, Layer, LayerAttributes, SpecificChannels, Vec2, WritableImage,
};

use crate::render::Film;

/// Name of the extra EXR attribute holding ghostship's provenance lines.
pub const PROVENANCE_ATTRIBUTE: &str = "ghostship";

/// Provenance written into the EXR header.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ExrMetadata {
    /// sha256 (hex) of the scene file content and resolved parameters.
    pub scene_hash: String,
    /// Observer (camera) height above the surface (m).
    pub observer_height_m: f64,
    /// Wavelength of the refractive index (nm).
    pub wavelength_nm: f64,
    /// Fan tolerance (pixels); `None` in exact mode.
    pub tolerance_px: Option<f64>,
    /// The ray tracer's position tolerance per step (m).
    pub tracer_tolerance_m: f64,
    /// Further `key=value` entries (Latin-1; other characters become `?`).
    pub extra: Vec<(String, String)>,
}

/// The EXR could not be encoded.
#[derive(Debug, thiserror::Error)]
#[error("cannot encode EXR: {0}")]
pub struct ExrError(#[from] exr::error::Error);

fn text(s: &str) -> Text {
    let latin1: String = s
        .chars()
        .map(|c| if (c as u32) < 256 { c } else { '?' })
        .collect();
    Text::new_or_none(latin1).unwrap_or_else(|| Text::from("?"))
}

impl ExrMetadata {
    /// The `key=value` lines of the provenance attribute, in a fixed order.
    pub fn lines(&self) -> Vec<String> {
        let mut v = vec![
            format!("version={}", env!("CARGO_PKG_VERSION")),
            format!("scene_sha256={}", self.scene_hash),
            format!("observer_height_m={}", self.observer_height_m),
            format!("wavelength_nm={}", self.wavelength_nm),
            match self.tolerance_px {
                Some(t) => format!("fan_tolerance_px={t}"),
                None => "fan_tolerance_px=exact".to_string(),
            },
            format!("tracer_tolerance_m={}", self.tracer_tolerance_m),
        ];
        v.extend(self.extra.iter().map(|(k, val)| format!("{k}={val}")));
        v
    }
}

/// Encode `film` as an EXR file (bytes).
///
/// A film whose pixel count is not width × height (its fields are public) is an error, not a
/// panic.
pub fn encode_exr(film: &Film, meta: &ExrMetadata) -> Result<Vec<u8>, ExrError> {
    let (w, h) = (film.width as usize, film.height as usize);
    if film.pixels.len() != w * h || w == 0 || h == 0 {
        return Err(ExrError(exr::error::Error::Invalid(
            "film pixel count does not match width × height (or the film is empty)".into(),
        )));
    }
    let mut attrs = LayerAttributes::named("rgba");
    attrs.software_name = Some(text(concat!("ghostship ", env!("CARGO_PKG_VERSION"))));
    attrs.comments = Some(text(&format!("scene sha256 {}", meta.scene_hash)));
    attrs.other.insert(
        text(PROVENANCE_ATTRIBUTE),
        AttributeValue::TextVector(meta.lines().iter().map(|l| text(l)).collect()),
    );
    let pixels = &film.pixels;
    let layer = Layer::new(
        (w, h),
        attrs,
        Encoding::SMALL_LOSSLESS,
        SpecificChannels::rgba(|p: Vec2<usize>| {
            let q = pixels[p.y() * w + p.x()];
            (q[0], q[1], q[2], q[3])
        }),
    );
    let mut image = Image::from_layer(layer);
    image.attributes.chromaticities = Some(Chromaticities {
        red: Vec2(0.64, 0.33),
        green: Vec2(0.30, 0.60),
        blue: Vec2(0.15, 0.06),
        white: Vec2(0.3127, 0.3290),
    });
    let mut out = Cursor::new(Vec::new());
    image.write().to_buffered(&mut out)?;
    Ok(out.into_inner())
}
