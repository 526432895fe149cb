//! Q-learning pieces of the paper's Algorithm 1 shared by the simulator and the live policy:
//! reward functions F_r, the per-state temperature schedule, the Q-table, the softmax and
//! greedy choices, and the update rule. One implementation, so simulation and node agree.

use sequence_game::{ACTION_COUNT, LEVEL_COUNT, STATE_COUNT, State};
use serde::{Deserialize, Serialize};

/// The reward function F_r of the evaluation.
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

    /// Short ASCII name used in files and on the command line.
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

impl std::fmt::Display for Reward {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// T_s = max(minimum, initial - decay * visits_s): the softmax cools per state as it is visited.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TemperatureSchedule {
    pub initial: f64,
    pub minimum: f64,
    pub decay_per_visit: f64,
}

impl Default for TemperatureSchedule {
    /// The authors': 300, 0.5, 5 (fully cooled after 60 counted visits).
    fn default() -> Self {
        TemperatureSchedule {
            initial: 300.0,
            minimum: 0.5,
            decay_per_visit: 5.0,
        }
    }
}

impl TemperatureSchedule {
    pub fn at(&self, visits: u32) -> f64 {
        (self.initial - self.decay_per_visit * f64::from(visits)).max(self.minimum)
    }
}

/// How actions are picked.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Mode {
    /// Softmax with the state's temperature (training in simulation).
    Explore,
    /// Greedy, ties broken at random, still learning (real sessions, transfer).
    Exploit,
    /// Greedy as `Exploit`, except that with probability ε (at most [`MAX_EPSILON`]) the
    /// action is drawn uniformly from the allowed ones: real sessions that explore a little,
    /// with every decision's probabilities logged, so that recorded sessions can judge
    /// another policy (`evaluate`).
    EpsilonGreedy(f64),
}

/// The largest ε a live policy may explore with. Each explored decision is a sequence the
/// policy does not think best for the child: against cluster 0's model the sample cluster-0
/// table scores 18.79 per session greedy, 17.62 at ε = 0.1 and 15.28 at 0.3, exactly (about
/// 1.2 points per 0.1 of ε; `evaluate-in-simulation`'s sweep, docs/behaviour_policy.md,
/// "Logged exploration"). At 0.3 `evaluate` judged a T = 1 policy's score within a point in
/// 95 % of seeds from 2,000 sessions, at 0.1 in 62 % from 5,000: a bound chosen there, a
/// judgement of what the children may pay, not an optimum.
pub const MAX_EPSILON: f64 = 0.3;

/// Learning constants (defaults: the authors', `../shared/REFERENCE.md`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Learning {
    pub alpha: f64,
    pub gamma: f64,
    pub temperature: TemperatureSchedule,
    pub beta: f64,
    pub lambda: f64,
    pub reward: Reward,
}

impl Default for Learning {
    fn default() -> Self {
        Learning {
            alpha: 0.05,
            gamma: 0.95,
            temperature: TemperatureSchedule::default(),
            beta: 3.0,
            lambda: 3.0,
            reward: Reward::Re,
        }
    }
}

impl Learning {
    /// F_r(RE, E).
    pub fn reward(&self, activity_result: f64, engagement: f64) -> f64 {
        match self.reward {
            Reward::Re => activity_result,
            Reward::RePlusBetaE => activity_result + self.beta * engagement,
            Reward::LambdaE => self.lambda * engagement,
        }
    }
}

/// The learning constants one by one, named as the node's parameters name them
/// (`params/behaviour_policy.yaml`; the lab's flags are the same names with dashes): the one
/// place a [`Learning`] is made from them and checked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LearningConstants {
    pub alpha: f64,
    pub gamma: f64,
    pub initial_temperature: f64,
    pub min_temperature: f64,
    pub temperature_decay: f64,
    pub beta: f64,
    pub lambda: f64,
}

