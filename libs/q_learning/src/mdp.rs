//! A user model as the decision problem of one session of ten sequences (the live state
//! convention: PS is the latest result): sessions played against it by any policy, a policy's
//! exact value by backward induction, and the optimal policy, whose value is the most any
//! policy (learning or not) can expect in a session against that model; played sessions as the
//! live game logs them, and a Q-table's policy over a session. Counterfactual evaluation's
//! validation and the per-child study share it.

mod logged;
mod table_policy;

pub use logged::{LoggedSession, LoggedStep};
pub use table_policy::{TargetPolicy, TargetPolicyError, TargetTemperature};

use crate::learning::{Learning, allowed_at};
use crate::simulation::{SessionMetrics, answers_right};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sequence_game::{
    ACTION_COUNT, Action, ModelInput, Outcome, SEQUENCES_PER_SESSION, STATE_COUNT, State,
    UserModelTable,
};
use serde::Serialize;

/// A policy over a session's decisions: π(· | state) for each sequence.
pub trait StepPolicy {
    /// The probability of each action for the sequence `step` (1-based) from `state`; 0 for
    /// the actions not allowed there.
    fn probabilities(&self, state: State, step: u8) -> [f64; ACTION_COUNT];
}

/// The draw of one action from a distribution, for a uniform `u` in [0, 1).
fn draw(probabilities: &[f64; ACTION_COUNT], u: f64) -> usize {
    let mut cumulative = 0.0;
    let mut last = 0;
    for (a, p) in probabilities.iter().enumerate() {
        if *p > 0.0 {
            cumulative += p;
            last = a;
            if u < cumulative {
                return a;
            }
        }
    }
    last
}

/// A simulated child's answer to a sequence, for a uniform `u`: right iff `u <= F^p(L, F, PS)`,
/// engagement F^e(L, F, PS, O) (the means, as the policy's simulation uses them).
pub fn child_answer(model: &UserModelTable, input: ModelInput, u: f64) -> (Outcome, f64) {
    let outcome = Outcome::from_correct(answers_right(u, model.success(input).mean));
    (
        outcome,
        model.engagement(input, outcome).mean.clamp(-1.0, 1.0),
    )
}

/// The model input of the sequence `action` sets up from `state`, and the state after it.
pub fn transition(state: State, action: Action, outcome: Outcome) -> Option<(ModelInput, State)> {
    let (level, feedback) = action.apply(state)?;
    let input = ModelInput {
        level,
        feedback,
        previous_score: state.previous_score,
    };
    Some((input, State::after(level, feedback, outcome)))
}

/// A session played by `policy` (which does not learn) against the user model, recorded as
/// the live game records it: every decision with its probability and the policy's whole
/// distribution. `uniforms(k)` gives sequence k's (0-based) uniforms: the action's draw, then
/// the child's answer.
pub fn play_session(
    model: &UserModelTable,
    policy: &impl StepPolicy,
    session_id: String,
    mut uniforms: impl FnMut(usize) -> (f64, f64),
) -> (LoggedSession, Vec<[f64; ACTION_COUNT]>) {
    let mut state = State::START;
    let mut steps = Vec::with_capacity(SEQUENCES_PER_SESSION);
    let mut full = Vec::with_capacity(SEQUENCES_PER_SESSION);
    for k in 0..SEQUENCES_PER_SESSION {
        let step = k as u8 + 1;
        let p = policy.probabilities(state, step);
        let (u_action, u_answer) = uniforms(k);
        let action = Action::ALL[draw(&p, u_action)];
        // Outcome first from the input (which does not depend on it), then the state.
        let Some((input, _)) = transition(state, action, Outcome::Success) else {
            break; // cannot happen: masked actions have probability 0
        };
        let (outcome, engagement) = child_answer(model, input, u_answer);
        let Some((_, next)) = transition(state, action, outcome) else {
            break;
        };
        steps.push(LoggedStep {
            state,
            step,
            action,
            logged_probability: p[action.index()],
            outcome,
            engagement,
        });
        full.push(p);
        state = next;
    }
    (LoggedSession { session_id, steps }, full)
}

/// `sessions` sessions played by `policy` from one random stream (`seed`), as [`play_session`].
pub fn simulate_sessions(
    model: &UserModelTable,
    policy: &impl StepPolicy,
    sessions: usize,
    seed: u64,
) -> (Vec<LoggedSession>, Vec<Vec<[f64; ACTION_COUNT]>>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..sessions)
        .map(|i| {
            play_session(model, policy, format!("simulated-{i}"), |_| {
                (rng.random::<f64>(), rng.random::<f64>())
            })
        })
        .unzip()
}

/// A played session's metrics as the policy's simulation reports them (`start_value` is left
/// 0: a policy that does not learn has no value of its own to report).
pub fn session_metrics(session: &LoggedSession, learning: &Learning) -> SessionMetrics {
    let mut m = SessionMetrics::default();
    let mut discount = 1.0;
    for s in &session.steps {
        let Some((level, _)) = s.action.apply(s.state) else {
            continue; // a played session's actions are always allowed
        };
        m.score += f64::from(s.outcome.score(level));
        m.max_score += f64::from(level.get());
        m.engagement += s.engagement;
        m.discounted_return +=
            discount * learning.reward(s.outcome.activity_result(level), s.engagement);
        discount *= learning.gamma;
    }
    m.engagement /= session.steps.len().max(1) as f64;
    m
}

