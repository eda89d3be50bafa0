//! Stage 5 (render) — spectral rendering. In: a [`Scene`] whose `[render] spectral_bands` is N,
//! its refractive atmosphere and the render options. Out: a [`SpectralFilm`] — the frame in
//! linear Rec.709 (the same unit as the RGB path: the white horizon sky is 1.0 in every channel)
//! and the radiance of every band.
//!
//! **Bands.** N bands of equal width tile 400–700 nm; band k is rendered at its centre
//! λ_k = 400 + (k + ½)·300/N nm. The fans of the bands share everything but the refractive index:
//! per band the refractive atmosphere is rebuilt at λ_k on the same air column
//! ([`RefractiveAtmosphere::at_wavelength_nm`]) and the frame is rendered with the sky model's
//! three channel wavelengths all set to λ_k ([`crate::scene::Sky::channel_wavelengths_nm`]), so
//! scattering, extinction along the sun's curved path and the aerial perspective take their
//! λ-dependence at the band itself. A band render costs what one RGB render costs (its own fan,
//! sun paths and shading), so a spectral frame costs about N RGB frames.
//!
//! **Spectra of the things in the scene.** The sky's source and the sun above the atmosphere
//! are flat (equal-energy) spectra, the spectral counterpart of the RGB path's white sun and
//! white sky source: the normalisation below maps a flat spectrum to (1, 1, 1), so a scene
//! without dispersion or wavelength-dependent extinction renders as white as before. Card
//! textures, the sea's water colour and terrain colours are RGB; each is turned into a
//! reflectance spectrum by linear interpolation between the channel wavelengths
//! ([`CHANNEL_WAVELENGTHS_NM`], constant beyond them): [`rgb_weights`] are those hat functions,
//! a partition of unity, so a grey stays grey. Shading is linear in those colours, so the band
//! radiance is `Σ_c w_c(λ_k) L_c` of the band frame's three channels.
//!
//! **Colour.** The band radiances are integrated against the CIE 1931 2° colour-matching
//! functions ([`CIE_1931_2DEG_10NM`]): band k's weight is ∫ x̄ȳz̄ dλ over its interval (the first
//! and last band also take the functions' tails, 380–400 and 700–780 nm), giving XYZ, then
//! linear Rec.709 through the standard XYZ→Rec.709 (D65) matrix, and each channel is divided by
//! that of a flat spectrum (a white balance to the equal-energy white): a flat spectrum of 1 is
//! (1, 1, 1).

use crate::refractivity::RefractiveAtmosphere;
use crate::scene::Scene;
use crate::scene::sky::CHANNEL_WAVELENGTHS_NM;

use super::{Film, PrepareError, RenderError, RenderOptions, RenderStats, prepare_tracer};

/// The wavelengths the bands tile (nm).
pub const SPECTRAL_RANGE_NM: (f64, f64) = (400.0, 700.0);

