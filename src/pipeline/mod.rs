//! Pipeline — batch runs. In: a pipeline file (TOML) listing jobs. Out: a [`ResolvedPipeline`]
//! (validated, paths resolved against the pipeline file, defaults filled in) that the binary runs
//! job by job, writing every output under one folder (`out/<pipeline>/` unless told otherwise).
//!
//! ```toml
//! name = "paper"                      # optional; default: the file stem
//! [[render]]
//! scene = "../data/scenes/fig04_superior_mirage.toml"
//! name = "fig04_superior_mirage"      # optional; default: the scene file stem
//! sizes = ["400x200", "1920x1080"]    # optional; default: the scene's own size
//! formats = ["png", "exr"]            # optional; default: ["png", "exr"]
//! spp = 4                             # optional; default: the scene's samples per pixel
//! tolerance_m = 0.001                 # optional; the tracer's tolerance, default 1 mm
//! [[profile]]
//! atmosphere = "../data/superior_mirage.toml"
//! # optional on profile and trace jobs: wavelength_nm, smooth_m, and igra2_time = "YYYY-MM-DD HH"
//! # (which sounding of a multi-sounding IGRA2 file; default the first)
//! [[trace]]
//! atmosphere = "../data/superior_mirage.toml"
//! observer_height_m = 10.0
//! elevation_deg = "-0.3:0.5:0.002"
//! distances_m = [5000.0, 15000.0, 26000.0]
//! target_heights_m = [40.0]           # optional; default [20.0]
//! ```

use std::path::{Path, PathBuf};

use serde::Deserialize;

/// A pipeline file could not be used.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// The file could not be read.
    #[error("cannot read pipeline {path}: {source}")]
    Read {
        /// The pipeline file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The TOML is malformed or has unknown/mistyped fields (the message has line and column).
    #[error("invalid pipeline {path}: {source}")]
    Parse {
        /// The pipeline file.
        path: PathBuf,
        /// The TOML error, with line and column.
        #[source]
        source: toml::de::Error,
    },
    /// A value is out of range or inconsistent.
    #[error("invalid pipeline {path}: {what}")]
    Invalid {
        /// The pipeline file.
        path: PathBuf,
        /// What is wrong, naming the job and field.
        what: String,
    },
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PipelineFile {
    name: Option<String>,
    #[serde(default)]
    render: Vec<RenderJobFile>,
    #[serde(default)]
    profile: Vec<ProfileJobFile>,
    #[serde(default)]
    trace: Vec<TraceJobFile>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RenderJobFile {
    scene: PathBuf,
    name: Option<String>,
    sizes: Option<Vec<String>>,
    formats: Option<Vec<String>>,
    spp: Option<u32>,
    tolerance_m: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ProfileJobFile {
    atmosphere: String,
    name: Option<String>,
    wavelength_nm: Option<f64>,
    smooth_m: Option<f64>,
    igra2_time: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TraceJobFile {
    atmosphere: String,
    name: Option<String>,
    observer_height_m: f64,
    elevation_deg: String,
    distances_m: Vec<f64>,
    target_heights_m: Option<Vec<f64>>,
    wavelength_nm: Option<f64>,
    smooth_m: Option<f64>,
    tolerance_m: Option<f64>,
    igra2_time: Option<String>,
}

/// Image file formats a render job can write.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ImageFormat {
    /// 8-bit sRGB PNG.
    Png,
    /// Linear f32 OpenEXR.
    Exr,
}

/// A render job: one scene, rendered at one or more sizes into one or more formats.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RenderJob {
    /// Output base name (files are `<name>_<W>x<H>.<ext>`, or `<name>.<ext>` at the scene's size).
    pub name: String,
    /// Scene file, resolved against the pipeline file's folder.
    pub scene: PathBuf,
    /// Sizes (width, height) in pixels; empty means the scene's own size.
    pub sizes: Vec<(u32, u32)>,
    /// Formats to write.
    pub formats: Vec<ImageFormat>,
    /// Samples per pixel override.
    pub spp: Option<u32>,
    /// Tracer tolerance (m) override; default the renderer's 1 cm.
    pub tolerance_m: Option<f64>,
}

/// A profile job: the `profile` command's outputs for one atmosphere, into `<out>/<name>/`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ProfileJob {
    /// Output sub-folder name.
    pub name: String,
    /// Sounding file, synthetic TOML (resolved against the pipeline folder) or `us1976`.
    pub atmosphere: String,
    /// Wavelength (nm).
    pub wavelength_nm: Option<f64>,
    /// Smoothing scale (m).
    pub smooth_m: Option<f64>,
    /// Which sounding of a multi-sounding IGRA2 file (`"YYYY-MM-DD HH"`); `None`: the first.
    pub igra2_time: Option<String>,
}

/// A trace job: a transfer-characteristic fan, written as `<name>.json` and `<name>.png`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TraceJob {
    /// Output base name.
    pub name: String,
    /// Sounding file, synthetic TOML (resolved against the pipeline folder) or `us1976`.
    pub atmosphere: String,
    /// Observer height above the surface (m).
    pub observer_height_m: f64,
    /// Elevations in degrees, as `trace --elevation-deg` reads them: one value, an ascending
    /// comma-separated list or a fan `FROM:TO:STEP`.
    pub elevation_deg: String,
    /// Target ground distances (m).
    pub distances_m: Vec<f64>,
    /// Heights of the targets standing at every distance (m); default `[20.0]`.
    pub target_heights_m: Vec<f64>,
    /// Wavelength (nm).
    pub wavelength_nm: Option<f64>,
    /// Smoothing scale (m).
    pub smooth_m: Option<f64>,
    /// Integration tolerance (m).
    pub tolerance_m: Option<f64>,
    /// Which sounding of a multi-sounding IGRA2 file (`"YYYY-MM-DD HH"`); `None`: the first.
    pub igra2_time: Option<String>,
}

