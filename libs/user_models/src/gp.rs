//! Gaussian-process regression on nalgebra, computed as scikit-learn's GaussianProcessRegressor
//! does (zero prior mean, no target normalisation, a small noise on the diagonal, Cholesky solve),
//! with the authors' RationalQuadratic kernel by default and RBF / Matérn selectable.
//! Hyperparameters maximise the log marginal likelihood with its analytic gradient, by a bounded
//! limited-memory quasi-Newton search in log space (as L-BFGS-B), from the initial values and
//! seeded log-uniform restarts.

use nalgebra::{DMatrix, DVector};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// A stationary kernel of the Euclidean distance d between two inputs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", deny_unknown_fields)]
pub enum Kernel {
    /// (1 + d² / (2 α l²))^-α
    RationalQuadratic { length_scale: f64, alpha: f64 },
    /// exp(-d² / (2 l²))
    Rbf { length_scale: f64 },
    /// Matérn with ν = 0.5, 1.5 or 2.5.
    Matern { length_scale: f64, nu: f64 },
}

impl Kernel {
    /// The authors' kernel and initial values.
    pub const AUTHORS: Kernel = Kernel::RationalQuadratic {
        length_scale: 1.0,
        alpha: 1.5,
    };

    pub fn name(&self) -> &'static str {
        match self {
            Kernel::RationalQuadratic { .. } => "RationalQuadratic",
            Kernel::Rbf { .. } => "RBF",
            Kernel::Matern { .. } => "Matern",
        }
    }

    /// Checks the hyperparameters: positive and finite, ν one of the closed forms.
    pub fn validate(&self) -> Result<(), GpError> {
        let bad = |what: &'static str, value: f64| GpError::Hyperparameter { what, value };
        let positive = |what, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(bad(what, v))
            }
        };
        match *self {
            Kernel::RationalQuadratic {
                length_scale,
                alpha,
            } => {
                positive("length_scale", length_scale)?;
                positive("alpha", alpha)
            }
            Kernel::Rbf { length_scale } => positive("length_scale", length_scale),
            Kernel::Matern { length_scale, nu } => {
                positive("length_scale", length_scale)?;
                if [0.5, 1.5, 2.5].contains(&nu) {
                    Ok(())
                } else {
                    Err(bad("nu (0.5, 1.5 or 2.5)", nu))
                }
            }
        }
    }

    /// k(d²).
    pub fn eval(&self, d2: f64) -> f64 {
        self.eval_with_gradient(d2).0
    }

    /// k(d²) and its derivatives with respect to the log hyperparameters ([`Kernel::theta`]).
    pub fn eval_with_gradient(&self, d2: f64) -> (f64, [f64; 2]) {
        match *self {
            Kernel::RationalQuadratic {
                length_scale: l,
                alpha,
            } => {
                let base = 1.0 + d2 / (2.0 * alpha * l * l);
                let k = base.powf(-alpha);
                let d_log_l = k * d2 / (l * l * base);
                let d_log_alpha = k * (-alpha * base.ln() + d2 / (2.0 * l * l * base));
                (k, [d_log_l, d_log_alpha])
            }
            Kernel::Rbf { length_scale: l } => {
                let k = (-d2 / (2.0 * l * l)).exp();
                (k, [k * d2 / (l * l), 0.0])
            }
            Kernel::Matern {
                length_scale: l,
                nu,
            } => {
                let r = d2.sqrt() / l;
                if nu == 0.5 {
                    let k = (-r).exp();
                    (k, [k * r, 0.0])
                } else if nu == 1.5 {
                    let s = 3f64.sqrt() * r;
                    let e = (-s).exp();
                    ((1.0 + s) * e, [s * s * e, 0.0])
                } else {
                    let s = 5f64.sqrt() * r;
                    let e = (-s).exp();
                    (
                        (1.0 + s + s * s / 3.0) * e,
                        [s * s * (1.0 + s) * e / 3.0, 0.0],
                    )
                }
            }
        }
    }

    /// The optimised hyperparameters in log space: (ln l, ln α) or (ln l).
    pub fn theta(&self) -> Vec<f64> {
        match *self {
            Kernel::RationalQuadratic {
                length_scale,
                alpha,
            } => vec![length_scale.ln(), alpha.ln()],
            Kernel::Rbf { length_scale } | Kernel::Matern { length_scale, .. } => {
                vec![length_scale.ln()]
            }
        }
    }

    /// The same kernel with log hyperparameters `theta` (as many as [`Kernel::theta`] gives).
    pub fn with_theta(&self, theta: &[f64]) -> Kernel {
        let at = |i: usize| theta.get(i).copied().unwrap_or(0.0).exp();
        match *self {
            Kernel::RationalQuadratic { .. } => Kernel::RationalQuadratic {
                length_scale: at(0),
                alpha: at(1),
            },
            Kernel::Rbf { .. } => Kernel::Rbf {
                length_scale: at(0),
            },
            Kernel::Matern { nu, .. } => Kernel::Matern {
                length_scale: at(0),
                nu,
            },
        }
    }
}

