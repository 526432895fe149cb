//! Per-child adaptation, measured: leave-one-child-out over a study's participants. For each
//! child the user models are fitted without them, the child is put in the nearest cluster, and
//! the child's own fitted model stands in for the child; then, over a run of simulated sessions
//! against it, the cluster's policy as it stands is compared with a per-user table started
//! from it (the node's `per_user_q_tables`) and a table learned on the child from scratch.
//! A policy trained offline on the child's own model is the ceiling none of them can know.

use crate::experiments::{EpochScheme, RunSpec, best_run, train_run};
use crate::grid::splitmix64;
use crate::learning::{Learning, Mode, QTable};
use crate::simulation::{
    SessionMetrics, SessionSettings, SimulatedRun, SimulatedUser, run_session,
};
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
    /// Pretrained on the child's own model in simulation, greedy: what a policy could reach
    /// if it knew the child in advance (a ceiling, not a policy a clinic can have).
    ChildModel,
}

impl Arm {
    pub const ALL: [Arm; 4] = [Arm::Cluster, Arm::PerUser, Arm::Scratch, Arm::ChildModel];

    pub fn name(self) -> &'static str {
        match self {
            Arm::Cluster => "cluster policy",
            Arm::PerUser => "per-user table from the cluster's",
            Arm::Scratch => "from scratch on the child",
            Arm::ChildModel => "trained on the child's model (ceiling)",
        }
    }
}

/// How the study is run.
#[derive(Debug, Clone, PartialEq)]
pub struct StudySpec {
    /// User models fitted without the child (clusters, seeds, kernel).
    pub fit: FitOptions,
    pub learning: Learning,
    /// Pretraining of the cluster's (and the ceiling's) policy, as the node pretrains: `runs`
    /// runs of `epochs` x 100 sessions, the best by its last epoch's return kept.
    pub pretrain_epochs: usize,
    pub pretrain_runs: usize,
    /// Sessions each child plays with each policy.
    pub sessions: usize,
    /// Independent repetitions (random streams) per child and policy.
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
fn seed_of(master: u64, path: &[u64]) -> u64 {
    path.iter()
        .fold(splitmix64(master), |s, &i| splitmix64(s ^ i))
}

/// The node's pretraining against `model`: the best of `runs` softmax runs.
fn pretrain(
    model: &UserModelTable,
    spec: &StudySpec,
    settings: &SessionSettings,
    seed: u64,
) -> QTable {
    let user = SimulatedUser::new(model, &spec.learning);
    let run_spec = RunSpec {
        epochs: spec.pretrain_epochs,
        sessions_per_epoch: 100,
        scheme: EpochScheme::Blocks,
        state_lags_result: settings.state_lags_result,
    };
    let runs: Vec<_> = (0..spec.pretrain_runs)
        .map(|r| {
            train_run(
                &user,
                settings,
                QTable::default(),
                &run_spec,
                seed_of(seed, &[r as u64]),
            )
        })
        .collect();
    best_run(&runs)
        .map(|b| runs[b].q_table.clone())
        .unwrap_or_default()
}

/// Per session of the run, the metrics of one child, policy and seed.
pub type SessionRun = Vec<SessionMetrics>;

/// What one child got with each policy: `[arm][seed][session]`.
#[derive(Debug, Clone, PartialEq)]
pub struct ChildResult {
    pub user: String,
    pub cluster: usize,
    pub runs: Vec<Vec<SessionRun>>,
}

/// Plays `spec.sessions` sessions per policy and seed against the child's own model.
pub fn run_child(case: &ChildCase, index: usize, spec: &StudySpec) -> ChildResult {
    let live = SessionSettings {
        learning: spec.learning,
        mode: Mode::Explore,
        state_lags_result: false,
    };
    let cluster_table = pretrain(
        &case.cluster_model,
        spec,
        &live,
        seed_of(spec.seed, &[index as u64, 0]),
    );
    let ceiling_table = pretrain(
        &case.child_model,
        spec,
        &live,
        seed_of(spec.seed, &[index as u64, 1]),
    );
    let child = SimulatedUser::new(&case.child_model, &spec.learning);
    let frozen = Learning {
        alpha: 0.0,
        ..spec.learning
    };
    let runs = Arm::ALL
        .iter()
        .enumerate()
        .map(|(a, arm)| {
            let (table, settings) = match arm {
                Arm::Cluster => (
                    cluster_table.clone(),
                    SessionSettings {
                        learning: frozen,
                        mode: Mode::Exploit,
                        ..live
                    },
                ),
                Arm::PerUser => (
                    cluster_table.clone(),
                    SessionSettings {
                        mode: Mode::Exploit,
                        ..live
                    },
                ),
                Arm::Scratch => (QTable::default(), live),
                Arm::ChildModel => (
                    ceiling_table.clone(),
                    SessionSettings {
                        learning: frozen,
                        mode: Mode::Exploit,
                        ..live
                    },
                ),
            };
            (0..spec.seeds)
                .map(|s| {
                    let seed = seed_of(spec.seed, &[index as u64, 2, a as u64, s as u64]);
                    let mut run = SimulatedRun::seeded(table.clone(), seed);
                    // Every learned sequence lowers its state's temperature, as in the node.
                    (0..spec.sessions)
                        .map(|_| run_session(&mut run, &child, &settings, true))
                        .collect()
                })
                .collect()
        })
        .collect();
    ChildResult {
        user: case.user.clone(),
        cluster: case.cluster,
        runs,
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

/// Mean and standard deviation over seeds of a per-seed mean.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MeanStd {
    pub mean: f64,
    pub std: f64,
}

fn mean_std(values: &[f64]) -> MeanStd {
    let n = values.len().max(1) as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    MeanStd {
        mean,
        std: var.sqrt(),
    }
}

/// Per seed, the mean over children (all, or those picked) and over the sessions in
/// `sessions` of a metric; then mean ± std over seeds.
pub fn summary(
    results: &[ChildResult],
    arm: Arm,
    metric: Metric,
    sessions: std::ops::Range<usize>,
    pick: &dyn Fn(&ChildResult) -> bool,
) -> MeanStd {
    let a = Arm::ALL.iter().position(|x| *x == arm).unwrap_or(0);
    let children: Vec<&ChildResult> = results.iter().filter(|r| pick(r)).collect();
    let seeds = children.first().map_or(0, |c| c.runs[a].len());
    let per_seed: Vec<f64> = (0..seeds)
        .map(|s| {
            let mut sum = 0.0;
            let mut n = 0usize;
            for c in &children {
                for m in &c.runs[a][s][sessions.clone()] {
                    sum += metric.of(m);
                    n += 1;
                }
            }
            sum / n.max(1) as f64
        })
        .collect();
    mean_std(&per_seed)
}

/// Per session index, mean ± std over seeds of the mean over children.
pub fn curve(results: &[ChildResult], arm: Arm, metric: Metric) -> Vec<MeanStd> {
    let sessions = results
        .first()
        .and_then(|c| c.runs.first()?.first().map(Vec::len))
        .unwrap_or(0);
    (0..sessions)
        .map(|k| summary(results, arm, metric, k..k + 1, &|_| true))
        .collect()
}

#[cfg(test)]
mod tests;
