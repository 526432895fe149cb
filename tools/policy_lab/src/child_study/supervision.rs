//! Supervised autonomy measured on the study's children: how many decisions a proposal rule
//! (`user_models::supervision`, the game manager's) sends to the therapist per session, and
//! how much score a therapist who answers them protects. Leave one child out, as `per_child`:
//! the cluster's models are fitted without the child twice, with the paper's noise and with
//! the noise fitted per sequence (the two meanings of σ), the cluster's policy is pretrained on
//! the paper's model as the node pretrains it and plays greedily, and the child's own model
//! stands in for the child.
//!
//! The simulated therapist knows the child: at a proposal they play the action of the policy
//! that maximises the child's expected score from there on (backward induction on the child's
//! model), accepting the proposal when it is that action. The score a rule protects (its
//! sessions' score minus the policy's alone, on the same draws) is therefore the most its
//! proposals could protect. A rule that proposes where the policy is wrong for the child
//! protects much per proposal; proposals at random, whatever the decision, show what
//! proposing alone buys.

use crate::child_study::per_child::{ChildCase, StudySpec, cluster_table, seed_of, session_draws};
use crate::stats::{PairedComparison, mean};
use q_learning::learning::{Learning, QTable, allowed_at, greedy_set, nth_member};
use q_learning::mdp::{
    Objective, OptimalPolicy, StepPolicy, child_answer, optimal_policy, transition,
};
use q_learning::simulation::SessionDraws;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use sequence_game::{Action, Outcome, SEQUENCES_PER_SESSION, State, UserModelTable};
use serde::Serialize;
use user_models::supervision::ProposalRule;
use user_models::{FitOptions, InteractionRecord, NoiseModel, UserModelError};

/// Which fit of the cluster's model σ comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Sigma {
    /// The paper's noise (1e-10): σ ≈ 0 wherever the study saw the input.
    Paper,
    /// The noise fitted per sequence (`user_model fit --noise fitted`).
    FittedNoise,
}

/// When a decision is proposed.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub enum Trigger {
    /// Never: the policy plays alone (what every rule is compared with).
    Never,
    /// The game manager's rule with these limits (infinite: that limit is off), σ from the
    /// cluster's model of this fit.
    Rule {
        above_temperature: f64,
        above_success_std: f64,
        sigma: Sigma,
    },
    /// Each decision with this probability, whatever it is.
    Random(f64),
    /// Every decision: the therapist plays the session.
    Always,
}

impl Trigger {
    /// The game manager's temperature rule alone.
    pub fn temperature(limit: f64) -> Trigger {
        Trigger::Rule {
            above_temperature: limit,
            above_success_std: f64::INFINITY,
            sigma: Sigma::Paper,
        }
    }

    /// The σ rule alone.
    pub fn sigma(limit: f64, sigma: Sigma) -> Trigger {
        Trigger::Rule {
            above_temperature: f64::INFINITY,
            above_success_std: limit,
            sigma,
        }
    }

    /// "T > 100 or σ (paper) > 0.3".
    pub fn name(&self) -> String {
        match *self {
            Trigger::Never => "never (the policy alone)".into(),
            Trigger::Always => "every decision".into(),
            Trigger::Random(p) => format!("at random, {:.0} % of decisions", 100.0 * p),
            Trigger::Rule {
                above_temperature,
                above_success_std,
                sigma,
            } => {
                let fit = match sigma {
                    Sigma::Paper => "paper fit",
                    Sigma::FittedNoise => "fitted noise",
                };
                let mut parts = Vec::new();
                if above_temperature.is_finite() {
                    parts.push(format!("T > {above_temperature}"));
                }
                if above_success_std.is_finite() {
                    parts.push(format!("σ ({fit}) > {above_success_std}"));
                }
                if parts.is_empty() {
                    "never (no limit)".into()
                } else {
                    parts.join(" or ")
                }
            }
        }
    }
}

/// One child's leave-one-out setting, with the cluster's model in both fits.
#[derive(Debug, Clone, PartialEq)]
pub struct SupervisionCase {
    /// The cluster (paper fit, whose model the policy is pretrained on and whose σ the
    /// paper's rule reads) and the child's own model.
    pub child: ChildCase,
    /// The same cluster's model fitted with the noise fitted per sequence, without the child.
    pub fitted_noise_model: UserModelTable,
}

