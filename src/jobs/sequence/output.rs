//! Jobs — sequence: what the frames become besides numbered images. In: the planned frames and
//! the rendered ones. Out: `frames.csv`, `sequence.gif`, `sequence.mp4` (through an `ffmpeg`
//! found on the PATH; never a dependency), and the figures `sun.png` and `transfer.png`.

use std::ffi::OsString;
use std::path::{Path, PathBuf};

use super::{FramePlan, SweepSpec};
use crate::jobs::{JobError, Product};
use crate::render::sweep::{SweepFrame, TransferSamples};
use crate::render::sweep_plot::{SunSeries, sun_sweep_png, transfer_png};
use crate::scene::{Card, Scene};

/// Display time of one frame of `sequence.gif` and `sequence.mp4` (ms).
pub const GIF_FRAME_MS: u32 = 80;

/// `frames.csv`: per frame its index, the swept values (`columns`), and the facts of the traced
/// map: when the scene has a sun its apparent band (degrees, empty when no row shows it) and
/// number of strips; per card (`card0_…`, in scene order) its number of images and their
/// apparent band (all empty when the card's centre is outside the frame).
pub fn frames_csv(columns: &[String], plans: &[FramePlan], frames: &[SweepFrame]) -> String {
    let mut header = vec!["frame".to_string()];
    header.extend(columns.iter().cloned());
    let with_sun = frames.first().is_some_and(|f| f.facts.sun.is_some());
    if with_sun {
        header.extend(
            [
                "sun_apparent_low_deg",
                "sun_apparent_high_deg",
                "sun_strips",
            ]
            .map(String::from),
        );
    }
    let cards = frames.first().map_or(0, |f| f.facts.cards.len());
    for i in 0..cards {
        header.extend([
            format!("card{i}_images"),
            format!("card{i}_apparent_low_deg"),
            format!("card{i}_apparent_high_deg"),
        ]);
    }
    let degrees = |v: Option<f64>| v.map_or_else(String::new, |r| format!("{:.6}", r.to_degrees()));
    let mut text = header.join(",");
    text.push('\n');
    for (i, (plan, frame)) in plans.iter().zip(frames).enumerate() {
        let mut row = vec![i.to_string()];
        row.extend(plan.values.iter().cloned());
        if let Some(sun) = frame.facts.sun.filter(|_| with_sun) {
            row.extend([
                degrees(sun.apparent_low_rad),
                degrees(sun.apparent_high_rad),
                sun.strips.to_string(),
            ]);
        }
        for card in frame.facts.cards.iter().take(cards) {
            match card {
                Some(c) => row.extend([
                    c.images.to_string(),
                    degrees(c.apparent_low_rad),
                    degrees(c.apparent_high_rad),
                ]),
                None => row.extend([String::new(), String::new(), String::new()]),
            }
        }
        text.push_str(&row.join(","));
        text.push('\n');
    }
    text
}

/// An animated GIF of `frames`, each 8-bit sRGB RGB of `width` × `height` pixels (one palette
/// of 256 colours for all frames, [`GIF_FRAME_MS`] per frame, looping; `crate::output::gif`).
pub fn encode_gif(frames: &[Vec<u8>], width: u32, height: u32) -> Result<Vec<u8>, JobError> {
    Ok(crate::output::gif::encode_animation(
        frames,
        width,
        height,
        GIF_FRAME_MS,
    )?)
}

/// The first executable file `name` in the folders of the PATH environment variable.
pub fn find_on_path(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .filter(|dir| !dir.as_os_str().is_empty())
        .map(|dir| dir.join(name))
        .find(|candidate| is_executable(candidate))
}

#[cfg(unix)]
fn is_executable(path: &Path) -> bool {
    use std::os::unix::fs::PermissionsExt;
    std::fs::metadata(path).is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
}

#[cfg(not(unix))]
fn is_executable(path: &Path) -> bool {
    path.is_file()
}

/// The arguments `ffmpeg` is run with to join `folder`'s `frame_%04d.png` into `out`: H.264 in
/// yuv420p (even sides: an odd width or height loses its last column or row), at
/// 1000 / [`GIF_FRAME_MS`] frames per second, one thread and bit-exact flags so that the same
/// ffmpeg writes the same bytes, no metadata.
pub fn ffmpeg_args(folder: &Path, out: &Path) -> Vec<OsString> {
    let mut args: Vec<OsString> = ["-nostdin", "-y", "-loglevel", "error", "-framerate"]
        .map(OsString::from)
        .to_vec();
    args.push(format!("1000/{GIF_FRAME_MS}").into());
    args.push("-i".into());
    args.push(folder.join("frame_%04d.png").into_os_string());
    for a in [
        "-vf",
        "crop=trunc(iw/2)*2:trunc(ih/2)*2:0:0",
        "-c:v",
        "libx264",
        "-crf",
        "18",
        "-pix_fmt",
        "yuv420p",
        "-threads",
        "1",
        "-map_metadata",
        "-1",
        "-fflags",
        "+bitexact",
        "-flags:v",
        "+bitexact",
    ] {
        args.push(a.into());
    }
    args.push(out.as_os_str().to_owned());
    args
}

