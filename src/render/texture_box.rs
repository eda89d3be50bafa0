//! Render — box-filtered card textures for the sea's blurred reflections. In: a card's
//! [`Texture`]. Out: its mean premultiplied RGBA over an interval of the vertical texture
//! coordinate v at one horizontal coordinate u, in O(1) from per-column integrals.
//!
//! The texture is the function [`Texture::sample`] gives (bilinear between texel centres, the
//! edge texels held out to the edges, transparent outside [0, 1]); along v it is piecewise
//! linear, so each column's running integral is piecewise quadratic and is stored at the texel
//! centres. The mean over [v₀, v₁] is the difference of two integrals over the interval's
//! length, bilinear in u like the samples; as v₁ − v₀ → 0 it tends to the bilinear sample.
//! A rough sea mirrors a whole interval of a card's heights into one part of a pixel's slope
//! cell, and this is the card's mean over it (see `super::reflection`).

use std::cell::Cell;

use crate::scene::Texture;

/// Running integrals along v of each column of one texture.
pub(super) struct TextureColumns {
    width: usize,
    height: usize,
    /// Column-major, `height` per column: ∫ from the first texel centre to texel centre k, in
    /// texels (the trapezoid sum of the texels before k).
    prefix: Vec<[f64; 4]>,
}

impl TextureColumns {
    /// The integrals of `texture`'s columns (none for an empty or inconsistent texture, which
    /// samples as transparent).
    pub(super) fn new(texture: &Texture) -> Self {
        let (w, h) = (texture.width as usize, texture.height as usize);
        if texture.texels.is_empty() || texture.texels.len() != w * h {
            return Self {
                width: 0,
                height: 0,
                prefix: Vec::new(),
            };
        }
        let mut prefix = Vec::with_capacity(w * h);
        for x in 0..w {
            let mut sum = [0.0f64; 4];
            prefix.push(sum);
            for k in 0..h - 1 {
                let (a, b) = (texture.texels[k * w + x], texture.texels[(k + 1) * w + x]);
                for c in 0..4 {
                    sum[c] += 0.5 * (f64::from(a[c]) + f64::from(b[c]));
                }
                prefix.push(sum);
            }
        }
        Self {
            width: w,
            height: h,
            prefix,
        }
    }

    /// ∫ of column `x` from the first texel centre to `y` (texels from that centre; the edge
    /// texels extend beyond the centres).
    #[inline]
    fn integral(&self, texture: &Texture, x: usize, y: f64) -> [f64; 4] {
        let h = self.height;
        let texel = |k: usize| {
            let t = texture.texels[k * self.width + x];
            [t[0] as f64, t[1] as f64, t[2] as f64, t[3] as f64]
        };
        let column = &self.prefix[x * h..(x + 1) * h];
        let last = (h - 1) as f64;
        let mut out = [0.0; 4];
        if y <= 0.0 {
            let t = texel(0);
            for c in 0..4 {
                out[c] = y * t[c];
            }
        } else if y >= last {
            let (p, t) = (column[h - 1], texel(h - 1));
            for c in 0..4 {
                out[c] = p[c] + (y - last) * t[c];
            }
        } else {
            let k = (y as usize).min(h - 2);
            let f = y - k as f64;
            let (p, a, b) = (column[k], texel(k), texel(k + 1));
            for c in 0..4 {
                out[c] = p[c] + f * a[c] + 0.5 * f * f * (b[c] - a[c]);
            }
        }
        out
    }

    /// Mean of column `x` over v ∈ [`v0`, `v1`] (`v0` < `v1`), transparent outside [0, 1].
    #[inline]
    fn column_mean(&self, texture: &Texture, x: usize, v0: f64, v1: f64) -> [f64; 4] {
        let (a, b) = (v0.max(0.0), v1.min(1.0));
        if b <= a {
            return [0.0; 4];
        }
        let h = self.height as f64;
        let (ia, ib) = (
            self.integral(texture, x, a * h - 0.5),
            self.integral(texture, x, b * h - 0.5),
        );
        let scale = 1.0 / (h * (v1 - v0));
        let mut out = [0.0; 4];
        for c in 0..4 {
            out[c] = (ib[c] - ia[c]) * scale;
        }
        out
    }

