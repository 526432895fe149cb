//! Per-child adaptation, measured: leave-one-child-out over a study's participants. For each
//! child the user models are fitted without them, the child is put in the nearest cluster, and
//! the child's own fitted model stands in for the child; then, over a run of simulated sessions
//! against it, the cluster's policy as it stands is compared with a per-user table started
//! from it (the node's `per_user_q_tables`), a table learned on the child from scratch, and
//! the optimal policy for the child's own model (which no clinic has: its value is the most
//! any policy can expect against that model). Every policy meets the same simulated child:
//! session k of repetition s of a child draws the same numbers whatever the policy
//! (`simulation::SessionDraws`, common random numbers), and the policies are compared child
//! by child (`stats::PairedComparison`).

use crate::experiments::grid::splitmix64;
use crate::stats::{Interval, PairedComparison, mean, t_interval};
use q_learning::learning::{Learning, Mode, QTable};
use q_learning::mdp::{ExactValue, Objective, optimal_policy, play_session, session_metrics};
use q_learning::simulation::{
    SessionDraws, SessionMetrics, SessionSettings, SimulatedRun, SimulatedUser, run_session_with,
};
use q_learning::training::Pretraining;
use rayon::prelude::*;
use sequence_game::UserModelTable;
use serde::Serialize;
use user_models::{FitOptions, InteractionRecord, UserModelError};

/// The policies compared for each child.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Arm {
    /// The child's cluster's table, greedy, not changed by the child's sessions.
    Cluster,
    /// A table of the child's own, copied from the cluster's, greedy, learning after every
    /// sequence (`per_user_q_tables: true`, `exploitation_only: true`).
    PerUser,
    /// A new table learned on the child alone: softmax with the per-state temperature.
    Scratch,
    /// The optimal policy for the child's own model (backward induction, best expected
    /// return): what a policy could do knowing the child's model in advance, which no clinic
    /// does. Its exact expected return is the most any policy can expect per session against
    /// that model; its score is not a bound on score (the return also pays for engagement).
    Optimal,
}

impl Arm {
    pub const ALL: [Arm; 4] = [Arm::Cluster, Arm::PerUser, Arm::Scratch, Arm::Optimal];

    pub fn name(self) -> &'static str {
        match self {
            Arm::Cluster => "cluster policy",
            Arm::PerUser => "per-user table from the cluster's",
            Arm::Scratch => "from scratch on the child",
            Arm::Optimal => "optimal for the child's model",
        }
    }

    /// Short name for files (CSV).
    pub fn key(self) -> &'static str {
        match self {
            Arm::Cluster => "cluster",
            Arm::PerUser => "per_user",
            Arm::Scratch => "scratch",
            Arm::Optimal => "optimal",
        }
    }

    fn index(self) -> usize {
        self as usize
    }
}

/// How the study is run.
#[derive(Debug, Clone, PartialEq)]
pub struct StudySpec {
    /// User models fitted without the child (clusters, seeds, kernel).
    pub fit: FitOptions,
    pub learning: Learning,
    /// Pretraining of the cluster's policy, as the node pretrains: `runs` runs of `epochs` x
    /// 100 sessions, the best by its last epoch's return kept.
    pub pretrain_epochs: usize,
    pub pretrain_runs: usize,
    /// Sessions each child plays with each policy.
    pub sessions: usize,
    /// Repetitions per child: each its own random streams, the same for every policy.
    pub seeds: usize,
    pub seed: u64,
}

/// One child's leave-one-out setting.
#[derive(Debug, Clone, PartialEq)]
pub struct ChildCase {
    pub user: String,
    /// The cluster the child is put in by the models fitted without them.
    pub cluster: usize,
    /// That cluster's model (fitted without the child).
    pub cluster_model: UserModelTable,
    /// The child's own model: the simulated child.
    pub child_model: UserModelTable,
}

/// Leave-one-out cases for every user of `records` (user-id order).
pub fn cases(
    records: &[InteractionRecord],
    fit: &FitOptions,
) -> Result<Vec<ChildCase>, UserModelError> {
    let users = user_models::fit::user_vectors(records)?;
    users
        .par_iter()
        .map(|(user, vector)| {
            let others: Vec<InteractionRecord> = records
                .iter()
                .filter(|r| &r.user_id != user)
                .cloned()
                .collect();
            let set = user_models::fit(&others, fit)?;
            let cluster = set.assign_cluster(vector)?;
            let cluster_model = set.table(cluster as i64)?.clone();
            let child_model = user_models::fit::fit_user(user, records, fit)?;
            Ok(ChildCase {
                user: user.clone(),
                cluster,
                cluster_model,
                child_model,
            })
        })
        .collect()
}

