//! Stage 5 (analysis), transfer characteristics: the height h(D; α) at which the ray of apparent
//! elevation α passes ground distance D, and what follows from it.
//!
//! In: a [`Tracer`], an observer height, a sampled fan of elevations. Out: every image of a target
//! occupying heights [0, H] at distance D ([`find_images`]), and the apparent horizon
//! ([`apparent_horizon`]).
//!
//! An image is a maximal interval of α on which 0 ≤ h(D; α) ≤ H and h is monotone: where h has an
//! extremum inside the band the picture folds and a new image, of opposite orientation, starts
//! (the Fata Morgana's stacked erect/inverted strips). The sampled fan only brackets things; every
//! extremum is refined by golden-section search and every band edge (h = 0 or h = H, or the edge
//! where rays start to hit the ground before D) by bisection, each evaluation a fresh trace.
//! Features narrower than the fan spacing can still be missed: sample densely.

use serde::Serialize;

use crate::tracer::{RayRecord, StratifiedIndex, Termination, Tracer};

/// Where a ray is at ground distance D.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Reach {
    /// It passes D at this height (m).
    Height(f64),
    /// It hit the ground before D.
    GroundBefore,
    /// It left the top of the atmosphere before D.
    EscapedBefore,
    /// It stopped before D for another reason (step limits, non-finite field, ...).
    Unknown,
}

impl Reach {
    /// From a traced record and the index of D among its distances.
    pub fn from_record(record: &RayRecord, index: usize) -> Reach {
        match record.heights_m.get(index).copied().flatten() {
            Some(h) => Reach::Height(h),
            None => match record.termination {
                Some(Termination::Ground) => Reach::GroundBefore,
                Some(Termination::Escaped) => Reach::EscapedBefore,
                _ => Reach::Unknown,
            },
        }
    }

    /// The height as an extended real: −∞ below ground, +∞ above the top, NaN unknown.
    pub fn value(self) -> f64 {
        match self {
            Reach::Height(h) => h,
            Reach::GroundBefore => f64::NEG_INFINITY,
            Reach::EscapedBefore => f64::INFINITY,
            Reach::Unknown => f64::NAN,
        }
    }
}

/// h(D; α) sampled on a fan of ascending elevations.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TransferCurve {
    /// Ground distance D (m).
    pub distance_m: f64,
    /// Apparent elevations (rad), ascending.
    pub elevations_rad: Vec<f64>,
    /// Where each ray is at D.
    pub reach: Vec<Reach>,
}

/// One image of a target [0, H] at distance D: a monotone piece of h(D; α) inside the band.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Image {
    /// Target distance (m).
    pub distance_m: f64,
    /// Target height H (m).
    pub height_m: f64,
    /// Centre of the image's elevation interval (deg).
    pub elevation_deg: f64,
    /// Lowest apparent elevation of the image (deg).
    pub elevation_min_deg: f64,
    /// Highest apparent elevation of the image (deg).
    pub elevation_max_deg: f64,
    /// Erect (h increases with α) or inverted.
    pub erect: bool,
    /// Target height seen at the image's lower edge (m).
    pub height_at_min_m: f64,
    /// Target height seen at the image's upper edge (m).
    pub height_at_max_m: f64,
    /// Mean vertical magnification: D·Δα / |Δh|, the image's angular height relative to the
    /// angular height the covered part of the target would have seen straight at distance D
    /// (1 = no distortion, > 1 stretched, < 1 compressed).
    pub magnification: f64,
}

/// Height at D of the ray at `alpha` (one fresh trace stopping at D).
fn probe<S: StratifiedIndex + ?Sized>(tracer: &Tracer<'_, S>, h0: f64, alpha: f64, d: f64) -> f64 {
    match tracer.trace(h0, alpha, &[d]) {
        Ok(r) => Reach::from_record(&r, 0).value(),
        Err(_) => f64::NAN,
    }
}

