//! The paper's evaluation grid: for each user model (cluster) and reward, independent seeded
//! runs; their curves as mean ± std across runs; then policy transfer between every two
//! clusters (the source's best run by mean return over its last epoch initialises the target's
//! Q-table, then RE + βE exploitation-only). Each run's seed comes from the master seed and the
//! run's (configuration, index), never from thread order, so any thread count gives the same
//! curves.

use q_learning::learning::{Learning, Mode, QTable, Reward};
use q_learning::simulation::{SessionSettings, SimulatedUser};
use q_learning::training::{EpochMetrics, Run, RunSpec, best_run, train_run, train_runs};
use rayon::prelude::*;
use sequence_game::{SEQUENCES_PER_SESSION, UserModelTable};

/// Runs interleaved on one thread (see `q_learning::simulation::run_sessions`).
const INTERLEAVE: usize = 2;

pub(crate) fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A configuration of the grid.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    /// "M1 RE", "M2 RE+bE", "M1->M2 RE+bE exploit", with M(k+1) for cluster k.
    pub name: String,
    /// Cluster whose user model is trained against.
    pub cluster: usize,
    pub reward: Reward,
    pub mode: Mode,
    /// Cluster whose best run initialises the Q-table (transfer).
    pub transfer_from: Option<usize>,
}

impl Config {
    /// Stable identity for seeding: the same configuration gets the same seeds whatever else
    /// the grid contains.
    fn key(&self) -> u64 {
        let reward = Reward::ALL
            .iter()
            .position(|r| *r == self.reward)
            .unwrap_or(0) as u64;
        match self.transfer_from {
            None => ((self.cluster as u64) << 8) | reward,
            Some(s) => (1 << 40) | ((s as u64) << 20) | ((self.cluster as u64) << 8) | reward,
        }
    }

    /// Seed of run `run` of this configuration.
    pub fn run_seed(&self, master: u64, run: usize) -> u64 {
        splitmix64(splitmix64(splitmix64(master) ^ self.key()) ^ run as u64)
    }
}

/// Mean and population standard deviation (numpy's default, as the authors) across runs.
#[derive(Debug, Clone, PartialEq)]
pub struct Curve {
    pub config: Config,
    pub mean: Vec<EpochMetrics>,
    pub std: Vec<EpochMetrics>,
    /// Index and final return of the best run.
    pub best_run: usize,
    pub best_return: f64,
}

fn summarise(config: Config, runs: &[Run]) -> Curve {
    let epochs = runs.first().map_or(0, |r| r.epochs.len());
    let n = runs.len().max(1) as f64;
    let (mut mean, mut std) = (Vec::with_capacity(epochs), Vec::with_capacity(epochs));
    for e in 0..epochs {
        let mut mu = [0.0; 6];
        for r in runs {
            for (m, v) in mu.iter_mut().zip(r.epochs[e].values()) {
                *m += v / n;
            }
        }
        let mut var = [0.0; 6];
        for r in runs {
            for ((s, v), m) in var.iter_mut().zip(r.epochs[e].values()).zip(mu) {
                *s += (v - m).powi(2) / n;
            }
        }
        mean.push(EpochMetrics::from_values(mu));
        std.push(EpochMetrics::from_values(var.map(f64::sqrt)));
    }
    let best = best_run(runs).unwrap_or(0);
    Curve {
        config,
        mean,
        std,
        best_run: best,
        best_return: runs.get(best).map_or(f64::NAN, |r| r.final_return),
    }
}

/// What the grid runs.
#[derive(Debug, Clone, PartialEq)]
pub struct GridSpec {
    pub runs: usize,
    pub seed: u64,
    pub run: RunSpec,
    /// α, γ, temperature, β, λ (the reward is set per configuration).
    pub learning: Learning,
    pub clusters: Vec<usize>,
    pub rewards: Vec<Reward>,
    /// Transfer between every two of `clusters` (needs RE + βE among `rewards`).
    pub transfer: bool,
}

/// The grid's curves and how many Q-iterations it took.
#[derive(Debug, Clone, PartialEq)]
pub struct GridResult {
    pub curves: Vec<Curve>,
    pub iterations: u64,
}

