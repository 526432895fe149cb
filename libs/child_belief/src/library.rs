//! A posterior over a library of known user models (the clusters' and other children's own):
//! the child is taken to be one of them, each with a prior weight, and every observed sequence
//! reweighs them by how likely each model made it (the answer's probability times the
//! engagement's density around the model's prediction). Forgetting lets a child who changes
//! leave a model that described them earlier.

use crate::{Belief, BeliefError, Observation, clamp_probability};
use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use sequence_game::user_model_table::{ENGAGEMENT_INPUTS, SUCCESS_INPUTS};
use sequence_game::{ModelInput, Outcome, Prediction, UserModelTable};
use serde::{Deserialize, Serialize};

/// A model the library knows, with a name to report it by.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct KnownModel {
    pub name: String,
    pub table: UserModelTable,
}

/// How observations weigh the models.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LibraryParams {
    /// σ of an observed engagement around a model's prediction: the engagement's likelihood
    /// is N(E; F^e(input, O), σ²). Small σ lets a few sequences decide between models.
    pub engagement_sd: f64,
    /// Each model's P(success) is clamped into [floor, 1 − floor] for the likelihood: models
    /// fitted on a few sequences per input often say 0 or 1, and one surprise must not rule
    /// a model out for ever.
    pub success_floor: f64,
    /// Before each observation the log-likelihood gathered so far is multiplied by this
    /// (1: nothing forgotten; 0.98: an observation 35 sequences old weighs half).
    pub forgetting: f64,
}

impl Default for LibraryParams {
    fn default() -> Self {
        LibraryParams {
            engagement_sd: 0.3,
            success_floor: 0.05,
            forgetting: 1.0,
        }
    }
}

impl LibraryParams {
    pub fn validate(&self) -> Result<(), BeliefError> {
        let bad = |what, value, why| Err(BeliefError::Parameter { what, value, why });
        if !(self.engagement_sd.is_finite() && self.engagement_sd > 0.0) {
            return bad("engagement_sd", self.engagement_sd, "must be > 0");
        }
        if !(self.success_floor > 0.0 && self.success_floor < 0.5) {
            return bad("success_floor", self.success_floor, "must be in (0, 0.5)");
        }
        if !(self.forgetting > 0.0 && self.forgetting <= 1.0) {
            return bad("forgetting", self.forgetting, "must be in (0, 1]");
        }
        Ok(())
    }
}

/// ln P(observation | model) up to a constant that is the same for every model: the answer's
/// probability (clamped) and the engagement's Gaussian exponent.
fn log_likelihood(params: &LibraryParams, model: &UserModelTable, o: &Observation) -> f64 {
    let p = clamp_probability(model.success(o.input).mean, params.success_floor);
    let answer = match o.outcome {
        Outcome::Success => p,
        Outcome::Failure => 1.0 - p,
    };
    let z = o.engagement.map_or(0.0, |e| {
        (e - model.engagement(o.input, o.outcome).mean) / params.engagement_sd
    });
    answer.ln() - 0.5 * z * z
}

/// The posterior over the library.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelPosterior {
    models: Vec<KnownModel>,
    log_prior: Vec<f64>,
    log_likelihood: Vec<f64>,
    params: LibraryParams,
    observed: usize,
}

impl ModelPosterior {
    /// `prior`: one weight per model (normalised here); a weight of 0 leaves the model out.
    pub fn new(
        models: Vec<KnownModel>,
        prior: &[f64],
        params: LibraryParams,
    ) -> Result<Self, BeliefError> {
        params.validate()?;
        if models.is_empty() {
            return Err(BeliefError::EmptyLibrary);
        }
        for m in &models {
            m.table.validate().map_err(|e| BeliefError::Model {
                name: m.name.clone(),
                reason: e.to_string(),
            })?;
        }
        if prior.len() != models.len() {
            return Err(BeliefError::PriorWeight {
                name: format!("{} weights for {} models", prior.len(), models.len()),
                value: f64::NAN,
            });
        }
        if let Some((m, w)) = models
            .iter()
            .zip(prior)
            .find(|(_, w)| !(w.is_finite() && **w >= 0.0))
        {
            return Err(BeliefError::PriorWeight {
                name: m.name.clone(),
                value: *w,
            });
        }
        let total: f64 = prior.iter().sum();
        if total <= 0.0 {
            return Err(BeliefError::PriorWeight {
                name: "every model".into(),
                value: 0.0,
            });
        }
        let n = models.len();
        Ok(ModelPosterior {
            models,
            log_prior: prior.iter().map(|w| (w / total).ln()).collect(),
            log_likelihood: vec![0.0; n],
            params,
            observed: 0,
        })
    }

