//! Stage 2 — smooth-layer fit, the paper's form. In: a measured [`Sounding`]. Out: a
//! [`StepFit`]: surface temperature and pressure, a background lapse rate and N smooth layers
//! (centre, thickness, ΔT: T += ΔT·½·(1 + tanh((h − centre)/(L/4))), as in `data/*.toml`), N being
//! the number of inversions `profile` detects in the fitted range; least squares on T(h).
//!
//! Method (variable projection, as [`super::layer_fit`]): for given centres and thicknesses the
//! surface temperature, lapse rate and the ΔT of every layer are a small linear least-squares
//! problem (normal equations, solved by Gaussian elimination: (N + 2)² unknowns, no matrix crate
//! needed); the centres and thicknesses are optimised over that reduced residual by argmin's
//! Nelder–Mead solver, started from the detected inversions' bounds.

use std::path::Path;

use argmin::core::{CostFunction, Executor, State};
use argmin::solver::neldermead::NelderMead;

use super::layer_fit::{LayerFitOptions, LevelResidual};
use super::{FitOptions, InversionOptions, Profile, ProfileError, SyntheticAtmosphere};
use crate::sounding::Sounding;

/// One smooth layer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepLayer {
    /// Centre (m above mean sea level).
    pub centre_m: f64,
    /// Thickness L (m): 96 % of the change happens inside it.
    pub thickness_m: f64,
    /// Temperature change across the layer (K).
    pub delta_t_k: f64,
}

impl StepLayer {
    /// The layer's share of its change at height `h_m`: ½·(1 + tanh((h − centre)/(L/4))).
    pub fn step(&self, h_m: f64) -> f64 {
        0.5 * (1.0 + ((h_m - self.centre_m) / (0.25 * self.thickness_m)).tanh())
    }
}

/// The result of [`fit_steps`].
#[derive(Debug, Clone)]
pub struct StepFit {
    /// Height of the surface (m above mean sea level): the sounding's lowest level.
    pub surface_height_m: f64,
    /// Surface temperature (K) of the synthetic atmosphere.
    pub surface_temperature_k: f64,
    /// Surface pressure (Pa): the lowest level's, or 1013.25 hPa if it has none.
    pub surface_pressure_pa: f64,
    /// Background lapse rate (K m⁻¹).
    pub lapse_k_per_m: f64,
    /// The smooth layers, lowest centre first.
    pub layers: Vec<StepLayer>,
    /// One entry per level inside the fitted range.
    pub residuals: Vec<LevelResidual>,
    /// RMS of the residuals (K).
    pub rms_k: f64,
    /// Largest |residual| (K).
    pub max_abs_k: f64,
    /// RMS (K) of one straight line over the same levels: the baseline to beat.
    pub lapse_only_rms_k: f64,
}

/// Heights and temperatures of the levels in the fitted range.
struct Levels {
    h: Vec<f64>,
    t: Vec<f64>,
    h0: f64,
    /// Largest minus smallest temperature of the levels (K).
    range_k: f64,
}

/// Fit the paper's form to `sounding` over the options' height range (`max_layers` caps N,
/// `min_thickness_m` bounds every layer's thickness from below, the range's height from
/// above). `level_weights` is not used: every level counts alike.
pub fn fit_steps(sounding: &Sounding, options: &LayerFitOptions) -> Result<StepFit, ProfileError> {
    super::layer_fit::check_options(options)?;
    let d = levels(sounding, options)?;
    let start = initial_layers(sounding, options, &d)?;
    let problem = Reduced {
        d: &d,
        min_thickness_m: options.min_thickness_m,
        max_thickness_m: (d.h[d.h.len() - 1] - d.h[0]).max(options.min_thickness_m),
    };
    let params: Vec<f64> = start
        .iter()
        .flat_map(|l| [l.centre_m, l.thickness_m])
        .collect();
    let best = if params.is_empty() {
        params
    } else {
        optimise(problem.clone(), params, options.max_iterations).map_err(|e| {
            ProfileError::LayerFitFailed {
                path: sounding.source.clone(),
                message: e.to_string(),
            }
        })?
    };
    let shapes = problem.shapes(&best);
    let (x, _) = solve(&d, &shapes);
    Ok(assemble(sounding, &d, &shapes, &x))
}

