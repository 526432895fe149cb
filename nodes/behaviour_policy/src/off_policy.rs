//! Counterfactual (off-policy) evaluation: how a new Q-table's policy would have done in
//! sessions another policy played, judged from the recorded decisions' probabilities alone
//! (importance sampling), before the new policy meets a child. Sans-IO: logged sessions in,
//! estimates with bootstrap intervals out. For the validation, `simulate_sessions` plays
//! sessions against a user model and `exact_value` gives a policy's true value there.

use crate::learning::{
    Learning, Mode, QTable, TemperatureSchedule, action_probabilities, allowed_at,
};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use sequence_game::{
    ACTION_COUNT, Action, ModelInput, Outcome, SEQUENCES_PER_SESSION, STATE_COUNT, State,
    UserModelTable,
};
use serde::Serialize;

/// Why logged sessions cannot be evaluated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OffPolicyError {
    #[error("no logged session to evaluate")]
    NoSessions,
    #[error(
        "session {session}, sequence {step}: the logged probability of {action} is {probability}, \
         not in (0, 1]"
    )]
    LoggedProbability {
        session: String,
        step: u8,
        action: Action,
        probability: f64,
    },
    #[error("session {session}, sequence {step}: engagement {engagement} is not in [-1, 1]")]
    Engagement {
        session: String,
        step: u8,
        engagement: f64,
    },
    #[error("session {session}, sequence {step}: {action} cannot be taken in {state}")]
    ActionNotAllowed {
        session: String,
        step: u8,
        action: Action,
        state: State,
    },
    #[error("temperature {0} is not a positive number")]
    Temperature(f64),
}

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

/// How the evaluated policy picks from its Q-table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TargetTemperature {
    /// Greedy, ties uniform: the exploitation-only mode of real sessions.
    Greedy,
    /// Softmax at one temperature in every state.
    Fixed(f64),
    /// Softmax at each state's own temperature T_s from its visits.
    PerState(TemperatureSchedule),
}

/// The policy being judged (or the one that logs, in simulation).
#[derive(Debug, Clone, PartialEq)]
pub struct TargetPolicy {
    pub table: QTable,
    pub temperature: TargetTemperature,
}

impl TargetPolicy {
    pub fn new(table: QTable, temperature: TargetTemperature) -> Result<Self, OffPolicyError> {
        if let TargetTemperature::Fixed(t) = temperature
            && !(t.is_finite() && t > 0.0)
        {
            return Err(OffPolicyError::Temperature(t));
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
        }
    }
}

/// A value with its bootstrap 95 % interval (percentiles 2.5 and 97.5).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Estimate {
    pub value: f64,
    pub low: f64,
    pub high: f64,
}

impl Estimate {
    pub fn contains(&self, x: f64) -> bool {
        self.low <= x && x <= self.high
    }
}

/// One quantity (discounted return or score) as logged and as estimated for the new policy.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Estimates {
    /// What the logging policy actually got: the mean over the logged sessions.
    pub logged: Estimate,
    /// Weighted importance sampling over whole sessions; `None` when the new policy gives
    /// every logged session probability 0 (nothing to weigh).
    pub weighted_is: Option<Estimate>,
    /// Per-decision importance sampling.
    pub per_decision_is: Estimate,
}

/// What `evaluate` found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Evaluation {
    pub sessions: usize,
    pub decisions: usize,
    /// Σ γ^(t-1) r_t per session, r = the reward F_r(RE, E).
    pub discounted_return: Estimates,
    /// Σ L·O per session.
    pub score: Estimates,
    /// (Σ w)² / Σ w² of the sessions' weights: how many logged sessions the weighted
    /// estimate is worth.
    pub effective_sample_size: f64,
    /// Logged sessions the new policy could have played (weight above 0).
    pub sessions_with_weight: usize,
    /// Mean probability the new policy gives the logged action.
    pub mean_new_probability: f64,
    /// Mean probability the new policy puts on actions the logging policy never takes there
    /// (logged probability 0): what importance sampling cannot see. Only decisions whose
    /// every probability was logged count; `None` when there are none.
    pub mass_outside_support: Option<f64>,
    /// Each session's weight Π π_new / π_logged, in input order.
    pub weights: Vec<f64>,
    /// Bootstrap resamples where the weighted estimate had no weight at all (skipped).
    pub resamples_without_weight: usize,
}

