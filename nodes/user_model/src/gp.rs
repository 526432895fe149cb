//! Gaussian-process regression on nalgebra, as scikit-learn's GaussianProcessRegressor does it
//! (zero prior mean, no target normalisation, a small noise on the diagonal, Cholesky solve),
//! with the authors' RationalQuadratic kernel by default and RBF / Matérn selectable.
//! Hyperparameters maximise the log marginal likelihood (Nelder-Mead in log space within
//! bounds, from the initial values and seeded random restarts).

use nalgebra::{Cholesky, DMatrix, DVector, Dyn};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// A stationary kernel on Euclidean distance.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind")]
pub enum Kernel {
    /// (1 + d² / (2 α l²))^-α
    RationalQuadratic { length_scale: f64, alpha: f64 },
    /// exp(-d² / (2 l²))
    Rbf { length_scale: f64 },
    /// Matérn with ν = 0.5, 1.5 or 2.5.
    Matern { length_scale: f64, nu: f64 },
}

impl Kernel {
    pub fn name(&self) -> &'static str {
        match self {
            Kernel::RationalQuadratic { .. } => "RationalQuadratic",
            Kernel::Rbf { .. } => "RBF",
            Kernel::Matern { .. } => "Matern",
        }
    }

    pub fn eval(&self, d2: f64) -> f64 {
        match *self {
            Kernel::RationalQuadratic {
                length_scale: l,
                alpha,
            } => (1.0 + d2 / (2.0 * alpha * l * l)).powf(-alpha),
            Kernel::Rbf { length_scale: l } => (-d2 / (2.0 * l * l)).exp(),
            Kernel::Matern {
                length_scale: l,
                nu,
            } => {
                let r = d2.sqrt() / l;
                if nu == 0.5 {
                    (-r).exp()
                } else if nu == 1.5 {
                    let s = 3f64.sqrt() * r;
                    (1.0 + s) * (-s).exp()
                } else {
                    let s = 5f64.sqrt() * r;
                    (1.0 + s + s * s / 3.0) * (-s).exp()
                }
            }
        }
    }

    /// The optimised hyperparameters, in log space.
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

    pub fn with_theta(&self, theta: &[f64]) -> Kernel {
        match *self {
            Kernel::RationalQuadratic { .. } => Kernel::RationalQuadratic {
                length_scale: theta[0].exp(),
                alpha: theta[1].exp(),
            },
            Kernel::Rbf { .. } => Kernel::Rbf {
                length_scale: theta[0].exp(),
            },
            Kernel::Matern { nu, .. } => Kernel::Matern {
                length_scale: theta[0].exp(),
                nu,
            },
        }
    }
}

/// What a GP could not do.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GpError {
    #[error("{0} training points: a GP needs at least one")]
    NoData(usize),
    #[error("training inputs and targets differ in length ({inputs} vs {targets})")]
    Shape { inputs: usize, targets: usize },
    #[error("training value {index} is not finite")]
    NotFinite { index: usize },
    #[error("the kernel matrix is not positive definite (kernel {kernel:?}, noise {noise})")]
    NotPositiveDefinite { kernel: Kernel, noise: f64 },
    #[error("input has {found} dimensions, the GP was trained on {expected}")]
    Dimension { expected: usize, found: usize },
}

/// A fitted GP: training data, kernel, and the solved weights.
#[derive(Debug, Clone)]
pub struct GaussianProcess {
    kernel: Kernel,
    noise: f64,
    x: Vec<Vec<f64>>,
    chol: Cholesky<f64, Dyn>,
    alpha: DVector<f64>,
    log_marginal_likelihood: f64,
}

fn sq_dist(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(p, q)| (p - q) * (p - q)).sum()
}

impl GaussianProcess {
    /// Fits with the kernel's hyperparameters as given.
    pub fn fit(x: Vec<Vec<f64>>, y: &[f64], kernel: Kernel, noise: f64) -> Result<Self, GpError> {
        if x.is_empty() {
            return Err(GpError::NoData(0));
        }
        if x.len() != y.len() {
            return Err(GpError::Shape {
                inputs: x.len(),
                targets: y.len(),
            });
        }
        if let Some(index) = y
            .iter()
            .position(|v| !v.is_finite())
            .or_else(|| x.iter().position(|r| r.iter().any(|v| !v.is_finite())))
        {
            return Err(GpError::NotFinite { index });
        }
        let n = x.len();
        let k = DMatrix::from_fn(n, n, |i, j| {
            kernel.eval(sq_dist(&x[i], &x[j])) + if i == j { noise } else { 0.0 }
        });
        let chol = k
            .cholesky()
            .ok_or(GpError::NotPositiveDefinite { kernel, noise })?;
        let yv = DVector::from_column_slice(y);
        let alpha = chol.solve(&yv);
        let log_det_half: f64 = chol.l_dirty().diagonal().iter().map(|d| d.ln()).sum();
        let log_marginal_likelihood = -0.5 * yv.dot(&alpha)
            - log_det_half
            - 0.5 * n as f64 * (2.0 * std::f64::consts::PI).ln();
        Ok(GaussianProcess {
            kernel,
            noise,
            x,
            chol,
            alpha,
            log_marginal_likelihood,
        })
    }

