//! Tabular Q-learning as the paper's Algorithm 1, with the authors' details (REFERENCE.md): the
//! state (L, F, PS) lags the result by one step, only a1..a3 in the start state, softmax with a
//! per-state temperature T_s = max(T_min, T0 - decay * visits_s) (visits from 1, counted in one
//! session per epoch), success drawn as U(0,1) <= F^p, E from F^e at (next state, O), rewards
//! RE / RE + βE / λE, no bootstrap on the last step of a session.

use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use sequence_game::{
    ACTION_COUNT, Action, ModelInput, Outcome, SEQUENCES_PER_SESSION, STATE_COUNT, State,
    UserModelTable,
};
use serde::{Deserialize, Serialize};

/// The reward function F_r.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Reward {
    /// RE: L on success, -1 on failure.
    Re,
    /// RE + βE.
    RePlusBetaE,
    /// λE.
    LambdaE,
}

impl Reward {
    pub const ALL: [Reward; 3] = [Reward::Re, Reward::RePlusBetaE, Reward::LambdaE];

    pub fn name(self) -> &'static str {
        match self {
            Reward::Re => "RE",
            Reward::RePlusBetaE => "RE+bE",
            Reward::LambdaE => "lE",
        }
    }

    pub fn parse(s: &str) -> Option<Reward> {
        match s {
            "RE" | "re" => Some(Reward::Re),
            "RE+bE" | "re+be" | "RE+βE" => Some(Reward::RePlusBetaE),
            "lE" | "le" | "λE" => Some(Reward::LambdaE),
            _ => None,
        }
    }
}

/// Learning constants (defaults: the authors').
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Learning {
    pub alpha: f64,
    pub gamma: f64,
    pub initial_temperature: f64,
    pub min_temperature: f64,
    pub temperature_decay: f64,
    pub beta: f64,
    pub lambda: f64,
    pub reward: Reward,
    /// The authors' state: PS is the score of the sequence *before* the one just played (the
    /// agent acts before it sees the latest result). False: PS is the latest result, as the
    /// live game reports it.
    pub state_lags_result: bool,
}

impl Default for Learning {
    fn default() -> Self {
        Learning {
            alpha: 0.05,
            gamma: 0.95,
            initial_temperature: 300.0,
            min_temperature: 0.5,
            temperature_decay: 5.0,
            beta: 3.0,
            lambda: 3.0,
            reward: Reward::Re,
            state_lags_result: true,
        }
    }
}

impl Learning {
    pub fn reward(&self, activity_result: f64, engagement: f64) -> f64 {
        match self.reward {
            Reward::Re => activity_result,
            Reward::RePlusBetaE => activity_result + self.beta * engagement,
            Reward::LambdaE => self.lambda * engagement,
        }
    }
}

/// Q-values and visit counts of every state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct QTable {
    pub q: Vec<[f64; ACTION_COUNT]>,
    /// Visits counted for the temperature (the authors start at 1).
    pub visits: Vec<u32>,
}

impl Default for QTable {
    fn default() -> Self {
        QTable {
            q: vec![[0.0; ACTION_COUNT]; STATE_COUNT],
            visits: vec![1; STATE_COUNT],
        }
    }
}

/// How an action is picked.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Mode {
    /// Softmax with the state's temperature (training).
    Explore,
    /// Greedy, ties broken at random, still learning (real sessions, transfer).
    Exploit,
}

/// One choice with what it was based on.
#[derive(Debug, Clone, PartialEq)]
pub struct Choice {
    pub action: Action,
    pub q_values: [f64; ACTION_COUNT],
    /// Softmax (or greedy) probabilities; 0 for masked actions.
    pub probabilities: [f64; ACTION_COUNT],
    pub temperature: f64,
    /// A non-greedy action was drawn.
    pub explored: bool,
}

impl QTable {
    pub fn temperature(&self, state: State, learning: &Learning) -> f64 {
        let visits = f64::from(self.visits[state.index()]);
        (learning.initial_temperature - learning.temperature_decay * visits)
            .max(learning.min_temperature)
    }

    /// Picks an action in `state` (feedback actions masked at the start).
    pub fn choose(
        &self,
        state: State,
        mode: Mode,
        learning: &Learning,
        rng: &mut ChaCha8Rng,
    ) -> Choice {
        let allowed = state.allowed_actions();
        let q = self.q[state.index()];
        let temperature = self.temperature(state, learning);
        let best = allowed
            .iter()
            .map(|a| q[a.index()])
            .fold(f64::NEG_INFINITY, f64::max);
        let mut probabilities = [0.0; ACTION_COUNT];
        match mode {
            Mode::Explore => {
                // Subtracting the max gives the same probabilities without overflow.
                let mut total = 0.0;
                for a in allowed {
                    let w = ((q[a.index()] - best) / temperature).exp();
                    probabilities[a.index()] = w;
                    total += w;
                }
                probabilities.iter_mut().for_each(|p| *p /= total);
            }
            Mode::Exploit => {
                let ties = allowed.iter().filter(|a| q[a.index()] == best).count() as f64;
                for a in allowed.iter().filter(|a| q[a.index()] == best) {
                    probabilities[a.index()] = 1.0 / ties;
                }
            }
        }
        let mut u: f64 = rng.random::<f64>();
        let mut action = allowed[allowed.len() - 1];
        for a in allowed {
            let p = probabilities[a.index()];
            if p > 0.0 && u < p {
                action = *a;
                break;
            }
            u -= p;
        }
        Choice {
            action,
            q_values: q,
            probabilities,
            temperature,
            explored: q[action.index()] < best,
        }
    }

