//! The child's own model as two Gaussian processes over the finite input space, F^p(L, F, PS)
//! and F^e(L, F, PS, O), whose prior mean is a known model (the child's cluster's, or the
//! population's) and whose prior covariance says how far a child may differ from it and how
//! what is seen at one input carries to its neighbours (a product kernel over level,
//! feedback, previous score and outcome). Each observed sequence is one noisy value at one
//! input; values at the same input are pooled (a mean of n values with noise σ² / n gives the
//! same posterior as the n values). Forgetting down-weighs older values, so a child who
//! changes is followed.

use crate::{Belief, BeliefError, Observation};
use nalgebra::{DMatrix, DVector};
use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use sequence_game::user_model_table::{ENGAGEMENT_INPUTS, SUCCESS_INPUTS};
use sequence_game::{ModelInput, Outcome, Prediction, UserModelTable};
use serde::{Deserialize, Serialize};

/// The prior covariance and the noise of the child's own model.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OwnModelParams {
    /// Prior standard deviation of the child's P(success) around the prior model's, at any
    /// input.
    pub success_sd: f64,
    /// Prior standard deviation of the child's engagement around the prior model's.
    pub engagement_sd: f64,
    /// Noise variance of one answer (1 right, 0 wrong) around P(success): p (1 − p) is at most
    /// 0.25.
    pub answer_noise: f64,
    /// Noise standard deviation of one sequence's engagement around F^e.
    pub engagement_noise: f64,
    /// Prior correlation of the child's deviations at two adjacent levels (ρ^|ΔL|).
    pub level_correlation: f64,
    /// Prior correlation between two different feedbacks at the same level and score.
    pub feedback_correlation: f64,
    /// Length scale over the previous score (exp(−ΔPS² / 2ℓ²)).
    pub previous_score_length: f64,
    /// Prior correlation of the engagement after a right and after a wrong answer.
    pub outcome_correlation: f64,
    /// Before each observation every earlier one's weight is multiplied by this (1: none
    /// forgotten).
    pub forgetting: f64,
}

impl Default for OwnModelParams {
    fn default() -> Self {
        OwnModelParams {
            success_sd: 0.3,
            engagement_sd: 0.5,
            answer_noise: 0.2,
            // The study's own: the pooled standard deviation of a child's engagement between
            // sequences of the same (L, F, PS, O) (24 such groups, 0.23).
            engagement_noise: 0.23,
            level_correlation: 0.5,
            feedback_correlation: 0.7,
            previous_score_length: 2.0,
            outcome_correlation: 0.7,
            forgetting: 1.0,
        }
    }
}

impl OwnModelParams {
    pub fn validate(&self) -> Result<(), BeliefError> {
        let positive = |what, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(BeliefError::Parameter {
                    what,
                    value: v,
                    why: "must be > 0",
                })
            }
        };
        let fraction = |what, v: f64| {
            if (0.0..=1.0).contains(&v) {
                Ok(())
            } else {
                Err(BeliefError::Parameter {
                    what,
                    value: v,
                    why: "must be in [0, 1]",
                })
            }
        };
        positive("success_sd", self.success_sd)?;
        positive("engagement_sd", self.engagement_sd)?;
        positive("answer_noise", self.answer_noise)?;
        positive("engagement_noise", self.engagement_noise)?;
        positive("previous_score_length", self.previous_score_length)?;
        fraction("level_correlation", self.level_correlation)?;
        fraction("feedback_correlation", self.feedback_correlation)?;
        fraction("outcome_correlation", self.outcome_correlation)?;
        if !(self.forgetting > 0.0 && self.forgetting <= 1.0) {
            return Err(BeliefError::Parameter {
                what: "forgetting",
                value: self.forgetting,
                why: "must be in (0, 1]",
            });
        }
        Ok(())
    }

    /// Prior correlation of the child's deviations at two inputs (without the outcome).
    fn input_correlation(&self, a: ModelInput, b: ModelInput) -> f64 {
        let dl = (i32::from(a.level.get()) - i32::from(b.level.get())).unsigned_abs();
        let f = if a.feedback == b.feedback {
            1.0
        } else {
            self.feedback_correlation
        };
        let dps = f64::from(a.previous_score - b.previous_score);
        self.level_correlation.powi(dl as i32)
            * f
            * (-dps * dps / (2.0 * self.previous_score_length.powi(2))).exp()
    }
}