    /// Fits after choosing hyperparameters that maximise the log marginal likelihood, from the
    /// kernel's initial values and `restarts` seeded log-uniform starts within `bounds`.
    pub fn fit_optimised(
        x: Vec<Vec<f64>>,
        y: &[f64],
        initial: Kernel,
        noise: f64,
        bounds: (f64, f64),
        restarts: usize,
        seed: u64,
    ) -> Result<Self, GpError> {
        let (lo, hi) = (bounds.0.ln(), bounds.1.ln());
        let objective = |theta: &[f64]| -> f64 {
            let t: Vec<f64> = theta.iter().map(|v| v.clamp(lo, hi)).collect();
            match GaussianProcess::fit(x.clone(), y, initial.with_theta(&t), noise) {
                Ok(gp) => -gp.log_marginal_likelihood,
                Err(_) => f64::INFINITY,
            }
        };
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut starts = vec![initial.theta()];
        for _ in 0..restarts {
            starts.push(
                initial
                    .theta()
                    .iter()
                    .map(|_| rng.random_range(lo..hi))
                    .collect(),
            );
        }
        let mut best: Option<(f64, Vec<f64>)> = None;
        for start in starts {
            let (theta, value) = nelder_mead(&objective, &start, 400);
            if value.is_finite() && best.as_ref().is_none_or(|(b, _)| value < *b) {
                best = Some((value, theta.iter().map(|v| v.clamp(lo, hi)).collect()));
            }
        }
        let theta = best.map(|b| b.1).unwrap_or_else(|| initial.theta());
        GaussianProcess::fit(x, y, initial.with_theta(&theta), noise)
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

    pub fn training_inputs(&self) -> &[Vec<f64>] {
        &self.x
    }

    /// Posterior mean and standard deviation at `x`.
    pub fn predict(&self, x: &[f64]) -> Result<(f64, f64), GpError> {
        let d = self.x[0].len();
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
        let v = self
            .chol
            .l_dirty()
            .solve_lower_triangular(&k_star)
            .unwrap_or_else(|| DVector::zeros(self.x.len()));
        let var = self.kernel.eval(0.0) - v.dot(&v);
        Ok((mean, var.max(0.0).sqrt()))
    }
}

/// Minimises `f` from `start` with the Nelder-Mead simplex; returns the point and its value.
fn nelder_mead(f: &dyn Fn(&[f64]) -> f64, start: &[f64], iterations: usize) -> (Vec<f64>, f64) {
    let n = start.len();
    let mut simplex: Vec<(Vec<f64>, f64)> = (0..=n)
        .map(|i| {
            let mut p = start.to_vec();
            if i > 0 {
                p[i - 1] += 0.5;
            }
            let v = f(&p);
            (p, v)
        })
        .collect();
    for _ in 0..iterations {
        simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
        if (simplex[n].1 - simplex[0].1).abs() < 1e-10 {
            break;
        }
        let centroid: Vec<f64> = (0..n)
            .map(|j| simplex[..n].iter().map(|p| p.0[j]).sum::<f64>() / n as f64)
            .collect();
        let along = |t: f64| -> Vec<f64> {
            (0..n)
                .map(|j| centroid[j] + t * (simplex[n].0[j] - centroid[j]))
                .collect()
        };
        let reflected = along(-1.0);
        let fr = f(&reflected);
        if fr < simplex[0].1 {
            let expanded = along(-2.0);
            let fe = f(&expanded);
            simplex[n] = if fe < fr {
                (expanded, fe)
            } else {
                (reflected, fr)
            };
        } else if fr < simplex[n - 1].1 {
            simplex[n] = (reflected, fr);
        } else {
            let contracted = along(0.5);
            let fc = f(&contracted);
            if fc < simplex[n].1 {
                simplex[n] = (contracted, fc);
            } else {
                let best = simplex[0].0.clone();
                for p in simplex.iter_mut().skip(1) {
                    p.0 = (0..n).map(|j| best[j] + 0.5 * (p.0[j] - best[j])).collect();
                    p.1 = f(&p.0);
                }
            }
        }
    }
    simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
    simplex.swap_remove(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_training_points_with_tiny_noise() {
        let x: Vec<Vec<f64>> = (0..6).map(|i| vec![f64::from(i) / 2.0]).collect();
        let y: Vec<f64> = x.iter().map(|v| v[0].sin()).collect();
        let gp = GaussianProcess::fit(
            x.clone(),
            &y,
            Kernel::RationalQuadratic {
                length_scale: 1.0,
                alpha: 1.5,
            },
            1e-10,
        )
        .expect("fits");
        for (xi, yi) in x.iter().zip(&y) {
            let (m, s) = gp.predict(xi).expect("predicts");
            assert!((m - yi).abs() < 1e-6 && s < 1e-3, "{m} vs {yi}, std {s}");
        }
        let (_, far) = gp.predict(&[40.0]).expect("predicts");
        assert!(far > 0.9, "{far}");
    }

    #[test]
    fn optimising_never_lowers_the_likelihood() {
        let x: Vec<Vec<f64>> = (0..12)
            .map(|i| vec![f64::from(i) / 3.0, f64::from(i % 3)])
            .collect();
        let y: Vec<f64> = x.iter().map(|v| (v[0] * 1.3).cos() + 0.1 * v[1]).collect();
        let k = Kernel::RationalQuadratic {
            length_scale: 1.0,
            alpha: 1.5,
        };
        let fixed = GaussianProcess::fit(x.clone(), &y, k, 1e-6).expect("fits");
        let best = GaussianProcess::fit_optimised(x, &y, k, 1e-6, (1e-5, 1e5), 3, 1).expect("fits");
        assert!(best.log_marginal_likelihood() >= fixed.log_marginal_likelihood() - 1e-9);
    }

    #[test]
    fn bad_training_data_is_named() {
        let k = Kernel::Rbf { length_scale: 1.0 };
        assert_eq!(
            GaussianProcess::fit(vec![], &[], k, 1e-10).err(),
            Some(GpError::NoData(0))
        );
        assert!(matches!(
            GaussianProcess::fit(vec![vec![0.0]], &[f64::NAN], k, 1e-10),
            Err(GpError::NotFinite { index: 0 })
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