/// Leave-one-out cases for every user of `records`: `per_child::cases` (fit `fit`), and the
/// cluster's model fitted again without the child with the noise fitted per sequence. The
/// clustering does not depend on the GPs' noise, so the child falls in the same cluster; an
/// error says so if it did not.
pub fn cases(
    records: &[InteractionRecord],
    fit: &FitOptions,
) -> Result<Vec<SupervisionCase>, UserModelError> {
    let children = crate::child_study::per_child::cases(records, fit)?;
    let users = user_models::fit::user_vectors(records)?;
    let fitted = FitOptions {
        noise_model: NoiseModel::FittedPerSequence,
        ..fit.clone()
    };
    children
        .into_par_iter()
        .zip(users.par_iter())
        .map(|(child, (user, vector))| {
            let others: Vec<InteractionRecord> = records
                .iter()
                .filter(|r| &r.user_id != user)
                .cloned()
                .collect();
            let set = user_models::fit(&others, &fitted)?;
            let cluster = set.assign_cluster(vector)?;
            if cluster != child.cluster || &child.user != user {
                return Err(UserModelError::Options(format!(
                    "{user}: cluster {cluster} with the fitted noise, {} with the paper's",
                    child.cluster
                )));
            }
            Ok(SupervisionCase {
                fitted_noise_model: set.table(cluster as i64)?.clone(),
                child,
            })
        })
        .collect()
}

/// One session (or a mean of sessions) under a rule.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Supervised {
    /// Σ L·O.
    pub score: f64,
    /// Σ γ^(t-1) r, the policy's own objective (reward of the study's `Learning`).
    pub discounted_return: f64,
    /// Decisions proposed to the therapist.
    pub proposals: f64,
    /// Proposals the therapist replaced (the policy's action was not the best for the child).
    pub replaced: f64,
}

/// What the therapist plays: the action of the child's optimal policy (score- or
/// return-optimal, as the study asks).
fn therapist_action(therapist: &OptimalPolicy, state: State, step: u8) -> Action {
    let p = therapist.probabilities(state, step);
    let best = p
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map_or(0, |(a, _)| a);
    Action::ALL[best]
}

/// Plays one session of the greedy cluster policy `table` against the child, proposing by
/// `trigger`; `random[k]` decides a random trigger's proposal at sequence k.
fn play(
    case: &SupervisionCase,
    table: &QTable,
    learning: &Learning,
    trigger: Trigger,
    therapist: &OptimalPolicy,
    draws: &SessionDraws,
    random: &[f64; SEQUENCES_PER_SESSION],
) -> Supervised {
    let mut out = Supervised::default();
    let mut state = State::START;
    let mut discount = 1.0;
    for (k, u_random) in random.iter().enumerate() {
        let step = k as u8 + 1;
        let row = table.row(state);
        let (set, n) = greedy_set(row, allowed_at(state, step));
        // The node's greedy choice: ties broken by the session's action draw.
        let mut action = Action::ALL[nth_member(set, SessionDraws::tie_of(draws.action[k], n))];
        // Success does not depend on the outcome: the input of the sequence it sets up.
        let Some((input, _)) = transition(state, action, Outcome::Success) else {
            break; // cannot happen: the greedy action is allowed
        };
        let proposed = match trigger {
            Trigger::Never => false,
            Trigger::Always => true,
            Trigger::Random(p) => *u_random < p,
            Trigger::Rule {
                above_temperature,
                above_success_std,
                sigma,
            } => {
                let model = match sigma {
                    Sigma::Paper => &case.child.cluster_model,
                    Sigma::FittedNoise => &case.fitted_noise_model,
                };
                let rule = ProposalRule {
                    above_temperature,
                    above_success_std,
                };
                let temperature = learning.temperature.at(table.visits[state.index()]);
                !rule
                    .reasons(temperature, Some(model.success(input).std))
                    .is_empty()
            }
        };
        if proposed {
            out.proposals += 1.0;
            let better = therapist_action(therapist, state, step);
            if better != action {
                out.replaced += 1.0;
                action = better;
            }
        }
        let Some((input, _)) = transition(state, action, Outcome::Success) else {
            break; // cannot happen: the therapist's action is allowed
        };
        let (outcome, engagement) = child_answer(&case.child.child_model, input, draws.answer[k]);
        out.score += f64::from(outcome.score(input.level));
        out.discounted_return +=
            discount * learning.reward(outcome.activity_result(input.level), engagement);
        discount *= learning.gamma;
        state = State::after(input.level, input.feedback, outcome);
    }
    out
}

/// One child under every rule: `runs[trigger][seed]`, each the mean over the seed's sessions.
#[derive(Debug, Clone, PartialEq)]
pub struct ChildSupervision {
    pub user: String,
    pub cluster: usize,
    pub runs: Vec<Vec<Supervised>>,
}