/// What a GP could not do.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GpError {
    #[error("no training points: a GP needs at least one")]
    NoData,
    #[error("training inputs and targets differ in length ({inputs} vs {targets})")]
    Shape { inputs: usize, targets: usize },
    #[error("training point {index} has {found} dimensions, the first has {expected}")]
    Ragged {
        index: usize,
        expected: usize,
        found: usize,
    },
    #[error("training point {index} is not finite")]
    NotFinite { index: usize },
    #[error("kernel {what} = {value} is not allowed")]
    Hyperparameter { what: &'static str, value: f64 },
    #[error("noise = {0} must be finite and >= 0")]
    Noise(f64),
    #[error("noise scale of training point {index} = {value} must be finite and > 0")]
    NoiseScale { index: usize, value: f64 },
    #[error("the kernel matrix is not positive definite (kernel {kernel:?}, noise {noise})")]
    NotPositiveDefinite { kernel: Kernel, noise: f64 },
    #[error("input has {found} dimensions, the GP was trained on {expected}")]
    Dimension { expected: usize, found: usize },
}

/// How the hyperparameters are searched.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OptimiserOptions {
    /// Bounds of every hyperparameter (not log).
    pub bounds: (f64, f64),
    /// Seeded log-uniform starts besides the initial values (scikit-learn's
    /// `n_restarts_optimizer`).
    pub restarts: usize,
    pub seed: u64,
}

impl Default for OptimiserOptions {
    fn default() -> Self {
        OptimiserOptions {
            bounds: (1e-5, 1e5),
            restarts: 0,
            seed: 0,
        }
    }
}

/// A fitted GP: training data, kernel, and the Cholesky factor and weights of the solve.
#[derive(Debug, Clone)]
pub struct GaussianProcess {
    kernel: Kernel,
    noise: f64,
    /// Per training point, what multiplies `noise` on the diagonal (1 for every point but in
    /// [`GaussianProcess::fit_scaled`]: 1 / n for a target that is a mean of n values).
    noise_scale: Vec<f64>,
    x: Vec<Vec<f64>>,
    /// Lower Cholesky factor of K + noise·I.
    l: DMatrix<f64>,
    y: DVector<f64>,
    /// (K + noise·I)^-1 y.
    alpha: DVector<f64>,
    log_marginal_likelihood: f64,
}

fn sq_dist(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(p, q)| (p - q) * (p - q)).sum()
}

fn check_scale(x: &[Vec<f64>], scale: &[f64]) -> Result<(), GpError> {
    if scale.len() != x.len() {
        return Err(GpError::Shape {
            inputs: x.len(),
            targets: scale.len(),
        });
    }
    match scale.iter().position(|v| !(v.is_finite() && *v > 0.0)) {
        Some(i) => Err(GpError::NoiseScale {
            index: i,
            value: scale[i],
        }),
        None => Ok(()),
    }
}

fn check(x: &[Vec<f64>], y: &[f64], noise: f64) -> Result<(), GpError> {
    let first = x.first().ok_or(GpError::NoData)?;
    if x.len() != y.len() {
        return Err(GpError::Shape {
            inputs: x.len(),
            targets: y.len(),
        });
    }
    for (index, (row, target)) in x.iter().zip(y).enumerate() {
        if row.len() != first.len() {
            return Err(GpError::Ragged {
                index,
                expected: first.len(),
                found: row.len(),
            });
        }
        if !target.is_finite() || row.iter().any(|v| !v.is_finite()) {
            return Err(GpError::NotFinite { index });
        }
    }
    if !(noise.is_finite() && noise >= 0.0) {
        return Err(GpError::Noise(noise));
    }
    Ok(())
}