    /// Mean of `texture` (the texture these integrals were built from) at horizontal
    /// coordinate `u` over v ∈ [min, max] of (`v0`, `v1`): [`Texture::sample`] at `u` averaged
    /// over the interval; the sample itself when the interval is empty.
    #[inline]
    pub(super) fn mean(&self, texture: &Texture, u: f64, v0: f64, v1: f64) -> [f32; 4] {
        self.mean_by(texture, u, v0, v1, |x0, x1, a, b| {
            let column = |x: usize| self.column_mean(texture, x, a, b);
            (column(x0), column(x1))
        })
    }

    /// [`Self::mean`], the two columns' means kept in `memo` and taken from it when found
    /// before over the same interval: the same values, each found once for a run of samples
    /// whose `u` moves rightwards across the texture over one interval (a band's samples on one
    /// part of a rough sea's slopes).
    #[inline]
    pub(super) fn mean_memo(
        &self,
        texture: &Texture,
        u: f64,
        (v0, v1): (f64, f64),
        memo: &ColumnMemo,
    ) -> [f32; 4] {
        self.mean_by(texture, u, v0, v1, |x0, x1, a, b| {
            memo.pair((x0, x1), (a, b), |x| self.column_mean(texture, x, a, b))
        })
    }

    /// [`Self::mean`] with the means of the two columns it interpolates from `pair` (columns
    /// x₀ and x₁, v₀, v₁ with v₀ ≤ v₁).
    #[inline(always)]
    fn mean_by(
        &self,
        texture: &Texture,
        u: f64,
        v0: f64,
        v1: f64,
        pair: impl FnOnce(usize, usize, f64, f64) -> ([f64; 4], [f64; 4]),
    ) -> [f32; 4] {
        let (v0, v1) = (v0.min(v1), v0.max(v1));
        if v1.is_nan() || v0.is_nan() || v1 <= v0 || self.prefix.is_empty() {
            return texture.sample(u, 0.5 * (v0 + v1));
        }
        if !(0.0..=1.0).contains(&u) {
            return texture.sample(u, 0.5 * (v0 + v1));
        }
        let w = self.width;
        let x = (u * w as f64 - 0.5).clamp(0.0, (w - 1) as f64);
        let x0 = (x as usize).min(w - 1);
        let x1 = (x0 + 1).min(w - 1);
        let fx = x - x0 as f64;
        let (a, b) = pair(x0, x1, v0, v1);
        let mut out = [0.0f32; 4];
        for c in 0..4 {
            out[c] = (a[c] + (b[c] - a[c]) * fx) as f32;
        }
        out
    }
}

/// The means of the last pair of neighbouring texture columns found over one interval of v
/// ([`TextureColumns::mean_memo`]).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct ColumnMemo {
    /// The pair's columns and the interval's bits; `usize::MAX`: none yet.
    key: Cell<(usize, usize, u64, u64)>,
    /// The two columns' means.
    means: Cell<[[f64; 4]; 2]>,
}

impl Default for ColumnMemo {
    fn default() -> Self {
        Self {
            key: Cell::new((usize::MAX, usize::MAX, 0, 0)),
            means: Cell::new([[0.0; 4]; 2]),
        }
    }
}

impl ColumnMemo {
    /// The means of columns `x` over `v`: those kept here, else from `find` (the left one taken
    /// over from the pair kept when that ended at it), kept in its place.
    #[inline]
    fn pair(
        &self,
        x: (usize, usize),
        v: (f64, f64),
        find: impl Fn(usize) -> [f64; 4],
    ) -> ([f64; 4], [f64; 4]) {
        let key = (x.0, x.1, v.0.to_bits(), v.1.to_bits());
        let (kept, means) = (self.key.get(), self.means.get());
        if kept == key {
            return (means[0], means[1]);
        }
        let a = if (kept.1, kept.2, kept.3) == (x.0, key.2, key.3) {
            means[1]
        } else {
            find(x.0)
        };
        let b = find(x.1);
        self.key.set(key);
        self.means.set([a, b]);
        (a, b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A texture whose texels vary in both directions, with transparent parts.
    fn texture() -> Texture {
        let (w, h) = (5u32, 7u32);
        let texels = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                let a = if ((x + y) as u32).is_multiple_of(3) {
                    0.0
                } else {
                    0.5 + 0.05 * y
                };
                [a * (0.1 * x), a * (0.9 - 0.1 * y), a * 0.3, a]
            })
            .collect();
        Texture {
            width: w,
            height: h,
            texels,
        }
    }

