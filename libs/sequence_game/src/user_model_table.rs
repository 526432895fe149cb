//! A user model's predictions tabulated over the whole finite input space: F^p(L, F, PS) for
//! the 3 x 3 x 7 = 63 states and F^e(L, F, PS, O) for the 126 state-outcome pairs. The state
//! space is finite, so a fitted Gaussian process is evaluated once and every later query (the
//! policy's simulations, the user-model service) is a table lookup.

use crate::{Feedback, GameError, Level, Outcome, State};
use serde::{Deserialize, Serialize};

/// Inputs of F^p: L x F x PS.
pub const SUCCESS_INPUTS: usize = 3 * 3 * 7;
/// Inputs of F^e: L x F x PS x O.
pub const ENGAGEMENT_INPUTS: usize = SUCCESS_INPUTS * 2;

/// A GP prediction: posterior mean (already clamped to the target's range) and standard
/// deviation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Prediction {
    pub mean: f64,
    pub std: f64,
}

/// The input (L, F, PS) of F^p; PS = 0 is allowed (the first sequence after the start state).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct ModelInput {
    pub level: Level,
    pub feedback: Feedback,
    pub previous_score: i8,
}

impl ModelInput {
    pub fn new(level: Level, feedback: Feedback, previous_score: i8) -> Result<Self, GameError> {
        if !(-3..=3).contains(&previous_score) {
            return Err(GameError::PreviousScore(previous_score.into()));
        }
        Ok(ModelInput {
            level,
            feedback,
            previous_score,
        })
    }

    /// The model input for a (non-start) MDP state.
    pub fn of_state(state: State) -> Option<Self> {
        Some(ModelInput {
            level: state.level()?,
            feedback: state.feedback,
            previous_score: state.previous_score,
        })
    }

    /// Row in the F^p table: L-major, then F, then PS + 3.
    pub fn index(self) -> usize {
        self.level.index() * 21 + self.feedback.index() * 7 + (self.previous_score + 3) as usize
    }

    /// Row in the F^e table for this input and outcome.
    pub fn engagement_index(self, outcome: Outcome) -> usize {
        self.index() * 2 + outcome.index()
    }

    /// All 63 inputs in table order.
    pub fn all() -> impl Iterator<Item = ModelInput> {
        Level::ALL.into_iter().flat_map(|level| {
            Feedback::ALL.into_iter().flat_map(move |feedback| {
                (-3i8..=3).map(move |previous_score| ModelInput {
                    level,
                    feedback,
                    previous_score,
                })
            })
        })
    }
}

/// One cluster's user model M_k = (F^p_k, F^e_k) as lookup tables.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UserModelTable {
    /// Which cluster C_k this model describes (0-based).
    pub cluster: usize,
    /// F^p in [`ModelInput::index`] order, 63 entries.
    pub success: Vec<Prediction>,
    /// F^e in [`ModelInput::engagement_index`] order, 126 entries.
    pub engagement: Vec<Prediction>,
}

/// A table whose shape or values do not fit the input space.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TableError {
    #[error("cluster {cluster}: {table} table has {found} entries, expected {expected}")]
    Length {
        cluster: usize,
        table: &'static str,
        found: usize,
        expected: usize,
    },
    #[error(
        "cluster {cluster}: {table}[{index}] = {value} is outside [{low}, {high}] or not finite"
    )]
    Value {
        cluster: usize,
        table: &'static str,
        index: usize,
        value: f64,
        low: f64,
        high: f64,
    },
}

impl UserModelTable {
    /// Builds a table by evaluating the two model components on every input.
    pub fn tabulate(
        cluster: usize,
        mut success: impl FnMut(ModelInput) -> Prediction,
        mut engagement: impl FnMut(ModelInput, Outcome) -> Prediction,
    ) -> Self {
        let inputs: Vec<ModelInput> = ModelInput::all().collect();
        UserModelTable {
            cluster,
            success: inputs.iter().map(|&i| success(i)).collect(),
            engagement: inputs
                .iter()
                .flat_map(|&i| Outcome::ALL.map(|o| (i, o)))
                .map(|(i, o)| engagement(i, o))
                .collect(),
        }
    }

    /// Checks lengths and ranges (P in [0, 1], E in [-1, 1], std >= 0), e.g. after loading.
    pub fn validate(&self) -> Result<(), TableError> {
        let check =
            |table: &'static str, v: &[Prediction], expected: usize, low: f64, high: f64| {
                if v.len() != expected {
                    return Err(TableError::Length {
                        cluster: self.cluster,
                        table,
                        found: v.len(),
                        expected,
                    });
                }
                for (index, p) in v.iter().enumerate() {
                    for (value, lo, hi) in [(p.mean, low, high), (p.std, 0.0, f64::INFINITY)] {
                        if !(value.is_finite() && value >= lo && value <= hi) {
                            return Err(TableError::Value {
                                cluster: self.cluster,
                                table,
                                index,
                                value,
                                low: lo,
                                high: hi,
                            });
                        }
                    }
                }
                Ok(())
            };
        check("success", &self.success, SUCCESS_INPUTS, 0.0, 1.0)?;
        check("engagement", &self.engagement, ENGAGEMENT_INPUTS, -1.0, 1.0)
    }

    /// F^p_k(L, F, PS): probability of success.
    pub fn success(&self, input: ModelInput) -> Prediction {
        self.success[input.index()]
    }

    /// F^e_k(L, F, PS, O): expected engagement.
    pub fn engagement(&self, input: ModelInput, outcome: Outcome) -> Prediction {
        self.engagement[input.engagement_index(outcome)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn indices_cover_the_tables_exactly_once() {
        let inputs: Vec<ModelInput> = ModelInput::all().collect();
        assert_eq!(inputs.len(), SUCCESS_INPUTS);
        for (i, input) in inputs.iter().enumerate() {
            assert_eq!(input.index(), i);
            assert_eq!(input.engagement_index(Outcome::Failure), 2 * i);
            assert_eq!(input.engagement_index(Outcome::Success), 2 * i + 1);
        }
    }

    #[test]
    fn tabulate_then_lookup_returns_the_evaluated_values() {
        let t = UserModelTable::tabulate(
            1,
            |i| Prediction {
                mean: f64::from(i.level.get()) / 4.0,
                std: 0.1,
            },
            |i, o| Prediction {
                mean: f64::from(o.sign()) * f64::from(i.previous_score) / 4.0,
                std: 0.0,
            },
        );
        t.validate().expect("valid table");
        let i = ModelInput::new(Level::THREE, Feedback::Challenging, -2).expect("valid");
        assert_eq!(t.success(i).mean, 0.75);
        assert_eq!(t.engagement(i, Outcome::Failure).mean, 0.5);
        let mut bad = t.clone();
        bad.engagement[7].mean = 1.5;
        assert!(matches!(
            bad.validate(),
            Err(TableError::Value { index: 7, .. })
        ));
    }
}
