//! Per-child adaptation by a belief about the child, measured beside `per_child`'s policies on
//! the same simulated children and the same draws. Each sequence updates a belief
//! (`child_belief`: a posterior over known models, or the child's own GPs around a prior
//! model) from the answer and the engagement, and each decision is planned on it by backward
//! induction over the rest of the session (the posterior predictive model, or one model drawn
//! from the belief per session). The known models never include the child's own: the library
//! holds the clusters' models fitted without the child and the other children's own models.
//! Each arm starts from the child's cluster (what the cluster policy knows) or from the
//! population alone (what a new child on the robot gets).

use super::per_child::{ChildCase, SessionRun, StudySpec, cluster_table, seed_of, session_draws};
use child_belief::library::KnownModel;
use child_belief::planner::{Baseline, BeliefPolicy, GuardTest, PlanningRule};
use child_belief::{
    Belief, BeliefError, LearnedCovariance, LibraryParams, ModelPosterior, Observation, OwnModel,
    OwnModelParams,
};
use q_learning::learning::{Learning, QTable};
use q_learning::mdp::{
    ExactValue, Objective, TargetPolicy, TargetTemperature, exact_value, optimal_policy, transition,
};
use q_learning::simulation::{SessionMetrics, answers_right};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use sequence_game::{Outcome, SEQUENCES_PER_SESSION, State, UserModelTable};
use serde::Serialize;
use user_models::{FitOptions, InteractionRecord, UserModelError};

/// What the belief is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Representation {
    /// A posterior over the known models (the clusters' and the other children's own).
    Library,
    /// The child's own GPs around the prior model (the cluster's or the population's), with
    /// the product kernel's prior covariance.
    OwnModel,
    /// The same with the prior covariance learned from the other children's own models
    /// (their deviations from their cluster's model, or from the population's).
    OwnModelLearned,
}

/// How a decision is planned on the belief.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Planning {
    /// Backward induction on the posterior predictive model, before each sequence.
    Mean,
    /// Backward induction on one model drawn from the belief at the start of each session
    /// (posterior sampling).
    Sampling,
    /// As `Mean`, but an action the baseline (the cluster's table, or the population's when
    /// the belief starts from the population) would not take pays `BeliefSpec::caution` times
    /// the belief's standard deviation of its expected reward.
    Cautious,
    /// The posterior-mean plan, but where it leaves the baseline its advantage over the
    /// baseline to the session's end, over `BeliefSpec::guard_samples` models drawn from the
    /// belief, must have a mean above `caution` standard deviations; else the baseline's
    /// action.
    Guarded,
    /// As `Guarded`, κ falling as the child's sequences n accumulate: κ h / (h + n), h
    /// `BeliefSpec::fading_half`.
    Fading,
    /// As `Guarded`, but the test is a chance constraint on the session's return: a mean gain,
    /// and in all but `BeliefSpec::chance_risk` of the drawn models the session loses at most
    /// what is left of `BeliefSpec::chance_margin` against the baseline.
    Chance,
    /// Both `Guarded`'s test and `Chance`'s constraint: the gain must stand out by `caution`
    /// standard deviations and the session's loss stay within `chance_margin`.
    SigmaChance,
    /// SPIBB: the posterior-mean plan, leaving the baseline only between inputs the child
    /// was seen at `BeliefSpec::spibb_min_observations` times.
    Spibb,
}

/// The planning the study chose (with `BeliefSpec::default()`'s numbers): what
/// `policy_lab per-child-belief` runs by default and the live policy is given.
pub const DEFAULT_PLANNING: Planning = Planning::Chance;

/// What the belief starts from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Start {
    /// The child's cluster (from the child's own records, as the cluster policy).
    Cluster,
    /// The population alone: no cluster.
    Population,
}

/// One belief arm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct BeliefArm {
    pub representation: Representation,
    pub planning: Planning,
    pub start: Start,
}

impl BeliefArm {
    /// "library, mean, from cluster".
    pub fn name(&self) -> String {
        format!(
            "{}, {}, from {}",
            match self.representation {
                Representation::Library => "library",
                Representation::OwnModel => "own model",
                Representation::OwnModelLearned => "own model (learned covariance)",
            },
            match self.planning {
                Planning::Mean => "mean",
                Planning::Sampling => "sampling",
                Planning::Cautious => "cautious",
                Planning::Guarded => "guarded",
                Planning::Fading => "fading guard",
                Planning::Chance => "chance guard",
                Planning::SigmaChance => "σ and chance guard",
                Planning::Spibb => "SPIBB",
            },
            match self.start {
                Start::Cluster => "cluster",
                Start::Population => "population",
            }
        )
    }
}

