//! Output — OpenEXR exporter. In: a [`Film`] (linear f32 RGBA) and provenance. Out: the bytes of
//! an EXR file: linear Rec.709 primaries with D65 white (the `chromaticities` attribute), f32 RGBA,
//! ZIP compression (blocks of 16 scan lines) in increasing line order, so the same film gives
//! byte-identical files whatever the thread count.
//!
//! The `exr` crate writes the header and the offset table; the blocks are prepared and
//! compressed here, in parallel on rayon's pool, straight from the film: OpenEXR's ZIP predictor
//! (bytes split into even and odd halves, then byte differences + 128, written in one pass per
//! half) and zlib-rs at [`ZIP_LEVEL`], its fastest level (why this level and this zlib, with
//! the measurements: docs/exr_compression.md). A block that does not shrink is stored raw, as
//! the format asks.
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

/// zlib level of the ZIP blocks (zlib-rs's fastest level: `deflate_quick`, one hash probe and
/// the fixed Huffman code).
pub const ZIP_LEVEL: i32 = 1;

/// The uncompressed bytes of one scan-line block (lines `y0..y0 + lines`), split into
/// OpenEXR's even/odd halves (`sep`), and the predicted bytes (`out`) that zlib compresses.
/// `channels[k]` is the film channel (0 R, 1 G, 2 B, 3 A) of the header's k-th channel. Every
/// byte of both buffers is written, so they are only resized (zeroed) when the block size
/// changes.
fn predicted_block(
    film: &Film,
    channels: &[usize],
    y0: usize,
    lines: usize,
    sep: &mut Vec<u8>,
    out: &mut Vec<u8>,
) {
    let w = film.width as usize;
    let n = lines * w * channels.len() * 4;
    for buffer in [&mut *sep, &mut *out] {
        if buffer.len() != n {
            buffer.clear();
            buffer.resize(n, 0);
        }
    }
    // Raw little-endian f32 samples b0 b1 b2 b3 per sample, line by line, channel by channel;
    // the even-indexed bytes (b0, b2) go to the first half, the odd ones (b1, b3) to the second.
    let (first, second) = sep.split_at_mut(n / 2);
    let mut pairs = first.chunks_exact_mut(2).zip(second.chunks_exact_mut(2));
    for row in film.pixels[y0 * w..(y0 + lines) * w].chunks_exact(w) {
        for &c in channels {
            for (p, (even, odd)) in row.iter().zip(pairs.by_ref()) {
                let b = p[c].to_le_bytes();
                even.copy_from_slice(&[b[0], b[2]]);
                odd.copy_from_slice(&[b[1], b[3]]);
            }
        }
    }
    out[0] = sep[0];
    for (o, pair) in out[1..].iter_mut().zip(sep.windows(2)) {
        *o = pair[1].wrapping_sub(pair[0]).wrapping_add(128);
    }
}

/// The raw little-endian bytes of a block (stored when compression does not shrink it).
fn raw_block(film: &Film, channels: &[usize], y0: usize, lines: usize) -> Vec<u8> {
    let w = film.width as usize;
    let mut raw = Vec::with_capacity(lines * w * channels.len() * 4);
    for row in film.pixels[y0 * w..(y0 + lines) * w].chunks_exact(w) {
        for &c in channels {
            for p in row {
                raw.extend_from_slice(&p[c].to_le_bytes());
            }
        }
    }
    raw
}

/// Blocks compressed one after another by one task (one encoder's buffers and zlib state):
/// enough to share them, few enough to keep both cores busy to the end.
const BLOCKS_PER_TASK: usize = 4;

/// One task's block encoder: the split and predicted bytes, zlib's output and its state, all
/// reused from block to block (a reset stream compresses exactly as a new one).
struct BlockEncoder {
    split: Vec<u8>,
    predicted: Vec<u8>,
    zlib: Vec<u8>,
    deflate: zlib_rs::Deflate,
}

impl BlockEncoder {
    fn new() -> Self {
        BlockEncoder {
            split: Vec::new(),
            predicted: Vec::new(),
            zlib: Vec::new(),
            deflate: zlib_rs::Deflate::new(ZIP_LEVEL, true, 15),
        }
    }