/// Per session, everything the estimators need.
#[derive(Debug, Clone, Copy)]
struct SessionTerms {
    logged_return: f64,
    logged_score: f64,
    weight: f64,
    pdis_return: f64,
    pdis_score: f64,
}

/// What an estimator gives from a set of sessions (indices into the terms).
#[derive(Debug, Clone, Copy)]
struct Values {
    logged_return: f64,
    logged_score: f64,
    wis_return: Option<f64>,
    wis_score: Option<f64>,
    pdis_return: f64,
    pdis_score: f64,
}

fn values(terms: &[SessionTerms], picks: impl Iterator<Item = usize> + Clone) -> Values {
    let n = picks.clone().count() as f64;
    let (mut lr, mut ls, mut w, mut wr, mut ws, mut pr, mut ps) =
        (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for i in picks {
        let t = &terms[i];
        lr += t.logged_return;
        ls += t.logged_score;
        w += t.weight;
        wr += t.weight * t.logged_return;
        ws += t.weight * t.logged_score;
        pr += t.pdis_return;
        ps += t.pdis_score;
    }
    let weighted = |x: f64| (w > 0.0).then(|| x / w);
    Values {
        logged_return: lr / n,
        logged_score: ls / n,
        wis_return: weighted(wr),
        wis_score: weighted(ws),
        pdis_return: pr / n,
        pdis_score: ps / n,
    }
}

/// The p-quantile (0..1) of sorted values, linearly interpolated.
fn quantile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let x = p * (sorted.len() - 1) as f64;
    let (lo, hi) = (x.floor() as usize, x.ceil() as usize);
    sorted[lo] + (sorted[hi] - sorted[lo]) * (x - lo as f64)
}

fn interval(value: f64, mut draws: Vec<f64>) -> Estimate {
    draws.sort_by(f64::total_cmp);
    Estimate {
        value,
        low: quantile(&draws, 0.025),
        high: quantile(&draws, 0.975),
    }
}

/// Checks one logged step and returns the new policy's probabilities for it.
fn check_step(
    session: &LoggedSession,
    s: &LoggedStep,
    target: &TargetPolicy,
) -> Result<[f64; ACTION_COUNT], OffPolicyError> {
    if !(s.logged_probability > 0.0 && s.logged_probability <= 1.0) {
        return Err(OffPolicyError::LoggedProbability {
            session: session.session_id.clone(),
            step: s.step,
            action: s.action,
            probability: s.logged_probability,
        });
    }
    if !(s.engagement.is_finite() && (-1.0..=1.0).contains(&s.engagement)) {
        return Err(OffPolicyError::Engagement {
            session: session.session_id.clone(),
            step: s.step,
            engagement: s.engagement,
        });
    }
    if s.action.index() >= allowed_at(s.state, s.step) {
        return Err(OffPolicyError::ActionNotAllowed {
            session: session.session_id.clone(),
            step: s.step,
            action: s.action,
            state: s.state,
        });
    }
    Ok(target.probabilities(s.state, s.step.max(1)))
}