/// Plays `spec.sessions` sessions per seed and rule against the child (`index`: the child's
/// place among the cases, which keys its draws), the therapist playing the child's optimal
/// action for `therapist` at each proposal. The cluster's policy and the draws are
/// `per_child`'s, so the "never" rule plays exactly `per_child`'s cluster policy.
pub fn run_child(
    case: &SupervisionCase,
    index: usize,
    spec: &StudySpec,
    triggers: &[Trigger],
    therapist: Objective,
) -> ChildSupervision {
    let table = cluster_table(&case.child, index, spec);
    let therapist = optimal_policy(&case.child.child_model, &spec.learning, therapist);
    let runs = triggers
        .iter()
        .map(|&trigger| {
            (0..spec.seeds)
                .map(|s| {
                    let sessions: Vec<Supervised> = (0..spec.sessions)
                        .map(|k| {
                            let draws = session_draws(spec, index, s, k);
                            // The random rule's own numbers, apart from the child's.
                            let mut rng = ChaCha8Rng::seed_from_u64(seed_of(
                                spec.seed,
                                &[index as u64, 3, s as u64, k as u64],
                            ));
                            let random = std::array::from_fn(|_| rng.random::<f64>());
                            play(
                                case,
                                &table,
                                &spec.learning,
                                trigger,
                                &therapist,
                                &draws,
                                &random,
                            )
                        })
                        .collect();
                    let of = |f: fn(&Supervised) -> f64| {
                        mean(&sessions.iter().map(f).collect::<Vec<_>>())
                    };
                    Supervised {
                        score: of(|x| x.score),
                        discounted_return: of(|x| x.discounted_return),
                        proposals: of(|x| x.proposals),
                        replaced: of(|x| x.replaced),
                    }
                })
                .collect()
        })
        .collect();
    ChildSupervision {
        user: case.child.user.clone(),
        cluster: case.child.cluster,
        runs,
    }
}

/// Every child, in parallel; `on_child_done` is called as each finishes.
pub fn run_study(
    cases: &[SupervisionCase],
    spec: &StudySpec,
    triggers: &[Trigger],
    therapist: Objective,
    on_child_done: &(dyn Fn() + Sync),
) -> Vec<ChildSupervision> {
    cases
        .par_iter()
        .enumerate()
        .map(|(i, c)| {
            let r = run_child(c, i, spec, triggers, therapist);
            on_child_done();
            r
        })
        .collect()
}

/// One rule over the children.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TriggerSummary {
    pub trigger: Trigger,
    pub name: String,
    /// Means over children (each child its mean over seeds and sessions), per session.
    pub proposals: f64,
    pub replaced: f64,
    pub score: f64,
    pub discounted_return: f64,
    /// Score minus the policy's alone, paired by child (and within a child by seed: the
    /// same draws).
    pub protected: PairedComparison,
    /// The same in discounted return.
    pub protected_return: PairedComparison,
    /// Mean score protected per proposal (`None` without proposals).
    pub protected_per_proposal: Option<f64>,
}

/// `first` − `second` in `quantity`, paired by child and within a child by seed.
pub fn paired(
    results: &[ChildSupervision],
    first: usize,
    second: usize,
    quantity: fn(&Supervised) -> f64,
    resamples: usize,
    seed: u64,
) -> PairedComparison {
    let units: Vec<(String, Vec<f64>)> = results
        .iter()
        .map(|c| {
            let d = c.runs[first]
                .iter()
                .zip(&c.runs[second])
                .map(|(a, b)| quantity(a) - quantity(b))
                .collect();
            (c.user.clone(), d)
        })
        .collect();
    PairedComparison::of(&units, resamples, seed)
}

/// The mean over children (each child its mean over seeds) of a quantity under rule `t`.
pub fn over_children(results: &[ChildSupervision], t: usize, f: fn(&Supervised) -> f64) -> f64 {
    mean(
        &results
            .iter()
            .map(|c| mean(&c.runs[t].iter().map(f).collect::<Vec<_>>()))
            .collect::<Vec<_>>(),
    )
}

/// Each rule's proposals, replacements, score and return over the children, and what it
/// protects against `triggers[never]` (the policy alone), paired by child; intervals from
/// `resamples` bootstrap draws seeded by `seed`.
pub fn summarise(
    results: &[ChildSupervision],
    triggers: &[Trigger],
    never: usize,
    resamples: usize,
    seed: u64,
) -> Vec<TriggerSummary> {
    triggers
        .iter()
        .enumerate()
        .map(|(t, trigger)| {
            let protected = paired(results, t, never, |x| x.score, resamples, seed);
            let proposals = over_children(results, t, |x| x.proposals);
            TriggerSummary {
                trigger: *trigger,
                name: trigger.name(),
                proposals,
                replaced: over_children(results, t, |x| x.replaced),
                score: over_children(results, t, |x| x.score),
                discounted_return: over_children(results, t, |x| x.discounted_return),
                protected_return: paired(
                    results,
                    t,
                    never,
                    |x| x.discounted_return,
                    resamples,
                    seed,
                ),
                protected_per_proposal: (proposals > 0.0).then(|| protected.all.mean / proposals),
                protected,
            }
        })
        .collect()
}

/// For each rule that proposes, proposals at random at the same mean rate (over children):
/// what the rule's choice of decisions must beat.
pub fn matched_random(summary: &[TriggerSummary]) -> Vec<Option<Trigger>> {
    summary
        .iter()
        .map(|s| match s.trigger {
            Trigger::Rule { .. } if s.proposals > 0.0 => Some(Trigger::Random(
                (s.proposals / SEQUENCES_PER_SESSION as f64).min(1.0),
            )),
            _ => None,
        })
        .collect()
}

#[cfg(test)]
mod tests;