impl Default for LearningConstants {
    /// The authors' ([`Learning::default`]).
    fn default() -> Self {
        let l = Learning::default();
        LearningConstants {
            alpha: l.alpha,
            gamma: l.gamma,
            initial_temperature: l.temperature.initial,
            min_temperature: l.temperature.minimum,
            temperature_decay: l.temperature.decay_per_visit,
            beta: l.beta,
            lambda: l.lambda,
        }
    }
}

/// A learning constant with a value Q-learning cannot use, named by its parameter.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{key}: {reason}")]
pub struct LearningError {
    pub key: &'static str,
    pub reason: String,
}

impl LearningConstants {
    /// The constants with `reward`, checked: α in (0, 1], γ in [0, 1], temperatures positive
    /// and finite (the initial one at least the minimum), the decay 0 or more, β and λ finite.
    pub fn learning(&self, reward: Reward) -> Result<Learning, LearningError> {
        let check = |key: &'static str, ok: bool, reason: &dyn Fn() -> String| {
            if ok {
                Ok(())
            } else {
                Err(LearningError {
                    key,
                    reason: reason(),
                })
            }
        };
        let c = self;
        check("alpha", c.alpha > 0.0 && c.alpha <= 1.0, &|| {
            format!("{} is outside (0, 1]", c.alpha)
        })?;
        check("gamma", (0.0..=1.0).contains(&c.gamma), &|| {
            format!("{} is outside [0, 1]", c.gamma)
        })?;
        check(
            "min_temperature",
            c.min_temperature.is_finite() && c.min_temperature > 0.0,
            &|| format!("{} must be positive", c.min_temperature),
        )?;
        check(
            "initial_temperature",
            c.initial_temperature.is_finite() && c.initial_temperature >= c.min_temperature,
            &|| format!("{} must be at least min_temperature", c.initial_temperature),
        )?;
        check(
            "temperature_decay",
            c.temperature_decay.is_finite() && c.temperature_decay >= 0.0,
            &|| format!("{} must be 0 or more", c.temperature_decay),
        )?;
        check("beta", c.beta.is_finite(), &|| {
            format!("{} is not finite", c.beta)
        })?;
        check("lambda", c.lambda.is_finite(), &|| {
            format!("{} is not finite", c.lambda)
        })?;
        Ok(Learning {
            alpha: c.alpha,
            gamma: c.gamma,
            temperature: TemperatureSchedule {
                initial: c.initial_temperature,
                minimum: c.min_temperature,
                decay_per_visit: c.temperature_decay,
            },
            beta: c.beta,
            lambda: c.lambda,
            reward,
        })
    }
}

/// Q-values and temperature visit counts of every state, rows in [`State::index`] order.
#[derive(Debug, Clone, PartialEq)]
pub struct QTable {
    pub q: [[f64; ACTION_COUNT]; STATE_COUNT],
    /// Visits counted for the temperature; the authors start every state at 1.
    pub visits: [u32; STATE_COUNT],
}

impl Default for QTable {
    fn default() -> Self {
        QTable {
            q: [[0.0; ACTION_COUNT]; STATE_COUNT],
            visits: [1; STATE_COUNT],
        }
    }
}

impl QTable {
    pub fn row(&self, state: State) -> &[f64; ACTION_COUNT] {
        &self.q[state.index()]
    }

    /// max_a Q(s, a) over the first `allowed` actions (3 in the start state, else 5).
    pub fn best_value(&self, state: State) -> f64 {
        best(&self.q[state.index()], allowed_count(state))
    }
}

/// Number of allowed actions: a1..a3 in the start state, a1..a5 elsewhere. The allowed
/// actions are always a prefix of a1..a5, so a count says which they are.
pub fn allowed_count(state: State) -> usize {
    if state.is_start() {
        LEVEL_COUNT
    } else {
        ACTION_COUNT
    }
}