    /// Q(s,a) += α (r + γ max_a' Q(s',a') - Q(s,a)); without the bootstrap on a session's last step.
    pub fn update(
        &mut self,
        state: State,
        action: Action,
        reward: f64,
        next: State,
        last_step: bool,
        learning: &Learning,
    ) {
        let bootstrap = if last_step {
            0.0
        } else {
            let nq = &self.q[next.index()];
            next.allowed_actions()
                .iter()
                .map(|a| nq[a.index()])
                .fold(f64::NEG_INFINITY, f64::max)
        };
        let q = &mut self.q[state.index()][action.index()];
        *q += learning.alpha * (reward + learning.gamma * bootstrap - *q);
    }
}

/// What one simulated session gave (the authors' per-session metrics).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SessionMetrics {
    /// Σ L·O
    pub score: f64,
    /// Σ L
    pub max_score: f64,
    /// Mean of the 10 E values.
    pub engagement: f64,
    /// Σ γ^(t-1) r
    pub discounted_return: f64,
    /// max_a Q(start, a) after the session.
    pub start_value: f64,
}

/// One session of Algorithm 1 against a user model; `count_visits` adds this session's state
/// visits to the temperature counts.
pub fn simulate_session(
    table: &mut QTable,
    model: &UserModelTable,
    learning: &Learning,
    mode: Mode,
    count_visits: bool,
    rng: &mut ChaCha8Rng,
) -> SessionMetrics {
    let mut state = State::START;
    let mut score_before: i8 = 0;
    let mut m = SessionMetrics::default();
    let mut discount = 1.0;
    for step in 0..SEQUENCES_PER_SESSION {
        let choice = table.choose(state, mode, learning, rng);
        if count_visits {
            table.visits[state.index()] += 1;
        }
        let Some((level, feedback)) = choice.action.apply(state) else {
            break;
        };
        // The user model sees the score of the sequence before this one.
        let input = ModelInput {
            level,
            feedback,
            previous_score: score_before,
        };
        let outcome = Outcome::from_correct(rng.random::<f64>() <= model.success(input).mean);
        let engagement = model.engagement(input, outcome).mean;
        let activity = outcome.activity_result(level);
        let reward = learning.reward(activity, engagement);
        let score = outcome.score(level);
        // With the authors' lag the new state carries that earlier score too: the agent has
        // not yet seen the result of the sequence it set up.
        let shown = if learning.state_lags_result {
            score_before
        } else {
            score
        };
        let next = State {
            level: level.get(),
            feedback,
            previous_score: shown,
        };
        table.update(
            state,
            choice.action,
            reward,
            next,
            step + 1 == SEQUENCES_PER_SESSION,
            learning,
        );
        score_before = score;
        m.score += f64::from(score_before);
        m.max_score += f64::from(level.get());
        m.engagement += engagement / SEQUENCES_PER_SESSION as f64;
        m.discounted_return += discount * reward;
        discount *= learning.gamma;
        state = next;
    }
    let start = &table.q[State::START.index()];
    m.start_value = State::START
        .allowed_actions()
        .iter()
        .map(|a| start[a.index()])
        .fold(f64::NEG_INFINITY, f64::max);
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use sequence_game::{Feedback, Level, Prediction};

    fn model(p: [f64; 3], e: f64) -> UserModelTable {
        UserModelTable::tabulate(
            0,
            |i| Prediction {
                mean: p[i.level.index()],
                std: 0.0,
            },
            |_, _| Prediction { mean: e, std: 0.0 },
        )
    }

    #[test]
    fn start_state_masks_feedback_and_softmax_is_stable() {
        let mut t = QTable::default();
        t.q[0] = [1e6, -1e6, 0.0, 5e6, 5e6];
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let l = Learning {
            min_temperature: 0.5,
            ..Default::default()
        };
        t.visits[0] = 1000;
        for _ in 0..100 {
            let c = t.choose(State::START, Mode::Explore, &l, &mut rng);
            assert!(!c.action.is_feedback());
            assert!(c.probabilities.iter().all(|p| p.is_finite()));
            assert_eq!(c.probabilities[3], 0.0);
        }
        assert_eq!(t.temperature(State::START, &l), 0.5);
        assert_eq!(QTable::default().temperature(State::START, &l), 295.0);
    }

    #[test]
    fn update_follows_the_formula_and_skips_bootstrap_at_the_end() {
        let l = Learning::default();
        let mut t = QTable::default();
        let s = State::new(1, 0, 1).expect("state");
        let n = State::new(2, 0, 1).expect("state");
        t.q[n.index()] = [0.0, 2.0, 0.0, 0.0, 0.0];
        t.update(s, Action::SetLevel(Level::TWO), 1.0, n, false, &l);
        assert!((t.q[s.index()][1] - 0.05 * (1.0 + 0.95 * 2.0)).abs() < 1e-12);
        let mut t2 = QTable::default();
        t2.q[n.index()] = [0.0, 2.0, 0.0, 0.0, 0.0];
        t2.update(s, Action::Encourage, 1.0, n, true, &l);
        assert!((t2.q[s.index()][3] - 0.05).abs() < 1e-12);
    }

    #[test]
    fn learns_the_best_level_for_a_user_who_always_succeeds() {
        let m = model([1.0, 1.0, 1.0], 0.0);
        let l = Learning::default();
        let mut t = QTable::default();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for s in 0..20_000 {
            simulate_session(&mut t, &m, &l, Mode::Explore, s % 100 == 0, &mut rng);
        }
        let greedy = simulate_session(&mut t, &m, &l, Mode::Exploit, false, &mut rng);
        assert_eq!(greedy.score, 30.0, "always level 3");
        let _ = Feedback::None;
    }
}