/// The CIE 1931 2° standard observer colour-matching functions x̄, ȳ, z̄ at 10 nm from 380 to
/// 780 nm (CIE 15:2004, table T.4; the 1 nm table sampled every 10 nm).
#[rustfmt::skip]
pub const CIE_1931_2DEG_10NM: [(f64, [f64; 3]); 41] = [
    (380.0, [0.001368, 0.000039, 0.006450]),
    (390.0, [0.004243, 0.000120, 0.020050]),
    (400.0, [0.014310, 0.000396, 0.067850]),
    (410.0, [0.043510, 0.001210, 0.207400]),
    (420.0, [0.134380, 0.004000, 0.645600]),
    (430.0, [0.283900, 0.011600, 1.385600]),
    (440.0, [0.348280, 0.023000, 1.747060]),
    (450.0, [0.336200, 0.038000, 1.772110]),
    (460.0, [0.290800, 0.060000, 1.669200]),
    (470.0, [0.195360, 0.090980, 1.287640]),
    (480.0, [0.095640, 0.139020, 0.812950]),
    (490.0, [0.032010, 0.208020, 0.465180]),
    (500.0, [0.004900, 0.323000, 0.272000]),
    (510.0, [0.009300, 0.503000, 0.158200]),
    (520.0, [0.063270, 0.710000, 0.078250]),
    (530.0, [0.165500, 0.862000, 0.042160]),
    (540.0, [0.290400, 0.954000, 0.020300]),
    (550.0, [0.433450, 0.994950, 0.008750]),
    (560.0, [0.594500, 0.995000, 0.003900]),
    (570.0, [0.762100, 0.952000, 0.002100]),
    (580.0, [0.916300, 0.870000, 0.001650]),
    (590.0, [1.026300, 0.757000, 0.001100]),
    (600.0, [1.062200, 0.631000, 0.000800]),
    (610.0, [1.002600, 0.503000, 0.000340]),
    (620.0, [0.854450, 0.381000, 0.000190]),
    (630.0, [0.642400, 0.265000, 0.000050]),
    (640.0, [0.447900, 0.175000, 0.000020]),
    (650.0, [0.283500, 0.107000, 0.000000]),
    (660.0, [0.164900, 0.061000, 0.000000]),
    (670.0, [0.087400, 0.032000, 0.000000]),
    (680.0, [0.046770, 0.017000, 0.000000]),
    (690.0, [0.022700, 0.008210, 0.000000]),
    (700.0, [0.011359, 0.004102, 0.000000]),
    (710.0, [0.005790, 0.002091, 0.000000]),
    (720.0, [0.002899, 0.001047, 0.000000]),
    (730.0, [0.001440, 0.000520, 0.000000]),
    (740.0, [0.000690, 0.000249, 0.000000]),
    (750.0, [0.000332, 0.000120, 0.000000]),
    (760.0, [0.000166, 0.000060, 0.000000]),
    (770.0, [0.000083, 0.000030, 0.000000]),
    (780.0, [0.000042, 0.000015, 0.000000]),
];

/// XYZ → linear Rec.709 (sRGB primaries, D65 white), rows R, G, B (IEC 61966-2-1).
pub const XYZ_TO_REC709: [[f64; 3]; 3] = [
    [3.240_454_2, -1.537_138_5, -0.498_531_4],
    [-0.969_266_0, 1.876_010_8, 0.041_556_0],
    [0.055_643_4, -0.204_025_9, 1.057_225_2],
];

/// x̄, ȳ, z̄ at `wavelength_nm` (linear between the 10 nm entries; 0 outside 380–780 nm).
pub fn colour_matching(wavelength_nm: f64) -> [f64; 3] {
    let table = &CIE_1931_2DEG_10NM;
    let (first, last) = (table[0].0, table[table.len() - 1].0);
    if !(first..=last).contains(&wavelength_nm) {
        return [0.0; 3];
    }
    let p = (wavelength_nm - first) / 10.0;
    let i = (p as usize).min(table.len() - 2);
    let t = p - i as f64;
    let (a, b) = (table[i].1, table[i + 1].1);
    [0, 1, 2].map(|c| a[c] + (b[c] - a[c]) * t)
}

/// ∫ x̄ȳz̄ dλ over [`lo_nm`, `hi_nm`] (exact for the piecewise-linear table: Simpson's rule
/// on each 1 nm piece between the 10 nm nodes).
pub fn integrated_colour_matching(lo_nm: f64, hi_nm: f64) -> [f64; 3] {
    let mut acc = [0.0; 3];
    let mut x = lo_nm;
    while x < hi_nm {
        let next = (x.floor() + 1.0).min(hi_nm);
        let (a, m, b) = (
            colour_matching(x),
            colour_matching(0.5 * (x + next)),
            colour_matching(next),
        );
        for c in 0..3 {
            acc[c] += (next - x) * (a[c] + 4.0 * m[c] + b[c]) / 6.0;
        }
        x = next;
    }
    acc
}

/// The centres (nm) of `bands` equal bands tiling [`SPECTRAL_RANGE_NM`].
pub fn band_centres_nm(bands: u32) -> Vec<f64> {
    let (lo, hi) = SPECTRAL_RANGE_NM;
    let width = (hi - lo) / bands as f64;
    (0..bands).map(|k| lo + (k as f64 + 0.5) * width).collect()
}