/// One GP over a finite set of inputs: prior mean and covariance, and the pooled values seen.
#[derive(Debug, Clone, PartialEq)]
struct FiniteGp {
    prior_mean: Vec<f64>,
    /// Prior covariance, n x n.
    prior_covariance: DMatrix<f64>,
    /// Per input: total weight of the values seen, and their weighted sum.
    weight: Vec<f64>,
    weighted_sum: Vec<f64>,
    noise: f64,
    range: (f64, f64),
    /// The inputs drawn jointly by `samples`.
    active: Vec<usize>,
}

/// The pieces of a GP's posterior: the observed inputs, the factor of
/// A = K_SS + diag(σ² / w_S) and A⁻¹ (ȳ_S − m0_S).
struct Solved {
    seen: Vec<usize>,
    factor: nalgebra::Cholesky<f64, nalgebra::Dyn>,
    alpha: DVector<f64>,
}

impl FiniteGp {
    fn new(
        prior_mean: Vec<f64>,
        prior_covariance: DMatrix<f64>,
        noise: f64,
        range: (f64, f64),
        active: Vec<usize>,
    ) -> Self {
        let n = prior_mean.len();
        FiniteGp {
            prior_mean,
            prior_covariance,
            weight: vec![0.0; n],
            weighted_sum: vec![0.0; n],
            noise,
            range,
            active,
        }
    }

    fn observe(&mut self, index: usize, value: f64, forgetting: f64) {
        self.fade(forgetting);
        self.weight[index] += 1.0;
        self.weighted_sum[index] += value;
    }

    /// Every earlier value's weight times `forgetting`, as before an observation.
    fn fade(&mut self, forgetting: f64) {
        if forgetting < 1.0 {
            self.weight.iter_mut().for_each(|w| *w *= forgetting);
            self.weighted_sum.iter_mut().for_each(|s| *s *= forgetting);
        }
    }

    /// `None` before any value (the posterior is the prior).
    fn solve(&self) -> Option<Solved> {
        let seen: Vec<usize> = (0..self.weight.len())
            .filter(|&i| self.weight[i] > 1e-9)
            .collect();
        if seen.is_empty() {
            return None;
        }
        let k = &self.prior_covariance;
        let s = seen.len();
        let a = DMatrix::from_fn(s, s, |i, j| {
            k[(seen[i], seen[j])]
                + if i == j {
                    self.noise / self.weight[seen[i]]
                } else {
                    0.0
                }
        });
        let residual = DVector::from_fn(s, |i, _| {
            self.weighted_sum[seen[i]] / self.weight[seen[i]] - self.prior_mean[seen[i]]
        });
        // A is a covariance plus a positive diagonal: positive definite.
        let factor = a.cholesky()?;
        let alpha = factor.solve(&residual);
        Some(Solved {
            seen,
            factor,
            alpha,
        })
    }

    /// The posterior mean at every input, and the variance at each (the covariance's
    /// diagonal: k_ii − k_iS A⁻¹ k_Si).
    fn marginals(&self) -> (Vec<f64>, Vec<f64>) {
        let n = self.prior_mean.len();
        let k = &self.prior_covariance;
        let Some(solved) = self.solve() else {
            return (self.prior_mean.clone(), (0..n).map(|i| k[(i, i)]).collect());
        };
        let seen = &solved.seen;
        // k_Sx, one column per input; A⁻¹ k_Sx by the factor.
        let k_sx = DMatrix::from_fn(seen.len(), n, |j, i| k[(seen[j], i)]);
        let v = solved.factor.solve(&k_sx);
        let mut mean = Vec::with_capacity(n);
        let mut var = Vec::with_capacity(n);
        for i in 0..n {
            let col = k_sx.column(i);
            mean.push(self.prior_mean[i] + col.dot(&solved.alpha));
            var.push((k[(i, i)] - col.dot(&v.column(i))).max(0.0));
        }
        (mean, var)
    }

    /// The posterior means alone.
    fn means(&self) -> Vec<f64> {
        let Some(solved) = self.solve() else {
            return self.prior_mean.clone();
        };
        let k = &self.prior_covariance;
        (0..self.prior_mean.len())
            .map(|i| {
                self.prior_mean[i]
                    + solved
                        .seen
                        .iter()
                        .zip(solved.alpha.iter())
                        .map(|(&j, a)| k[(i, j)] * a)
                        .sum::<f64>()
            })
            .collect()
    }