/// How the beliefs are set up.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct BeliefSpec {
    pub library: LibraryParams,
    /// Starting from a cluster, the prior weight of each known model of another cluster
    /// (the cluster's own models weigh 1 each).
    pub other_cluster_weight: f64,
    /// Starting from a cluster, the prior weight of the cluster's model against 1 for each
    /// child of the cluster.
    pub cluster_model_weight: f64,
    pub own_model: OwnModelParams,
    /// Learned covariance: shrinkage towards the diagonal, and the least variance.
    pub shrinkage: f64,
    pub variance_floor: f64,
    /// The learned covariance times this (above 1: a child may differ more than the known
    /// ones did).
    pub covariance_scale: f64,
    /// κ of cautious and guarded planning.
    pub caution: f64,
    /// Sessions played by the baseline alone at the start, the belief watching.
    pub baseline_sessions: usize,
    /// Models drawn from the belief for the guard.
    pub guard_samples: usize,
    /// Fading guard: the child's sequences after which κ is halved.
    pub fading_half: f64,
    /// Chance guard: the session's return it may risk against the baseline, and the share of
    /// drawn models allowed past it.
    pub chance_margin: f64,
    pub chance_risk: f64,
    /// SPIBB: the child's sequences at an input before the plan may use it.
    pub spibb_min_observations: f64,
}

impl Default for BeliefSpec {
    fn default() -> Self {
        BeliefSpec {
            library: LibraryParams::default(),
            other_cluster_weight: 0.1,
            cluster_model_weight: 1.0,
            own_model: OwnModelParams::default(),
            shrinkage: 0.5,
            variance_floor: 0.01,
            covariance_scale: 2.0,
            caution: 0.5,
            baseline_sessions: 0,
            guard_samples: 64,
            fading_half: 50.0,
            chance_margin: 0.5,
            chance_risk: 0.1,
            spibb_min_observations: 2.0,
        }
    }
}

/// What the belief arms know of one child besides `per_child`'s case: the models fitted
/// without the child.
#[derive(Debug, Clone, PartialEq)]
pub struct LibraryCase {
    pub case: ChildCase,
    /// Every cluster's model fitted without the child.
    pub clusters: Vec<UserModelTable>,
    /// The other children, each with the cluster the fit without the child put them in.
    pub others: Vec<(String, usize)>,
    /// One model fitted on all the other children together.
    pub population: UserModelTable,
}

/// The library cases of every child, in `cases`' order.
pub fn library_cases(
    records: &[InteractionRecord],
    cases: &[ChildCase],
    fit: &FitOptions,
) -> Result<Vec<LibraryCase>, UserModelError> {
    cases
        .par_iter()
        .map(|case| {
            let others: Vec<InteractionRecord> = records
                .iter()
                .filter(|r| r.user_id != case.user)
                .cloned()
                .collect();
            let set = user_models::fit(&others, fit)?;
            let population = user_models::fit(
                &others,
                &FitOptions {
                    clusters: 1,
                    ..fit.clone()
                },
            )?;
            Ok(LibraryCase {
                case: case.clone(),
                clusters: set.tables(),
                others: set
                    .file()
                    .users
                    .iter()
                    .map(|u| (u.user.clone(), u.cluster))
                    .collect(),
                population: population.table(0)?.clone(),
            })
        })
        .collect()
}

/// The known models for child `index` (never their own) with the prior weights of `start`.
pub fn library_for(
    cases: &[LibraryCase],
    index: usize,
    start: Start,
    spec: &BeliefSpec,
) -> (Vec<KnownModel>, Vec<f64>) {
    let me = &cases[index];
    let mut models = Vec::new();
    let mut prior = Vec::new();
    let weight_of_cluster = |k: usize| match start {
        Start::Population => 1.0,
        Start::Cluster if k == me.case.cluster => 1.0,
        Start::Cluster => spec.other_cluster_weight,
    };
    for (k, table) in me.clusters.iter().enumerate() {
        models.push(KnownModel {
            name: format!("cluster {k}"),
            table: table.clone(),
        });
        prior.push(
            weight_of_cluster(k)
                * match start {
                    Start::Cluster => spec.cluster_model_weight,
                    Start::Population => 1.0,
                },
        );
    }
    for (user, k) in &me.others {
        // The other children's own models do not depend on who is left out.
        if let Some(c) = cases.iter().find(|c| &c.case.user == user) {
            models.push(KnownModel {
                name: user.clone(),
                table: c.case.child_model.clone(),
            });
            prior.push(weight_of_cluster(*k));
        }
    }
    (models, prior)
}