#[inline]
pub fn best(row: &[f64; ACTION_COUNT], allowed: usize) -> f64 {
    let mut m = row[0];
    // Q-values are never NaN (updates that would make one are refused), so a plain
    // comparison does, without f64::max's NaN handling.
    for &q in &row[1..allowed] {
        m = if q > m { q } else { m };
    }
    m
}

/// Unnormalised softmax of one state's row.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Softmax {
    /// exp((Q - max Q) / T) for the allowed actions, 0 for the rest.
    pub weights: [f64; ACTION_COUNT],
    /// Their sum (at least 1: the greedy actions weigh exactly 1).
    pub total: f64,
    /// max Q over the allowed actions.
    pub best: f64,
}

/// Softmax weights of the first `allowed` actions. Subtracting the max gives the paper's
/// probabilities without overflow.
#[inline]
pub fn softmax_weights(row: &[f64; ACTION_COUNT], allowed: usize, temperature: f64) -> Softmax {
    let m = best(row, allowed);
    let mut w = [0.0; ACTION_COUNT];
    let mut total = 0.0;
    for a in 0..allowed {
        let d = row[a] - m;
        // exp(0) = 1 needs no call: saves one exp per step in the hot loop.
        w[a] = if d == 0.0 {
            1.0
        } else {
            (d / temperature).exp()
        };
        total += w[a];
    }
    Softmax {
        weights: w,
        total,
        best: m,
    }
}

/// The action whose cumulative weight first exceeds `u * total`, for u uniform in [0, 1).
/// Counted without branches (how many cumulative sums are <= the target): the draw is
/// unpredictable, and a mispredicted branch costs more than the comparisons.
#[inline]
pub fn sample_weights(w: &[f64; ACTION_COUNT], allowed: usize, total: f64, u: f64) -> usize {
    let target = u * total;
    let mut cumulative = 0.0;
    let mut below = 0;
    for &wa in w.iter().take(allowed) {
        cumulative += wa;
        below += usize::from(cumulative <= target);
    }
    if below < allowed {
        below
    } else {
        // Only when rounding puts u * total at the very top: the last action that can be drawn.
        (0..allowed).rev().find(|&a| w[a] > 0.0).unwrap_or(0)
    }
}

/// The greedy actions among the first `allowed`, as a bit set, and how many there are.
#[inline]
pub fn greedy_set(row: &[f64; ACTION_COUNT], allowed: usize) -> (u8, u32) {
    let m = best(row, allowed);
    let mut set = 0u8;
    for (a, &q) in row.iter().enumerate().take(allowed) {
        if q == m {
            set |= 1 << a;
        }
    }
    (set, set.count_ones())
}

/// The `k`-th (0-based) member of a bit set.
#[inline]
pub fn nth_member(set: u8, k: u32) -> usize {
    let mut s = set;
    for _ in 0..k {
        s &= s - 1;
    }
    s.trailing_zeros() as usize
}

/// How many of a1..a5 may be chosen for the sequence `step` (1-based) from `state`: a1..a3 at
/// the first sequence and in the start state (no context for feedback yet), else all five.
pub fn allowed_at(state: State, step: u8) -> usize {
    if step <= 1 {
        LEVEL_COUNT
    } else {
        allowed_count(state)
    }
}

/// The ε-greedy choice for a uniform `u` in [0, 1): below ε, the `allowed` actions share
/// [0, ε) equally; above, the greedy ties share [ε, 1) equally. One draw decides both, so the
/// live policy and the simulator pick alike from the same number, and each action's
/// probability is exactly ε / allowed, plus (1 − ε) / ties for a greedy one.
#[inline]
pub fn epsilon_greedy_pick(
    row: &[f64; ACTION_COUNT],
    allowed: usize,
    epsilon: f64,
    u: f64,
) -> usize {
    if u < epsilon {
        ((u / epsilon * allowed as f64) as usize).min(allowed - 1)
    } else {
        let (set, n) = greedy_set(row, allowed);
        let v = (u - epsilon) / (1.0 - epsilon);
        nth_member(set, ((v * f64::from(n)) as u32).min(n - 1))
    }
}