    /// `n` draws from the posterior, each clamped to the target's range. Only the active
    /// inputs (those a session can reach) are drawn jointly; the others keep their posterior
    /// mean. The covariance is factored once.
    fn samples(&self, rng: &mut ChaCha8Rng, n: usize) -> Vec<Vec<f64>> {
        let mean = self.means();
        let act = &self.active;
        let d = act.len();
        let k = &self.prior_covariance;
        let mut c = DMatrix::from_fn(d, d, |i, j| k[(act[i], act[j])]);
        if let Some(solved) = self.solve() {
            let seen = &solved.seen;
            let k_sa = DMatrix::from_fn(seen.len(), d, |j, i| k[(seen[j], act[i])]);
            let v = solved.factor.solve(&k_sa);
            c -= k_sa.transpose() * v;
        }
        // A little jitter keeps the factor real where the posterior is nearly degenerate.
        for i in 0..d {
            c[(i, i)] += 1e-9;
        }
        let factor = c.cholesky().map(|l| l.unpack());
        (0..n)
            .map(|_| {
                let mut draw = mean.clone();
                if let Some(l) = &factor {
                    let z = standard_normals(rng, d);
                    let x = l * z;
                    for (i, &a) in act.iter().enumerate() {
                        draw[a] += x[i];
                    }
                }
                draw.iter()
                    .map(|v| v.clamp(self.range.0, self.range.1))
                    .collect()
            })
            .collect()
    }
}

/// Whether a session can play a sequence at `input`: the first sequence (from the start state:
/// no feedback, PS 0), a level chosen after any result (no feedback, PS ±1..3), or feedback
/// before the same level again (PS ±L). 33 of the 63.
pub fn reachable_input(input: ModelInput) -> bool {
    let l = input.level.get() as i8;
    match (input.feedback, input.previous_score) {
        (sequence_game::Feedback::None, _) => true,
        (_, ps) => ps == l || ps == -l,
    }
}

/// E[clamp(X, lo, hi)] for X ~ N(mean, sd²): lo Φ(a) + hi (1 − Φ(b)) + mean (Φ(b) − Φ(a))
/// + sd (φ(a) − φ(b)), a and b the bounds standardised.
pub fn clamped_normal_mean(mean: f64, sd: f64, lo: f64, hi: f64) -> f64 {
    if sd < 1e-12 {
        return mean.clamp(lo, hi);
    }
    let (a, b) = ((lo - mean) / sd, (hi - mean) / sd);
    let pdf = |z: f64| (-0.5 * z * z).exp() / std::f64::consts::TAU.sqrt();
    let cdf = |z: f64| 0.5 * erfc(-z / std::f64::consts::SQRT_2);
    let (ca, cb) = (cdf(a), cdf(b));
    (lo * ca + hi * (1.0 - cb) + mean * (cb - ca) + sd * (pdf(a) - pdf(b))).clamp(lo, hi)
}

/// The complementary error function (Numerical Recipes' erfcc, fractional error < 1.2e-7).
fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = -z * z - 1.265_512_23
        + t * (1.000_023_68
            + t * (0.374_091_96
                + t * (0.096_784_18
                    + t * (-0.186_288_06
                        + t * (0.278_868_07
                            + t * (-1.135_203_98
                                + t * (1.488_515_87 + t * (-0.822_152_23 + t * 0.170_872_77))))))));
    let r = t * poly.exp();
    if x >= 0.0 { r } else { 2.0 - r }
}

/// `d` standard normal draws (Box–Muller, both of each pair used).
fn standard_normals(rng: &mut ChaCha8Rng, d: usize) -> DVector<f64> {
    let mut z = DVector::zeros(d);
    let mut i = 0;
    while i < d {
        let u1: f64 = 1.0 - rng.random::<f64>();
        let u2: f64 = rng.random::<f64>();
        let r = (-2.0 * u1.ln()).sqrt();
        let (sin, cos) = (std::f64::consts::TAU * u2).sin_cos();
        z[i] = r * cos;
        if i + 1 < d {
            z[i + 1] = r * sin;
        }
        i += 2;
    }
    z
}

/// A prior covariance of a child's deviations from the prior model, learned from known
/// children: the mean over them of d dᵀ, d the child's model minus the prior mean they are
/// compared with, shrunk towards its diagonal (a few children cannot pin down every
/// correlation) and with a floor on every variance (no input is known exactly).
#[derive(Debug, Clone, PartialEq)]
pub struct LearnedCovariance {
    pub success: DMatrix<f64>,
    pub engagement: DMatrix<f64>,
}