fn run_configs(
    models: &[UserModelTable],
    spec: &GridSpec,
    configs: &[(Config, QTable)],
    progress: &(dyn Fn() + Sync),
) -> Vec<Vec<Run>> {
    let prepared: Vec<(SimulatedUser, SessionSettings)> = configs
        .iter()
        .map(|(c, _)| {
            let learning = Learning {
                reward: c.reward,
                ..spec.learning
            };
            let settings = SessionSettings {
                learning,
                mode: c.mode,
                state_lags_result: spec.run.state_lags_result,
            };
            (SimulatedUser::new(&models[c.cluster], &learning), settings)
        })
        .collect();
    // Jobs are groups of INTERLEAVE runs of one configuration (fewer at the end), played in
    // turn on one thread; run r's seed depends only on (seed, configuration, r).
    let jobs: Vec<(usize, usize)> = (0..configs.len())
        .flat_map(|c| (0..spec.runs).step_by(INTERLEAVE).map(move |r| (c, r)))
        .collect();
    let mut runs: Vec<Run> = jobs
        .par_iter()
        .flat_map_iter(|&(c, r)| {
            let (config, initial) = &configs[c];
            let (user, settings) = &prepared[c];
            let seed = |r| config.run_seed(spec.seed, r);
            let done: Vec<Run> = if r + INTERLEAVE <= spec.runs {
                let seeds: [u64; INTERLEAVE] = std::array::from_fn(|i| seed(r + i));
                train_runs(user, settings, initial, &spec.run, seeds).into()
            } else {
                (r..spec.runs)
                    .map(|r| train_run(user, settings, initial.clone(), &spec.run, seed(r)))
                    .collect()
            };
            for _ in &done {
                progress();
            }
            done
        })
        .collect();
    let mut out = Vec::with_capacity(configs.len());
    for _ in 0..configs.len() {
        let rest = runs.split_off(spec.runs.min(runs.len()));
        out.push(std::mem::replace(&mut runs, rest));
    }
    out
}

/// Runs of each (cluster, reward) configuration from an empty Q-table with softmax, then the
/// transfers; `progress` is called after every finished run.
pub fn run_grid(
    models: &[UserModelTable],
    spec: &GridSpec,
    progress: &(dyn Fn() + Sync),
) -> GridResult {
    let name = |k: usize| format!("M{}", k + 1);
    let configs: Vec<(Config, QTable)> = spec
        .clusters
        .iter()
        .flat_map(|&k| spec.rewards.iter().map(move |&r| (k, r)))
        .map(|(k, reward)| {
            let config = Config {
                name: format!("{} {}", name(k), reward.name()),
                cluster: k,
                reward,
                mode: Mode::Explore,
                transfer_from: None,
            };
            (config, QTable::default())
        })
        .collect();
    let runs = run_configs(models, spec, &configs, progress);
    let mut iterations = (configs.len() * spec.runs * spec.run.sessions()) as u64;
    let mut transfers = Vec::new();
    if spec.transfer {
        for &source in &spec.clusters {
            let Some(c) = configs
                .iter()
                .position(|(c, _)| c.cluster == source && c.reward == Reward::RePlusBetaE)
            else {
                continue;
            };
            let Some(best) = best_run(&runs[c]) else {
                continue;
            };
            for &target in spec.clusters.iter().filter(|&&t| t != source) {
                let config = Config {
                    name: format!("{}->{} RE+bE exploit", name(source), name(target)),
                    cluster: target,
                    reward: Reward::RePlusBetaE,
                    mode: Mode::Exploit,
                    transfer_from: Some(source),
                };
                transfers.push((config, runs[c][best].q_table.clone()));
            }
        }
    }
    let transfer_runs = run_configs(models, spec, &transfers, progress);
    iterations += (transfers.len() * spec.runs * spec.run.sessions()) as u64;
    let curves = configs
        .into_iter()
        .zip(&runs)
        .chain(transfers.into_iter().zip(&transfer_runs))
        .map(|((config, _), runs)| summarise(config, runs))
        .collect();
    GridResult {
        curves,
        iterations: iterations * SEQUENCES_PER_SESSION as u64,
    }
}

#[cfg(test)]
mod tests;
