//! Stage 5c — render a sun sweep. In: a [`Scene`] with a sun, its [`RayTracer`], render options
//! and a list of true sun elevations. Out: one [`SunFrame`] per elevation — the [`Film`] that
//! [`render_scene`] gives for the scene with the sun there, and the sun's [`SunFacts`] read
//! from the traced map.
//!
//! **What is shared.** Moving the sun changes neither the camera, nor the atmosphere, nor the
//! cards: every ray from the camera is the same ray in every frame. The frames are rendered
//! through one [`MemoRays`], so each ray (of the elevation fan, of the sun's transmittance, of
//! the sea's reflections and glitter, of the haze) is traced once for the whole sweep and
//! looked up by every later frame. Each frame still builds its own fan (refined around its own
//! sun, from remembered rays) and shades every pixel, so it is bit for bit the frame a single
//! render of that sun position gives. The union of the frames' fans is the fan widened to the
//! whole sweep, traced once. The first frame is rendered alone (its fan is traced in parallel),
//! then the others in parallel, each frame on its own: the films do not depend on the thread
//! count.
//!
//! **Facts from the traced map.** [`SunFacts`] come from the rays through the pixel centres of
//! one column — the column through the sun's azimuth on the middle row, or the centre column
//! when the sun's azimuth is outside the frame: a row *shows the sun* when its ray leaves the
//! atmosphere in a direction inside the sun's disc (cards, terrain and extinction are not
//! considered: a sun dimmed to nothing still counts). Strips are the maximal runs of
//! consecutive rows that show it.

use rayon::prelude::*;

use super::memo::MemoRays;
use super::ray_model::{FanEnd, RayTracer};
use super::shade::wrap_pi;
use super::{Film, RenderError, RenderOptions, render_scene};
use crate::scene::{Scene, Sun};

/// What the traced map says of the sun in one frame, along the column of [`sun_column`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SunFacts {
    /// Apparent elevation (rad) of the pixel centre of the lowest row that shows the sun.
    pub apparent_low_rad: Option<f64>,
    /// Apparent elevation (rad) of the pixel centre of the highest row that shows the sun.
    pub apparent_high_rad: Option<f64>,
    /// Number of separate runs of rows that show the sun (0 when none does).
    pub strips: usize,
}

/// One frame of a sun sweep.
#[derive(Debug, Clone)]
pub struct SunFrame {
    /// The sun's true elevation (rad) in this frame.
    pub sun_elevation_rad: f64,
    /// The image: the same as [`render_scene`] of the scene with the sun at that elevation.
    pub film: Film,
    /// The sun in the traced map.
    pub facts: SunFacts,
}

/// The column whose facts [`SunFacts`] reports: the one whose pixel centre on the middle row is
/// nearest the sun's azimuth, when that azimuth lies between the first and last columns' on
/// that row; otherwise the centre column.
pub fn sun_column(scene: &Scene, sun: &Sun) -> u32 {
    let cam = &scene.camera;
    let frame = cam.frame();
    let y = 0.5 * cam.height as f64;
    let offset = |x: u32| wrap_pi(frame.direction(x as f64 + 0.5, y).0 - sun.azimuth_rad);
    let (first, last) = (offset(0), offset(cam.width - 1));
    if first.min(last) > 0.0 || first.max(last) < 0.0 {
        return cam.width / 2;
    }
    (0..cam.width)
        .min_by(|&a, &b| offset(a).abs().total_cmp(&offset(b).abs()))
        .unwrap_or(cam.width / 2)
}

/// The sun's facts in `scene` (which has `sun`) along column `x`, from rays traced through
/// `tracer` (need_sky_direction: their final directions).
pub fn sun_facts(scene: &Scene, sun: &Sun, tracer: &dyn RayTracer, x: u32) -> SunFacts {
    let cam = &scene.camera;
    let frame = cam.frame();
    let radius = 0.5 * sun.angular_diameter_rad;
    let mut facts = SunFacts {
        apparent_low_rad: None,
        apparent_high_rad: None,
        strips: 0,
    };
    let mut previous = false;
    // Top row first: the first row that shows the sun is the highest.
    for y in 0..cam.height {
        let (fx, fy) = (x as f64 + 0.5, y as f64 + 0.5);
        let alpha = frame.view_direction(fx, fy).elevation_rad;
        let azimuth = frame.direction(fx, fy).0;
        let shows = match tracer.trace(cam.height_m, alpha, &[], true).end {
            FanEnd::Sky { elevation_rad } => {
                angle_between(azimuth, elevation_rad, sun.azimuth_rad, sun.elevation_rad) <= radius
            }
            _ => false,
        };
        if shows {
            facts.apparent_high_rad.get_or_insert(alpha);
            facts.apparent_low_rad = Some(alpha);
            if !previous {
                facts.strips += 1;
            }
        }
        previous = shows;
    }
    facts
}

/// Great-circle angle (rad) between two directions given as (azimuth, elevation), by the
/// haversine formula (accurate for the small angles of a sun's disc).
fn angle_between(az1: f64, el1: f64, az2: f64, el2: f64) -> f64 {
    let s_el = (0.5 * (el1 - el2)).sin();
    let s_az = (0.5 * (az1 - az2)).sin();
    let h = s_el * s_el + el1.cos() * el2.cos() * s_az * s_az;
    2.0 * h.sqrt().min(1.0).asin()
}

/// Render `scene` once per true sun elevation in `sun_elevations_rad` (module docs: the rays
/// are traced once for the whole sweep). Errors if the scene has no sun, an elevation is
/// outside −90°…90°, or a frame cannot be rendered.
pub fn render_sun_sweep(
    scene: &Scene,
    tracer: &dyn RayTracer,
    options: &RenderOptions,
    sun_elevations_rad: &[f64],
) -> Result<Vec<SunFrame>, RenderError> {
    let sun = scene.sun.ok_or(RenderError::NoSun)?;
    let half_pi = std::f64::consts::FRAC_PI_2;
    if let Some(&bad) = sun_elevations_rad
        .iter()
        .find(|e| !(e.is_finite() && e.abs() <= half_pi))
    {
        return Err(RenderError::SunElevation(bad));
    }
    let memo = MemoRays::new(tracer);
    let column = sun_column(scene, &sun);
    let render_one = |elevation_rad: f64| -> Result<SunFrame, RenderError> {
        let sun = Sun {
            elevation_rad,
            ..sun
        };
        let mut frame_scene = scene.clone();
        frame_scene.sun = Some(sun);
        let film = render_scene(&frame_scene, &memo, options)?;
        let facts = sun_facts(&frame_scene, &sun, &memo, column);
        Ok(SunFrame {
            sun_elevation_rad: elevation_rad,
            film,
            facts,
        })
    };
    let Some((&first, rest)) = sun_elevations_rad.split_first() else {
        return Ok(Vec::new());
    };
    let mut frames = vec![render_one(first)?];
    let rest: Vec<SunFrame> = rest
        .par_iter()
        .map(|&e| render_one(e))
        .collect::<Result<_, _>>()?;
    frames.extend(rest);
    Ok(frames)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn haversine_angle_matches_simple_cases() {
        let d = 1e-3;
        assert!((angle_between(0.0, 0.0, 0.0, d) - d).abs() < 1e-15);
        assert!((angle_between(0.0, 0.0, d, 0.0) - d).abs() < 1e-12);
        // At elevation 60° an azimuth step is shortened by cos 60°.
        let e = 60f64.to_radians();
        assert!((angle_between(0.0, e, d, e) - 0.5 * d).abs() < 1e-9);
    }
}