fn levels(s: &Sounding, o: &LayerFitOptions) -> Result<Levels, ProfileError> {
    let h0 = s.levels.first().map_or(f64::NAN, |l| l.height_m);
    let (lo, hi) = (
        h0 + o.range_bottom_above_surface_m,
        h0 + o.range_top_above_surface_m,
    );
    let (h, t): (Vec<f64>, Vec<f64>) = s
        .levels
        .iter()
        .filter(|l| l.height_m >= lo && l.height_m <= hi && l.temperature_k.is_finite())
        .map(|l| (l.height_m, l.temperature_k))
        .unzip();
    if h.len() < 2 {
        return Err(ProfileError::BadSounding {
            path: s.source.clone(),
            line: s.levels.first().map_or(0, |l| l.line),
            message: format!(
                "{} usable levels between {lo:.0} m and {hi:.0} m; a layer fit needs at least 2",
                h.len()
            ),
        });
    }
    let range_k = t.iter().copied().fold(f64::NEG_INFINITY, f64::max)
        - t.iter().copied().fold(f64::INFINITY, f64::min);
    Ok(Levels { h, t, h0, range_k })
}

/// One layer per inversion `profile` detects in the range (at most `max_layers`, the strongest
/// kept), started at its bounds and temperature change.
fn initial_layers(
    s: &Sounding,
    o: &LayerFitOptions,
    d: &Levels,
) -> Result<Vec<StepLayer>, ProfileError> {
    let profile = Profile::from_sounding(s, &FitOptions::default())?;
    let top = d.h[d.h.len() - 1];
    let mut inversions = super::detect_inversions(&profile, top, &InversionOptions::default());
    inversions.sort_by(|a, b| b.delta_t_k.total_cmp(&a.delta_t_k));
    inversions.truncate(o.max_layers);
    let mut layers: Vec<StepLayer> = inversions
        .iter()
        .map(|i| StepLayer {
            centre_m: 0.5 * (i.base_m + i.top_m),
            thickness_m: (i.top_m - i.base_m).max(o.min_thickness_m),
            delta_t_k: i.delta_t_k,
        })
        .collect();
    layers.sort_by(|a, b| a.centre_m.total_cmp(&b.centre_m));
    Ok(layers)
}

#[derive(Clone)]
struct Reduced<'a> {
    d: &'a Levels,
    min_thickness_m: f64,
    /// The fitted range's height: no layer is thicker.
    max_thickness_m: f64,
}

impl Reduced<'_> {
    /// (centre, thickness) pairs → layers (ΔT to be solved), thickness kept ≥ the minimum.
    fn shapes(&self, p: &[f64]) -> Vec<StepLayer> {
        p.chunks_exact(2)
            .map(|c| StepLayer {
                centre_m: if c[0].is_finite() { c[0] } else { self.d.h0 },
                thickness_m: if c[1].is_finite() {
                    c[1].abs().clamp(self.min_thickness_m, self.max_thickness_m)
                } else {
                    self.min_thickness_m
                },
                delta_t_k: 0.0,
            })
            .collect()
    }
}

impl CostFunction for Reduced<'_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, p: &Vec<f64>) -> Result<f64, argmin::core::Error> {
        let (x, sse) = solve(self.d, &self.shapes(p));
        // Two layers at one place with opposite large ΔT fit sparse levels as well as one: no
        // layer may change the temperature by more than the levels' whole range (plus 1 K).
        let excess: f64 = x[2..]
            .iter()
            .map(|dt| (dt.abs() - self.d.range_k - 1.0).max(0.0).powi(2))
            .sum();
        Ok(sse + 1e3 * excess * self.d.h.len() as f64)
    }
}

fn optimise(
    problem: Reduced<'_>,
    init: Vec<f64>,
    max_iterations: u64,
) -> Result<Vec<f64>, argmin::core::Error> {
    let mut simplex = vec![init.clone()];
    for i in 0..init.len() {
        let mut v = init.clone();
        // Centres move by a few metres, thicknesses by a quarter.
        v[i] += if i % 2 == 0 {
            5.0
        } else {
            0.25 * init[i].abs().max(5.0)
        };
        simplex.push(v);
    }
    let solver = NelderMead::new(simplex).with_sd_tolerance(1e-12)?;
    let result = Executor::new(problem, solver)
        .configure(|s| s.max_iters(max_iterations))
        .run()?;
    Ok(result.state().get_best_param().cloned().unwrap_or(init))
}

/// The basis at height `h`: 1, h − h0, then each layer's step.
fn basis(d: &Levels, shapes: &[StepLayer], h: f64) -> Vec<f64> {
    let mut row = vec![1.0, h - d.h0];
    row.extend(shapes.iter().map(|l| l.step(h)));
    row
}