/// Off-policy estimates of `target`'s per-session discounted return (reward and γ from
/// `learning`) and score from `sessions`, with `bootstrap` resamples of the sessions (drawn
/// from `seed`) for the intervals. `logged_probabilities`, when given, holds for each step
/// of each session the logging policy's whole distribution (for the support diagnostic).
pub fn evaluate(
    sessions: &[LoggedSession],
    logged_probabilities: Option<&[Vec<[f64; ACTION_COUNT]>]>,
    target: &TargetPolicy,
    learning: &Learning,
    bootstrap: usize,
    seed: u64,
) -> Result<Evaluation, OffPolicyError> {
    if sessions.is_empty() {
        return Err(OffPolicyError::NoSessions);
    }
    let mut terms = Vec::with_capacity(sessions.len());
    let (mut decisions, mut new_probability) = (0usize, 0.0);
    let (mut outside, mut outside_count) = (0.0, 0usize);
    for (i, session) in sessions.iter().enumerate() {
        let mut t = SessionTerms {
            logged_return: 0.0,
            logged_score: 0.0,
            weight: 1.0,
            pdis_return: 0.0,
            pdis_score: 0.0,
        };
        let mut discount = 1.0;
        for (k, s) in session.steps.iter().enumerate() {
            let new = check_step(session, s, target)?;
            let p_new = new[s.action.index()];
            decisions += 1;
            new_probability += p_new;
            if let Some(full) = logged_probabilities.and_then(|l| l.get(i)?.get(k)) {
                outside += new
                    .iter()
                    .zip(full)
                    .filter(|(_, logged)| **logged <= 0.0)
                    .map(|(p, _)| p)
                    .sum::<f64>();
                outside_count += 1;
            }
            let level = s
                .action
                .apply(s.state)
                .map(|(level, _)| level)
                .ok_or_else(|| OffPolicyError::ActionNotAllowed {
                    session: session.session_id.clone(),
                    step: s.step,
                    action: s.action,
                    state: s.state,
                })?;
            let reward = learning.reward(s.outcome.activity_result(level), s.engagement);
            let score = f64::from(s.outcome.score(level));
            t.weight *= p_new / s.logged_probability;
            t.logged_return += discount * reward;
            t.logged_score += score;
            t.pdis_return += discount * t.weight * reward;
            t.pdis_score += t.weight * score;
            discount *= learning.gamma;
        }
        terms.push(t);
    }
    let all = values(&terms, 0..terms.len());
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = terms.len();
    let mut draws: [Vec<f64>; 6] = Default::default();
    let mut without_weight = 0;
    for _ in 0..bootstrap {
        let picks: Vec<usize> = (0..n).map(|_| rng.random_range(0..n)).collect();
        let v = values(&terms, picks.iter().copied());
        draws[0].push(v.logged_return);
        draws[1].push(v.logged_score);
        draws[2].push(v.pdis_return);
        draws[3].push(v.pdis_score);
        match (v.wis_return, v.wis_score) {
            (Some(r), Some(s)) => {
                draws[4].push(r);
                draws[5].push(s);
            }
            _ => without_weight += 1,
        }
    }
    let [lr, ls, pr, ps, wr, ws] = draws;
    let weights: Vec<f64> = terms.iter().map(|t| t.weight).collect();
    let (sum, sum_sq) = weights
        .iter()
        .fold((0.0, 0.0), |(s, q), w| (s + w, q + w * w));
    Ok(Evaluation {
        sessions: n,
        decisions,
        discounted_return: Estimates {
            logged: interval(all.logged_return, lr),
            weighted_is: all.wis_return.map(|v| interval(v, wr.clone())),
            per_decision_is: interval(all.pdis_return, pr),
        },
        score: Estimates {
            logged: interval(all.logged_score, ls),
            weighted_is: all.wis_score.map(|v| interval(v, ws.clone())),
            per_decision_is: interval(all.pdis_score, ps),
        },
        effective_sample_size: if sum_sq > 0.0 {
            sum * sum / sum_sq
        } else {
            0.0
        },
        sessions_with_weight: weights.iter().filter(|w| **w > 0.0).count(),
        mean_new_probability: new_probability / decisions.max(1) as f64,
        mass_outside_support: (outside_count > 0).then(|| outside / outside_count as f64),
        weights,
        resamples_without_weight: without_weight,
    })
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

/// A simulated child's answer to a sequence: success with F^p(L, F, PS), engagement
/// F^e(L, F, PS, O) (the means, as the policy's simulation uses them).
fn child_answer(model: &UserModelTable, input: ModelInput, u: f64) -> (Outcome, f64) {
    let outcome = Outcome::from_correct(u < model.success(input).mean);
    (
        outcome,
        model.engagement(input, outcome).mean.clamp(-1.0, 1.0),
    )
}

/// The model input of the sequence `action` sets up from `state`, and the state after it.
fn transition(state: State, action: Action, outcome: Outcome) -> Option<(ModelInput, State)> {
    let (level, feedback) = action.apply(state)?;
    let input = ModelInput {
        level,
        feedback,
        previous_score: state.previous_score,
    };
    Some((input, State::after(level, feedback, outcome)))
}

/// `sessions` sessions of ten sequences played by `policy` (which does not learn) against the
/// user model, recorded as the live game records them: every decision with its probability,
/// and, for the support diagnostic, the policy's whole distribution.
pub fn simulate_sessions(
    model: &UserModelTable,
    policy: &TargetPolicy,
    sessions: usize,
    seed: u64,
) -> (Vec<LoggedSession>, Vec<Vec<[f64; ACTION_COUNT]>>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut logged = Vec::with_capacity(sessions);
    let mut distributions = Vec::with_capacity(sessions);
    for i in 0..sessions {
        let mut state = State::START;
        let mut steps = Vec::with_capacity(SEQUENCES_PER_SESSION);
        let mut full = Vec::with_capacity(SEQUENCES_PER_SESSION);
        for step in 1..=SEQUENCES_PER_SESSION as u8 {
            let p = policy.probabilities(state, step);
            let action = Action::ALL[draw(&p, rng.random::<f64>())];
            let u = rng.random::<f64>();
            // Outcome first from the input (which does not depend on it), then the state.
            let Some((input, _)) = transition(state, action, Outcome::Success) else {
                break; // cannot happen: masked actions have probability 0
            };
            let (outcome, engagement) = child_answer(model, input, u);
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
        logged.push(LoggedSession {
            session_id: format!("simulated-{i}"),
            steps,
        });
        distributions.push(full);
    }
    (logged, distributions)
}

/// A policy's true expected discounted return and score over a ten-sequence session against
/// the user model, by backward induction over the 64 states (no sampling).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ExactValue {
    pub discounted_return: f64,
    pub score: f64,
}

pub fn exact_value(
    model: &UserModelTable,
    policy: &TargetPolicy,
    learning: &Learning,
) -> ExactValue {
    let mut ret = [0.0; STATE_COUNT];
    let mut score = [0.0; STATE_COUNT];
    for step in (1..=SEQUENCES_PER_SESSION as u8).rev() {
        let (mut r_now, mut s_now) = ([0.0; STATE_COUNT], [0.0; STATE_COUNT]);
        for state in State::all() {
            let p = policy.probabilities(state, step);
            let (mut r, mut s) = (0.0, 0.0);
            for (a, pa) in p.iter().enumerate() {
                if *pa == 0.0 {
                    continue;
                }
                let action = Action::ALL[a];
                for outcome in Outcome::ALL {
                    let Some((input, next)) = transition(state, action, outcome) else {
                        continue;
                    };
                    let success = model.success(input).mean.clamp(0.0, 1.0);
                    let po = match outcome {
                        Outcome::Success => success,
                        Outcome::Failure => 1.0 - success,
                    };
                    let e = model.engagement(input, outcome).mean.clamp(-1.0, 1.0);
                    let reward = learning.reward(outcome.activity_result(input.level), e);
                    r += pa * po * (reward + learning.gamma * ret[next.index()]);
                    s += pa * po * (f64::from(outcome.score(input.level)) + score[next.index()]);
                }
            }
            r_now[state.index()] = r;
            s_now[state.index()] = s;
        }
        ret = r_now;
        score = s_now;
    }
    ExactValue {
        discounted_return: ret[State::START.index()],
        score: score[State::START.index()],
    }
}

/// How one estimator did over the validation's seeds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct EstimatorCheck {
    /// Mean of estimate − truth.
    pub bias: f64,
    /// Root mean square of estimate − truth.
    pub rmse: f64,
    /// Share of seeds whose 95 % interval holds the truth.
    pub coverage: f64,
    /// Seeds where the estimator had a value.
    pub seeds: usize,
}