/// The prior mean of `start` for child `index` and the covariance of the other children's
/// deviations from theirs (each from their cluster's model in the fit without the child, or
/// all from the population's).
pub fn learned_prior<'a>(
    cases: &'a [LibraryCase],
    index: usize,
    start: Start,
    spec: &BeliefSpec,
) -> Result<(&'a UserModelTable, LearnedCovariance), BeliefError> {
    let me = &cases[index];
    let pairs: Vec<(&UserModelTable, &UserModelTable)> = me
        .others
        .iter()
        .filter_map(|(user, k)| {
            let c = cases.iter().find(|c| &c.case.user == user)?;
            let prior = match start {
                Start::Cluster => me.clusters.get(*k)?,
                Start::Population => &me.population,
            };
            Some((&c.case.child_model, prior))
        })
        .collect();
    let prior = match start {
        Start::Cluster => &me.case.cluster_model,
        Start::Population => &me.population,
    };
    let mut covariance =
        LearnedCovariance::from_children(&pairs, spec.shrinkage, spec.variance_floor)?;
    covariance.success *= spec.covariance_scale;
    covariance.engagement *= spec.covariance_scale;
    Ok((prior, covariance))
}

/// The belief an arm starts with for child `index`.
fn initial_belief(
    cases: &[LibraryCase],
    index: usize,
    arm: &BeliefArm,
    spec: &BeliefSpec,
) -> Result<Box<dyn Belief + Send>, BeliefError> {
    let me = &cases[index];
    Ok(match arm.representation {
        Representation::Library => {
            let (models, prior) = library_for(cases, index, arm.start, spec);
            Box::new(ModelPosterior::new(models, &prior, spec.library)?)
        }
        Representation::OwnModel => {
            let prior = match arm.start {
                Start::Cluster => &me.case.cluster_model,
                Start::Population => &me.population,
            };
            Box::new(OwnModel::new(prior, spec.own_model)?)
        }
        Representation::OwnModelLearned => {
            let (prior, covariance) = learned_prior(cases, index, arm.start, spec)?;
            Box::new(OwnModel::with_covariance(
                prior,
                &covariance,
                spec.own_model,
            )?)
        }
    })
}

/// The baseline an arm's cautious plan stays near: the table the node would use without the
/// belief (the cluster's, pretrained as the node pretrains it; from the population, one
/// pretrained alike on the population's model).
pub fn baseline_table(
    cases: &[LibraryCase],
    index: usize,
    start: Start,
    spec: &StudySpec,
) -> QTable {
    let me = &cases[index];
    match start {
        Start::Cluster => cluster_table(&me.case, index, spec),
        Start::Population => cluster_table(
            &ChildCase {
                cluster_model: me.population.clone(),
                ..me.case.clone()
            },
            index,
            spec,
        ),
    }
}

/// The planner's rule of `planning` with `spec`'s numbers (what the live policy is given).
pub fn planning_rule(planning: Planning, spec: &BeliefSpec) -> PlanningRule {
    match planning {
        Planning::Mean => PlanningRule::Mean,
        Planning::Sampling => PlanningRule::Sampling,
        Planning::Cautious => PlanningRule::Cautious {
            caution: spec.caution,
        },
        Planning::Guarded => PlanningRule::Guarded {
            test: GuardTest::Sigma {
                caution: spec.caution,
            },
            samples: spec.guard_samples,
        },
        Planning::Fading => PlanningRule::Guarded {
            test: GuardTest::Fading {
                caution: spec.caution,
                half: spec.fading_half,
            },
            samples: spec.guard_samples,
        },
        Planning::Chance => PlanningRule::Guarded {
            test: GuardTest::Chance {
                margin: spec.chance_margin,
                risk: spec.chance_risk,
            },
            samples: spec.guard_samples,
        },
        Planning::SigmaChance => PlanningRule::Guarded {
            test: GuardTest::SigmaChance {
                caution: spec.caution,
                margin: spec.chance_margin,
                risk: spec.chance_risk,
            },
            samples: spec.guard_samples,
        },
        Planning::Spibb => PlanningRule::Spibb {
            min_observations: spec.spibb_min_observations,
        },
    }
}