/// A seed from the master seed and a path of indices, independent of thread order.
pub(crate) fn seed_of(master: u64, path: &[u64]) -> u64 {
    path.iter()
        .fold(splitmix64(master), |s, &i| splitmix64(s ^ i))
}

/// Per session of the run, the metrics of one child, policy and seed.
pub type SessionRun = Vec<SessionMetrics>;

/// What the child's own model allows, exactly (backward induction, no sampling).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Bounds {
    /// The optimal policy's value: its expected return is the most any policy can expect.
    pub optimal: ExactValue,
    /// The most any policy can expect to score (the policy that maximises the score).
    pub best_score: f64,
}

/// What one child got with each policy: `runs[arm][seed][session]`.
#[derive(Debug, Clone, PartialEq)]
pub struct ChildResult {
    pub user: String,
    pub cluster: usize,
    pub runs: Vec<Vec<SessionRun>>,
    pub bounds: Bounds,
}

/// The random numbers of session `session` of repetition `seed` of child `index`: the same
/// for every policy.
pub(crate) fn session_draws(
    spec: &StudySpec,
    index: usize,
    seed: usize,
    session: usize,
) -> SessionDraws {
    SessionDraws::new(seed_of(
        spec.seed,
        &[index as u64, 2, seed as u64, session as u64],
    ))
}

/// The live state convention and the softmax the node pretrains with.
fn live_settings(spec: &StudySpec) -> SessionSettings {
    SessionSettings {
        learning: spec.learning,
        mode: Mode::Explore,
        state_lags_result: false,
    }
}

/// The child's cluster's table as the node pretrains it against the cluster's model (what
/// the child meets as the cluster policy).
pub fn cluster_table(case: &ChildCase, index: usize, spec: &StudySpec) -> QTable {
    let seed = seed_of(spec.seed, &[index as u64, 0]);
    Pretraining {
        epochs: spec.pretrain_epochs,
        runs: spec.pretrain_runs,
        state_lags_result: live_settings(spec).state_lags_result,
    }
    .best_run(&case.cluster_model, &spec.learning, |r| {
        seed_of(seed, &[r as u64])
    })
    .map(|run| run.q_table)
    .unwrap_or_default()
}

/// Plays `spec.sessions` sessions per policy and seed against the child's own model.
pub fn run_child(case: &ChildCase, index: usize, spec: &StudySpec) -> ChildResult {
    let live = live_settings(spec);
    let cluster_table = cluster_table(case, index, spec);
    let optimal = optimal_policy(&case.child_model, &spec.learning, Objective::Return);
    let bounds = Bounds {
        optimal: optimal.value,
        best_score: optimal_policy(&case.child_model, &spec.learning, Objective::Score)
            .value
            .score,
    };
    let child = SimulatedUser::new(&case.child_model, &spec.learning);
    let frozen = Learning {
        alpha: 0.0,
        ..spec.learning
    };
    let greedy = |learning| SessionSettings {
        learning,
        mode: Mode::Exploit,
        ..live
    };
    let runs = Arm::ALL
        .iter()
        .map(|arm| {
            (0..spec.seeds)
                .map(|s| {
                    let draws = (0..spec.sessions).map(|k| session_draws(spec, index, s, k));
                    let learner = |table: &QTable, settings: SessionSettings| -> SessionRun {
                        // The run's own stream is never drawn from: `draws` decide.
                        let mut run = SimulatedRun::seeded(table.clone(), 0);
                        // Every learned sequence lowers its state's temperature, as in the
                        // node.
                        draws
                            .clone()
                            .map(|d| run_session_with(&mut run, &child, &settings, true, &d))
                            .collect()
                    };
                    match arm {
                        Arm::Cluster => learner(&cluster_table, greedy(frozen)),
                        Arm::PerUser => learner(&cluster_table, greedy(spec.learning)),
                        Arm::Scratch => learner(&QTable::default(), live),
                        Arm::Optimal => draws
                            .clone()
                            .map(|d| {
                                let (session, _) =
                                    play_session(&case.child_model, &optimal, String::new(), |k| {
                                        (d.action[k], d.answer[k])
                                    });
                                SessionMetrics {
                                    start_value: optimal.value.discounted_return,
                                    ..session_metrics(&session, &spec.learning)
                                }
                            })
                            .collect(),
                    }
                })
                .collect()
        })
        .collect();
    ChildResult {
        user: case.user.clone(),
        cluster: case.cluster,
        runs,
        bounds,
    }
}