impl LearnedCovariance {
    /// `children`: each known child's model with the prior mean their deviation is taken
    /// from; `shrinkage` in [0, 1] (0: the sample covariance, 1: its diagonal alone);
    /// `floor`: the least variance of any input.
    pub fn from_children(
        children: &[(&UserModelTable, &UserModelTable)],
        shrinkage: f64,
        floor: f64,
    ) -> Result<Self, BeliefError> {
        if children.is_empty() {
            return Err(BeliefError::EmptyLibrary);
        }
        if !(0.0..=1.0).contains(&shrinkage) {
            return Err(BeliefError::Parameter {
                what: "shrinkage",
                value: shrinkage,
                why: "must be in [0, 1]",
            });
        }
        if !(floor.is_finite() && floor > 0.0) {
            return Err(BeliefError::Parameter {
                what: "floor",
                value: floor,
                why: "must be > 0",
            });
        }
        let second_moment =
            |n: usize, deviation: &dyn Fn(&UserModelTable, &UserModelTable, usize) -> f64| {
                let mut c = DMatrix::zeros(n, n);
                for (child, prior) in children {
                    let d = DVector::from_fn(n, |i, _| deviation(child, prior, i));
                    c += &d * d.transpose();
                }
                c /= children.len() as f64;
                for i in 0..n {
                    for j in 0..n {
                        if i != j {
                            c[(i, j)] *= 1.0 - shrinkage;
                        }
                    }
                    c[(i, i)] = c[(i, i)].max(floor);
                }
                c
            };
        Ok(LearnedCovariance {
            success: second_moment(SUCCESS_INPUTS, &|c, p, i| {
                c.success[i].mean - p.success[i].mean
            }),
            engagement: second_moment(ENGAGEMENT_INPUTS, &|c, p, i| {
                c.engagement[i].mean - p.engagement[i].mean
            }),
        })
    }
}

/// The GPs' posterior at every input, before clamping to the targets' ranges.
#[derive(Debug, Clone, PartialEq)]
pub struct GpPosterior {
    /// (mean, standard deviation) of P(success), in table order.
    pub success: Vec<(f64, f64)>,
    /// (mean, standard deviation) of engagement, in table order.
    pub engagement: Vec<(f64, f64)>,
}

/// The child's own model: a GP for P(success) and one for engagement around a prior model.
#[derive(Debug, Clone, PartialEq)]
pub struct OwnModel {
    params: OwnModelParams,
    success: FiniteGp,
    engagement: FiniteGp,
    observed: usize,
}

impl OwnModel {
    pub fn new(prior: &UserModelTable, params: OwnModelParams) -> Result<Self, BeliefError> {
        params.validate()?;
        prior.validate().map_err(|e| BeliefError::Model {
            name: "prior".into(),
            reason: e.to_string(),
        })?;
        let inputs: Vec<ModelInput> = ModelInput::all().collect();
        let sp = params.success_sd * params.success_sd;
        let success_cov = DMatrix::from_fn(SUCCESS_INPUTS, SUCCESS_INPUTS, |i, j| {
            sp * params.input_correlation(inputs[i], inputs[j])
        });
        let se = params.engagement_sd * params.engagement_sd;
        // Engagement rows: input-major, then outcome (failure, success), as the table.
        let engagement_cov = DMatrix::from_fn(ENGAGEMENT_INPUTS, ENGAGEMENT_INPUTS, |i, j| {
            let o = if i % 2 == j % 2 {
                1.0
            } else {
                params.outcome_correlation
            };
            se * o * params.input_correlation(inputs[i / 2], inputs[j / 2])
        });
        let reachable: Vec<usize> = inputs
            .iter()
            .filter(|i| reachable_input(**i))
            .map(|i| i.index())
            .collect();
        Ok(OwnModel {
            params,
            success: FiniteGp::new(
                prior.success.iter().map(|p| p.mean).collect(),
                success_cov,
                params.answer_noise,
                (0.0, 1.0),
                reachable.clone(),
            ),
            engagement: FiniteGp::new(
                prior.engagement.iter().map(|p| p.mean).collect(),
                engagement_cov,
                params.engagement_noise * params.engagement_noise,
                (-1.0, 1.0),
                reachable.iter().flat_map(|&i| [2 * i, 2 * i + 1]).collect(),
            ),
            observed: 0,
        })
    }

