//! Output — animated GIF. In: equally sized 8-bit sRGB frames (RGB triplets). Out: the bytes of
//! a looping GIF with one global palette of 256 colours for every frame.
//!
//! One palette for the whole animation, trained once by NeuQuant (the `color_quant` crate, the
//! quantiser the `gif` crate itself uses) on pixels drawn evenly from every frame: frames of a
//! sweep share their sky and sea, so a shared palette keeps those colours from flickering from
//! frame to frame, and the training, the costly part, runs once instead of once per frame.
//! Frames are mapped to the palette and LZW-compressed in parallel (`gif`'s pre-encoded frames);
//! the bytes do not depend on the thread count.

use std::borrow::Cow;

use rayon::prelude::*;

/// Pixels the palette is trained on, at most (drawn evenly from all frames).
const TRAINING_PIXELS: usize = 1 << 18;

/// NeuQuant's sampling factor (1: every training pixel, 30: fastest); 10 is its authors'
/// suggested balance of quality and speed.
const SAMPLING_FACTOR: i32 = 10;

/// The frames could not be made into a GIF.
#[derive(Debug, thiserror::Error)]
pub enum GifError {
    /// GIF stores sizes in 16 bits.
    #[error("{width}×{height} frames are too large for a GIF (at most 65535 pixels a side)")]
    TooLarge {
        /// Frame width (pixels).
        width: u32,
        /// Frame height (pixels).
        height: u32,
    },
    /// A frame holds other than width × height RGB pixels.
    #[error("frame {index} holds {len} bytes, not {width}×{height} RGB pixels")]
    FrameSize {
        /// The frame's position.
        index: usize,
        /// Its length in bytes.
        len: usize,
        /// Frame width (pixels).
        width: u32,
        /// Frame height (pixels).
        height: u32,
    },
    /// The encoder failed.
    #[error("cannot encode GIF: {0}")]
    Encode(#[from] gif::EncodingError),
}

/// A looping GIF of `frames` (8-bit sRGB, `width` × `height` RGB triplets each), each shown for
/// `frame_ms` milliseconds (rounded to the format's 10 ms).
pub fn encode_animation(
    frames: &[Vec<u8>],
    width: u32,
    height: u32,
    frame_ms: u32,
) -> Result<Vec<u8>, GifError> {
    let too_large = || GifError::TooLarge { width, height };
    let (w, h) = (
        u16::try_from(width).map_err(|_| too_large())?,
        u16::try_from(height).map_err(|_| too_large())?,
    );
    let pixels = width as usize * height as usize;
    if let Some((index, f)) = frames
        .iter()
        .enumerate()
        .find(|(_, f)| f.len() != 3 * pixels)
    {
        return Err(GifError::FrameSize {
            index,
            len: f.len(),
            width,
            height,
        });
    }
    let palette = train_palette(frames);
    let delay = u16::try_from(frame_ms.div_ceil(10)).unwrap_or(u16::MAX);
    let encoded: Vec<gif::Frame<'static>> = frames
        .par_iter()
        .map(|rgb| {
            let mut frame = gif::Frame::from_indexed_pixels(w, h, palette.indices(rgb), None);
            frame.delay = delay;
            frame.make_lzw_pre_encoded();
            frame
        })
        .collect();
    let mut encoder = gif::Encoder::new(Vec::new(), w, h, &palette.rgb)?;
    encoder.set_repeat(gif::Repeat::Infinite)?;
    for frame in &encoded {
        encoder.write_lzw_pre_encoded_frame(frame)?;
    }
    Ok(encoder.into_inner()?)
}

/// A trained palette: the quantiser and its colours as RGB triplets.
struct Palette {
    quant: color_quant::NeuQuant,
    rgb: Vec<u8>,
}

/// NeuQuant trained on at most [`TRAINING_PIXELS`] pixels drawn evenly from all `frames`.
fn train_palette(frames: &[Vec<u8>]) -> Palette {
    let total: usize = frames.iter().map(|f| f.len() / 3).sum();
    let stride = total.div_ceil(TRAINING_PIXELS).max(1);
    let mut sample = Vec::with_capacity(4 * (total / stride + 1));
    let mut k = 0usize;
    for f in frames {
        for p in f.chunks_exact(3) {
            if k.is_multiple_of(stride) {
                sample.extend_from_slice(&[p[0], p[1], p[2], 255]);
            }
            k += 1;
        }
    }
    if sample.is_empty() {
        sample.extend_from_slice(&[0, 0, 0, 255]);
    }
    let quant = color_quant::NeuQuant::new(SAMPLING_FACTOR, 256, &sample);
    let rgb = quant.color_map_rgb();
    Palette { quant, rgb }
}

/// Entries of [`Palette::indices`]' colour cache (a power of two).
const CACHE_SIZE: usize = 1 << 12;

impl Palette {
    /// The palette index of every pixel of `rgb`, through a direct-mapped cache of recent
    /// colours (a frame of sky and sea holds few distinct ones; NeuQuant's search is the cost).
    fn indices(&self, rgb: &[u8]) -> Cow<'static, [u8]> {
        // Keys are 24-bit colours; u32::MAX marks an empty slot.
        let mut keys = vec![u32::MAX; CACHE_SIZE];
        let mut values = vec![0u8; CACHE_SIZE];
        let out: Vec<u8> = rgb
            .chunks_exact(3)
            .map(|p| {
                let key = u32::from(p[0]) << 16 | u32::from(p[1]) << 8 | u32::from(p[2]);
                let slot = (key.wrapping_mul(0x9E37_79B1) >> 20) as usize % CACHE_SIZE;
                if keys[slot] != key {
                    keys[slot] = key;
                    // A 256-colour map has indices below 256.
                    values[slot] = u8::try_from(self.quant.index_of(&[p[0], p[1], p[2], 255]))
                        .unwrap_or(u8::MAX);
                }
                values[slot]
            })
            .collect();
        Cow::Owned(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Frames of a sky gradient over a darker sea with a bright disc that moves.
    fn frames(count: usize, width: u32, height: u32) -> Vec<Vec<u8>> {
        (0..count)
            .map(|i| {
                let mut rgb = Vec::with_capacity(3 * (width * height) as usize);
                for y in 0..height {
                    for x in 0..width {
                        let (fx, fy) = (f64::from(x), f64::from(y));
                        let cx = 20.0 + 10.0 * i as f64;
                        let disc = (fx - cx).hypot(fy - 30.0) < 6.0;
                        let p = if disc {
                            [255, 230, 160]
                        } else if y < height / 2 {
                            let t = fy / f64::from(height / 2);
                            [(90.0 + 80.0 * t) as u8, (130.0 + 70.0 * t) as u8, 220]
                        } else {
                            let t = (fx / f64::from(width) * 40.0) as u8;
                            [20 + t, 50 + t, 80 + t / 2]
                        };
                        rgb.extend_from_slice(&p);
                    }
                }
                rgb
            })
            .collect()
    }

    #[test]
    fn the_gif_holds_every_frame_close_to_its_pixels_with_one_palette() {
        let (width, height) = (120, 80);
        let input = frames(6, width, height);
        let bytes = encode_animation(&input, width, height, 80).unwrap();
        let mut options = gif::DecodeOptions::new();
        options.set_color_output(gif::ColorOutput::RGBA);
        let mut decoder = options.read_info(bytes.as_slice()).unwrap();
        assert!(decoder.global_palette().is_some_and(|p| p.len() == 3 * 256));
        assert_eq!((decoder.width(), decoder.height()), (120, 80));
        let mut count = 0;
        while let Some(frame) = decoder.read_next_frame().unwrap() {
            assert!(frame.palette.is_none(), "frame {count} has its own palette");
            assert_eq!(frame.delay, 8);
            let want = &input[count];
            let (mut sum, mut worst) = (0u64, 0u8);
            for (got, want) in frame.buffer.chunks_exact(4).zip(want.chunks_exact(3)) {
                for c in 0..3 {
                    let d = got[c].abs_diff(want[c]);
                    sum += u64::from(d);
                    worst = worst.max(d);
                }
            }
            let mean = sum as f64 / (3 * width * height) as f64;
            // 256 colours for smooth gradients and a disc: a level or two on average, and no
            // colour far from its own.
            assert!(
                mean < 2.0 && worst <= 24,
                "frame {count}: mean {mean}, worst {worst}"
            );
            count += 1;
        }
        assert_eq!(count, 6);
    }

    #[test]
    fn the_bytes_do_not_depend_on_the_thread_count() {
        let input = frames(5, 64, 40);
        let with = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| encode_animation(&input, 64, 40, 80).unwrap())
        };
        assert_eq!(with(1), with(2));
    }

    #[test]
    fn bad_frames_are_refused() {
        let input = frames(2, 10, 10);
        assert!(matches!(
            encode_animation(&input, 70_000, 1, 80),
            Err(GifError::TooLarge { .. })
        ));
        let mut short = input.clone();
        short[1].pop();
        assert!(matches!(
            encode_animation(&short, 10, 10, 80),
            Err(GifError::FrameSize { index: 1, .. })
        ));
    }
}
