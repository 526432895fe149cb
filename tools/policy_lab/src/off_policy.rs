//! Counterfactual (off-policy) evaluation: how a new Q-table's policy would have done in
//! sessions another policy played, judged from the recorded decisions' probabilities alone
//! (importance sampling), before the new policy meets a child. Sans-IO: logged sessions in,
//! estimates with bootstrap intervals out, and the rules for when there are none to give
//! ([`Limits`]: too few sessions, or a new policy that leaves the logged actions). For the
//! validation, sessions are played against a user model and the new policy's exact value
//! comes from `q_learning::mdp`, as do the logged sessions and the judged Q-table's policy;
//! recorded sessions are read from the bags by `recorded`.

pub mod recorded;

use crate::stats::quantile;
use q_learning::learning::{Learning, allowed_at};
use q_learning::mdp::{
    ExactValue, LoggedSession, LoggedStep, TargetPolicy, TargetPolicyError, exact_value,
    simulate_sessions,
};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use sequence_game::{ACTION_COUNT, Action, State, UserModelTable};
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
    #[error(transparent)]
    Policy(#[from] TargetPolicyError),
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
    /// The share of the new policy's sessions that would leave the logged actions somewhere:
    /// per logged session 1 − Π (1 − mass outside the support at each decision), averaged.
    /// Where the logging policy was greedy this is 1 − the session's weight, so the mean is
    /// an unbiased estimate of the probability that the new policy plays a session the log
    /// cannot show. Only sessions whose every distribution was logged count.
    pub sessions_leaving_support: Option<f64>,
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

fn interval(value: f64, mut draws: Vec<f64>) -> Estimate {
    draws.sort_by(f64::total_cmp);
    Estimate {
        value,
        low: quantile(&draws, 0.025),
        high: quantile(&draws, 0.975),
    }
}

/// When an evaluation gives no estimate, or an estimate without an interval.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Limits {
    /// The most of the new policy's sessions that may leave the logged actions
    /// ([`Evaluation::sessions_leaving_support`]); above it the estimates would describe only
    /// the part of the new policy the log shows, a biased answer, so none is given.
    pub max_sessions_leaving_support: f64,
    /// Fewer whole sessions than this give no estimate: a bootstrap over a handful of
    /// sessions gives intervals far narrower than the uncertainty (one session: zero width).
    /// In simulation (200 seeds) the per-decision interval held the truth in 82.5 / 85.5 /
    /// 89.5 / 91.5 % of seeds at 10 / 20 / 30 / 50 sessions, the weighted one in 76 / 77 / 83
    /// / 85 % (docs/behaviour_policy.md): 50 is where both reach 85 %.
    pub min_sessions: usize,
    /// Below this effective sample size the weighted estimate gets no interval: it rests on
    /// a few sessions and its bootstrap interval is as narrow as it is wrong (in simulation
    /// it held the truth in 6-35 % of seeds at 0.7-3.4 effective sessions). Above it the
    /// interval is no guarantee either (docs/behaviour_policy.md).
    pub min_effective_sessions: f64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_sessions_leaving_support: 0.05,
            min_sessions: 50,
            min_effective_sessions: 10.0,
        }
    }
}

/// Why an evaluation gives no estimate.
#[derive(Debug, Clone, PartialEq, Serialize, thiserror::Error)]
pub enum Refusal {
    #[error(
        "{sessions} whole session(s) played by the policy, fewer than the {minimum} needed \
         (--min-sessions): too few to estimate anything, and a bootstrap over them would \
         give intervals narrower than the uncertainty"
    )]
    TooFewSessions { sessions: usize, minimum: usize },
    #[error(
        "the new policy would leave the actions the logged policy took in {:.0} % of its \
         sessions ({:.0} % of its probability per decision), above the {:.0} % allowed \
         (--max-off-support): importance sampling sees only the part of the new policy the \
         log shows, so any estimate would be biased by what it cannot see",
        100.0 * share, 100.0 * per_decision, 100.0 * maximum
    )]
    OffSupport {
        share: f64,
        per_decision: f64,
        maximum: f64,
    },
    #[error(
        "the logged policy's whole distributions are missing, so whether the new policy \
         stays within the logged actions cannot be checked"
    )]
    SupportUnknown,
}

impl Evaluation {
    /// Every reason the limits give for not estimating at all (none: estimate).
    pub fn refusals(&self, limits: &Limits) -> Vec<Refusal> {
        let mut out = Vec::new();
        if self.sessions < limits.min_sessions {
            out.push(Refusal::TooFewSessions {
                sessions: self.sessions,
                minimum: limits.min_sessions,
            });
        }
        match (self.sessions_leaving_support, self.mass_outside_support) {
            (Some(share), Some(per_decision)) => {
                if share > limits.max_sessions_leaving_support {
                    out.push(Refusal::OffSupport {
                        share,
                        per_decision,
                        maximum: limits.max_sessions_leaving_support,
                    });
                }
            }
            _ => out.push(Refusal::SupportUnknown),
        }
        out
    }