    /// The child's own model with a prior covariance learned from known children (see
    /// [`LearnedCovariance`]) instead of the product kernel; the noises and the forgetting
    /// come from `params`.
    pub fn with_covariance(
        prior: &UserModelTable,
        covariance: &LearnedCovariance,
        params: OwnModelParams,
    ) -> Result<Self, BeliefError> {
        let mut m = OwnModel::new(prior, params)?;
        m.success.prior_covariance = covariance.success.clone();
        m.engagement.prior_covariance = covariance.engagement.clone();
        Ok(m)
    }

    pub fn params(&self) -> &OwnModelParams {
        &self.params
    }

    /// A table of the GPs' posterior: each value the expectation of the clamped Gaussian
    /// (P(success) in [0, 1], engagement in [−1, 1]: a value the GP puts above 1 is 1 for the
    /// child), with the GP's posterior standard deviation. Without variances, the clamped
    /// means.
    fn table(
        success: &[f64],
        engagement: &[f64],
        var: Option<(Vec<f64>, Vec<f64>)>,
    ) -> UserModelTable {
        let (sv, ev) =
            var.unwrap_or_else(|| (vec![0.0; SUCCESS_INPUTS], vec![0.0; ENGAGEMENT_INPUTS]));
        let column = |means: &[f64], vars: &[f64], lo: f64, hi: f64| -> Vec<Prediction> {
            means
                .iter()
                .zip(vars)
                .map(|(m, v)| {
                    let sd = v.max(0.0).sqrt();
                    Prediction {
                        mean: clamped_normal_mean(*m, sd, lo, hi),
                        std: sd,
                    }
                })
                .collect()
        };
        UserModelTable {
            cluster: 0,
            success: column(success, &sv, 0.0, 1.0),
            engagement: column(engagement, &ev, -1.0, 1.0),
        }
    }

    /// The GPs' posterior at every input before clamping.
    pub fn posterior(&self) -> GpPosterior {
        let pair = |(m, v): (Vec<f64>, Vec<f64>)| -> Vec<(f64, f64)> {
            m.into_iter()
                .zip(v)
                .map(|(m, v)| (m, v.max(0.0).sqrt()))
                .collect()
        };
        GpPosterior {
            success: pair(self.success.marginals()),
            engagement: pair(self.engagement.marginals()),
        }
    }

    /// The posterior means alone (standard deviations left 0): what a plan without caution
    /// needs, at a fraction of the cost.
    pub fn predictive_mean(&self) -> UserModelTable {
        OwnModel::table(&self.success.means(), &self.engagement.means(), None)
    }
}

impl Belief for OwnModel {
    fn observe(&mut self, o: &Observation) {
        let lambda = self.params.forgetting;
        let right = f64::from(u8::from(o.outcome == Outcome::Success));
        self.success.observe(o.input.index(), right, lambda);
        match o.engagement {
            Some(e) => self
                .engagement
                .observe(o.input.engagement_index(o.outcome), e, lambda),
            // No face seen: the answer speaks, the engagement GP only ages.
            None => self.engagement.fade(lambda),
        }
        self.observed += 1;
    }

    /// The posterior means (clamped to the targets' ranges) with each input's posterior
    /// standard deviation.
    fn predictive(&self) -> UserModelTable {
        let (s, sv) = self.success.marginals();
        let (e, ev) = self.engagement.marginals();
        OwnModel::table(&s, &e, Some((sv, ev)))
    }

    fn sample(&self, rng: &mut ChaCha8Rng) -> UserModelTable {
        let mut one = self.samples(rng, 1);
        one.pop().unwrap_or_else(|| self.predictive())
    }

    /// P(success) draws first, then engagement draws, from the one stream.
    fn samples(&self, rng: &mut ChaCha8Rng, n: usize) -> Vec<UserModelTable> {
        let s = self.success.samples(rng, n);
        let e = self.engagement.samples(rng, n);
        s.iter()
            .zip(&e)
            .map(|(s, e)| OwnModel::table(s, e, None))
            .collect()
    }

    fn observations(&self) -> usize {
        self.observed
    }

    fn evidence(&self, input: ModelInput) -> Option<f64> {
        self.success.weight.get(input.index()).copied()
    }
}

#[cfg(test)]
mod tests;