    #[test]
    fn the_mean_is_the_average_of_the_bilinear_samples() {
        let tex = texture();
        let cols = TextureColumns::new(&tex);
        for &(u, v0, v1) in &[
            (0.5, 0.2, 0.7),
            (0.13, -0.3, 0.4),
            (0.91, 0.6, 1.4),
            (0.02, 0.0, 1.0),
            (0.77, 0.41, 0.43),
            (0.5, -0.5, -0.1),
        ] {
            let n = 200_000;
            let mut sum = [0.0f64; 4];
            for i in 0..n {
                let v = v0 + (v1 - v0) * (i as f64 + 0.5) / n as f64;
                let s = tex.sample(u, v);
                for c in 0..4 {
                    sum[c] += f64::from(s[c]) / n as f64;
                }
            }
            let mean = cols.mean(&tex, u, v1, v0);
            for c in 0..4 {
                assert!(
                    (f64::from(mean[c]) - sum[c]).abs() < 1e-5,
                    "u {u} v {v0}..{v1} channel {c}: {} vs {}",
                    mean[c],
                    sum[c]
                );
            }
        }
    }

    #[test]
    fn the_memo_gives_the_means_found_without_it() {
        let tex = texture();
        let cols = TextureColumns::new(&tex);
        let memo = ColumnMemo::default();
        // A run of samples across the texture over one interval, then back over another (and
        // outside the texture, and empty intervals): bit for bit the same.
        let mut found = 0;
        for (v0, v1) in [(0.2, 0.7), (0.8, 0.31), (0.5, 0.5), (-0.2, 1.3)] {
            for i in 0..=60 {
                let u = -0.1 + 1.2 * f64::from(i) / 60.0;
                let want = cols.mean(&tex, u, v0, v1);
                let got = cols.mean_memo(&tex, u, (v0, v1), &memo);
                assert_eq!(
                    got.map(f32::to_bits),
                    want.map(f32::to_bits),
                    "{u} {v0} {v1}"
                );
                found += usize::from(want != [0.0; 4]);
            }
        }
        assert!(found > 100, "{found}");
    }

    #[test]
    fn a_rightward_run_finds_each_column_mean_once() {
        let memo = ColumnMemo::default();
        let calls = Cell::new(0);
        let find = |x: usize| {
            calls.set(calls.get() + 1);
            [x as f64; 4]
        };
        // Four samples per column pair, across columns 0…9.
        for i in 0..36 {
            let x0 = i / 4;
            let (a, b) = memo.pair((x0, x0 + 1), (0.25, 0.5), find);
            assert_eq!((a[0], b[0]), (x0 as f64, (x0 + 1) as f64));
        }
        assert_eq!(calls.get(), 10);
        // Another interval is found anew.
        let (a, _) = memo.pair((8, 9), (0.25, 0.75), find);
        assert_eq!((a[0], calls.get()), (8.0, 12));
    }

    #[test]
    fn a_short_interval_tends_to_the_sample() {
        let tex = texture();
        let cols = TextureColumns::new(&tex);
        for &(u, v) in &[(0.3, 0.5), (0.61, 0.07), (0.99, 0.93)] {
            let (point, near) = (tex.sample(u, v), cols.mean(&tex, u, v - 1e-7, v + 1e-7));
            assert_eq!(cols.mean(&tex, u, v, v), point);
            for c in 0..4 {
                assert!((point[c] - near[c]).abs() < 1e-5, "{point:?} {near:?}");
            }
        }
        // An inconsistent texture (texel count not width × height) is transparent, no panic.
        let bad = Texture {
            width: 2,
            height: 2,
            texels: vec![[1.0; 4]],
        };
        let cols = TextureColumns::new(&bad);
        assert_eq!(cols.mean(&bad, 0.9, 0.1, 0.9), [0.0; 4]);
    }
}