fn check(truth: f64, estimates: &[Option<Estimate>]) -> EstimatorCheck {
    let got: Vec<&Estimate> = estimates.iter().flatten().collect();
    let n = got.len().max(1) as f64;
    EstimatorCheck {
        bias: got.iter().map(|e| e.value - truth).sum::<f64>() / n,
        rmse: (got.iter().map(|e| (e.value - truth).powi(2)).sum::<f64>() / n).sqrt(),
        coverage: got.iter().filter(|e| e.contains(truth)).count() as f64 / n,
        seeds: got.len(),
    }
}

/// The validation where the truth is known: per seed, `sessions` sessions logged by
/// `logging` against `model`, the new policy `target` estimated from them, compared with its
/// exact value.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Validation {
    pub truth: ExactValue,
    pub logging_truth: ExactValue,
    pub sessions: usize,
    pub seeds: usize,
    pub weighted_is_return: EstimatorCheck,
    pub per_decision_is_return: EstimatorCheck,
    pub weighted_is_score: EstimatorCheck,
    pub per_decision_is_score: EstimatorCheck,
    pub mean_effective_sample_size: f64,
    /// Per seed, the evaluation (weights left out).
    pub per_seed: Vec<Evaluation>,
}

#[allow(clippy::too_many_arguments)]
pub fn validate(
    model: &UserModelTable,
    logging: &TargetPolicy,
    target: &TargetPolicy,
    learning: &Learning,
    sessions: usize,
    seeds: std::ops::Range<u64>,
    bootstrap: usize,
    on_seed_done: &(dyn Fn() + Sync),
) -> Result<Validation, OffPolicyError> {
    let truth = exact_value(model, target, learning);
    let logging_truth = exact_value(model, logging, learning);
    let per_seed: Vec<Evaluation> = seeds
        .clone()
        .into_par_iter()
        .map(|seed| {
            let (logged, full) = simulate_sessions(model, logging, sessions, seed);
            let mut e = evaluate(&logged, Some(&full), target, learning, bootstrap, seed)?;
            e.weights.clear();
            on_seed_done();
            Ok(e)
        })
        .collect::<Result<_, OffPolicyError>>()?;
    let pick = |f: &dyn Fn(&Evaluation) -> Option<Estimate>| -> Vec<Option<Estimate>> {
        per_seed.iter().map(f).collect()
    };
    Ok(Validation {
        truth,
        logging_truth,
        sessions,
        seeds: per_seed.len(),
        weighted_is_return: check(
            truth.discounted_return,
            &pick(&|e| e.discounted_return.weighted_is),
        ),
        per_decision_is_return: check(
            truth.discounted_return,
            &pick(&|e| Some(e.discounted_return.per_decision_is)),
        ),
        weighted_is_score: check(truth.score, &pick(&|e| e.score.weighted_is)),
        per_decision_is_score: check(truth.score, &pick(&|e| Some(e.score.per_decision_is))),
        mean_effective_sample_size: per_seed
            .iter()
            .map(|e| e.effective_sample_size)
            .sum::<f64>()
            / per_seed.len().max(1) as f64,
        per_seed,
    })
}

#[cfg(test)]
mod tests;