/// `sequence.mp4` of the PNG frames `pngs` (in order) through the `ffmpeg` on the PATH; `None`
/// (with a note on stderr) when there is none. A failing ffmpeg is an error with its message.
pub fn encode_mp4(pngs: &[Product]) -> Result<Option<Vec<u8>>, JobError> {
    let Some(ffmpeg) = find_on_path("ffmpeg") else {
        eprintln!(
            "note: ffmpeg is not on the PATH: sequence.mp4 not written (the frames and \
             sequence.gif are complete)"
        );
        return Ok(None);
    };
    let failed = |m: String| JobError::Invalid(format!("ffmpeg ({}): {m}", ffmpeg.display()));
    let folder = scratch_folder().map_err(|e| failed(e.to_string()))?;
    let result = (|| {
        for (i, png) in pngs.iter().enumerate() {
            std::fs::write(folder.join(super::frame_name(i)), &png.bytes)
                .map_err(|e| failed(e.to_string()))?;
        }
        let out = folder.join("sequence.mp4");
        let run = std::process::Command::new(&ffmpeg)
            .args(ffmpeg_args(&folder, &out))
            .stdin(std::process::Stdio::null())
            .output()
            .map_err(|e| failed(e.to_string()))?;
        if !run.status.success() {
            return Err(failed(format!(
                "{}: {}",
                run.status,
                String::from_utf8_lossy(&run.stderr).trim()
            )));
        }
        std::fs::read(&out).map_err(|e| failed(e.to_string()))
    })();
    // The scratch folder goes whatever happened.
    let _ = std::fs::remove_dir_all(&folder);
    result.map(Some)
}

/// A new empty folder under the system's temporary folder.
fn scratch_folder() -> std::io::Result<PathBuf> {
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    let name = format!(
        "ghostship-mp4-{}-{nanos}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    );
    let folder = std::env::temp_dir().join(name);
    std::fs::create_dir(&folder)?;
    Ok(folder)
}

/// `sun.png` of a sweep that moves the sun: against the true elevation for an elevation sweep,
/// against time for a sweep over time.
pub fn sun_plot(
    sweep: &SweepSpec,
    plans: &[FramePlan],
    frames: &[SweepFrame],
    scene: &Scene,
    name: &str,
) -> Result<Vec<u8>, JobError> {
    let true_deg: Vec<f64> = plans
        .iter()
        .map(|p| {
            p.scene
                .sun
                .map_or(f64::NAN, |s| s.elevation_rad.to_degrees())
        })
        .collect();
    let (x, x_desc) = match sweep {
        SweepSpec::SunTime { span, .. } => (
            (0..plans.len())
                .map(|i| (i as i64 * span.step_s) as f64 / 60.0)
                .collect(),
            format!("minutes after {}", span.from),
        ),
        _ => (
            true_deg.clone(),
            "true elevation of the sun's centre (deg)".into(),
        ),
    };
    let series = SunSeries {
        x,
        x_desc,
        true_deg,
        facts: frames
            .iter()
            .map(|f| {
                f.facts.sun.unwrap_or(crate::render::sweep::SunFacts {
                    apparent_low_rad: None,
                    apparent_high_rad: None,
                    strips: 0,
                })
            })
            .collect(),
        camera_height_m: scene.camera.height_m,
        earth_radius_m: scene.earth_radius_m,
        title: format!("The sun through {name}"),
    };
    sun_sweep_png(&series).map_err(|e| JobError::Plot(format!("sun.png: {e}")))
}

/// `transfer.png` of an observer sweep: each frame's transfer curve at `card`'s distance.
pub fn transfer_plot(frames: &[SweepFrame], card: &Card, name: &str) -> Result<Vec<u8>, JobError> {
    let curves: Vec<&TransferSamples> = frames.iter().filter_map(|f| f.transfer.as_ref()).collect();
    let title = format!(
        "Transfer curves at {:.1} km through {name}, one per observer height",
        card.distance_m / 1000.0
    );
    transfer_png(&curves, (card.base_m, card.base_m + card.height_m), &title)
        .map_err(|e| JobError::Plot(format!("transfer.png: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ffmpeg_joins_the_numbered_frames_at_the_gif_rate_into_even_sized_h264() {
        let args: Vec<String> = ffmpeg_args(Path::new("/tmp/f"), Path::new("/tmp/f/s.mp4"))
            .into_iter()
            .map(|a| a.into_string().unwrap())
            .collect();
        let after = |flag: &str| {
            let i = args.iter().position(|a| a == flag).unwrap();
            args[i + 1].as_str()
        };
        assert_eq!(after("-framerate"), "1000/80");
        assert_eq!(after("-i"), "/tmp/f/frame_%04d.png");
        assert_eq!(after("-c:v"), "libx264");
        assert_eq!(after("-pix_fmt"), "yuv420p");
        assert_eq!(after("-threads"), "1");
        assert!(after("-vf").starts_with("crop=trunc(iw/2)*2:trunc(ih/2)*2"));
        assert_eq!(args.last().unwrap(), "/tmp/f/s.mp4");
        // No question is ever asked: overwrite, no standard input.
        assert!(args.contains(&"-y".to_string()) && args.contains(&"-nostdin".to_string()));
    }
}