/// A policy's true expected discounted return and score over a ten-sequence session against
/// the user model (no sampling).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ExactValue {
    pub discounted_return: f64,
    pub score: f64,
}

/// Expected discounted return and score from `state` at sequence `step` if `action` is taken
/// there and the values of the next sequence's states are `next`.
fn action_value(
    model: &UserModelTable,
    learning: &Learning,
    state: State,
    action: Action,
    next: &[ExactValue; STATE_COUNT],
) -> ExactValue {
    let mut v = ExactValue {
        discounted_return: 0.0,
        score: 0.0,
    };
    for outcome in Outcome::ALL {
        let Some((input, after)) = transition(state, action, outcome) else {
            continue;
        };
        let success = model.success(input).mean.clamp(0.0, 1.0);
        let po = match outcome {
            Outcome::Success => success,
            Outcome::Failure => 1.0 - success,
        };
        let e = model.engagement(input, outcome).mean.clamp(-1.0, 1.0);
        let reward = learning.reward(outcome.activity_result(input.level), e);
        let n = next[after.index()];
        v.discounted_return += po * (reward + learning.gamma * n.discounted_return);
        v.score += po * (f64::from(outcome.score(input.level)) + n.score);
    }
    v
}

/// Backward induction over the ten sequences: `choose(state, step, values of the allowed
/// actions)` gives the probabilities of the actions at that point; returns the start
/// state's value.
fn backward_induction(
    model: &UserModelTable,
    learning: &Learning,
    mut choose: impl FnMut(State, u8, &[ExactValue]) -> [f64; ACTION_COUNT],
) -> ExactValue {
    let zero = ExactValue {
        discounted_return: 0.0,
        score: 0.0,
    };
    let mut next = [zero; STATE_COUNT];
    for step in (1..=SEQUENCES_PER_SESSION as u8).rev() {
        let mut now = [zero; STATE_COUNT];
        for state in State::all() {
            let allowed = allowed_at(state, step);
            let values: Vec<ExactValue> = Action::ALL[..allowed]
                .iter()
                .map(|&a| action_value(model, learning, state, a, &next))
                .collect();
            let p = choose(state, step, &values);
            let v = &mut now[state.index()];
            for (pa, q) in p.iter().zip(&values) {
                v.discounted_return += pa * q.discounted_return;
                v.score += pa * q.score;
            }
        }
        next = now;
    }
    next[State::START.index()]
}

/// `policy`'s exact value against the model, by backward induction over the 64 states.
pub fn exact_value(
    model: &UserModelTable,
    policy: &impl StepPolicy,
    learning: &Learning,
) -> ExactValue {
    backward_induction(model, learning, |state, step, _| {
        policy.probabilities(state, step)
    })
}

/// What the optimal policy maximises.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Objective {
    /// The expected discounted return Σ γ^(t-1) r (the reward of `Learning`): what Q-learning
    /// maximises.
    Return,
    /// The expected score Σ L·O.
    Score,
}

/// The policy with the highest expected objective against a model: for each sequence and
/// state the action with the best expected objective from there to the session's end
/// (backward induction; among equals the lowest-numbered). Its value is the most any policy
/// can expect per session against that model, whatever it has learned, since the model's
/// answers depend only on the state and the sequence played.
#[derive(Debug, Clone, PartialEq)]
pub struct OptimalPolicy {
    pub objective: Objective,
    /// Per sequence (0-based) and state row, the action's index.
    actions: [[u8; STATE_COUNT]; SEQUENCES_PER_SESSION],
    /// Its exact value (both quantities, whichever it maximises).
    pub value: ExactValue,
}

impl StepPolicy for OptimalPolicy {
    fn probabilities(&self, state: State, step: u8) -> [f64; ACTION_COUNT] {
        let k = usize::from(step.clamp(1, SEQUENCES_PER_SESSION as u8)) - 1;
        let mut p = [0.0; ACTION_COUNT];
        p[usize::from(self.actions[k][state.index()])] = 1.0;
        p
    }
}

pub fn optimal_policy(
    model: &UserModelTable,
    learning: &Learning,
    objective: Objective,
) -> OptimalPolicy {
    let mut actions = [[0u8; STATE_COUNT]; SEQUENCES_PER_SESSION];
    let value = backward_induction(model, learning, |state, step, values| {
        let of = |v: &ExactValue| match objective {
            Objective::Return => v.discounted_return,
            Objective::Score => v.score,
        };
        let mut best = 0;
        for (a, v) in values.iter().enumerate().skip(1) {
            if of(v) > of(&values[best]) {
                best = a;
            }
        }
        actions[usize::from(step) - 1][state.index()] = best as u8;
        let mut p = [0.0; ACTION_COUNT];
        p[best] = 1.0;
        p
    });
    OptimalPolicy {
        objective,
        actions,
        value,
    }
}

#[cfg(test)]
mod tests;
