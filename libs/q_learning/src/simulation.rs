//! Algorithm 1 against a user model, as a tight loop: the user model's F^p, F^e and the reward
//! are tabulated once per (model, reward) over the 63 inputs, states are row numbers, softmax
//! weights are cached per state, and one Q-iteration is two random draws, one exp and one
//! update. The draws come from the run's own stream, or, for studies that compare policies on
//! the same simulated child, from a session's fixed [`SessionDraws`] (common random numbers).

mod softmax_cache;

use crate::learning::{
    Learning, Mode, QTable, best, epsilon_greedy_pick, greedy_set, nth_member, sample_weights,
    td_target,
};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sequence_game::{
    ACTION_COUNT, LEVEL_COUNT, ModelInput, Outcome, SEQUENCES_PER_SESSION, UserModelTable,
};
use softmax_cache::SoftmaxCache;

const INPUTS: usize = sequence_game::user_model_table::SUCCESS_INPUTS;

/// A user model with the reward precomputed for every (input, outcome).
#[derive(Debug, Clone, PartialEq)]
pub struct SimulatedUser {
    /// F^p(L, F, PS) by [`ModelInput::index`].
    success: [f64; INPUTS],
    /// F^e(L, F, PS, O) by input, then outcome (failure 0, success 1).
    engagement: [[f64; 2]; INPUTS],
    /// F_r(RE, E) by input and outcome.
    reward: [[f64; 2]; INPUTS],
}

impl SimulatedUser {
    pub fn new(model: &UserModelTable, learning: &Learning) -> Self {
        let mut user = SimulatedUser {
            success: [0.0; INPUTS],
            engagement: [[0.0; 2]; INPUTS],
            reward: [[0.0; 2]; INPUTS],
        };
        for input in ModelInput::all() {
            let j = input.index();
            user.success[j] = model.success(input).mean;
            for outcome in Outcome::ALL {
                let e = model.engagement(input, outcome).mean;
                user.engagement[j][outcome.index()] = e;
                user.reward[j][outcome.index()] =
                    learning.reward(outcome.activity_result(input.level), e);
            }
        }
        user
    }
}

/// What the simulated sessions run with, besides the user.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SessionSettings {
    pub learning: Learning,
    pub mode: Mode,
    /// The authors' and Algorithm 1's state: PS of s_{t+1} is CS_t, the score of the sequence
    /// *before* the one just played (the agent picks the next action before it sees the latest
    /// result). False: PS is the latest result, as the live game reports it.
    pub state_lags_result: bool,
}

/// One session's metrics, as the authors log them.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SessionMetrics {
    /// Σ L·O over the session (the "performance score").
    pub score: f64,
    /// Σ L.
    pub max_score: f64,
    /// Mean of the ω values of E.
    pub engagement: f64,
    /// Σ γ^(t-1) r.
    pub discounted_return: f64,
    /// V = max_a Q(start, a) after the session.
    pub start_value: f64,
    /// Steps where a non-greedy action was drawn.
    pub explored: u32,
}

// Row of the MDP state (L, F, PS) in the Q-table: as `State::index`, with L 1-based.
#[inline]
fn lf_base(level: usize, feedback: usize) -> usize {
    (level - 1) * 21 + feedback * 7
}

// Level of a state row: 0 for the start state.
const fn level_of_rows() -> [u8; sequence_game::STATE_COUNT] {
    let mut t = [0u8; sequence_game::STATE_COUNT];
    let mut s = 1;
    while s < sequence_game::STATE_COUNT {
        t[s] = ((s - 1) / 21 + 1) as u8;
        s += 1;
    }
    t
}
const LEVEL_OF_ROW: [u8; sequence_game::STATE_COUNT] = level_of_rows();

/// One simulated run's learning state: its Q-table, its random stream, and the softmax
/// weights cached from its Q-table (hence the table is only changed here).
#[derive(Debug, Clone, PartialEq)]
pub struct SimulatedRun {
    table: QTable,
    rng: ChaCha8Rng,
    cache: SoftmaxCache,
}

impl SimulatedRun {
    pub fn new(table: QTable, rng: ChaCha8Rng) -> Self {
        SimulatedRun {
            table,
            rng,
            cache: SoftmaxCache::default(),
        }
    }

    pub fn seeded(table: QTable, seed: u64) -> Self {
        SimulatedRun::new(table, ChaCha8Rng::seed_from_u64(seed))
    }

    pub fn table(&self) -> &QTable {
        &self.table
    }