/// Squared distances between all training points (they do not change during the search).
fn distances(x: &[Vec<f64>]) -> DMatrix<f64> {
    DMatrix::from_fn(x.len(), x.len(), |i, j| sq_dist(&x[i], &x[j]))
}

/// The noise on the kernel matrix's diagonal: `noise` times each point's scale, and whether
/// the gradient includes d/d ln(noise) (the noise is then a hyperparameter too, last).
#[derive(Debug, Clone, Copy)]
struct Diagonal<'a> {
    noise: f64,
    scale: &'a [f64],
    fitted: bool,
}

/// The log marginal likelihood and its gradient in log hyperparameters, or `None` where the
/// kernel matrix is not positive definite (scikit-learn then reports -inf).
fn lml_and_gradient(
    d2: &DMatrix<f64>,
    y: &DVector<f64>,
    kernel: Kernel,
    diagonal: Diagonal,
) -> Option<(f64, Vec<f64>)> {
    let n = y.len();
    let dims = kernel.theta().len();
    let mut k = DMatrix::zeros(n, n);
    let mut dk = vec![DMatrix::zeros(n, n); dims];
    for j in 0..n {
        for i in j..n {
            let (v, g) = kernel.eval_with_gradient(d2[(i, j)]);
            k[(i, j)] = v;
            k[(j, i)] = v;
            for (m, gm) in dk.iter_mut().zip(g) {
                m[(i, j)] = gm;
                m[(j, i)] = gm;
            }
        }
        k[(j, j)] += diagonal.noise * diagonal.scale.get(j).copied().unwrap_or(1.0);
    }
    let chol = k.cholesky()?;
    let alpha = chol.solve(y);
    let log_det_half: f64 = chol.l_dirty().diagonal().iter().map(|d| d.ln()).sum();
    let lml = -0.5 * y.dot(&alpha) - log_det_half - 0.5 * n as f64 * std::f64::consts::TAU.ln();
    // d lml / d theta = 1/2 tr((alpha alpha^T - K^-1) dK/dtheta)
    let inverse = chol.inverse();
    let mut gradient: Vec<f64> = dk
        .iter()
        .map(|m| {
            let mut sum = 0.0;
            for j in 0..n {
                for i in 0..n {
                    sum += (alpha[i] * alpha[j] - inverse[(i, j)]) * m[(i, j)];
                }
            }
            0.5 * sum
        })
        .collect();
    if diagonal.fitted {
        // dK / d ln(noise) is diagonal: noise times each point's scale.
        let sum: f64 = (0..n)
            .map(|i| {
                let d = diagonal.noise * diagonal.scale.get(i).copied().unwrap_or(1.0);
                (alpha[i] * alpha[i] - inverse[(i, i)]) * d
            })
            .sum();
        gradient.push(0.5 * sum);
    }
    Some((lml, gradient))
}

impl GaussianProcess {
    /// Fits with the kernel's hyperparameters as given.
    pub fn fit(x: Vec<Vec<f64>>, y: &[f64], kernel: Kernel, noise: f64) -> Result<Self, GpError> {
        let scale = vec![1.0; x.len()];
        GaussianProcess::fit_scaled(x, y, kernel, noise, scale)
    }

    /// Fits with the kernel's hyperparameters as given and `noise * noise_scale[i]` on the
    /// diagonal at point i (scikit-learn's `alpha` given per point).
    pub fn fit_scaled(
        x: Vec<Vec<f64>>,
        y: &[f64],
        kernel: Kernel,
        noise: f64,
        noise_scale: Vec<f64>,
    ) -> Result<Self, GpError> {
        check(&x, y, noise)?;
        check_scale(&x, &noise_scale)?;
        kernel.validate()?;
        let n = x.len();
        let k = DMatrix::from_fn(n, n, |i, j| {
            kernel.eval(sq_dist(&x[i], &x[j])) + if i == j { noise * noise_scale[i] } else { 0.0 }
        });
        let chol = k
            .cholesky()
            .ok_or(GpError::NotPositiveDefinite { kernel, noise })?;
        let yv = DVector::from_column_slice(y);
        let alpha = chol.solve(&yv);
        let l = chol.unpack();
        let log_det_half: f64 = l.diagonal().iter().map(|d| d.ln()).sum();
        let log_marginal_likelihood =
            -0.5 * yv.dot(&alpha) - log_det_half - 0.5 * n as f64 * std::f64::consts::TAU.ln();
        Ok(GaussianProcess {
            kernel,
            noise,
            noise_scale,
            x,
            l,
            y: yv,
            alpha,
            log_marginal_likelihood,
        })
    }

