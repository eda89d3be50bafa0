//! Comparing rendered films: channel differences that hold the sun's disc to the same share of
//! its value as the sky, edges, and the pixels two renders disagree on.

use ghostship::render::Film;

/// The largest difference of the colour channels of `a` and `b`: absolute up to the white
/// horizon sky (1), relative to the larger value above it — so the sun's disc, 1e2 to 1e5 times
/// the sky, is held to the same share of its value as the sky.
pub fn max_channel_difference(a: [f32; 4], b: [f32; 4]) -> f32 {
    (0..3)
        .map(|c| (a[c] - b[c]).abs() / a[c].abs().max(b[c].abs()).max(1.0))
        .fold(0.0, f32::max)
}

/// Whether pixel (`x`, `y`) of `film` sits at an edge: one of its four neighbours differs from
/// it by more than `threshold` in some channel ([`max_channel_difference`]).
pub fn at_edge(film: &Film, x: u32, y: u32, threshold: f32) -> bool {
    let p = film.pixel(x, y);
    [(0i32, -1i32), (0, 1), (-1, 0), (1, 0)]
        .iter()
        .any(|(dx, dy)| {
            let (nx, ny) = (x as i32 + dx, y as i32 + dy);
            nx >= 0
                && ny >= 0
                && (nx as u32) < film.width
                && (ny as u32) < film.height
                && max_channel_difference(p, film.pixel(nx as u32, ny as u32)) > threshold
        })
}

/// Pixels of `a` and `b` that differ by more than `threshold` ([`max_channel_difference`]), and
/// pixels of `b` on an edge (differing so from a vertical neighbour). Panics if a
/// differing pixel is not next to an edge (any of its four neighbours differs from it) in `a` or
/// in `b`: the fan moves edges, it never changes a pixel inside a uniform region.
pub fn differing_and_edge_pixels(a: &Film, b: &Film, threshold: f32) -> (usize, usize) {
    let differ = |p: [f32; 4], q: [f32; 4]| max_channel_difference(p, q) > threshold;
    let mut diff = 0;
    let mut edges = 0;
    for y in 0..b.height {
        for x in 0..b.width {
            let p = b.pixel(x, y);
            if differ(a.pixel(x, y), p) {
                diff += 1;
                assert!(
                    at_edge(a, x, y, threshold) || at_edge(b, x, y, threshold),
                    "pixel ({x}, {y}) differs away from any edge"
                );
            }
            let up = y > 0 && differ(p, b.pixel(x, y - 1));
            let down = y + 1 < b.height && differ(p, b.pixel(x, y + 1));
            if up || down {
                edges += 1;
            }
        }
    }
    (diff, edges)
}

/// The largest difference, in any colour channel, between pixel (`x`, `y`) of `film` and its
/// four neighbours (those inside the film): how much the pixel changes when the image moves by
/// a whole pixel.
pub fn neighbour_contrast(film: &Film, x: u32, y: u32) -> f32 {
    let p = film.pixel(x, y);
    [(0i32, -1i32), (0, 1), (-1, 0), (1, 0)]
        .iter()
        .filter_map(|(dx, dy)| {
            let (nx, ny) = (x as i32 + dx, y as i32 + dy);
            (nx >= 0 && ny >= 0 && (nx as u32) < film.width && (ny as u32) < film.height)
                .then(|| film.pixel(nx as u32, ny as u32))
        })
        .flat_map(|q| (0..3).map(move |c| (p[c] - q[c]).abs()))
        .fold(0.0, f32::max)
}
