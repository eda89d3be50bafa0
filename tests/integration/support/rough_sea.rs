//! An independent model of a wind-roughened sea's reflections, written from the physics the
//! renderer documents (docs/scene.md, `[sea]`), not from its code: straight rays over a sphere,
//! Cox–Munk facets whose along-ray tilt s is Gaussian with rms σ′ = tan(rms slope)/√2, seen in
//! proportion to their projected area sin(g + s) (none facing away, g + s ≤ 0), each sending the
//! ray up at g + 2s (at 0 if that is below the horizontal: it skims the sea) with the Fresnel
//! reflectance of its own incidence. Integrated by the midpoint rule over many slopes.

/// Unpolarised Fresnel reflectance from air into water of index `n` at grazing angle `g`.
pub fn fresnel(g: f64, n: f64) -> f64 {
    let cos_i = g.clamp(0.0, std::f64::consts::FRAC_PI_2).sin();
    let cos_t = (1.0 - (1.0 - cos_i * cos_i) / (n * n)).sqrt();
    let rs = (cos_i - n * cos_t) / (cos_i + n * cos_t);
    let rp = (cos_t - n * cos_i) / (cos_t + n * cos_i);
    0.5 * (rs * rs + rp * rp)
}

/// Where a straight ray from a camera `camera_m` above a sphere of `radius_m`, leaving at
/// elevation `alpha` (< 0), meets it: the ground distance (m) and the grazing angle (rad).
pub fn straight_sea_hit(camera_m: f64, alpha: f64, radius_m: f64) -> Option<(f64, f64)> {
    let c = radius_m + camera_m;
    let (sa, ca) = alpha.sin_cos();
    let disc = c * c * sa * sa - (c * c - radius_m * radius_m);
    if alpha >= 0.0 || disc < 0.0 {
        return None;
    }
    let t = -c * sa - disc.sqrt();
    let (x, y) = (t * ca, c + t * sa);
    let grazing = (-(x * ca + y * sa) / radius_m).asin();
    Some((radius_m * x.atan2(y), grazing))
}

/// Height (m) at ground range `range_m` of a straight ray leaving the surface of a sphere of
/// `radius_m` at elevation `e` (`None` once it would have to pass the sphere's far side).
pub fn straight_height_m(e: f64, range_m: f64, radius_m: f64) -> Option<f64> {
    let angle = e + range_m / radius_m;
    (angle < std::f64::consts::FRAC_PI_2).then(|| radius_m * e.cos() / angle.cos() - radius_m)
}

/// What the sea adds to its sky reflection along a ray meeting it at grazing angle `g`, when a
/// ray reflected up at elevation e adds `extra(e)` over the sky it would otherwise show: the
/// facet-weighted, Fresnel-weighted mean of `extra` over `samples` slopes from −g to 8σ′.
pub fn blurred_reflection(
    g: f64,
    sigma_along: f64,
    water_index: f64,
    samples: usize,
    extra: impl Fn(f64) -> [f64; 3],
) -> [f64; 3] {
    let (lo, hi) = (-g, 8.0 * sigma_along);
    let ds = (hi - lo) / samples as f64;
    let (mut total, mut sum) = (0.0, [0.0; 3]);
    for i in 0..samples {
        let s = lo + (i as f64 + 0.5) * ds;
        let w = (g + s).sin() * (-0.5 * (s / sigma_along).powi(2)).exp();
        total += w;
        let f = fresnel(g + s, water_index);
        let x = extra((g + 2.0 * s).max(0.0));
        for c in 0..3 {
            sum[c] += w * f * x[c];
        }
    }
    sum.map(|v| v / total)
}

/// Assert that a rendered column profile (what an image adds to the sea, row by row) matches
/// the `expected` one: in every row within 0.5 % of the image's `strongest` value (the
/// renderer's tables of the slope distribution) plus, through the fan (`exact` false), 0.15 of
/// the expected profile's change over a row there (the fan places features to 0.1 pixel, flat
/// rows to 0.01 more); the column's sum within 1 % in each channel.
pub fn assert_profile_matches(
    rendered: &[[f64; 3]],
    expected: &[[f64; 3]],
    strongest: f64,
    exact: bool,
) {
    let n = expected.len();
    let mut closest = 0.0f64;
    for y in 0..n {
        let (lo, hi) = (y.saturating_sub(1), (y + 1).min(n - 1));
        for c in 0..3 {
            let slope = 0.5 * (expected[hi][c] - expected[lo][c]).abs();
            let allowed = 0.005 * strongest + if exact { 0.0 } else { 0.15 * slope };
            let off = (rendered[y][c] - expected[y][c]).abs();
            closest = closest.max(off / allowed);
            assert!(
                off <= allowed,
                "exact={exact}: row {y} channel {c}: {} vs {} (off {off:.3e}, allowed \
                 {allowed:.3e})",
                rendered[y][c],
                expected[y][c]
            );
        }
    }
    eprintln!("exact={exact}: the worst row is off by {closest:.2} of what is allowed");
    for c in 0..3 {
        let sum_r: f64 = rendered.iter().map(|v| v[c]).sum();
        let sum_e: f64 = expected.iter().map(|v| v[c]).sum();
        assert!(
            (sum_r - sum_e).abs() <= 0.01 * sum_e.abs().max(strongest),
            "exact={exact} channel {c}: column sum {sum_r} vs {sum_e}"
        );
    }
}
