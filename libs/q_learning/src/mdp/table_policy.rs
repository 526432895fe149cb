//! A Q-table's policy over a session, its probabilities exactly as the live policy computes
//! them: greedy, softmax at one temperature or at each state's own, or ε-greedy. The policy
//! counterfactual evaluation judges (or that logs, in simulation), and whose exact value
//! backward induction gives.

use super::StepPolicy;
use crate::learning::{Mode, QTable, TemperatureSchedule, action_probabilities, allowed_at};
use sequence_game::{ACTION_COUNT, State};

/// Why a Q-table's policy cannot be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TargetPolicyError {
    #[error("temperature {0} is not a positive number")]
    Temperature(f64),
    #[error("ε {0} is not in [0, 1]")]
    Epsilon(f64),
}

/// How the evaluated policy picks from its Q-table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TargetTemperature {
    /// Greedy, ties uniform: the exploitation-only mode of real sessions.
    Greedy,
    /// Softmax at one temperature in every state.
    Fixed(f64),
    /// Softmax at each state's own temperature T_s from its visits.
    PerState(TemperatureSchedule),
    /// Greedy, but with probability ε an action drawn uniformly from the allowed ones: the
    /// live policy's logged exploration (`exploration_epsilon`).
    EpsilonGreedy(f64),
}

/// The policy being judged (or the one that logs, in simulation).
#[derive(Debug, Clone, PartialEq)]
pub struct TargetPolicy {
    pub table: QTable,
    pub temperature: TargetTemperature,
}

impl TargetPolicy {
    pub fn new(table: QTable, temperature: TargetTemperature) -> Result<Self, TargetPolicyError> {
        if let TargetTemperature::Fixed(t) = temperature
            && !(t.is_finite() && t > 0.0)
        {
            return Err(TargetPolicyError::Temperature(t));
        }
        if let TargetTemperature::EpsilonGreedy(e) = temperature
            && !(0.0..=1.0).contains(&e)
        {
            return Err(TargetPolicyError::Epsilon(e));
        }
        Ok(TargetPolicy { table, temperature })
    }

    /// π(· | state) for the sequence `step`, exactly as the live policy computes it.
    pub fn probabilities(&self, state: State, step: u8) -> [f64; ACTION_COUNT] {
        let row = self.table.row(state);
        let allowed = allowed_at(state, step);
        match self.temperature {
            TargetTemperature::Greedy => action_probabilities(row, allowed, Mode::Exploit, 1.0),
            TargetTemperature::Fixed(t) => action_probabilities(row, allowed, Mode::Explore, t),
            TargetTemperature::PerState(schedule) => {
                let t = schedule.at(self.table.visits[state.index()]);
                action_probabilities(row, allowed, Mode::Explore, t)
            }
            TargetTemperature::EpsilonGreedy(e) => {
                action_probabilities(row, allowed, Mode::EpsilonGreedy(e), 1.0)
            }
        }
    }
}

impl StepPolicy for TargetPolicy {
    fn probabilities(&self, state: State, step: u8) -> [f64; ACTION_COUNT] {
        TargetPolicy::probabilities(self, state, step)
    }
}