/// `spec.sessions` sessions of one seed of a belief arm against the child's own model, on the
/// same draws as `per_child`'s policies.
pub fn run_belief_seed(
    cases: &[LibraryCase],
    index: usize,
    arm: &BeliefArm,
    belief_spec: &BeliefSpec,
    spec: &StudySpec,
    baseline: Option<&Baseline>,
    seed: usize,
) -> Result<SessionRun, BeliefError> {
    let child = &cases[index].case.child_model;
    let learning = &spec.learning;
    let rule = planning_rule(arm.planning, belief_spec);
    let mut policy = BeliefPolicy::new(
        initial_belief(cases, index, arm, belief_spec)?,
        baseline.cloned(),
        *learning,
        rule,
    );
    // Posterior sampling's own stream: the child's answers stay on the common draws.
    let mut rng = ChaCha8Rng::seed_from_u64(seed_of(spec.seed, &[index as u64, 3, seed as u64]));
    Ok((0..spec.sessions)
        .map(|k| {
            let draws = session_draws(spec, index, seed, k);
            policy.start_session(&mut rng);
            let mut m = SessionMetrics::default();
            let mut state = State::START;
            let mut discount = 1.0;
            for j in 0..SEQUENCES_PER_SESSION {
                let step = j as u8 + 1;
                let action = match baseline {
                    Some(b) if k < belief_spec.baseline_sessions => {
                        b.action(state, step, draws.action[j])
                    }
                    _ => {
                        // The guard's draws: a stream of their own per decision.
                        let mut g = ChaCha8Rng::seed_from_u64(seed_of(
                            spec.seed,
                            &[index as u64, 4, seed as u64, k as u64, j as u64],
                        ));
                        policy.decide(state, step, draws.action[j], &mut g).action
                    }
                };
                let Some((input, _)) = transition(state, action, Outcome::Success) else {
                    break; // cannot happen: the plan keeps to the allowed actions
                };
                let outcome = Outcome::from_correct(answers_right(
                    draws.answer[j],
                    child.success(input).mean,
                ));
                let engagement = child.engagement(input, outcome).mean.clamp(-1.0, 1.0);
                let Some((_, next)) = transition(state, action, outcome) else {
                    break;
                };
                let reward = learning.reward(outcome.activity_result(input.level), engagement);
                m.score += f64::from(outcome.score(input.level));
                m.max_score += f64::from(input.level.get());
                m.engagement += engagement;
                m.discounted_return += discount * reward;
                discount *= learning.gamma;
                if let Ok(o) = Observation::new(input, outcome, engagement) {
                    policy.observe(&o);
                }
                state = next;
            }
            m.engagement /= SEQUENCES_PER_SESSION as f64;
            m
        })
        .collect())
}

/// Every seed of a belief arm for one child: `[seed][session]`.
pub fn run_belief_arm(
    cases: &[LibraryCase],
    index: usize,
    arm: &BeliefArm,
    belief_spec: &BeliefSpec,
    spec: &StudySpec,
) -> Result<Vec<SessionRun>, BeliefError> {
    let baseline = (arm.planning != Planning::Mean && arm.planning != Planning::Sampling
        || belief_spec.baseline_sessions > 0)
        .then(|| Baseline::of_table(&baseline_table(cases, index, arm.start, spec)));
    (0..spec.seeds)
        .into_par_iter()
        .map(|s| run_belief_seed(cases, index, arm, belief_spec, spec, baseline.as_ref(), s))
        .collect()
}

/// What identification alone could reach for one child, exactly: the optimal policies of the
/// known models (and of the cluster's model), each evaluated on the child's own model.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Identification {
    /// The cluster policy (the cluster's table, greedy) on the child's model.
    pub cluster_policy: ExactValue,
    /// The cluster model's optimal policy on the child's model.
    pub cluster_model_optimal: ExactValue,
    /// The best of the known models' optimal policies on the child's model, and whose it is.
    pub best_known: ExactValue,
    pub best_known_model: String,
    /// The child's own optimum.
    pub optimal: ExactValue,
}

pub fn identification(
    cases: &[LibraryCase],
    index: usize,
    spec: &StudySpec,
    belief_spec: &BeliefSpec,
) -> Identification {
    let me = &cases[index];
    let learning: &Learning = &spec.learning;
    let child = &me.case.child_model;
    let table: QTable = cluster_table(&me.case, index, spec);
    let cluster_policy = TargetPolicy::new(table, TargetTemperature::Greedy)
        .map(|p| exact_value(child, &p, learning))
        .unwrap_or(ExactValue {
            discounted_return: f64::NAN,
            score: f64::NAN,
        });
    let of = |model: &UserModelTable| {
        exact_value(
            child,
            &optimal_policy(model, learning, Objective::Return),
            learning,
        )
    };
    let (models, _) = library_for(cases, index, Start::Population, belief_spec);
    let mut best = (f64::NEG_INFINITY, None, String::new());
    for m in models.iter().chain(std::iter::once(&KnownModel {
        name: "population".into(),
        table: me.population.clone(),
    })) {
        let v = of(&m.table);
        if v.discounted_return > best.0 {
            best = (v.discounted_return, Some(v), m.name.clone());
        }
    }
    Identification {
        cluster_policy,
        cluster_model_optimal: of(&me.case.cluster_model),
        best_known: best.1.unwrap_or(cluster_policy),
        best_known_model: best.2,
        optimal: optimal_policy(child, learning, Objective::Return).value,
    }
}

#[cfg(test)]
mod tests;