/// How much of each RGB channel an RGB colour's reflectance spectrum takes at `wavelength_nm`:
/// hat functions linear between the channel wavelengths ([`CHANNEL_WAVELENGTHS_NM`], R 612,
/// G 549, B 465 nm), the outer ones constant beyond them. They sum to 1 at every wavelength.
pub fn rgb_weights(wavelength_nm: f64) -> [f64; 3] {
    let [r, g, b] = CHANNEL_WAVELENGTHS_NM;
    let l = wavelength_nm;
    if l <= b {
        [0.0, 0.0, 1.0]
    } else if l <= g {
        let t = (l - b) / (g - b);
        [0.0, t, 1.0 - t]
    } else if l <= r {
        let t = (l - g) / (r - g);
        [t, 1.0 - t, 0.0]
    } else {
        [1.0, 0.0, 0.0]
    }
}

/// XYZ → linear Rec.709 with [`XYZ_TO_REC709`].
pub fn xyz_to_rec709(xyz: [f64; 3]) -> [f64; 3] {
    XYZ_TO_REC709.map(|row| row[0] * xyz[0] + row[1] * xyz[1] + row[2] * xyz[2])
}

/// The colour of band radiances: each band's XYZ weight, and the Rec.709 of a flat spectrum of
/// 1 that the result is divided by (module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct BandColour {
    /// The bands' centres (nm).
    pub wavelengths_nm: Vec<f64>,
    /// ∫ x̄ȳz̄ dλ over each band's interval.
    pub xyz_weights: Vec<[f64; 3]>,
    /// Linear Rec.709 of a flat spectrum of 1, before normalisation.
    pub flat_rec709: [f64; 3],
}

impl BandColour {
    /// The colour weights of `bands` bands (see [`band_centres_nm`]).
    pub fn new(bands: u32) -> Self {
        let (lo, hi) = SPECTRAL_RANGE_NM;
        let width = (hi - lo) / bands as f64;
        let (first, last) = (
            CIE_1931_2DEG_10NM[0].0,
            CIE_1931_2DEG_10NM[CIE_1931_2DEG_10NM.len() - 1].0,
        );
        let xyz_weights: Vec<[f64; 3]> = (0..bands)
            .map(|k| {
                let a = if k == 0 { first } else { lo + k as f64 * width };
                let b = if k + 1 == bands {
                    last
                } else {
                    lo + (k + 1) as f64 * width
                };
                integrated_colour_matching(a, b)
            })
            .collect();
        let flat_xyz = Self::sum(&xyz_weights, |_| 1.0);
        BandColour {
            wavelengths_nm: band_centres_nm(bands),
            xyz_weights,
            flat_rec709: xyz_to_rec709(flat_xyz),
        }
    }

    fn sum(weights: &[[f64; 3]], radiance: impl Fn(usize) -> f64) -> [f64; 3] {
        let mut xyz = [0.0; 3];
        for (k, w) in weights.iter().enumerate() {
            let l = radiance(k);
            for c in 0..3 {
                xyz[c] += w[c] * l;
            }
        }
        xyz
    }

    /// CIE XYZ of band radiances `radiance(k)` (unnormalised: a flat spectrum of 1 has
    /// Y = ∫ ȳ dλ ≈ 106.9).
    pub fn xyz(&self, radiance: impl Fn(usize) -> f64) -> [f64; 3] {
        Self::sum(&self.xyz_weights, radiance)
    }

    /// Normalised linear Rec.709 of band radiances `radiance(k)`: a flat spectrum of 1 gives
    /// (1, 1, 1).
    pub fn rec709(&self, radiance: impl Fn(usize) -> f64) -> [f64; 3] {
        let rgb = xyz_to_rec709(self.xyz(radiance));
        [0, 1, 2].map(|c| rgb[c] / self.flat_rec709[c])
    }
}

/// A spectral frame: its colour image and the bands it was made of.
#[derive(Debug, Clone, PartialEq)]
pub struct SpectralFilm {
    /// Linear Rec.709 (the RGB path's unit); its stats add up the bands' (the deepest fan
    /// level of any band).
    pub film: Film,
    /// The band centres (nm).
    pub wavelengths_nm: Vec<f64>,
    /// Each band's radiance, row-major like the film's pixels.
    pub bands: Vec<Vec<f32>>,
}