    /// The stored bytes of one ZIP block: zlib (RFC 1950, [`ZIP_LEVEL`]) of the predicted
    /// bytes, or the raw bytes when that is not smaller.
    fn zip_block(&mut self, film: &Film, channels: &[usize], y0: usize, lines: usize) -> Vec<u8> {
        let n = lines * film.width as usize * channels.len() * 4;
        predicted_block(
            film,
            channels,
            y0,
            lines,
            &mut self.split,
            &mut self.predicted,
        );
        // Room for a stream as long as the input: one that does not fit is not wanted either.
        if self.zlib.len() < n {
            self.zlib.resize(n, 0);
        }
        self.deflate.reset();
        let status = self.deflate.compress(
            &self.predicted,
            &mut self.zlib[..n],
            zlib_rs::DeflateFlush::Finish,
        );
        let written = self.deflate.total_out() as usize;
        match status {
            Ok(zlib_rs::Status::StreamEnd) if written < n => self.zlib[..written].to_vec(),
            _ => raw_block(film, channels, y0, lines),
        }
    }
}

/// Encode `film` as an EXR file (bytes).
///
/// A film whose pixel count is not width × height (its fields are public) is an error, not a
/// panic.
pub fn encode_exr(film: &Film, meta: &ExrMetadata) -> Result<Vec<u8>, ExrError> {
    use exr::block::chunk::{Chunk, CompressedBlock, CompressedScanLineBlock};
    use exr::block::writer::ChunksWriter;
    use exr::meta::attribute::SampleType;
    use rayon::prelude::*;

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
    // The layer describes the channels (f32 R, G, B, A) for the header; its pixels are never
    // read: the blocks are built below.
    let layer = Layer::new(
        (w, h),
        attrs,
        Encoding::SMALL_LOSSLESS,
        SpecificChannels::rgba(|_: Vec2<usize>| (0.0f32, 0.0f32, 0.0f32, 0.0f32)),
    );
    let mut image = Image::from_layer(layer);
    image.attributes.chromaticities = Some(Chromaticities {
        red: Vec2(0.64, 0.33),
        green: Vec2(0.30, 0.60),
        blue: Vec2(0.15, 0.06),
        white: Vec2(0.3127, 0.3290),
    });
    let headers = image.write().infer_meta_data();
    let header = &headers[0];
    let lines_per_block = header.compression.scan_lines_per_block();
    // The header lists the channels sorted by name (A, B, G, R); blocks follow that order.
    let channels = header
        .channels
        .list
        .iter()
        .map(|c| {
            let index = match c.name.to_string().as_str() {
                "R" => 0,
                "G" => 1,
                "B" => 2,
                "A" => 3,
                other => return Err(format!("unexpected channel {other:?}")),
            };
            if c.sample_type != SampleType::F32 {
                return Err(format!("channel {} is not f32", c.name));
            }
            Ok(index)
        })
        .collect::<Result<Vec<usize>, String>>()
        .map_err(|e| ExrError(exr::error::Error::Invalid(e.into())))?;
    // Every block compressed independently, in parallel; written in order below.
    let starts: Vec<usize> = (0..h).step_by(lines_per_block).collect();
    let blocks: Vec<Vec<u8>> = starts
        .par_chunks(BLOCKS_PER_TASK)
        .flat_map_iter(|group| {
            let mut encoder = BlockEncoder::new();
            group
                .iter()
                .map(|&y0| encoder.zip_block(film, &channels, y0, lines_per_block.min(h - y0)))
                .collect::<Vec<_>>()
        })
        .collect();
    let mut out = Cursor::new(Vec::new());
    exr::block::write(&mut out, headers.clone(), true, |_meta, writer| {
        for (index, (y0, bytes)) in starts.iter().zip(blocks).enumerate() {
            let y_coordinate = i32::try_from(*y0).map_err(|_| {
                exr::error::Error::Invalid("image too tall for EXR line numbers".into())
            })?;
            writer.write_chunk(
                index,
                Chunk {
                    layer_index: 0,
                    compressed_block: CompressedBlock::ScanLine(CompressedScanLineBlock {
                        y_coordinate,
                        compressed_pixels_le: bytes,
                    }),
                },
            )?;
        }
        Ok(())
    })?;
    Ok(out.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;
    use exr::prelude::{ReadChannels, ReadLayers};

    /// Pixels read back by the `exr` crate's own reader, as bit patterns.
    fn read_back(bytes: &[u8], w: usize) -> Vec<[u32; 4]> {
        let image = exr::prelude::read()
            .no_deep_data()
            .largest_resolution_level()
            .rgba_channels(
                move |size, _| vec![[0u32; 4]; size.width() * size.height()],
                move |buf: &mut Vec<[u32; 4]>,
                      pos: Vec2<usize>,
                      (r, g, b, a): (f32, f32, f32, f32)| {
                    buf[pos.y() * w + pos.x()] = [r, g, b, a].map(f32::to_bits);
                },
            )
            .first_valid_layer()
            .all_attributes()
            .from_buffered(Cursor::new(bytes))
            .unwrap();
        image.layer_data.channel_data.pixels
    }

    fn film(w: u32, h: u32, mut pixel: impl FnMut(u32, u32) -> [f32; 4]) -> Film {
        let mut pixels = Vec::new();
        for y in 0..h {
            for x in 0..w {
                pixels.push(pixel(x, y));
            }
        }
        Film {
            width: w,
            height: h,
            pixels,
            stats: Default::default(),
        }
    }

    #[test]
    fn every_bit_survives_the_round_trip_and_incompressible_blocks_are_stored_raw() {
        // 37 × 23: a last block of 7 lines; smooth rows, special values and pure noise rows.
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut noise = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            f32::from_bits(state as u32)
        };
        let specials = [
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            -0.0,
            f32::MIN_POSITIVE / 8.0,
            -3.5,
            1e30,
        ];
        let f = film(37, 23, |x, y| match y {
            0..=5 => [x as f32 / 37.0, y as f32 / 23.0, 0.5, 1.0],
            6..=9 => [
                specials[(x % 7) as usize],
                1.0,
                specials[((x + y) % 7) as usize],
                1.0,
            ],
            _ => [noise(), noise(), noise(), noise()],
        });
        let bytes = encode_exr(&f, &ExrMetadata::default()).unwrap();
        let want: Vec<[u32; 4]> = f.pixels.iter().map(|p| p.map(f32::to_bits)).collect();
        let got = read_back(&bytes, 37);
        // NaN payloads may be canonicalised by a reader; compare NaN-ness there, bits elsewhere.
        for (g, w) in got.iter().zip(&want) {
            for (a, b) in g.iter().zip(w) {
                let (fa, fb) = (f32::from_bits(*a), f32::from_bits(*b));
                assert!(a == b || (fa.is_nan() && fb.is_nan()), "{fa} vs {fb}");
            }
        }
    }

    #[test]
    fn a_block_that_does_not_shrink_is_stored_raw() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let f = film(16, 4, |_, _| {
            [0; 4].map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                f32::from_bits(state as u32)
            })
        });
        let order = [3, 2, 1, 0];
        let mut encoder = BlockEncoder::new();
        let stored = encoder.zip_block(&f, &order, 0, 4);
        assert_eq!(stored, raw_block(&f, &order, 0, 4));
        // A flat block does shrink.
        let flat = film(16, 4, |_, _| [0.5, 0.5, 0.5, 1.0]);
        let stored = encoder.zip_block(&flat, &order, 0, 4);
        assert!(stored.len() < 16 * 4 * 16 / 4, "{}", stored.len());
    }

    #[test]
    fn same_pixels_as_the_exr_crates_own_encoder() {
        let f = film(64, 40, |x, y| {
            let v = (x as f32 * 0.37 + y as f32 * 0.11).sin().abs();
            [v, v * 0.5, 1.0 - v, 1.0]
        });
        let ours = encode_exr(&f, &ExrMetadata::default()).unwrap();
        let w = 64usize;
        let pixels = &f.pixels;
        let layer = Layer::new(
            (64, 40),
            LayerAttributes::named("rgba"),
            Encoding::SMALL_LOSSLESS,
            SpecificChannels::rgba(|p: Vec2<usize>| {
                let q = pixels[p.y() * w + p.x()];
                (q[0], q[1], q[2], q[3])
            }),
        );
        let mut theirs = Cursor::new(Vec::new());
        Image::from_layer(layer)
            .write()
            .to_buffered(&mut theirs)
            .unwrap();
        assert_eq!(read_back(&ours, w), read_back(&theirs.into_inner(), w));
    }
}