    pub fn models(&self) -> &[KnownModel] {
        &self.models
    }

    pub fn params(&self) -> &LibraryParams {
        &self.params
    }

    /// ln P(observation | model): the answer's probability and the engagement's density.
    pub fn log_likelihood_under(&self, model: &UserModelTable, o: &Observation) -> f64 {
        let sd = self.params.engagement_sd;
        log_likelihood(&self.params, model, o) - sd.ln() - 0.5 * std::f64::consts::TAU.ln()
    }

    /// The posterior weights, in library order, summing to 1.
    pub fn weights(&self) -> Vec<f64> {
        let log: Vec<f64> = self
            .log_prior
            .iter()
            .zip(&self.log_likelihood)
            .map(|(p, l)| p + l)
            .collect();
        let top = log.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let w: Vec<f64> = log.iter().map(|l| (l - top).exp()).collect();
        let total: f64 = w.iter().sum();
        w.iter().map(|x| x / total).collect()
    }

    /// The model with the largest posterior weight and that weight.
    pub fn most_likely(&self) -> (&KnownModel, f64) {
        let w = self.weights();
        let (i, best) = w
            .iter()
            .enumerate()
            .fold((0, f64::NEG_INFINITY), |(bi, bw), (i, x)| {
                if *x > bw { (i, *x) } else { (bi, bw) }
            });
        (&self.models[i], best)
    }

    /// The mixture of the models with weights `w`: P(success) their weighted mean, E given the
    /// outcome their mean weighted by w_m P_m(outcome | input) (the posterior predictive),
    /// each with the mixture's standard deviation of the model means.
    pub fn mixture(&self, w: &[f64]) -> UserModelTable {
        let mut success = vec![
            Prediction {
                mean: 0.0,
                std: 0.0
            };
            SUCCESS_INPUTS
        ];
        let mut engagement = vec![
            Prediction {
                mean: 0.0,
                std: 0.0
            };
            ENGAGEMENT_INPUTS
        ];
        for input in ModelInput::all() {
            let i = input.index();
            let (mut p, mut p2) = (0.0, 0.0);
            for (m, wm) in self.models.iter().zip(w) {
                let x = m.table.success[i].mean;
                p += wm * x;
                p2 += wm * x * x;
            }
            success[i] = Prediction {
                mean: p.clamp(0.0, 1.0),
                std: (p2 - p * p).max(0.0).sqrt(),
            };
            for outcome in Outcome::ALL {
                let j = input.engagement_index(outcome);
                let (mut total, mut e, mut e2) = (0.0, 0.0, 0.0);
                for (m, wm) in self.models.iter().zip(w) {
                    let ps = m.table.success[i].mean;
                    let po = match outcome {
                        Outcome::Success => ps,
                        Outcome::Failure => 1.0 - ps,
                    };
                    let x = m.table.engagement[j].mean;
                    total += wm * po;
                    e += wm * po * x;
                    e2 += wm * po * x * x;
                }
                // An outcome no model expects: its engagement is the plain weighted mean.
                let (mean, second) = if total > 1e-12 {
                    (e / total, e2 / total)
                } else {
                    let mut m1 = 0.0;
                    let mut m2 = 0.0;
                    for (m, wm) in self.models.iter().zip(w) {
                        let x = m.table.engagement[j].mean;
                        m1 += wm * x;
                        m2 += wm * x * x;
                    }
                    (m1, m2)
                };
                engagement[j] = Prediction {
                    mean: mean.clamp(-1.0, 1.0),
                    std: (second - mean * mean).max(0.0).sqrt(),
                };
            }
        }
        UserModelTable {
            cluster: 0,
            success,
            engagement,
        }
    }
}

impl Belief for ModelPosterior {
    fn observe(&mut self, o: &Observation) {
        let lambda = self.params.forgetting;
        for (m, l) in self.models.iter().zip(self.log_likelihood.iter_mut()) {
            *l = lambda * *l + log_likelihood(&self.params, &m.table, o);
        }
        self.observed += 1;
    }

    fn predictive(&self) -> UserModelTable {
        self.mixture(&self.weights())
    }

    fn sample(&self, rng: &mut ChaCha8Rng) -> UserModelTable {
        let u = rng.random::<f64>();
        let w = self.weights();
        let mut cumulative = 0.0;
        for (m, wm) in self.models.iter().zip(&w) {
            cumulative += wm;
            if u < cumulative {
                return m.table.clone();
            }
        }
        self.models[self.models.len() - 1].table.clone()
    }

    fn observations(&self) -> usize {
        self.observed
    }
}

#[cfg(test)]
mod tests;
