//! Output — a rendered film to a file. In: a [`Film`], a path whose extension picks the format
//! (`.exr`: linear f32 EXR with provenance; `.png`: 8-bit sRGB), provenance and exposure.
//! Out: the file, written atomically.

use std::path::Path;

use super::exr::{ExrError, ExrMetadata, encode_exr};
use super::png::encode_png;
use super::{WriteError, write_atomic};
use crate::render::Film;

/// An image file format for films: the one list of formats every command and pipeline uses.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum ImageFormat {
    /// OpenEXR, linear f32 RGBA.
    Exr,
    /// PNG, 8-bit sRGB.
    Png,
}

impl ImageFormat {
    /// The file extension, without the dot.
    pub fn extension(self) -> &'static str {
        match self {
            Self::Exr => "exr",
            Self::Png => "png",
        }
    }

    /// The format named by `path`'s extension (case-insensitive), if known.
    pub fn from_path(path: &Path) -> Option<Self> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "exr" => Some(Self::Exr),
            "png" => Some(Self::Png),
            _ => None,
        }
    }
}

/// A film could not be exported.
#[derive(Debug, thiserror::Error)]
pub enum FilmExportError {
    /// The extension names no supported format.
    #[error("{0}: unknown image format (use .exr or .png)")]
    UnknownFormat(std::path::PathBuf),
    /// EXR encoding failed.
    #[error(transparent)]
    Exr(#[from] ExrError),
    /// PNG encoding failed.
    #[error("cannot encode PNG: {0}")]
    Png(#[from] image::ImageError),
    /// Writing failed.
    #[error(transparent)]
    Write(#[from] WriteError),
}

/// Encode `film` in `format` (`exposure` applies to PNG only; EXR stays scene-linear).
pub fn encode_film(
    film: &Film,
    format: ImageFormat,
    meta: &ExrMetadata,
    exposure: f64,
) -> Result<Vec<u8>, FilmExportError> {
    Ok(match format {
        ImageFormat::Exr => encode_exr(film, meta)?,
        ImageFormat::Png => encode_png(film, exposure)?,
    })
}

/// Encode `film` once per format that `paths` name (PNG and EXR in parallel, `rayon::join`)
/// and write every path atomically; each format's files are written as soon as it is encoded.
/// Nothing is written if a path names no known format. The bytes do not depend on the thread
/// count. On failure the first error is returned (PNG's before EXR's), and the other format's
/// files may already be written.
pub fn write_films<P: AsRef<Path> + Sync>(
    film: &Film,
    paths: &[P],
    meta: &ExrMetadata,
    exposure: f64,
) -> Result<(), FilmExportError> {
    let mut by_format: [(ImageFormat, Vec<&Path>); 2] = [
        (ImageFormat::Png, Vec::new()),
        (ImageFormat::Exr, Vec::new()),
    ];
    for path in paths {
        let path = path.as_ref();
        let format = ImageFormat::from_path(path)
            .ok_or_else(|| FilmExportError::UnknownFormat(path.into()))?;
        let slot = by_format.iter_mut().find(|(f, _)| *f == format);
        if let Some((_, list)) = slot {
            list.push(path);
        }
    }
    let encode_and_write = |(format, paths): &(ImageFormat, Vec<&Path>)| {
        if paths.is_empty() {
            return Ok(());
        }
        let bytes = encode_film(film, *format, meta, exposure)?;
        for path in paths {
            write_atomic(path, &bytes)?;
        }
        Ok::<(), FilmExportError>(())
    };
    let (png, exr) = rayon::join(
        || encode_and_write(&by_format[0]),
        || encode_and_write(&by_format[1]),
    );
    png.and(exr)
}

/// Encode `film` in the format named by `path`'s extension and write it atomically.
pub fn write_film(
    film: &Film,
    path: &Path,
    meta: &ExrMetadata,
    exposure: f64,
) -> Result<(), FilmExportError> {
    let format =
        ImageFormat::from_path(path).ok_or_else(|| FilmExportError::UnknownFormat(path.into()))?;
    let bytes = encode_film(film, format, meta, exposure)?;
    write_atomic(path, &bytes)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn format_from_extension() {
        assert_eq!(
            ImageFormat::from_path(Path::new("a/b.EXR")),
            Some(ImageFormat::Exr)
        );
        assert_eq!(
            ImageFormat::from_path(Path::new("b.png")),
            Some(ImageFormat::Png)
        );
        assert_eq!(ImageFormat::from_path(Path::new("b.jpg")), None);
        assert_eq!(ImageFormat::from_path(Path::new("b")), None);
    }

    #[test]
    fn writes_both_formats_and_rejects_unknown_ones() {
        let film = Film {
            width: 3,
            height: 2,
            pixels: vec![[0.5, 0.25, 0.125, 1.0]; 6],
            stats: Default::default(),
        };
        let dir = tempfile::tempdir().unwrap();
        let meta = ExrMetadata::default();
        for name in ["x.exr", "x.png"] {
            let p = dir.path().join(name);
            write_film(&film, &p, &meta, 1.0).unwrap();
            assert!(std::fs::metadata(&p).unwrap().len() > 0);
        }
        let err = write_film(&film, &dir.path().join("x.tif"), &meta, 1.0).unwrap_err();
        assert!(err.to_string().contains("x.tif"));
    }

    #[test]
    fn write_films_writes_each_format_once_encoded_and_refuses_unknown_ones() {
        let film = Film {
            width: 4,
            height: 3,
            pixels: (0..12).map(|i| [i as f32 / 12.0, 0.5, 2.0, 1.0]).collect(),
            stats: Default::default(),
        };
        let dir = tempfile::tempdir().unwrap();
        let meta = ExrMetadata::default();
        let paths = [
            dir.path().join("a.png"),
            dir.path().join("b.exr"),
            dir.path().join("c.PNG"),
        ];
        write_films(&film, &paths, &meta, 0.85).unwrap();
        let png = encode_film(&film, ImageFormat::Png, &meta, 0.85).unwrap();
        let exr = encode_film(&film, ImageFormat::Exr, &meta, 0.85).unwrap();
        assert_eq!(std::fs::read(&paths[0]).unwrap(), png);
        assert_eq!(std::fs::read(&paths[1]).unwrap(), exr);
        assert_eq!(std::fs::read(&paths[2]).unwrap(), png);
        // An unknown extension anywhere: an error before anything is written.
        let more = [dir.path().join("d.png"), dir.path().join("e.tif")];
        let err = write_films(&film, &more, &meta, 0.85).unwrap_err();
        assert!(err.to_string().contains("e.tif"), "{err}");
        assert!(!more[0].exists());
    }

    #[test]
    fn a_film_with_the_wrong_pixel_count_is_an_error_not_a_panic() {
        // Film's fields are public: 3×2 declared, 5 pixels given (and an empty 0×0 film).
        let short = Film {
            width: 3,
            height: 2,
            pixels: vec![[0.5, 0.25, 0.125, 1.0]; 5],
            stats: Default::default(),
        };
        let empty = Film {
            width: 0,
            height: 0,
            pixels: Vec::new(),
            stats: Default::default(),
        };
        let meta = ExrMetadata::default();
        for film in [&short, &empty] {
            for format in [ImageFormat::Exr, ImageFormat::Png] {
                assert!(
                    encode_film(film, format, &meta, 1.0).is_err(),
                    "{format:?} {}x{}",
                    film.width,
                    film.height
                );
            }
        }
    }
}