/// Render `scene` in `bands` wavelength bands (module documentation) through `atmosphere` (the
/// scene's, at any wavelength; `None` for straight rays).
pub fn render_spectral(
    scene: &Scene,
    atmosphere: Option<&RefractiveAtmosphere>,
    options: &RenderOptions,
    bands: u32,
) -> Result<SpectralFilm, SpectralError> {
    let colour = BandColour::new(bands);
    let mut band_images = Vec::with_capacity(bands as usize);
    let mut stats = RenderStats::default();
    let (mut width, mut height) = (scene.camera.width, scene.camera.height);
    for &wavelength_nm in &colour.wavelengths_nm {
        let band = render_band(scene, atmosphere, options, wavelength_nm)?;
        (width, height) = (band.width, band.height);
        add_stats(&mut stats, &band.stats);
        let w = rgb_weights(wavelength_nm);
        band_images.push(
            band.pixels
                .iter()
                .map(|p| (w[0] * p[0] as f64 + w[1] * p[1] as f64 + w[2] * p[2] as f64) as f32)
                .collect::<Vec<f32>>(),
        );
    }
    let pixels = (0..width as usize * height as usize)
        .map(|i| {
            let rgb = colour.rec709(|k| band_images[k][i] as f64);
            [rgb[0] as f32, rgb[1] as f32, rgb[2] as f32, 1.0]
        })
        .collect();
    Ok(SpectralFilm {
        film: Film {
            width,
            height,
            pixels,
            stats,
        },
        wavelengths_nm: colour.wavelengths_nm,
        bands: band_images,
    })
}

/// The frame at one wavelength: the index, the sky's scattering and extinction all at
/// `wavelength_nm` (the three channels then differ only by the RGB colours of the scene's
/// objects).
pub fn render_band(
    scene: &Scene,
    atmosphere: Option<&RefractiveAtmosphere>,
    options: &RenderOptions,
    wavelength_nm: f64,
) -> Result<Film, SpectralError> {
    let mut band_scene = scene.clone();
    band_scene.sky.channel_wavelengths_nm = [wavelength_nm; 3];
    band_scene.atmosphere.wavelength_nm = wavelength_nm;
    let refractive = match atmosphere {
        Some(a) if !scene.atmosphere.straight => Some(
            a.at_wavelength_nm(wavelength_nm)
                .map_err(|e| SpectralError::Prepare(PrepareError::Refractivity(e)))?,
        ),
        _ => None,
    };
    let tracer = prepare_tracer(&band_scene, refractive.as_ref(), options)?;
    Ok(super::render_scene(&band_scene, tracer.as_ref(), options)?)
}

fn add_stats(total: &mut RenderStats, band: &RenderStats) {
    total.fan_rays += band.fan_rays;
    total.fan_depth = total.fan_depth.max(band.fan_depth);
    total.sample_rays += band.sample_rays;
    total.non_finite_samples += band.non_finite_samples;
    total.cards_in_view = band.cards_in_view;
    total.sun_rays += band.sun_rays;
    total.air_path_rays += band.air_path_rays;
    total.sea_fan_rays += band.sea_fan_rays;
}

/// A spectral render failed.
#[derive(Debug, thiserror::Error)]
pub enum SpectralError {
    /// A band's tracer could not be prepared.
    #[error(transparent)]
    Prepare(#[from] PrepareError),
    /// A band could not be rendered.
    #[error(transparent)]
    Render(#[from] RenderError),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bands_tile_the_range_and_weights_sum_to_one() {
        let centres = band_centres_nm(8);
        assert_eq!(centres.len(), 8);
        assert!((centres[0] - 418.75).abs() < 1e-12 && (centres[7] - 681.25).abs() < 1e-12);
        for l in [380.0, 465.0, 500.0, 549.0, 580.0, 612.0, 700.0] {
            let w = rgb_weights(l);
            assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12, "{l}");
            assert!(w.iter().all(|&v| (0.0..=1.0).contains(&v)), "{l}");
        }
        assert_eq!(rgb_weights(549.0), [0.0, 1.0, 0.0]);
    }

    #[test]
    fn colour_matching_interpolates_the_table() {
        assert_eq!(colour_matching(550.0), [0.433450, 0.994950, 0.008750]);
        assert_eq!(colour_matching(379.0), [0.0; 3]);
        let m = colour_matching(555.0);
        assert!((m[1] - 0.9949750).abs() < 1e-9);
    }
}