/// The probability of each action: the softmax at `temperature` over the first `allowed`
/// actions (`Mode::Explore`), uniform over the greedy ties (`Mode::Exploit`), or ε spread
/// evenly over the allowed actions and 1 − ε over the greedy ties (`Mode::EpsilonGreedy`);
/// 0 for the masked actions. What the live policy reports with each decision and what
/// counterfactual evaluation weighs recorded decisions with.
pub fn action_probabilities(
    row: &[f64; ACTION_COUNT],
    allowed: usize,
    mode: Mode,
    temperature: f64,
) -> [f64; ACTION_COUNT] {
    let mut probabilities = [0.0; ACTION_COUNT];
    let greedy = |probabilities: &mut [f64; ACTION_COUNT], share: f64| {
        let (set, n) = greedy_set(row, allowed);
        for (a, p) in probabilities.iter_mut().enumerate() {
            if set & (1 << a) != 0 {
                *p += share / f64::from(n);
            }
        }
    };
    match mode {
        Mode::Explore => {
            let s = softmax_weights(row, allowed, temperature);
            for (p, w) in probabilities.iter_mut().zip(&s.weights).take(allowed) {
                *p = w / s.total;
            }
        }
        Mode::Exploit => greedy(&mut probabilities, 1.0),
        Mode::EpsilonGreedy(epsilon) => {
            for p in probabilities.iter_mut().take(allowed) {
                *p = epsilon / allowed as f64;
            }
            greedy(&mut probabilities, 1.0 - epsilon);
        }
    }
    probabilities
}

