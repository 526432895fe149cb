//! The live policy, sans-IO: given (state, step in the session) it returns an explained
//! `Decision`; given an observed sequence result it applies Algorithm 1's update. Data in,
//! data out: the node moves messages and saves files (`nodes/behaviour_policy`, `persistent`).

use crate::learning::{
    Learning, Mode, QTable, action_probabilities, allowed_at, best, epsilon_greedy_pick,
    greedy_set, nth_member, sample_weights, softmax_weights, td_target,
};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sequence_game::{ACTION_COUNT, Action, Feedback, LEVEL_COUNT, Level, State};

/// Why the policy refused a request; nothing was changed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PolicyError {
    #[error("state (L={level}, F={feedback}, PS={previous_score}) is outside the state space")]
    StateOutsideSpace {
        level: u8,
        feedback: u8,
        previous_score: i8,
    },
    #[error("step {0}: steps in a session count from 1")]
    Step(u8),
    #[error("action {action} is not allowed in {state}")]
    ActionNotAllowed { action: Action, state: State },
    #[error(
        "next state {next} does not follow {action} taken in {state} (expected L={level}, F={feedback})"
    )]
    NextStateMismatch {
        state: State,
        action: Action,
        next: State,
        level: u8,
        feedback: u8,
    },
    #[error("next state is the start state: a sequence always has a level")]
    NextIsStart,
    #[error("engagement {0} is not a number in [-1, 1]")]
    Engagement(f64),
    #[error("activity result {0} is not a number in [-1, {LEVEL_COUNT}]")]
    ActivityResult(f64),
    #[error("the update of Q({state}, {action}) would give {value}; the table is unchanged")]
    NotFinite {
        state: State,
        action: Action,
        value: f64,
    },
}

/// One decision with everything it was based on, so it can be explained to the therapist.
#[derive(Debug, Clone, PartialEq)]
pub struct Decision {
    pub state: State,
    /// 1-based sequence in the session this action sets up.
    pub step: u8,
    pub action: Action,
    pub level: Level,
    pub feedback: Feedback,
    /// Q(s, a) for a1..a5 (masked actions included, as stored).
    pub q_values: [f64; ACTION_COUNT],
    /// Probability each action had under the draw that chose it: softmax, uniform over the
    /// greedy ties when exploiting, or ε-greedy's (ε / allowed, plus (1 − ε) / ties for a
    /// greedy action); 0 for masked actions. Counterfactual evaluation weighs the decision
    /// with exactly these.
    pub probabilities: [f64; ACTION_COUNT],
    /// How many of a1..a5 were allowed (3 at the first sequence or in the start state).
    pub allowed_actions: usize,
    /// T_s (reported in exploitation and ε-greedy too, where it is not used).
    pub temperature: f64,
    /// A non-greedy action was drawn.
    pub explored: bool,
    pub mode: Mode,
}

/// An observed sequence: what the policy learns from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transition {
    pub state: State,
    pub action: Action,
    /// RE: L on success, -1 on failure.
    pub activity_result: f64,
    /// Mean engagement E over the sequence, in [-1, 1].
    pub engagement: f64,
    pub next_state: State,
    /// The session's last sequence: no bootstrap.
    pub is_last: bool,
}

/// What an update did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Update {
    pub reward: f64,
    pub old_q: f64,
    pub new_q: f64,
}

/// One Q-table (a cluster's or a user's) with its learning constants and random stream.
#[derive(Debug, Clone)]
pub struct PolicyCore {
    table: QTable,
    learning: Learning,
    mode: Mode,
    rng: ChaCha8Rng,
    updates: u64,
}

/// A state built by hand (its fields are public) may not be one of the 64.
pub fn check_state(state: State) -> Result<State, PolicyError> {
    match State::new(
        state.level.into(),
        state.feedback as i64,
        state.previous_score.into(),
    ) {
        Ok(s) if s == state => Ok(s),
        _ => Err(PolicyError::StateOutsideSpace {
            level: state.level,
            feedback: state.feedback as u8,
            previous_score: state.previous_score,
        }),
    }
}