    /// Fits after choosing the hyperparameters that maximise the log marginal likelihood, from
    /// `initial` and `options.restarts` seeded log-uniform starts within the bounds.
    pub fn fit_optimised(
        x: Vec<Vec<f64>>,
        y: &[f64],
        initial: Kernel,
        noise: f64,
        options: &OptimiserOptions,
    ) -> Result<Self, GpError> {
        let scale = vec![1.0; x.len()];
        GaussianProcess::search(x, y, initial, noise, scale, false, options)
    }

    /// Fits after choosing the kernel's hyperparameters *and* the noise that maximise the log
    /// marginal likelihood (the noise is searched in log space within the same bounds, from
    /// `initial_noise`); point i gets `noise * noise_scale[i]` on the diagonal.
    pub fn fit_optimised_with_noise(
        x: Vec<Vec<f64>>,
        y: &[f64],
        initial: Kernel,
        initial_noise: f64,
        noise_scale: Vec<f64>,
        options: &OptimiserOptions,
    ) -> Result<Self, GpError> {
        GaussianProcess::search(x, y, initial, initial_noise, noise_scale, true, options)
    }

    fn search(
        x: Vec<Vec<f64>>,
        y: &[f64],
        initial: Kernel,
        noise: f64,
        noise_scale: Vec<f64>,
        fit_noise: bool,
        options: &OptimiserOptions,
    ) -> Result<Self, GpError> {
        check(&x, y, noise)?;
        check_scale(&x, &noise_scale)?;
        initial.validate()?;
        let (lo, hi) = options.bounds;
        if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi) {
            return Err(GpError::Hyperparameter {
                what: "bound",
                value: lo,
            });
        }
        if fit_noise && noise <= 0.0 {
            return Err(GpError::Noise(noise));
        }
        let (lo, hi) = (lo.ln(), hi.ln());
        let d2 = distances(&x);
        let yv = DVector::from_column_slice(y);
        let kernel_dims = initial.theta().len();
        // θ: the kernel's log hyperparameters, then ln(noise) when it is fitted.
        let split = |theta: &[f64]| -> (Kernel, f64) {
            let noise = if fit_noise {
                theta.get(kernel_dims).copied().unwrap_or(0.0).exp()
            } else {
                noise
            };
            (initial.with_theta(&theta[..kernel_dims]), noise)
        };
        // Minimised: the negative log marginal likelihood and its gradient.
        let objective = |theta: &[f64]| -> Option<(f64, Vec<f64>)> {
            let (kernel, noise) = split(theta);
            let diagonal = Diagonal {
                noise,
                scale: &noise_scale,
                fitted: fit_noise,
            };
            lml_and_gradient(&d2, &yv, kernel, diagonal)
                .map(|(v, g)| (-v, g.iter().map(|x| -x).collect()))
        };
        let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
        let mut first = initial.theta();
        if fit_noise {
            first.push(noise.ln().clamp(lo, hi));
        }
        let dims = first.len();
        let mut starts = vec![first.clone()];
        for _ in 0..options.restarts {
            starts.push((0..dims).map(|_| rng.random_range(lo..hi)).collect());
        }
        let mut best: Option<(f64, Vec<f64>)> = None;
        for start in starts {
            if let Some((theta, value)) = minimise_in_box(&objective, &start, lo, hi)
                && best.as_ref().is_none_or(|(b, _)| value < *b)
            {
                best = Some((value, theta));
            }
        }
        let theta = best.map_or(first, |b| b.1);
        let (kernel, noise) = split(&theta);
        GaussianProcess::fit_scaled(x, y, kernel, noise, noise_scale)
    }

    pub fn kernel(&self) -> Kernel {
        self.kernel
    }

    pub fn noise(&self) -> f64 {
        self.noise
    }

    pub fn log_marginal_likelihood(&self) -> f64 {
        self.log_marginal_likelihood
    }

    /// The gradient of the log marginal likelihood in log hyperparameters, at this GP's
    /// hyperparameters.
    pub fn log_marginal_likelihood_gradient(&self) -> Vec<f64> {
        let diagonal = Diagonal {
            noise: self.noise,
            scale: &self.noise_scale,
            fitted: false,
        };
        lml_and_gradient(&distances(&self.x), &self.y, self.kernel, diagonal)
            .map_or_else(|| vec![0.0; self.kernel.theta().len()], |(_, g)| g)
    }

    /// The gradient with respect to the kernel's log hyperparameters and, last, ln(noise).
    pub fn log_marginal_likelihood_gradient_with_noise(&self) -> Vec<f64> {
        let diagonal = Diagonal {
            noise: self.noise,
            scale: &self.noise_scale,
            fitted: true,
        };
        lml_and_gradient(&distances(&self.x), &self.y, self.kernel, diagonal)
            .map_or_else(|| vec![0.0; self.kernel.theta().len() + 1], |(_, g)| g)
    }

    pub fn training_inputs(&self) -> &[Vec<f64>] {
        &self.x
    }

    /// Posterior mean and standard deviation at `x` (the noise is not added to the variance).
    pub fn predict(&self, x: &[f64]) -> Result<(f64, f64), GpError> {
        let d = self.x.first().map_or(0, Vec::len);
        if x.len() != d {
            return Err(GpError::Dimension {
                expected: d,
                found: x.len(),
            });
        }
        let k_star = DVector::from_iterator(
            self.x.len(),
            self.x.iter().map(|xi| self.kernel.eval(sq_dist(xi, x))),
        );
        let mean = k_star.dot(&self.alpha);
        // L is lower triangular with a positive diagonal, so the solve exists.
        let v = self
            .l
            .solve_lower_triangular(&k_star)
            .unwrap_or_else(|| DVector::zeros(self.x.len()));
        let var = self.kernel.eval(0.0) - v.dot(&v);
        Ok((mean, var.max(0.0).sqrt()))
    }
}