/// The Q-learning target: r + γ max_a' Q(s', a'), or r alone on a session's last step (the
/// authors' episode end).
#[inline]
pub fn td_target(reward: f64, gamma: f64, next_row: &[f64; ACTION_COUNT], last: bool) -> f64 {
    if last {
        reward
    } else {
        reward + gamma * best(next_row, ACTION_COUNT)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temperature_follows_the_authors_schedule() {
        let t = TemperatureSchedule::default();
        assert_eq!(t.at(1), 295.0);
        assert_eq!(t.at(59), 5.0);
        assert_eq!(t.at(60), 0.5);
        assert_eq!(t.at(10_000), 0.5);
    }

    #[test]
    fn softmax_matches_the_textbook_formula_and_survives_huge_values() {
        let row = [1.0, 2.0, 0.5, -1.0, 3.0];
        let t = 1.7;
        let Softmax {
            weights: w, total, ..
        } = softmax_weights(&row, 5, t);
        let plain: Vec<f64> = row.iter().map(|q| (q / t).exp()).collect();
        let plain_total: f64 = plain.iter().sum();
        for a in 0..5 {
            assert!((w[a] / total - plain[a] / plain_total).abs() < 1e-12);
        }
        // The start state masks a4 and a5.
        let w = softmax_weights(&row, 3, t).weights;
        assert_eq!((w[3], w[4]), (0.0, 0.0));
        // Without subtracting the max, exp(1e6 / 0.5) is infinite and the probabilities NaN.
        let s = softmax_weights(&[1e6, -1e6, 0.0, 5e6, 5e6], 5, 0.5);
        assert!(s.weights.iter().all(|x| x.is_finite()) && s.total == 2.0 && s.best == 5e6);
    }

    #[test]
    fn sampling_walks_the_cumulative_weights() {
        let w = [1.0, 0.0, 3.0, 0.0, 0.0];
        assert_eq!(sample_weights(&w, 5, 4.0, 0.0), 0);
        assert_eq!(sample_weights(&w, 5, 4.0, 0.2499), 0);
        assert_eq!(sample_weights(&w, 5, 4.0, 0.25), 2);
        assert_eq!(sample_weights(&w, 5, 4.0, 0.999_999), 2);
        // A zero-weight action is never drawn, even at the top edge.
        assert_eq!(sample_weights(&w, 5, 4.0, 1.0), 2);
    }

    #[test]
    fn greedy_set_lists_ties_within_the_allowed_actions() {
        let (set, n) = greedy_set(&[2.0, 1.0, 2.0, 9.0, 2.0], 3);
        assert_eq!((set, n), (0b101, 2));
        assert_eq!(nth_member(set, 0), 0);
        assert_eq!(nth_member(set, 1), 2);
        let (set, n) = greedy_set(&[2.0, 1.0, 2.0, 9.0, 2.0], 5);
        assert_eq!((nth_member(set, 0), n), (3, 1));
    }

    #[test]
    fn epsilon_greedy_picks_each_action_on_a_share_of_draws_equal_to_its_probability() {
        let row = [0.3, 0.9, -1.0, 0.9, 0.9];
        for (allowed, epsilon) in [(5, 0.1), (5, 0.3), (3, 0.2), (3, 1.0)] {
            let p = action_probabilities(&row, allowed, Mode::EpsilonGreedy(epsilon), 1.0);
            assert!((p.iter().sum::<f64>() - 1.0).abs() < 1e-12, "{p:?}");
            // A fine grid of uniforms: each action's share of it is its probability.
            let n = 1_000_000;
            let mut seen = [0usize; ACTION_COUNT];
            for i in 0..n {
                let u = (i as f64 + 0.5) / n as f64;
                seen[epsilon_greedy_pick(&row, allowed, epsilon, u)] += 1;
            }
            for a in 0..ACTION_COUNT {
                let share = seen[a] as f64 / n as f64;
                assert!(
                    (share - p[a]).abs() < 1e-5,
                    "{allowed} {epsilon} a{a}: {share} {p:?}"
                );
            }
        }
        // ε = 0 is the greedy choice, ties shared.
        let p = action_probabilities(&row, 5, Mode::EpsilonGreedy(0.0), 1.0);
        assert_eq!(p, action_probabilities(&row, 5, Mode::Exploit, 1.0));
    }

    #[test]
    fn the_constants_make_the_authors_learning_and_bad_ones_are_named() {
        let c = LearningConstants::default();
        assert_eq!(c.learning(Reward::Re), Ok(Learning::default()));
        for (bad, key) in [
            (
                LearningConstants {
                    alpha: f64::NAN,
                    ..c
                },
                "alpha",
            ),
            (LearningConstants { gamma: 1.5, ..c }, "gamma"),
            (
                LearningConstants {
                    min_temperature: 0.0,
                    ..c
                },
                "min_temperature",
            ),
            (
                LearningConstants {
                    initial_temperature: 0.1,
                    ..c
                },
                "initial_temperature",
            ),
            (
                LearningConstants {
                    temperature_decay: -1.0,
                    ..c
                },
                "temperature_decay",
            ),
            (
                LearningConstants {
                    beta: f64::INFINITY,
                    ..c
                },
                "beta",
            ),
            (
                LearningConstants {
                    lambda: f64::NAN,
                    ..c
                },
                "lambda",
            ),
        ] {
            assert_eq!(bad.learning(Reward::Re).expect_err(key).key, key);
        }
    }

    #[test]
    fn rewards_are_re_re_plus_beta_e_and_lambda_e() {
        let mut l = Learning::default();
        assert_eq!(l.reward(3.0, 0.5), 3.0);
        l.reward = Reward::RePlusBetaE;
        assert_eq!(l.reward(-1.0, 0.5), 0.5);
        l.reward = Reward::LambdaE;
        assert_eq!(l.reward(2.0, -0.25), -0.75);
        for r in Reward::ALL {
            assert_eq!(Reward::parse(r.name()), Some(r));
        }
        assert_eq!(Reward::parse("RE+E"), None);
    }
}
