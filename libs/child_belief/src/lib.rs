//! A belief about one child: what kind of learner they are, as a distribution over user models
//! M = (F^p, F^e), updated after every sequence from what the game observes (the answer, right
//! or wrong, at the level, feedback and previous score played, and the sequence's engagement).
//! Two representations: a posterior over a library of known models (`library`), and the
//! child's own Gaussian processes around a prior model (`own_model`). Either gives the
//! posterior predictive model a plan is solved on, a model drawn from the belief (posterior
//! sampling), and a summary per level for the therapist, the bag and replay. `planner`
//! decides on a belief: backward induction over the rest of the session on the paper's MDP
//! (`q_learning::mdp`), within the action mask, near a baseline table where it is unsure.
//! `prior_file` carries a prior covariance learned offline to the node.

pub mod library;
pub mod own_model;
pub mod planner;
pub mod prior_file;
mod summary;

pub use library::{LibraryParams, ModelPosterior};
pub use own_model::{LearnedCovariance, OwnModel, OwnModelParams};
pub use summary::{LevelBelief, level_summary};

use rand_chacha::ChaCha8Rng;
use sequence_game::{ModelInput, Outcome, UserModelTable};
use serde::{Deserialize, Serialize};

/// What was wrong with a belief's input; nothing was changed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BeliefError {
    #[error("engagement {0} is not a number in [-1, 1]")]
    Engagement(f64),
    #[error("the library of known models is empty")]
    EmptyLibrary,
    #[error("known model {name:?}: {reason}")]
    Model { name: String, reason: String },
    #[error("prior weight of {name:?} = {value} must be finite and >= 0, and some must be > 0")]
    PriorWeight { name: String, value: f64 },
    #[error("{what} = {value} is not allowed: {why}")]
    Parameter {
        what: &'static str,
        value: f64,
        why: &'static str,
    },
}

/// One observed sequence: the input (L, F, PS) it was played at, whether the child answered
/// right, and its engagement E in [-1, 1] (`None` where no face was seen: the answer alone
/// is evidence).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Observation {
    pub input: ModelInput,
    pub outcome: Outcome,
    pub engagement: Option<f64>,
}

impl Observation {
    /// Refuses an engagement that is not a number in [-1, 1].
    pub fn new(input: ModelInput, outcome: Outcome, engagement: f64) -> Result<Self, BeliefError> {
        if !(engagement.is_finite() && (-1.0..=1.0).contains(&engagement)) {
            return Err(BeliefError::Engagement(engagement));
        }
        Ok(Observation {
            input,
            outcome,
            engagement: Some(engagement),
        })
    }

    /// A sequence whose engagement was not seen (no face in its period).
    pub fn without_engagement(input: ModelInput, outcome: Outcome) -> Self {
        Observation {
            input,
            outcome,
            engagement: None,
        }
    }
}

/// What any belief about a child offers the planner and the reports.
pub trait Belief {
    /// Takes one observed sequence into account.
    fn observe(&mut self, observation: &Observation);
    /// The posterior predictive model: P(success | input) and E[engagement | input, outcome]
    /// under the belief, with each one's posterior standard deviation. Its expected return
    /// for a policy is the belief's expected return for that policy over the next session
    /// (ignoring what the session itself will teach).
    fn predictive(&self) -> UserModelTable;
    /// One model drawn from the belief (posterior sampling).
    fn sample(&self, rng: &mut ChaCha8Rng) -> UserModelTable;
    /// `n` models drawn from the belief, one after the other from `rng`.
    fn samples(&self, rng: &mut ChaCha8Rng, n: usize) -> Vec<UserModelTable> {
        (0..n).map(|_| self.sample(rng)).collect()
    }
    /// Sequences observed so far.
    fn observations(&self) -> usize;
    /// How many of the child's own sequences were played at `input` (forgetting applied),
    /// where the belief keeps count.
    fn evidence(&self, _input: ModelInput) -> Option<f64> {
        None
    }
}

impl<B: Belief + ?Sized> Belief for Box<B> {
    fn observe(&mut self, observation: &Observation) {
        (**self).observe(observation)
    }
    fn predictive(&self) -> UserModelTable {
        (**self).predictive()
    }
    fn sample(&self, rng: &mut ChaCha8Rng) -> UserModelTable {
        (**self).sample(rng)
    }
    fn samples(&self, rng: &mut ChaCha8Rng, n: usize) -> Vec<UserModelTable> {
        (**self).samples(rng, n)
    }
    fn observations(&self) -> usize {
        (**self).observations()
    }
    fn evidence(&self, input: ModelInput) -> Option<f64> {
        (**self).evidence(input)
    }
}

/// Clamps a probability into [floor, 1 − floor]: no known model may call an answer impossible
/// (the models are fitted on one or a few sequences per input, where 0 and 1 are common).
pub(crate) fn clamp_probability(p: f64, floor: f64) -> f64 {
    p.clamp(floor, 1.0 - floor)
}