/// Clamps `x` into the box [lo, hi]^n.
fn project(x: &[f64], lo: f64, hi: f64) -> Vec<f64> {
    x.iter().map(|v| v.clamp(lo, hi)).collect()
}

/// The projected gradient: zero where a bound stops the descent.
fn projected_gradient(x: &[f64], g: &[f64], lo: f64, hi: f64) -> Vec<f64> {
    x.iter()
        .zip(g)
        .map(|(xi, gi)| {
            if (*xi <= lo && *gi > 0.0) || (*xi >= hi && *gi < 0.0) {
                0.0
            } else {
                *gi
            }
        })
        .collect()
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(p, q)| p * q).sum()
}

/// A function to minimise: value and gradient, `None` where it is undefined.
type Objective<'a> = dyn Fn(&[f64]) -> Option<(f64, Vec<f64>)> + 'a;

/// Minimises `f` (value and gradient) in the box [lo, hi]^n from `start`: limited-memory BFGS
/// directions on the variables no bound holds, a projected backtracking (Armijo) line search,
/// and L-BFGS-B's stopping rules (projected gradient below 1e-5, or a relative decrease below
/// 1e7 machine epsilons). Returns `None` when `f` is undefined at the start.
fn minimise_in_box(f: &Objective, start: &[f64], lo: f64, hi: f64) -> Option<(Vec<f64>, f64)> {
    const MEMORY: usize = 10;
    const MAX_ITERATIONS: usize = 500;
    const PGTOL: f64 = 1e-5;
    let ftol = 1e7 * f64::EPSILON;
    let mut x = project(start, lo, hi);
    let (mut fx, mut g) = f(&x)?;
    if !fx.is_finite() {
        return None;
    }
    let mut history: Vec<(Vec<f64>, Vec<f64>)> = Vec::new();
    for iteration in 0..MAX_ITERATIONS {
        let pg = projected_gradient(&x, &g, lo, hi);
        if pg.iter().all(|v| v.abs() <= PGTOL) {
            break;
        }
        let free: Vec<bool> = pg.iter().map(|v| *v != 0.0).collect();
        // Two-loop recursion on the free variables.
        let mut q: Vec<f64> = pg.clone();
        let mut alphas = Vec::with_capacity(history.len());
        for (s, y) in history.iter().rev() {
            let rho = 1.0 / dot(y, s);
            let a = rho * dot(s, &q);
            q.iter_mut().zip(y).for_each(|(qi, yi)| *qi -= a * yi);
            alphas.push((a, rho));
        }
        if let Some((s, y)) = history.last() {
            let gamma = dot(s, y) / dot(y, y);
            q.iter_mut().for_each(|v| *v *= gamma);
        }
        for ((s, y), (a, rho)) in history.iter().zip(alphas.iter().rev()) {
            let b = rho * dot(y, &q);
            q.iter_mut().zip(s).for_each(|(qi, si)| *qi += (a - b) * si);
        }
        let mut d: Vec<f64> = q
            .iter()
            .zip(&free)
            .map(|(v, f)| if *f { -v } else { 0.0 })
            .collect();
        if dot(&d, &pg) >= 0.0 {
            // Not a descent direction: fall back to steepest descent and forget the curvature.
            d = pg.iter().map(|v| -v).collect();
            history.clear();
        }
        // The first step is scaled so that it moves at most one unit (as L-BFGS-B does).
        let norm = dot(&d, &d).sqrt();
        let mut t = if history.is_empty() && iteration == 0 {
            (1.0 / norm).min(1.0)
        } else {
            1.0
        };
        let mut accepted = None;
        for _ in 0..60 {
            let candidate = project(
                &x.iter()
                    .zip(&d)
                    .map(|(xi, di)| xi + t * di)
                    .collect::<Vec<_>>(),
                lo,
                hi,
            );
            let step: Vec<f64> = candidate.iter().zip(&x).map(|(c, xi)| c - xi).collect();
            if let Some((fc, gc)) = f(&candidate)
                && fc.is_finite()
                && fc <= fx + 1e-4 * dot(&g, &step)
            {
                accepted = Some((candidate, fc, gc, step));
                break;
            }
            t *= 0.5;
        }
        let Some((candidate, fc, gc, step)) = accepted else {
            break;
        };
        let change: Vec<f64> = gc.iter().zip(&g).map(|(a, b)| a - b).collect();
        if dot(&step, &change) > 1e-10 * dot(&change, &change).max(f64::MIN_POSITIVE) {
            if history.len() == MEMORY {
                history.remove(0);
            }
            history.push((step, change));
        }
        let decrease = (fx - fc) / fx.abs().max(fc.abs()).max(1.0);
        x = candidate;
        fx = fc;
        g = gc;
        if decrease <= ftol {
            break;
        }
    }
    Some((x, fx))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn data() -> (Vec<Vec<f64>>, Vec<f64>) {
        let x: Vec<Vec<f64>> = (0..12)
            .map(|i| vec![f64::from(i) / 3.0, f64::from(i % 3)])
            .collect();
        let y = x.iter().map(|v| (v[0] * 1.3).cos() + 0.1 * v[1]).collect();
        (x, y)
    }

    #[test]
    fn interpolates_training_points_with_tiny_noise() {
        let x: Vec<Vec<f64>> = (0..6).map(|i| vec![f64::from(i) / 2.0]).collect();
        let y: Vec<f64> = x.iter().map(|v| v[0].sin()).collect();
        let gp = GaussianProcess::fit(x.clone(), &y, Kernel::AUTHORS, 1e-10).expect("fits");
        for (xi, yi) in x.iter().zip(&y) {
            let (m, s) = gp.predict(xi).expect("predicts");
            assert!((m - yi).abs() < 1e-6 && s < 1e-3, "{m} vs {yi}, std {s}");
        }
        let (_, far) = gp.predict(&[40.0]).expect("predicts");
        assert!(far > 0.9, "{far}");
    }

    #[test]
    fn analytic_gradient_matches_finite_differences_for_every_kernel() {
        let (x, y) = data();
        let d2 = distances(&x);
        let yv = DVector::from_column_slice(&y);
        for kernel in [
            Kernel::RationalQuadratic {
                length_scale: 0.8,
                alpha: 0.7,
            },
            Kernel::Rbf { length_scale: 1.3 },
            Kernel::Matern {
                length_scale: 0.9,
                nu: 0.5,
            },
            Kernel::Matern {
                length_scale: 0.9,
                nu: 1.5,
            },
            Kernel::Matern {
                length_scale: 0.9,
                nu: 2.5,
            },
        ] {
            let theta = kernel.theta();
            let ones = vec![1.0; x.len()];
            let fixed = Diagonal {
                noise: 1e-6,
                scale: &ones,
                fitted: false,
            };
            let (_, g) = lml_and_gradient(&d2, &yv, kernel, fixed).expect("defined");
            for i in 0..theta.len() {
                let h = 1e-6;
                let at = |delta: f64| {
                    let mut t = theta.clone();
                    t[i] += delta;
                    lml_and_gradient(&d2, &yv, kernel.with_theta(&t), fixed)
                        .expect("defined")
                        .0
                };
                let numeric = (at(h) - at(-h)) / (2.0 * h);
                assert!(
                    (numeric - g[i]).abs() < 1e-4 * numeric.abs().max(1.0),
                    "{kernel:?} d{i}: {numeric} vs {}",
                    g[i]
                );
            }
        }
    }

    #[test]
    fn the_noise_gradient_matches_finite_differences() {
        let (x, y) = data();
        let d2 = distances(&x);
        let yv = DVector::from_column_slice(&y);
        let scale: Vec<f64> = (0..x.len()).map(|i| 1.0 / (1 + i % 4) as f64).collect();
        let kernel = Kernel::AUTHORS;
        let at = |ln_noise: f64| {
            let d = Diagonal {
                noise: ln_noise.exp(),
                scale: &scale,
                fitted: true,
            };
            lml_and_gradient(&d2, &yv, kernel, d).expect("defined")
        };
        for ln_noise in [-6.0, -2.0, 0.5] {
            let (_, g) = at(ln_noise);
            assert_eq!(g.len(), 3, "two kernel hyperparameters, then the noise");
            let h = 1e-6;
            let numeric = (at(ln_noise + h).0 - at(ln_noise - h).0) / (2.0 * h);
            assert!(
                (numeric - g[2]).abs() < 1e-4 * numeric.abs().max(1.0),
                "{numeric} vs {}",
                g[2]
            );
        }
    }

    #[test]
    fn a_fitted_noise_finds_the_scatter_of_noisy_means_and_widens_sigma_where_a_mean_rests_on_little()
     {
        // Group means of Bernoulli(0.7) draws: most groups of 20, one of a single draw.
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let x: Vec<Vec<f64>> = (0..15).map(|i| vec![f64::from(i) / 4.0]).collect();
        let sizes: Vec<u32> = (0..15).map(|i| if i == 7 { 1 } else { 20 }).collect();
        let y: Vec<f64> = sizes
            .iter()
            .map(|n| {
                let hits = (0..*n).filter(|_| rng.random::<f64>() < 0.7).count();
                hits as f64 / f64::from(*n)
            })
            .collect();
        let scale: Vec<f64> = sizes.iter().map(|n| 1.0 / f64::from(*n)).collect();
        let gp = GaussianProcess::fit_optimised_with_noise(
            x.clone(),
            &y,
            Kernel::AUTHORS,
            0.1,
            scale,
            &OptimiserOptions::default(),
        )
        .expect("fits");
        // The per-draw variance is 0.7 * 0.3 = 0.21; the fit finds it within a factor of 3.
        assert!((0.07..0.63).contains(&gp.noise()), "noise {}", gp.noise());
        let g = gp.log_marginal_likelihood_gradient_with_noise();
        assert!(g.last().is_some_and(|d| d.abs() < 1e-3), "{g:?}");
        // With that noise and a kernel that ties neighbours loosely (points 1.5 apart), the
        // group of one draw is not taken at its word: its σ is several times its
        // neighbours', and its mean is pulled towards them.
        let apart: Vec<Vec<f64>> = x.iter().map(|v| vec![v[0] * 6.0]).collect();
        let scale: Vec<f64> = sizes.iter().map(|n| 1.0 / f64::from(*n)).collect();
        let loose =
            GaussianProcess::fit_scaled(apart.clone(), &y, Kernel::AUTHORS, gp.noise(), scale)
                .expect("fits");
        let (m_one, s_one) = loose.predict(&apart[7]).expect("predicts");
        let (_, s_many) = loose.predict(&apart[3]).expect("predicts");
        assert!(s_one > 2.0 * s_many && s_many > 1e-2, "{s_one} vs {s_many}");
        assert!(
            (m_one - y[7]).abs() > 0.05,
            "{m_one} vs the single draw {}",
            y[7]
        );
        // The paper's noise interpolates: σ ≈ 0 at every point, the single draw included.
        let paper = GaussianProcess::fit(apart.clone(), &y, Kernel::AUTHORS, 1e-10).expect("fits");
        let (_, s_paper) = paper.predict(&apart[7]).expect("predicts");
        assert!(s_paper < 1e-3, "{s_paper}");
    }

    #[test]
    fn optimising_finds_a_stationary_point_above_the_start() {
        let (x, y) = data();
        let fixed = GaussianProcess::fit(x.clone(), &y, Kernel::AUTHORS, 1e-6).expect("fits");
        let best = GaussianProcess::fit_optimised(
            x,
            &y,
            Kernel::AUTHORS,
            1e-6,
            &OptimiserOptions {
                restarts: 3,
                seed: 1,
                ..Default::default()
            },
        )
        .expect("fits");
        assert!(best.log_marginal_likelihood() > fixed.log_marginal_likelihood());
        let (lo, hi) = (1e-5f64.ln(), 1e5f64.ln());
        let theta = best.kernel().theta();
        let pg = projected_gradient(&theta, &best.log_marginal_likelihood_gradient(), lo, hi);
        assert!(pg.iter().all(|g| g.abs() < 1e-3), "{pg:?} at {theta:?}");
    }

    #[test]
    fn box_search_stops_at_a_bound() {
        // f = (x - 10)^2 in [-1, 2]: the minimum is at the upper bound.
        let f = |x: &[f64]| Some(((x[0] - 10.0).powi(2), vec![2.0 * (x[0] - 10.0)]));
        let (x, _) = minimise_in_box(&f, &[0.0], -1.0, 2.0).expect("defined");
        assert_eq!(x, [2.0]);
        // Rosenbrock inside a box that holds its minimum.
        let r = |x: &[f64]| {
            let (a, b) = (x[0], x[1]);
            Some((
                (1.0 - a).powi(2) + 100.0 * (b - a * a).powi(2),
                vec![
                    -2.0 * (1.0 - a) - 400.0 * a * (b - a * a),
                    200.0 * (b - a * a),
                ],
            ))
        };
        let (x, v) = minimise_in_box(&r, &[-1.2, 1.0], -5.0, 5.0).expect("defined");
        assert!(v < 1e-8 && (x[0] - 1.0).abs() < 1e-3, "{x:?} {v}");
    }

    #[test]
    fn bad_training_data_and_hyperparameters_are_named() {
        let k = Kernel::Rbf { length_scale: 1.0 };
        assert_eq!(
            GaussianProcess::fit(vec![], &[], k, 1e-10).err(),
            Some(GpError::NoData)
        );
        assert!(matches!(
            GaussianProcess::fit(vec![vec![0.0]], &[f64::NAN], k, 1e-10),
            Err(GpError::NotFinite { index: 0 })
        ));
        assert!(matches!(
            GaussianProcess::fit(vec![vec![0.0], vec![0.0, 1.0]], &[0.0, 1.0], k, 1e-10),
            Err(GpError::Ragged { index: 1, .. })
        ));
        assert!(matches!(
            GaussianProcess::fit(
                vec![vec![0.0]],
                &[0.0],
                Kernel::Matern {
                    length_scale: 1.0,
                    nu: 2.0
                },
                1e-10
            ),
            Err(GpError::Hyperparameter { .. })
        ));
        assert!(matches!(
            GaussianProcess::fit(
                vec![vec![0.0]],
                &[0.0],
                Kernel::Rbf { length_scale: -1.0 },
                0.0
            ),
            Err(GpError::Hyperparameter {
                what: "length_scale",
                ..
            })
        ));
        let gp = GaussianProcess::fit(vec![vec![0.0, 1.0]], &[1.0], k, 1e-10).expect("fits");
        assert!(matches!(
            gp.predict(&[0.0]),
            Err(GpError::Dimension {
                expected: 2,
                found: 1
            })
        ));
    }
}
