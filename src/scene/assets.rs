//! Scene — card images the project draws itself. In: nothing. Out: 8-bit sRGB RGBA images (and
//! PNG bytes) of a ship silhouette, an ice cliff and a calibration board; `data/cards/*.png` are
//! these images, checked by a test and regenerated with [`write_card_images`] (the integration
//! test does it when `GHOSTSHIP_WRITE_CARDS=1`).
//!
//! Drawn by hand (a tiny polygon rasteriser with 4×4 supersampled coverage) because the shapes are
//! a handful of polygons and the output must be bit-identical on every machine; a drawing crate
//! would add a dependency and an anti-aliasing algorithm that may change between versions.

use std::path::Path;

use image::{ImageEncoder, RgbaImage};

/// Heights of the calibration board's colour bands (m, each) and the board's height (m).
pub const BOARD_BAND_M: f64 = 2.0;
/// Calibration board height (m): ten bands.
pub const BOARD_HEIGHT_M: f64 = 20.0;
/// Calibration board width (m) matching its image aspect (256 × 640 px, 32 px/m).
pub const BOARD_WIDTH_M: f64 = 8.0;
/// Band colours of the calibration board, bottom band first (sRGB 8-bit): ten distinct hues so
/// stretching, compression and inversion can be read off a rendered image.
pub const BOARD_BAND_COLOURS: [[u8; 3]; 10] = [
    [220, 30, 30],   // 0–2 m red
    [240, 140, 20],  // 2–4 m orange
    [240, 230, 40],  // 4–6 m yellow
    [60, 190, 60],   // 6–8 m green
    [30, 200, 200],  // 8–10 m cyan
    [40, 70, 220],   // 10–12 m blue
    [140, 50, 200],  // 12–14 m violet
    [230, 60, 180],  // 14–16 m magenta
    [245, 245, 245], // 16–18 m white
    [120, 80, 40],   // 18–20 m brown
];

/// Ship card: 512 × 160 px for an 80 m × 25 m card (6.4 px/m).
pub const SHIP_SIZE_M: (f64, f64) = (80.0, 25.0);
/// Ice-cliff card: 512 × 128 px for a 400 m × 25 m card.
pub const ICE_CLIFF_SIZE_M: (f64, f64) = (400.0, 25.0);

type Poly = Vec<(f64, f64)>;

/// A filled polygon (pixel coordinates, y down) with a colour.
struct Shape {
    poly: Poly,
    rgba: [u8; 4],
}

fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Poly {
    vec![(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
}

/// Even–odd point-in-polygon test.
fn inside(poly: &[(f64, f64)], x: f64, y: f64) -> bool {
    let mut c = false;
    let n = poly.len();
    for i in 0..n {
        let (xi, yi) = poly[i];
        let (xj, yj) = poly[(i + n - 1) % n];
        if (yi > y) != (yj > y) && x < (xj - xi) * (y - yi) / (yj - yi) + xi {
            c = !c;
        }
    }
    c
}

/// Paint shapes in order (later over earlier) with 4×4 supersampled coverage; blends in linear
/// 8-bit space per subsample (straight alpha, "over").
fn paint(width: u32, height: u32, shapes: &[Shape]) -> RgbaImage {
    const N: u32 = 4;
    RgbaImage::from_fn(width, height, |px, py| {
        let mut acc = [0u32; 4];
        for sy in 0..N {
            for sx in 0..N {
                let x = px as f64 + (sx as f64 + 0.5) / N as f64;
                let y = py as f64 + (sy as f64 + 0.5) / N as f64;
                let top = shapes.iter().rev().find(|s| inside(&s.poly, x, y));
                if let Some(s) = top {
                    let a = s.rgba[3] as u32;
                    for (slot, &v) in acc.iter_mut().zip(&s.rgba[..3]) {
                        *slot += v as u32 * a;
                    }
                    acc[3] += a;
                }
            }
        }
        if acc[3] == 0 {
            return image::Rgba([0, 0, 0, 0]);
        }
        let rgb = [0, 1, 2].map(|c| ((acc[c] + acc[3] / 2) / acc[3]) as u8);
        let a = ((acc[3] + (N * N) / 2) / (N * N)) as u8;
        image::Rgba([rgb[0], rgb[1], rgb[2], a])
    })
}

/// A ship silhouette: dark hull with a red boot-top, white superstructure, a funnel, two masts
/// with yards and stays; transparent background. 512 × 160 px (80 m × 25 m).
pub fn ship() -> RgbaImage {
    let hull = [40, 42, 48, 255];
    let white = [215, 215, 208, 255];
    let mast = [60, 60, 60, 255];
    let shapes = vec![
        // Hull: raked bow on the right, stern on the left, bottom on the waterline.
        Shape {
            poly: vec![
                (14.0, 104.0),
                (120.0, 108.0),
                (400.0, 106.0),
                (508.0, 92.0),
                (470.0, 160.0),
                (44.0, 160.0),
            ],
            rgba: hull,
        },
        // Boot-top (red band at the waterline).
        Shape {
            poly: vec![(38.0, 150.0), (474.0, 150.0), (470.0, 160.0), (44.0, 160.0)],
            rgba: [150, 35, 30, 255],
        },
        // Superstructure aft, bridge deck, wheelhouse.
        Shape {
            poly: rect(48.0, 70.0, 190.0, 106.0),
            rgba: white,
        },
        Shape {
            poly: rect(70.0, 48.0, 175.0, 70.0),
            rgba: white,
        },
        Shape {
            poly: rect(95.0, 34.0, 160.0, 48.0),
            rgba: [190, 195, 200, 255],
        },
        // Funnel with a black top.
        Shape {
            poly: vec![(178.0, 70.0), (186.0, 24.0), (214.0, 24.0), (212.0, 70.0)],
            rgba: [170, 45, 30, 255],
        },
        Shape {
            poly: vec![(185.5, 27.0), (186.0, 24.0), (214.0, 24.0), (213.8, 27.0)],
            rgba: [20, 20, 20, 255],
        },
        // Fore mast and main mast with yards.
        Shape {
            poly: rect(298.0, 8.0, 302.0, 107.0),
            rgba: mast,
        },
        Shape {
            poly: rect(284.0, 28.0, 316.0, 31.0),
            rgba: mast,
        },
        Shape {
            poly: rect(438.0, 22.0, 442.0, 100.0),
            rgba: mast,
        },
        Shape {
            poly: rect(426.0, 40.0, 454.0, 43.0),
            rgba: mast,
        },
        // Stays: from the mast tops down to the bow and to the funnel.
        Shape {
            poly: vec![(440.0, 22.0), (442.0, 22.0), (506.0, 93.0), (503.0, 94.0)],
            rgba: mast,
        },
        Shape {
            poly: vec![(298.0, 10.0), (300.0, 9.0), (442.0, 23.0), (440.0, 25.0)],
            rgba: mast,
        },
        // Cargo hatches on deck.
        Shape {
            poly: rect(320.0, 96.0, 420.0, 107.0),
            rgba: [90, 70, 50, 255],
        },
        Shape {
            poly: rect(215.0, 97.0, 285.0, 107.0),
            rgba: [90, 70, 50, 255],
        },
    ];
    paint(512, 160, &shapes)
}

/// Deterministic hash → [0, 1).
fn unit_hash(i: u64) -> f64 {
    let mut z = i.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}

/// An ice cliff: bluish-white face with darker vertical crevasses and a jagged top edge;
/// transparent above. 512 × 128 px (400 m × 25 m).
pub fn ice_cliff() -> RgbaImage {
    let (w, h) = (512u32, 128u32);
    let mut top = vec![(w as f64, h as f64), (0.0, h as f64)];
    let mut x = 0.0;
    let mut i = 0u64;
    while x <= w as f64 {
        let y = 12.0 + 40.0 * unit_hash(i);
        top.push((x, y));
        x += 6.0 + 14.0 * unit_hash(1000 + i);
        i += 1;
    }
    top.push((w as f64, 12.0 + 40.0 * unit_hash(i)));
    let mut shapes = vec![Shape {
        poly: top.clone(),
        rgba: [175, 198, 222, 255],
    }];
    // Crevasses: thin darker wedges from the bottom, clipped by drawing them under a re-drawn top
    // band would be complicated; they stop 30 px below the lowest possible top edge instead.
    for k in 0..14u64 {
        let cx = 20.0 + 480.0 * unit_hash(5000 + k);
        let half = 1.5 + 3.0 * unit_hash(6000 + k);
        let y_top = 56.0 + 40.0 * unit_hash(7000 + k);
        shapes.push(Shape {
            poly: vec![(cx - half, h as f64), (cx, y_top), (cx + half, h as f64)],
            rgba: [105, 135, 170, 255],
        });
    }
    // A shadowed band at the foot of the cliff.
    shapes.push(Shape {
        poly: rect(0.0, 116.0, w as f64, h as f64),
        rgba: [90, 115, 145, 255],
    });
    paint(w, h, &shapes)
}

/// A calibration board 8 m × 20 m (256 × 640 px, 32 px/m): ten 2 m bands of distinct hues
/// ([`BOARD_BAND_COLOURS`], bottom first), black tick marks on both sides every metre (long at
/// band edges), and a thin black frame.
pub fn calibration_board() -> RgbaImage {
    let (w, h) = (256u32, 640u32);
    let px_per_m = h as f64 / BOARD_HEIGHT_M;
    let mut shapes = Vec::new();
    for (b, c) in BOARD_BAND_COLOURS.iter().enumerate() {
        let y1 = h as f64 - b as f64 * BOARD_BAND_M * px_per_m;
        let y0 = y1 - BOARD_BAND_M * px_per_m;
        shapes.push(Shape {
            poly: rect(0.0, y0, w as f64, y1),
            rgba: [c[0], c[1], c[2], 255],
        });
    }
    let black = [0, 0, 0, 255];
    for m in 1..(BOARD_HEIGHT_M as u32) {
        let y = h as f64 - m as f64 * px_per_m;
        let len = if m % 2 == 0 { 64.0 } else { 32.0 };
        shapes.push(Shape {
            poly: rect(0.0, y - 2.0, len, y + 2.0),
            rgba: black,
        });
        shapes.push(Shape {
            poly: rect(w as f64 - len, y - 2.0, w as f64, y + 2.0),
            rgba: black,
        });
    }
    for frame in [
        rect(0.0, 0.0, w as f64, 3.0),
        rect(0.0, h as f64 - 3.0, w as f64, h as f64),
        rect(0.0, 0.0, 3.0, h as f64),
        rect(w as f64 - 3.0, 0.0, w as f64, h as f64),
    ] {
        shapes.push(Shape {
            poly: frame,
            rgba: black,
        });
    }
    paint(w, h, &shapes)
}

/// PNG bytes of an image (deterministic for a given `image` version).
pub fn png_bytes(img: &RgbaImage) -> Result<Vec<u8>, image::ImageError> {
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out).write_image(
        img.as_raw(),
        img.width(),
        img.height(),
        image::ExtendedColorType::Rgba8,
    )?;
    Ok(out)
}

/// The card images by file name.
pub fn card_images() -> Vec<(&'static str, RgbaImage)> {
    vec![
        ("ship.png", ship()),
        ("ice_cliff.png", ice_cliff()),
        ("calibration_board.png", calibration_board()),
    ]
}

/// Write every card image into `dir` (atomically).
pub fn write_card_images(dir: &Path) -> anyhow::Result<()> {
    for (name, img) in card_images() {
        crate::output::write_atomic(&dir.join(name), &png_bytes(&img)?)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn board_bands_are_where_they_should_be() {
        let img = calibration_board();
        // Middle of band b (from the bottom), at the card's horizontal centre.
        for (b, c) in BOARD_BAND_COLOURS.iter().enumerate() {
            let y = 640 - (b as u32 * 64 + 32);
            let p = img.get_pixel(128, y);
            assert_eq!(
                [p[0], p[1], p[2], p[3]],
                [c[0], c[1], c[2], 255],
                "band {b}"
            );
        }
        // Hues are pairwise distinct by a wide margin.
        for (i, a) in BOARD_BAND_COLOURS.iter().enumerate() {
            for (j, b) in BOARD_BAND_COLOURS.iter().enumerate().take(i) {
                let d: i32 = a
                    .iter()
                    .zip(b)
                    .map(|(&x, &y)| (x as i32 - y as i32).abs())
                    .sum();
                assert!(d > 90, "{i} {j}");
            }
        }
        // A tick at 1 m on the left edge.
        assert_eq!(img.get_pixel(10, 640 - 32)[0], 0);
    }

    #[test]
    fn ship_is_transparent_around_and_opaque_in_the_hull() {
        let img = ship();
        assert_eq!(img.get_pixel(2, 2)[3], 0);
        assert_eq!(img.get_pixel(250, 130)[3], 255);
        let cliff = ice_cliff();
        assert_eq!(cliff.get_pixel(100, 2)[3], 0);
        assert_eq!(cliff.get_pixel(100, 100)[3], 255);
    }
}