impl PolicyCore {
    pub fn new(table: QTable, learning: Learning, mode: Mode, seed: u64, updates: u64) -> Self {
        PolicyCore {
            table,
            learning,
            mode,
            rng: ChaCha8Rng::seed_from_u64(seed),
            updates,
        }
    }

    pub fn q_table(&self) -> &QTable {
        &self.table
    }

    pub fn learning(&self) -> &Learning {
        &self.learning
    }

    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Updates applied since the table was created (kept in its file).
    pub fn updates(&self) -> u64 {
        self.updates
    }

    /// The action for the sequence `step` (1-based) from `state`. At the first sequence only
    /// a1..a3 are allowed: there is no context for feedback yet.
    pub fn decide(&mut self, state: State, step: u8) -> Result<Decision, PolicyError> {
        let state = check_state(state)?;
        if step == 0 {
            return Err(PolicyError::Step(step));
        }
        let allowed = allowed_at(state, step);
        let row = *self.table.row(state);
        let temperature = self
            .learning
            .temperature
            .at(self.table.visits[state.index()]);
        let probabilities = action_probabilities(&row, allowed, self.mode, temperature);
        let (index, explored) = match self.mode {
            Mode::Explore => {
                let s = softmax_weights(&row, allowed, temperature);
                let a = sample_weights(&s.weights, allowed, s.total, self.rng.random::<f64>());
                (a, row[a] < s.best)
            }
            Mode::Exploit => {
                let (set, n) = greedy_set(&row, allowed);
                let k = if n > 1 {
                    self.rng.random_range(0..n)
                } else {
                    0
                };
                (nth_member(set, k), false)
            }
            Mode::EpsilonGreedy(epsilon) => {
                let a = epsilon_greedy_pick(&row, allowed, epsilon, self.rng.random::<f64>());
                (a, row[a] < best(&row, allowed))
            }
        };
        let action = Action::ALL[index];
        // A feedback action repeats the state's level; at step 1 only a1..a3 can be drawn.
        let (level, feedback) = action
            .apply(state)
            .ok_or(PolicyError::ActionNotAllowed { action, state })?;
        Ok(Decision {
            state,
            step,
            action,
            level,
            feedback,
            q_values: row,
            probabilities,
            allowed_actions: allowed,
            temperature,
            explored,
            mode: self.mode,
        })
    }

    /// Q(s, a) += α (F_r(RE, E) + γ max Q(s', ·) − Q(s, a)), without the bootstrap on the
    /// session's last sequence; the state's visit count (its temperature) goes up by one.
    /// Refuses bad input and any update that would leave a non-finite Q-value.
    pub fn learn(&mut self, t: &Transition) -> Result<Update, PolicyError> {
        let state = check_state(t.state)?;
        let next = check_state(t.next_state)?;
        if !(t.engagement.is_finite() && (-1.0..=1.0).contains(&t.engagement)) {
            return Err(PolicyError::Engagement(t.engagement));
        }
        if !(t.activity_result.is_finite()
            && (-1.0..=LEVEL_COUNT as f64).contains(&t.activity_result))
        {
            return Err(PolicyError::ActivityResult(t.activity_result));
        }
        let (level, feedback) = t.action.apply(state).ok_or(PolicyError::ActionNotAllowed {
            action: t.action,
            state,
        })?;
        if next.is_start() {
            return Err(PolicyError::NextIsStart);
        }
        if next.level != level.get() || next.feedback != feedback {
            return Err(PolicyError::NextStateMismatch {
                state,
                action: t.action,
                next,
                level: level.get(),
                feedback: feedback as u8,
            });
        }
        let reward = self.learning.reward(t.activity_result, t.engagement);
        let target = td_target(reward, self.learning.gamma, self.table.row(next), t.is_last);
        let old_q = self.table.row(state)[t.action.index()];
        let new_q = old_q + self.learning.alpha * (target - old_q);
        if !new_q.is_finite() {
            return Err(PolicyError::NotFinite {
                state,
                action: t.action,
                value: new_q,
            });
        }
        self.table.q[state.index()][t.action.index()] = new_q;
        let visits = &mut self.table.visits[state.index()];
        *visits = visits.saturating_add(1);
        self.updates += 1;
        Ok(Update {
            reward,
            old_q,
            new_q,
        })
    }
}

#[cfg(test)]
mod tests;