/// Least-squares [a, b, ΔT…] for the given shapes, and the residual sum of squares.
fn solve(d: &Levels, shapes: &[StepLayer]) -> (Vec<f64>, f64) {
    let n = shapes.len() + 2;
    let (mut ata, mut atb) = (vec![vec![0.0; n]; n], vec![0.0; n]);
    for (&h, &t) in d.h.iter().zip(&d.t) {
        let row = basis(d, shapes, h);
        for i in 0..n {
            atb[i] += row[i] * t;
            for j in 0..n {
                ata[i][j] += row[i] * row[j];
            }
        }
    }
    // A tiny ridge keeps a layer with no level inside it determined (ΔT → 0).
    let scale = d.h.len() as f64;
    for (i, r) in ata.iter_mut().enumerate().skip(2) {
        r[i] += 1e-9 * scale;
    }
    let x = gauss(ata, atb);
    let sse =
        d.h.iter()
            .zip(&d.t)
            .map(|(&h, &t)| (dot(&basis(d, shapes, h), &x) - t).powi(2))
            .sum();
    (x, sse)
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Gaussian elimination with partial pivoting (hand-written: a dozen unknowns at most).
fn gauss(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Vec<f64> {
    let n = b.len();
    for col in 0..n {
        let pivot = (col..n)
            .max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))
            .unwrap_or(col);
        a.swap(col, pivot);
        b.swap(col, pivot);
        let p = a[col][col];
        if p.abs() < 1e-300 {
            continue;
        }
        let pivot_row = a[col].clone();
        for row in col + 1..n {
            let f = a[row][col] / p;
            for (v, &q) in a[row].iter_mut().zip(&pivot_row).skip(col) {
                *v -= f * q;
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = vec![0.0; n];
    for row in (0..n).rev() {
        let s: f64 = (row + 1..n).map(|k| a[row][k] * x[k]).sum();
        x[row] = if a[row][row].abs() < 1e-300 {
            0.0
        } else {
            (b[row] - s) / a[row][row]
        };
    }
    x
}

fn assemble(s: &Sounding, d: &Levels, shapes: &[StepLayer], x: &[f64]) -> StepFit {
    let layers: Vec<StepLayer> = shapes
        .iter()
        .zip(&x[2..])
        .map(|(l, &dt)| StepLayer {
            delta_t_k: dt,
            ..*l
        })
        .collect();
    let model = |h: f64| dot(&basis(d, shapes, h), x);
    let residuals: Vec<LevelResidual> =
        d.h.iter()
            .zip(&d.t)
            .map(|(&h, &t)| LevelResidual {
                height_m: h,
                measured_k: t,
                fitted_k: model(h),
            })
            .collect();
    let n = residuals.len().max(1) as f64;
    let sq = |r: &LevelResidual| (r.fitted_k - r.measured_k).powi(2);
    let (_, line_sse) = solve(d, &[]);
    StepFit {
        surface_height_m: d.h0,
        surface_temperature_k: model(d.h0),
        surface_pressure_pa: s.levels[0].pressure_pa.unwrap_or(101_325.0),
        lapse_k_per_m: x[1],
        rms_k: (residuals.iter().map(sq).sum::<f64>() / n).sqrt(),
        max_abs_k: residuals
            .iter()
            .map(|r| (r.fitted_k - r.measured_k).abs())
            .fold(0.0, f64::max),
        residuals,
        lapse_only_rms_k: (line_sse / n).sqrt(),
        layers,
    }
}

impl StepFit {
    /// The fit as a synthetic TOML in the form of `data/*.toml` (`centre_m`, `thickness_m`,
    /// `delta_t_k` layers on a lapse-rate background), which every command accepts.
    pub fn to_toml(&self) -> String {
        let mut out = format!(
            "description = \"smooth-layer fit: {} layers, rms {:.3} K\"\nsurface_height_m = {:?}\n\
             surface_temperature_c = {:?}\nsurface_pressure_hpa = {:?}\nbackground = {:?}\n",
            self.layers.len(),
            self.rms_k,
            self.surface_height_m,
            self.surface_temperature_k - 273.15,
            self.surface_pressure_pa / 100.0,
            self.lapse_k_per_m,
        );
        for l in &self.layers {
            out += &format!(
                "\n[[layers]]\ncentre_m = {:?}\nthickness_m = {:?}\ndelta_t_k = {:?}\n",
                l.centre_m, l.thickness_m, l.delta_t_k
            );
        }
        out
    }

    /// The fit as the project's synthetic atmosphere (parsed from [`StepFit::to_toml`]).
    pub fn to_synthetic(&self) -> Result<SyntheticAtmosphere, ProfileError> {
        SyntheticAtmosphere::from_toml_str(&self.to_toml(), Path::new("<smooth-layer fit>"))
    }
}
