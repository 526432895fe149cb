//! A played session as the live game logs it: each decision with the probability the policy
//! gave the action taken, and what followed. Sessions played against a user model
//! (`play_session`) and sessions read from bags (the lab's counterfactual evaluation) both come
//! as these.

use sequence_game::{Action, Outcome, State};

/// One recorded decision and what followed it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoggedStep {
    /// The state the decision was taken in.
    pub state: State,
    /// 1-based sequence the decision set up.
    pub step: u8,
    pub action: Action,
    /// The probability the logging policy gave `action` (the decision's `probabilities`).
    pub logged_probability: f64,
    pub outcome: Outcome,
    /// Mean expected engagement E over the sequence.
    pub engagement: f64,
}

/// One played session, its decisions in order.
#[derive(Debug, Clone, PartialEq)]
pub struct LoggedSession {
    pub session_id: String,
    pub steps: Vec<LoggedStep>,
}