    pub fn into_table(self) -> QTable {
        self.table
    }
}

/// Whether the child answers a sequence right: `u <= P(success)` for a uniform `u`, as
/// Algorithm 1 and the authors draw it. The one home of that rule for every simulated session.
#[inline(always)]
pub fn answers_right(u: f64, success: f64) -> bool {
    u <= success
}

/// Where a session's random numbers come from: a uniform for each sequence's action (softmax
/// draw or greedy tie-break) and one for the child's answer.
trait Draws {
    fn action(&mut self, rng: &mut ChaCha8Rng, step: usize) -> f64;
    /// Which of `n` (> 1) tied greedy actions.
    fn tie(&mut self, rng: &mut ChaCha8Rng, step: usize, n: u32) -> u32;
    fn answer(&mut self, rng: &mut ChaCha8Rng, step: usize) -> f64;
}

/// The run's own stream, drawn as needed in Algorithm 1's order (a greedy choice without a
/// tie draws nothing).
struct RunStream;

impl Draws for RunStream {
    #[inline(always)]
    fn action(&mut self, rng: &mut ChaCha8Rng, _: usize) -> f64 {
        rng.random::<f64>()
    }
    #[inline(always)]
    fn tie(&mut self, rng: &mut ChaCha8Rng, _: usize, n: u32) -> u32 {
        rng.random_range(0..n)
    }
    #[inline(always)]
    fn answer(&mut self, rng: &mut ChaCha8Rng, _: usize) -> f64 {
        rng.random::<f64>()
    }
}

/// The uniforms of one session fixed in advance, two per sequence whatever the policy does
/// with them: `action[k]` decides sequence k+1's action (the softmax draw, or which greedy tie;
/// unused by a greedy choice without a tie) and `answer[k]` the child's answer to it (right
/// iff `answer[k] <= P(success)` of the sequence played). Policies given the same
/// `SessionDraws` meet the same simulated child: where they play the same sequence from the
/// same state the child answers alike, and where they differ the answers are coupled through
/// the same `answer[k]` (common random numbers).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SessionDraws {
    pub action: [f64; SEQUENCES_PER_SESSION],
    pub answer: [f64; SEQUENCES_PER_SESSION],
}

impl SessionDraws {
    /// The draws of the session keyed by `seed` (ChaCha8: action then answer, sequence by
    /// sequence).
    pub fn new(seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut d = SessionDraws {
            action: [0.0; SEQUENCES_PER_SESSION],
            answer: [0.0; SEQUENCES_PER_SESSION],
        };
        for k in 0..SEQUENCES_PER_SESSION {
            d.action[k] = rng.random::<f64>();
            d.answer[k] = rng.random::<f64>();
        }
        d
    }

    /// Which of `n` tied actions the uniform `u` picks: the k-th of n equal slices of [0, 1).
    pub fn tie_of(u: f64, n: u32) -> u32 {
        ((u * f64::from(n)) as u32).min(n.saturating_sub(1))
    }
}

impl Draws for &SessionDraws {
    #[inline(always)]
    fn action(&mut self, _: &mut ChaCha8Rng, step: usize) -> f64 {
        self.action[step]
    }
    #[inline(always)]
    fn tie(&mut self, _: &mut ChaCha8Rng, step: usize, n: u32) -> u32 {
        SessionDraws::tie_of(self.action[step], n)
    }
    #[inline(always)]
    fn answer(&mut self, _: &mut ChaCha8Rng, step: usize) -> f64 {
        self.answer[step]
    }
}

/// One run's position inside a session.
struct Walker<'a> {
    run: &'a mut SimulatedRun,
    state: usize,
    previous_score: i32,
    discount: f64,
    m: SessionMetrics,
}

impl<'a> Walker<'a> {
    fn new(run: &'a mut SimulatedRun) -> Self {
        Walker {
            run,
            state: 0,
            previous_score: 0,
            discount: 1.0,
            m: SessionMetrics::default(),
        }
    }