    /// Whether the weighted estimate's interval means anything under the limits.
    pub fn weighted_interval_holds(&self, limits: &Limits) -> bool {
        self.effective_sample_size >= limits.min_effective_sessions
    }

    /// Whether the per-decision estimate's interval means anything: not when no logged
    /// session follows the new policy throughout (every weight 0), so that the estimate
    /// rests only on the beginnings of sessions. In simulation, a greedy policy judged on
    /// logs of another table's ε-greedy play was there: its intervals held the truth in 1-32 %
    /// of seeds (docs/behaviour_policy.md, "Logged exploration").
    pub fn per_decision_interval_holds(&self) -> bool {
        self.sessions_with_weight > 0
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
    let (mut leaving, mut leaving_count) = (0.0, 0usize);
    for (i, session) in sessions.iter().enumerate() {
        // The probability the new policy stays within the logged actions along this session.
        let mut stays = Some(1.0);
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
            match logged_probabilities.and_then(|l| l.get(i)?.get(k)) {
                Some(full) => {
                    let off: f64 = new
                        .iter()
                        .zip(full)
                        .filter(|(_, logged)| **logged <= 0.0)
                        .map(|(p, _)| p)
                        .sum();
                    outside += off;
                    outside_count += 1;
                    stays = stays.map(|p| p * (1.0 - off).max(0.0));
                }
                None => stays = None,
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
        if let Some(p) = stays {
            leaving += 1.0 - p;
            leaving_count += 1;
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
        sessions_leaving_support: (leaving_count > 0).then(|| leaving / leaving_count as f64),
        weights,
        resamples_without_weight: without_weight,
    })
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
    /// The weighted estimate of the return over the seeds where `evaluate` gives it an
    /// interval (effective sample size at least [`Limits::default`]'s).
    pub weighted_is_return_where_shown: EstimatorCheck,
    pub mean_effective_sample_size: f64,
    /// Per seed, the evaluation (weights left out).
    pub per_seed: Vec<Evaluation>,
}

/// How near one estimator of the score came to the truth over a validation's seeds: is
/// `evaluate` able to judge the policy within ±`tolerance` points?
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Closeness {
    pub tolerance: f64,
    /// Share of seeds whose estimate lies within ±tolerance of the truth.
    pub estimate_within: f64,
    /// Share of seeds where `evaluate` shows an interval (it does not refuse, the interval
    /// is wider than zero and, for the weighted estimate, rests on enough effective sessions)
    /// and the interval lies wholly within the truth ± tolerance.
    pub interval_within: f64,
    /// Share of seeds where `evaluate` shows the interval at all.
    pub interval_shown: f64,
    /// Median half-width of the shown intervals (`None`: none shown).
    pub median_half_width: Option<f64>,
    pub seeds: usize,
}

/// [`Closeness`] of the weighted and the per-decision estimates of the score.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ScoreCloseness {
    pub weighted_is: Closeness,
    pub per_decision_is: Closeness,
}

fn closeness(
    truth: f64,
    per_seed: &[Evaluation],
    tolerance: f64,
    estimate: impl Fn(&Evaluation) -> Option<Estimate>,
    shown: impl Fn(&Evaluation) -> bool,
) -> Closeness {
    let n = per_seed.len().max(1) as f64;
    let mut within = 0usize;
    let mut inside = 0usize;
    let mut half_widths = Vec::new();
    for e in per_seed {
        let Some(x) = estimate(e) else {
            continue;
        };
        within += usize::from((x.value - truth).abs() <= tolerance);
        if shown(e) && x.high > x.low {
            half_widths.push((x.high - x.low) / 2.0);
            inside += usize::from(truth - tolerance <= x.low && x.high <= truth + tolerance);
        }
    }
    half_widths.sort_by(f64::total_cmp);
    Closeness {
        tolerance,
        estimate_within: within as f64 / n,
        interval_within: inside as f64 / n,
        interval_shown: half_widths.len() as f64 / n,
        median_half_width: (!half_widths.is_empty()).then(|| quantile(&half_widths, 0.5)),
        seeds: per_seed.len(),
    }
}

impl Validation {
    /// Whether `evaluate`, with its default [`Limits`], judges the score within ±`tolerance`
    /// points of the truth, seed by seed.
    pub fn score_closeness(&self, tolerance: f64) -> ScoreCloseness {
        let limits = Limits::default();
        let estimates = |e: &Evaluation| e.refusals(&limits).is_empty();
        ScoreCloseness {
            weighted_is: closeness(
                self.truth.score,
                &self.per_seed,
                tolerance,
                |e| e.score.weighted_is,
                |e| estimates(e) && e.weighted_interval_holds(&limits),
            ),
            per_decision_is: closeness(
                self.truth.score,
                &self.per_seed,
                tolerance,
                |e| Some(e.score.per_decision_is),
                |e| estimates(e) && e.per_decision_interval_holds(),
            ),
        }
    }
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
        weighted_is_return_where_shown: check(
            truth.discounted_return,
            &pick(&|e| {
                e.discounted_return
                    .weighted_is
                    .filter(|_| e.weighted_interval_holds(&Limits::default()))
            }),
        ),
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