/// A validated pipeline with every path resolved.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ResolvedPipeline {
    /// Pipeline name (the default output folder is `out/<name>`).
    pub name: String,
    /// The pipeline file.
    pub source: PathBuf,
    /// Render jobs, in file order.
    pub renders: Vec<RenderJob>,
    /// Profile jobs, in file order.
    pub profiles: Vec<ProfileJob>,
    /// Trace jobs, in file order.
    pub traces: Vec<TraceJob>,
}

impl ResolvedPipeline {
    /// Read and resolve a pipeline file.
    pub fn from_file(path: &Path) -> Result<Self, PipelineError> {
        let text = std::fs::read_to_string(path).map_err(|source| PipelineError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_toml_str(&text, path)
    }

    /// Resolve a pipeline from its TOML text; `path` is where it came from (relative paths in the
    /// file are resolved against its folder).
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Self, PipelineError> {
        let file: PipelineFile = toml::from_str(text).map_err(|source| PipelineError::Parse {
            path: path.to_path_buf(),
            source,
        })?;
        let invalid = |what: String| PipelineError::Invalid {
            path: path.to_path_buf(),
            what,
        };
        let folder = path.parent().unwrap_or(Path::new("")).to_path_buf();
        let resolve_atmosphere = |a: &str| -> String {
            if a.eq_ignore_ascii_case("us1976") {
                "us1976".into()
            } else {
                folder.join(a).to_string_lossy().into_owned()
            }
        };
        let stem = |p: &Path| {
            p.file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "job".into())
        };
        let name = match file.name {
            Some(n) => n,
            None => stem(path),
        };
        check_name(&name).map_err(|e| invalid(format!("name: {e}")))?;
        if file.render.is_empty() && file.profile.is_empty() && file.trace.is_empty() {
            return Err(invalid(
                "no jobs: add at least one [[render]], [[profile]] or [[trace]] table".into(),
            ));
        }

        let mut renders = Vec::new();
        for (i, job) in file.render.into_iter().enumerate() {
            let at = format!("render job {} ({})", i + 1, job.scene.display());
            let name = job.name.unwrap_or_else(|| stem(&job.scene));
            check_name(&name).map_err(|e| invalid(format!("{at}: name: {e}")))?;
            let sizes = job
                .sizes
                .unwrap_or_default()
                .iter()
                .map(|s| parse_size(s).map_err(|e| invalid(format!("{at}: sizes: {e}"))))
                .collect::<Result<Vec<_>, _>>()?;
            let formats = match job.formats {
                None => vec![ImageFormat::Png, ImageFormat::Exr],
                Some(list) => list
                    .iter()
                    .map(|f| match f.to_ascii_lowercase().as_str() {
                        "png" => Ok(ImageFormat::Png),
                        "exr" => Ok(ImageFormat::Exr),
                        other => Err(invalid(format!(
                            "{at}: formats: unknown format {other:?} (expected \"png\" or \"exr\")"
                        ))),
                    })
                    .collect::<Result<Vec<_>, _>>()?,
            };
            if formats.is_empty() {
                return Err(invalid(format!("{at}: formats is empty")));
            }
            if let Some(spp) = job.spp
                && crate::scene::samples_per_pixel_root(spp).is_none()
            {
                return Err(invalid(format!(
                    "{at}: spp must be a square number (1, 4, 9, 16, …, {}), got {spp}",
                    crate::scene::MAX_SAMPLES_PER_PIXEL
                )));
            }
            if let Some(t) = job.tolerance_m
                && crate::render::check_tracer_tolerance(t).is_err()
            {
                let (lo, hi) = crate::render::TRACER_TOLERANCE_RANGE_M;
                return Err(invalid(format!(
                    "{at}: tolerance_m must be a finite number of metres from {lo:e} to {hi}, got {t}"
                )));
            }
            renders.push(RenderJob {
                name,
                scene: folder.join(&job.scene),
                sizes,
                formats,
                spp: job.spp,
                tolerance_m: job.tolerance_m,
            });
        }

        let mut profiles = Vec::new();
        for (i, job) in file.profile.into_iter().enumerate() {
            let at = format!("profile job {} ({})", i + 1, job.atmosphere);
            let name = job.name.unwrap_or_else(|| stem(Path::new(&job.atmosphere)));
            check_name(&name).map_err(|e| invalid(format!("{at}: name: {e}")))?;
            profiles.push(ProfileJob {
                name,
                atmosphere: resolve_atmosphere(&job.atmosphere),
                wavelength_nm: job.wavelength_nm,
                smooth_m: job.smooth_m,
                igra2_time: job.igra2_time,
            });
        }

        let mut traces = Vec::new();
        for (i, job) in file.trace.into_iter().enumerate() {
            let at = format!("trace job {} ({})", i + 1, job.atmosphere);
            let name = job
                .name
                .unwrap_or_else(|| format!("{}_transfer", stem(Path::new(&job.atmosphere))));
            check_name(&name).map_err(|e| invalid(format!("{at}: name: {e}")))?;
            if !(job.observer_height_m.is_finite() && job.observer_height_m >= 0.0) {
                return Err(invalid(format!(
                    "{at}: observer_height_m must be a finite height ≥ 0 m"
                )));
            }
            if job.distances_m.iter().any(|d| !(d.is_finite() && *d > 0.0)) {
                return Err(invalid(format!("{at}: distances_m must be finite and > 0")));
            }
            let target_heights_m = job.target_heights_m.unwrap_or_else(|| vec![20.0]);
            if target_heights_m
                .iter()
                .any(|h| !(h.is_finite() && *h > 0.0))
            {
                return Err(invalid(format!(
                    "{at}: target_heights_m must be finite and > 0"
                )));
            }
            traces.push(TraceJob {
                name,
                atmosphere: resolve_atmosphere(&job.atmosphere),
                observer_height_m: job.observer_height_m,
                elevation_deg: job.elevation_deg,
                distances_m: job.distances_m,
                target_heights_m,
                wavelength_nm: job.wavelength_nm,
                smooth_m: job.smooth_m,
                tolerance_m: job.tolerance_m,
                igra2_time: job.igra2_time,
            });
        }

        let mut seen = std::collections::BTreeSet::new();
        for n in renders
            .iter()
            .map(|r| &r.name)
            .chain(profiles.iter().map(|p| &p.name))
            .chain(traces.iter().map(|t| &t.name))
        {
            if !seen.insert(n.clone()) {
                return Err(invalid(format!(
                    "two jobs are named {n:?}; give one of them another `name`"
                )));
            }
        }

        Ok(ResolvedPipeline {
            name,
            source: path.to_path_buf(),
            renders,
            profiles,
            traces,
        })
    }
}