    /// One Q-iteration of Algorithm 1: sequence `k` (0-based) of the session.
    #[inline(always)]
    fn step<D: Draws>(
        &mut self,
        user: &SimulatedUser,
        s: &SessionSettings,
        count_visits: bool,
        k: usize,
        draws: &mut D,
    ) {
        let last = k + 1 == SEQUENCES_PER_SESSION;
        let learning = &s.learning;
        let state = self.state;
        let run = &mut *self.run;
        let allowed = if state == 0 {
            LEVEL_COUNT
        } else {
            ACTION_COUNT
        };
        let row = &run.table.q[state];
        let (action, explored) = match s.mode {
            Mode::Explore => {
                let t = learning.temperature.at(run.table.visits[state]);
                let w = run.cache.weights(state, row, t);
                let total: f64 = w[..allowed].iter().sum();
                let a = sample_weights(w, allowed, total, draws.action(&mut run.rng, k));
                (a, row[a] < best(row, allowed))
            }
            Mode::Exploit => {
                let (set, n) = greedy_set(row, allowed);
                let tie = if n > 1 {
                    draws.tie(&mut run.rng, k, n)
                } else {
                    0
                };
                (nth_member(set, tie), false)
            }
            Mode::EpsilonGreedy(epsilon) => {
                let u = draws.action(&mut run.rng, k);
                let a = epsilon_greedy_pick(row, allowed, epsilon, u);
                (a, row[a] < best(row, allowed))
            }
        };
        if count_visits {
            run.table.visits[state] += 1;
        }
        // a1..a3 set the level without feedback; a4/a5 repeat it with feedback 1/2.
        let (level, feedback) = if action < LEVEL_COUNT {
            (action + 1, 0)
        } else {
            (LEVEL_OF_ROW[state] as usize, action - LEVEL_COUNT + 1)
        };
        let base = lf_base(level, feedback);
        // F^p and F^e see (L_{t+1}, F_{t+1}, CS_t).
        let input = base + (self.previous_score + 3) as usize;
        let success = answers_right(draws.answer(&mut run.rng, k), user.success[input]);
        let outcome = usize::from(success);
        let reward = user.reward[input][outcome];
        let score = if success {
            level as i32
        } else {
            -(level as i32)
        };
        let next = 1 + if s.state_lags_result {
            input
        } else {
            base + (score + 3) as usize
        };
        let target = td_target(reward, learning.gamma, &run.table.q[next], last);
        let q = &mut run.table.q[state][action];
        *q += learning.alpha * (target - *q);
        if s.mode == Mode::Explore {
            run.cache.updated(state, action, &run.table.q[state]);
        }

        let m = &mut self.m;
        m.score += f64::from(score);
        m.max_score += level as f64;
        m.engagement += user.engagement[input][outcome];
        m.discounted_return += self.discount * reward;
        m.explored += u32::from(explored);
        self.discount *= learning.gamma;
        self.previous_score = score;
        self.state = next;
    }

    fn finish(self) -> SessionMetrics {
        let mut m = self.m;
        m.engagement /= SEQUENCES_PER_SESSION as f64;
        m.start_value = best(&self.run.table.q[0], LEVEL_COUNT);
        m
    }
}

/// Plays one session of ω = 10 sequences, updating the run's Q-table after each
/// (Algorithm 1). `count_visits`: this session's state visits lower the temperature (the
/// authors count one session per epoch).
pub fn run_session(
    run: &mut SimulatedRun,
    user: &SimulatedUser,
    settings: &SessionSettings,
    count_visits: bool,
) -> SessionMetrics {
    let mut w = Walker::new(run);
    for k in 0..SEQUENCES_PER_SESSION {
        w.step(user, settings, count_visits, k, &mut RunStream);
    }
    w.finish()
}

/// [`run_session`] with the session's random numbers fixed in advance instead of drawn from
/// the run's stream: every policy played with the same `draws` meets the same child.
pub fn run_session_with(
    run: &mut SimulatedRun,
    user: &SimulatedUser,
    settings: &SessionSettings,
    count_visits: bool,
    draws: &SessionDraws,
) -> SessionMetrics {
    let mut w = Walker::new(run);
    for k in 0..SEQUENCES_PER_SESSION {
        w.step(user, settings, count_visits, k, &mut &*draws);
    }
    w.finish()
}

/// N independent sessions (N runs) played step by step in turn: exactly what N
/// `run_session` calls give, but the processor overlaps the N chains of dependent steps,
/// which one session alone leaves idle.
pub fn run_sessions<const N: usize>(
    runs: &mut [SimulatedRun; N],
    user: &SimulatedUser,
    settings: &SessionSettings,
    count_visits: bool,
) -> [SessionMetrics; N] {
    let mut walkers = runs.each_mut().map(Walker::new);
    for k in 0..SEQUENCES_PER_SESSION {
        for w in walkers.iter_mut() {
            w.step(user, settings, count_visits, k, &mut RunStream);
        }
    }
    walkers.map(Walker::finish)
}

#[cfg(test)]
mod tests;