/// Every child, in parallel; `on_child_done` is called as each finishes.
pub fn run_study(
    cases: &[ChildCase],
    spec: &StudySpec,
    on_child_done: &(dyn Fn() + Sync),
) -> Vec<ChildResult> {
    cases
        .par_iter()
        .enumerate()
        .map(|(i, c)| {
            let r = run_child(c, i, spec);
            on_child_done();
            r
        })
        .collect()
}

/// A metric of a session: score, engagement or discounted return.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Metric {
    Score,
    Engagement,
    Return,
}

impl Metric {
    pub const ALL: [Metric; 3] = [Metric::Score, Metric::Engagement, Metric::Return];

    pub fn of(self, m: &SessionMetrics) -> f64 {
        match self {
            Metric::Score => m.score,
            Metric::Engagement => m.engagement,
            Metric::Return => m.discounted_return,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Metric::Score => "score",
            Metric::Engagement => "engagement",
            Metric::Return => "return",
        }
    }
}

/// A metric over a range of sessions (0-based, end excluded).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Window {
    pub metric: Metric,
    pub sessions: std::ops::Range<usize>,
}

impl Window {
    /// "score, sessions 16-20".
    pub fn describe(&self) -> String {
        format!(
            "{}, sessions {}-{}",
            self.metric.name(),
            self.sessions.start + 1,
            self.sessions.end
        )
    }

    /// The windows every report shows: score over all sessions and over the last five,
    /// engagement and return over all.
    pub fn standard(sessions: usize) -> Vec<Window> {
        vec![
            Window {
                metric: Metric::Score,
                sessions: 0..sessions,
            },
            Window {
                metric: Metric::Score,
                sessions: sessions.saturating_sub(5)..sessions,
            },
            Window {
                metric: Metric::Engagement,
                sessions: 0..sessions,
            },
            Window {
                metric: Metric::Return,
                sessions: 0..sessions,
            },
        ]
    }
}

/// One child's mean of the window's metric with one policy in each seed.
pub fn per_seed(child: &ChildResult, arm: Arm, window: &Window) -> Vec<f64> {
    child.runs[arm.index()]
        .iter()
        .map(|run| {
            let values: Vec<f64> = run[window.sessions.clone()]
                .iter()
                .map(|m| window.metric.of(m))
                .collect();
            mean(&values)
        })
        .collect()
}

/// One child's mean over seeds (and the window's sessions) with one policy.
pub fn child_mean(child: &ChildResult, arm: Arm, window: &Window) -> f64 {
    mean(&per_seed(child, arm, window))
}

/// The mean over children (each weighing the same) with one policy.
pub fn mean_over_children(results: &[ChildResult], arm: Arm, window: &Window) -> f64 {
    let per_child: Vec<f64> = results.iter().map(|c| child_mean(c, arm, window)).collect();
    mean(&per_child)
}

/// The comparisons every report makes, first minus second: does adapting to the child help,
/// does learning from scratch, and how far is the per-user table from the best possible.
pub const COMPARISONS: [(Arm, Arm); 3] = [
    (Arm::PerUser, Arm::Cluster),
    (Arm::Scratch, Arm::Cluster),
    (Arm::Optimal, Arm::PerUser),
];

/// `first` − `second`, paired by child (and, within a child, by seed: both played the same
/// draws): per child the difference with its verdict, and over children the mean with t and
/// bootstrap intervals (`resamples` drawn from `seed`), the median, and the result without
/// the most influential child.
pub fn paired(
    results: &[ChildResult],
    first: Arm,
    second: Arm,
    window: &Window,
    resamples: usize,
    seed: u64,
) -> PairedComparison {
    let units: Vec<(String, Vec<f64>)> = results
        .iter()
        .map(|c| {
            let a = per_seed(c, first, window);
            let b = per_seed(c, second, window);
            (
                c.user.clone(),
                a.iter().zip(&b).map(|(x, y)| x - y).collect(),
            )
        })
        .collect();
    PairedComparison::of(&units, resamples, seed)
}

/// Per session index, the mean over children (each child: its mean over seeds) and the 95 %
/// t interval over children (`None` below two children).
pub fn curve(results: &[ChildResult], arm: Arm, metric: Metric) -> Vec<(f64, Option<Interval>)> {
    let sessions = results
        .first()
        .and_then(|c| c.runs.first()?.first().map(Vec::len))
        .unwrap_or(0);
    (0..sessions)
        .map(|k| {
            let window = Window {
                metric,
                sessions: k..k + 1,
            };
            let per_child: Vec<f64> = results
                .iter()
                .map(|c| child_mean(c, arm, &window))
                .collect();
            (mean(&per_child), t_interval(&per_child))
        })
        .collect()
}

#[cfg(test)]
mod tests;