/// Bisection on `above(α)`; `lo` is false, `hi` is true. Returns the final bracket.
fn bisect(mut lo: f64, mut hi: f64, mut above: impl FnMut(f64) -> bool) -> (f64, f64) {
    for _ in 0..80 {
        if (hi - lo).abs() < 1e-11 {
            break;
        }
        let mid = 0.5 * (lo + hi);
        if above(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    (lo, hi)
}

/// A point of the refined curve: the value just left and just right of it (different only at
/// jumps and at bisected band edges), and whether it is an extremum.
#[derive(Debug, Clone, Copy)]
struct Node {
    alpha: f64,
    left: f64,
    right: f64,
    extremum: bool,
}

/// Golden-section search for the extremum of `g` in [a, c] (maximum if `max`).
fn golden(mut a: f64, mut c: f64, max: bool, mut g: impl FnMut(f64) -> f64) -> (f64, f64) {
    let sign = if max { -1.0 } else { 1.0 };
    let r = 0.5 * (5f64.sqrt() - 1.0);
    let mut x1 = c - r * (c - a);
    let mut x2 = a + r * (c - a);
    let mut f1 = sign * g(x1);
    let mut f2 = sign * g(x2);
    for _ in 0..100 {
        if (c - a).abs() < 1e-11 {
            break;
        }
        if f1 < f2 || f2.is_nan() {
            c = x2;
            x2 = x1;
            f2 = f1;
            x1 = c - r * (c - a);
            f1 = sign * g(x1);
        } else {
            a = x1;
            x1 = x2;
            f1 = f2;
            x2 = a + r * (c - a);
            f2 = sign * g(x2);
        }
    }
    if f1 < f2 {
        (x1, sign * f1)
    } else {
        (x2, sign * f2)
    }
}

/// Every image of a target occupying heights [0, `height_m`] at the curve's distance, refined on
/// `tracer` (whose config should stop rays at the last target) from observer height `h0`.
pub fn find_images<S: StratifiedIndex + ?Sized>(
    tracer: &Tracer<'_, S>,
    observer_height_m: f64,
    curve: &TransferCurve,
    height_m: f64,
) -> Vec<Image> {
    let d = curve.distance_m;
    let g = |alpha: f64| probe(tracer, observer_height_m, alpha, d);
    let a = &curve.elevations_rad;
    let v: Vec<f64> = curve.reach.iter().map(|r| r.value()).collect();
    let n = a.len();
    if n < 2 {
        return Vec::new();
    }
    // 1. Samples and refined extrema.
    let mut nodes: Vec<Node> = Vec::with_capacity(n + 8);
    for i in 0..n {
        nodes.push(Node {
            alpha: a[i],
            left: v[i],
            right: v[i],
            extremum: false,
        });
        if i + 2 < n {
            let (p, q, r) = (v[i], v[i + 1], v[i + 2]);
            if p.is_finite() && q.is_finite() && r.is_finite() && (q - p) * (r - q) < 0.0 {
                let max = q > p;
                let (ae, ge) = golden(a[i], a[i + 2], max, g);
                if ge.is_finite() {
                    // Replaces sample i+1 as the turning point; the sample stays as a node too.
                    nodes.push(Node {
                        alpha: ae,
                        left: ge,
                        right: ge,
                        extremum: true,
                    });
                }
            }
        }
    }
    nodes.sort_by(|x, y| x.alpha.total_cmp(&y.alpha));
    // 2. Band edges between consecutive nodes.
    let mut refined: Vec<Node> = Vec::with_capacity(nodes.len() * 2);
    for w in 0..nodes.len() {
        let cur = nodes[w];
        refined.push(cur);
        if w + 1 == nodes.len() {
            break;
        }
        let nxt = nodes[w + 1];
        let (lo_v, hi_v) = (cur.right, nxt.left);
        if lo_v.is_nan() || hi_v.is_nan() {
            continue;
        }
        let mut edges: Vec<Node> = Vec::new();
        for level in [0.0, height_m] {
            let below_lo = lo_v < level;
            let below_hi = hi_v < level;
            if below_lo != below_hi {
                // above(α): h(α) ≥ level on the side where the right end is.
                let rising = below_lo;
                let (l, r) = bisect(cur.alpha, nxt.alpha, |x| {
                    let h = g(x);
                    if rising { h >= level } else { h < level }
                });
                let (vl, vr) = (g(l), g(r));
                edges.push(Node {
                    alpha: 0.5 * (l + r),
                    left: vl,
                    right: vr,
                    extremum: false,
                });
            }
        }
        edges.sort_by(|x, y| x.alpha.total_cmp(&y.alpha));
        refined.extend(edges);
    }
    // 3. Segments inside the band, merged into monotone images.
    let in_band = |x: f64| (0.0..=height_m).contains(&x);
    let mut images = Vec::new();
    let mut open: Option<(Node, Node)> = None; // (first node, last node)
    let close = |first: Node, last: Node, images: &mut Vec<Image>| {
        let (h_lo, h_hi) = (first.right, last.left);
        let dh = h_hi - h_lo;
        if last.alpha <= first.alpha || dh == 0.0 {
            return;
        }
        let (amin, amax) = (first.alpha.to_degrees(), last.alpha.to_degrees());
        images.push(Image {
            distance_m: d,
            height_m,
            elevation_deg: 0.5 * (amin + amax),
            elevation_min_deg: amin,
            elevation_max_deg: amax,
            erect: dh > 0.0,
            height_at_min_m: h_lo,
            height_at_max_m: h_hi,
            magnification: d * (last.alpha - first.alpha) / dh.abs(),
        });
    };
    for w in 0..refined.len().saturating_sub(1) {
        let (p, q) = (refined[w], refined[w + 1]);
        let inside = in_band(p.right) && in_band(q.left);
        match (&mut open, inside) {
            (Some((first, last)), true) => {
                if p.extremum {
                    close(*first, *last, &mut images);
                    open = Some((p, q));
                } else {
                    *last = q;
                }
            }
            (Some((first, last)), false) => {
                close(*first, *last, &mut images);
                open = None;
            }
            (None, true) => open = Some((p, q)),
            (None, false) => {}
        }
    }
    if let Some((first, last)) = open {
        close(first, last, &mut images);
    }
    images
}

/// The lowest apparent elevation whose ray is not stopped by the ground before ground distance
/// `distance_m` (`None`: before it ends at all — the sea horizon). `clear[i]` says whether the
/// fan ray `elevations_rad[i]` (ascending) qualifies; the lowest qualifying fan ray and the one
/// below it bracket the horizon, which is refined by bisection on fresh traces. `None` if the
/// lowest fan ray already qualifies (the horizon is below the fan) or none does.
pub fn apparent_horizon<S: StratifiedIndex + ?Sized>(
    tracer: &Tracer<'_, S>,
    observer_height_m: f64,
    elevations_rad: &[f64],
    clear: &[bool],
    distance_m: Option<f64>,
) -> Option<f64> {
    let targets: Vec<f64> = distance_m.into_iter().collect();
    let is_clear = |alpha: f64| match tracer.trace(observer_height_m, alpha, &targets) {
        Ok(r) => match distance_m {
            Some(_) => r.heights_m[0].is_some(),
            None => r.termination != Some(Termination::Ground),
        },
        Err(_) => false,
    };
    let first = clear.iter().position(|&c| c)?;
    if first == 0 || first >= elevations_rad.len() {
        return None;
    }
    let (_, hi) = bisect(elevations_rad[first - 1], elevations_rad[first], is_clear);
    Some(hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bisect_brackets_the_switch() {
        let (lo, hi) = bisect(0.0, 1.0, |x| x >= 0.3);
        assert!(lo < 0.3 && hi >= 0.3 && hi - lo < 1e-10);
    }

    #[test]
    fn golden_finds_maximum_and_minimum() {
        let (x, v) = golden(0.0, 2.0, true, |x| -(x - 1.2) * (x - 1.2) + 3.0);
        assert!((x - 1.2).abs() < 1e-5 && (v - 3.0).abs() < 1e-9);
        let (x, _) = golden(0.0, 2.0, false, |x| (x - 0.4) * (x - 0.4));
        assert!((x - 0.4).abs() < 1e-5);
    }

    #[test]
    fn reach_values_order_ground_below_and_escape_above() {
        assert_eq!(Reach::GroundBefore.value(), f64::NEG_INFINITY);
        assert_eq!(Reach::EscapedBefore.value(), f64::INFINITY);
        assert!(Reach::Unknown.value().is_nan());
        assert_eq!(Reach::Height(3.5).value(), 3.5);
    }

    struct Homogeneous;
    impl StratifiedIndex for Homogeneous {
        fn index_and_derivative(&self, _h: f64) -> (f64, f64) {
            (1.0, 0.0)
        }
    }

    #[test]
    fn straight_rays_see_one_erect_image_with_unit_magnification() {
        let tracer = Tracer::new(&Homogeneous, crate::tracer::TracerConfig::default()).unwrap();
        let elevations: Vec<f64> = (0..51)
            .map(|i| (-0.2 + 0.02 * i as f64).to_radians())
            .collect();
        let records = tracer.trace_fan(3.0, &elevations, &[1_000.0]).unwrap();
        let curve = TransferCurve {
            distance_m: 1_000.0,
            elevations_rad: elevations,
            reach: records.iter().map(|r| Reach::from_record(r, 0)).collect(),
        };
        let images = find_images(&tracer, 3.0, &curve, 5.0);
        assert_eq!(images.len(), 1);
        assert!(images[0].erect);
        assert!((images[0].magnification - 1.0).abs() < 0.01);
        assert!((images[0].height_at_max_m - 5.0).abs() < 1e-6);
    }
}