/// Parse `"400x200"` into (400, 200).
pub fn parse_size(text: &str) -> Result<(u32, u32), String> {
    let (w, h) = text
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("{text:?} is not WIDTHxHEIGHT (e.g. \"400x200\")"))?;
    let parse = |s: &str| {
        s.trim()
            .parse::<u32>()
            .ok()
            .filter(|v| (1..=16384).contains(v))
            .ok_or_else(|| format!("{text:?}: {s:?} is not a size from 1 to 16384 pixels"))
    };
    Ok((parse(w)?, parse(h)?))
}

fn check_name(name: &str) -> Result<(), String> {
    if name.is_empty()
        || !name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'))
        || name.starts_with('.')
    {
        return Err(format!(
            "{name:?} must be a plain file name (letters, digits, '_', '-', '.')"
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resolves_paths_and_defaults() {
        let text = r#"
[[render]]
scene = "../data/scenes/a.toml"
sizes = ["400x200", "1920x1080"]
[[trace]]
atmosphere = "us1976"
observer_height_m = 10
elevation_deg = "-0.5:0.5:0.01"
distances_m = [1000.0]
"#;
        let p = ResolvedPipeline::from_toml_str(text, Path::new("pipelines/paper.toml")).unwrap();
        assert_eq!(p.name, "paper");
        assert_eq!(
            p.renders[0].scene,
            Path::new("pipelines/../data/scenes/a.toml")
        );
        assert_eq!(p.renders[0].name, "a");
        assert_eq!(p.renders[0].sizes, vec![(400, 200), (1920, 1080)]);
        assert_eq!(
            p.renders[0].formats,
            vec![ImageFormat::Png, ImageFormat::Exr]
        );
        assert_eq!(p.renders[0].tolerance_m, None);
        assert_eq!(p.traces[0].atmosphere, "us1976");
        assert_eq!(p.traces[0].name, "us1976_transfer");
        assert_eq!(p.traces[0].target_heights_m, vec![20.0]);
    }

    #[test]
    fn render_jobs_take_a_tracer_tolerance() {
        let text = "[[render]]\nscene = \"a.toml\"\ntolerance_m = 0.05\n";
        let p = ResolvedPipeline::from_toml_str(text, Path::new("p.toml")).unwrap();
        assert_eq!(p.renders[0].tolerance_m, Some(0.05));
        // A misspelt key is refused like every other unknown key.
        let text = "[[render]]\nscene = \"a.toml\"\ntolerance = 0.05\n";
        let err = ResolvedPipeline::from_toml_str(text, Path::new("p.toml")).unwrap_err();
        let msg = format!("{err}: {}", std::error::Error::source(&err).unwrap());
        assert!(msg.contains("tolerance"), "{msg}");
    }

    #[test]
    fn unknown_field_names_line_and_column() {
        let text = "[[render]]\nscene = \"a.toml\"\nsize = [\"1x1\"]\n";
        let err = ResolvedPipeline::from_toml_str(text, Path::new("p.toml")).unwrap_err();
        let msg = format!("{err}: {}", std::error::Error::source(&err).unwrap());
        assert!(msg.contains("p.toml"), "{msg}");
        assert!(msg.contains("line 3"), "{msg}");
        assert!(msg.contains("size"), "{msg}");
    }

    #[test]
    fn rejects_bad_values() {
        for (text, needle) in [
            (
                "[[render]]\nscene = \"a.toml\"\nsizes = [\"400*200\"]\n",
                "WIDTHxHEIGHT",
            ),
            (
                "[[render]]\nscene = \"a.toml\"\nformats = [\"jpg\"]\n",
                "unknown format",
            ),
            ("[[render]]\nscene = \"a.toml\"\nspp = 0\n", "spp"),
            ("[[render]]\nscene = \"a.toml\"\nspp = 3\n", "square"),
            ("[[render]]\nscene = \"a.toml\"\nspp = 4096\n", "square"),
            (
                "[[render]]\nscene = \"a.toml\"\ntolerance_m = 0\n",
                "tolerance_m",
            ),
            (
                "[[render]]\nscene = \"a.toml\"\ntolerance_m = 100.0\n",
                "tolerance_m",
            ),
            (
                "[[render]]\nscene = \"a.toml\"\ntolerance_m = nan\n",
                "tolerance_m",
            ),
            (
                "name = \"../x\"\n[[render]]\nscene = \"a.toml\"\n",
                "plain file name",
            ),
            ("name = \"x\"\n", "no jobs"),
            (
                "[[trace]]\natmosphere = \"us1976\"\nobserver_height_m = 1\nelevation_deg = \"0:1:0.1\"\ndistances_m = [1.0]\ntarget_heights_m = [0.0]\n",
                "target_heights_m",
            ),
            (
                "[[render]]\nscene = \"a.toml\"\n[[render]]\nscene = \"b/a.toml\"\n",
                "two jobs",
            ),
        ] {
            let err = ResolvedPipeline::from_toml_str(text, Path::new("p.toml")).unwrap_err();
            assert!(err.to_string().contains(needle), "{text}: {err}");
        }
    }

    #[test]
    fn size_parsing() {
        assert_eq!(parse_size("1920x1080").unwrap(), (1920, 1080));
        assert!(parse_size("0x10").is_err());
        assert!(parse_size("axb").is_err());
    }
}
