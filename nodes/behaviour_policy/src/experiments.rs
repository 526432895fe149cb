//! The paper's evaluation: for each user model and reward, independent seeded runs of E epochs
//! (100 sessions each), recording per epoch the mean score, engagement, ratio, return and V of
//! its sessions; then policy transfer both ways (the best source run by mean return in its last
//! epoch initialises the target's Q-table, trained exploitation-only with RE + βE). Runs are
//! parallel; each run's seed comes from the master seed and its index, never from thread
//! order, so results do not depend on the thread count.

use crate::learning::{Learning, Mode, QTable, Reward, SessionMetrics, simulate_session};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use sequence_game::UserModelTable;

/// Per-epoch means of one run.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EpochMetrics {
    pub score: f64,
    pub engagement: f64,
    pub ratio: f64,
    pub discounted_return: f64,
    pub start_value: f64,
}

/// One run's curve and final Q-table.
#[derive(Debug, Clone, PartialEq)]
pub struct Run {
    pub epochs: Vec<EpochMetrics>,
    pub q_table: QTable,
}

/// A configuration of the grid.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    pub name: String,
    /// Index of the user model (cluster) trained against.
    pub model: usize,
    pub reward: Reward,
    pub mode: Mode,
    /// Cluster whose best run initialises the Q-table (transfer).
    pub transfer_from: Option<usize>,
}

/// SplitMix64: independent-looking seeds from (master, config, run).
pub fn run_seed(master: u64, config: usize, run: usize) -> u64 {
    let mut z = master
        ^ (config as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (run as u64).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Trains one run of `epochs` x `sessions_per_epoch` sessions from `initial`.
pub fn train_run(
    model: &UserModelTable,
    learning: &Learning,
    mode: Mode,
    initial: QTable,
    epochs: usize,
    sessions_per_epoch: usize,
    seed: u64,
) -> Run {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut q_table = initial;
    let mut curve = Vec::with_capacity(epochs);
    for _ in 0..epochs {
        let mut sum = SessionMetrics::default();
        let mut ratio = 0.0;
        for s in 0..sessions_per_epoch {
            let m = simulate_session(&mut q_table, model, learning, mode, s == 0, &mut rng);
            sum.score += m.score;
            sum.engagement += m.engagement;
            sum.discounted_return += m.discounted_return;
            sum.start_value += m.start_value;
            ratio += m.score / m.max_score;
        }
        let n = sessions_per_epoch as f64;
        curve.push(EpochMetrics {
            score: sum.score / n,
            engagement: sum.engagement / n,
            ratio: ratio / n,
            discounted_return: sum.discounted_return / n,
            start_value: sum.start_value / n,
        });
    }
    Run {
        epochs: curve,
        q_table,
    }
}

/// Mean and standard deviation across runs, per epoch.
#[derive(Debug, Clone, PartialEq)]
pub struct Curve {
    pub config: Config,
    pub mean: Vec<EpochMetrics>,
    pub std: Vec<EpochMetrics>,
}

fn summarise(config: Config, runs: &[Run]) -> Curve {
    let epochs = runs.first().map_or(0, |r| r.epochs.len());
    let n = runs.len().max(1) as f64;
    let pick = |m: &EpochMetrics, k: usize| {
        [
            m.score,
            m.engagement,
            m.ratio,
            m.discounted_return,
            m.start_value,
        ][k]
    };
    let make = |v: [f64; 5]| EpochMetrics {
        score: v[0],
        engagement: v[1],
        ratio: v[2],
        discounted_return: v[3],
        start_value: v[4],
    };
    let mut mean = Vec::with_capacity(epochs);
    let mut std = Vec::with_capacity(epochs);
    for e in 0..epochs {
        let mut mu = [0.0; 5];
        let mut sd = [0.0; 5];
        for k in 0..5 {
            mu[k] = runs.iter().map(|r| pick(&r.epochs[e], k)).sum::<f64>() / n;
            sd[k] = (runs
                .iter()
                .map(|r| (pick(&r.epochs[e], k) - mu[k]).powi(2))
                .sum::<f64>()
                / n)
                .sqrt();
        }
        mean.push(make(mu));
        std.push(make(sd));
    }
    Curve { config, mean, std }
}

/// The grid's size.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridSpec {
    pub runs: usize,
    pub epochs: usize,
    pub sessions_per_epoch: usize,
    pub seed: u64,
    pub transfer: bool,
}

/// Runs every (model, reward) configuration, then the transfers; `progress` is called after
/// each finished run.
pub fn run_grid(
    models: &[UserModelTable],
    learning: &Learning,
    spec: &GridSpec,
    progress: &(dyn Fn() + Sync),
) -> Vec<Curve> {
    let mut configs = Vec::new();
    for (m, _) in models.iter().enumerate() {
        for reward in Reward::ALL {
            configs.push(Config {
                name: format!("M{} {}", m + 1, reward.name()),
                model: m,
                reward,
                mode: Mode::Explore,
                transfer_from: None,
            });
        }
    }
    let jobs: Vec<(usize, usize)> = (0..configs.len())
        .flat_map(|c| (0..spec.runs).map(move |r| (c, r)))
        .collect();
    let runs: Vec<Run> = jobs
        .par_iter()
        .map(|&(c, r)| {
            let cfg = &configs[c];
            let l = Learning {
                reward: cfg.reward,
                ..*learning
            };
            let run = train_run(
                &models[cfg.model],
                &l,
                cfg.mode,
                QTable::default(),
                spec.epochs,
                spec.sessions_per_epoch,
                run_seed(spec.seed, c, r),
            );
            progress();
            run
        })
        .collect();
    let mut curves: Vec<Curve> = configs
        .iter()
        .enumerate()
        .map(|(c, cfg)| summarise(cfg.clone(), &runs[c * spec.runs..(c + 1) * spec.runs]))
        .collect();
    if spec.transfer && models.len() >= 2 {
        // Transfer with RE + βE, exploitation only, both directions between the first two models.
        let mut transfer_configs = Vec::new();
        for (source, target) in [(0usize, 1usize), (1, 0)] {
            let c = configs
                .iter()
                .position(|x| x.model == source && x.reward == Reward::RePlusBetaE)
                .unwrap_or(0);
            let source_runs = &runs[c * spec.runs..(c + 1) * spec.runs];
            let best = source_runs
                .iter()
                .max_by(|a, b| {
                    let la = a
                        .epochs
                        .last()
                        .map_or(f64::NEG_INFINITY, |e| e.discounted_return);
                    let lb = b
                        .epochs
                        .last()
                        .map_or(f64::NEG_INFINITY, |e| e.discounted_return);
                    la.total_cmp(&lb)
                })
                .map(|r| r.q_table.clone())
                .unwrap_or_default();
            transfer_configs.push((
                Config {
                    name: format!("M{}->M{} RE+bE exploit", source + 1, target + 1),
                    model: target,
                    reward: Reward::RePlusBetaE,
                    mode: Mode::Exploit,
                    transfer_from: Some(source),
                },
                best,
            ));
        }
        let base = configs.len();
        let jobs: Vec<(usize, usize)> = (0..transfer_configs.len())
            .flat_map(|c| (0..spec.runs).map(move |r| (c, r)))
            .collect();
        let runs: Vec<Run> = jobs
            .par_iter()
            .map(|&(c, r)| {
                let (cfg, initial) = &transfer_configs[c];
                let l = Learning {
                    reward: cfg.reward,
                    ..*learning
                };
                let run = train_run(
                    &models[cfg.model],
                    &l,
                    cfg.mode,
                    initial.clone(),
                    spec.epochs,
                    spec.sessions_per_epoch,
                    run_seed(spec.seed, base + c, r),
                );
                progress();
                run
            })
            .collect();
        for (c, (cfg, _)) in transfer_configs.into_iter().enumerate() {
            curves.push(summarise(cfg, &runs[c * spec.runs..(c + 1) * spec.runs]));
        }
    }
    curves
}

/// The curves as CSV: one row per configuration and epoch.
pub fn curves_csv(curves: &[Curve]) -> String {
    let mut out = String::from(
        "config,model,reward,mode,transfer_from,epoch,score_mean,score_std,engagement_mean,engagement_std,ratio_mean,ratio_std,return_mean,return_std,v_mean,v_std\n",
    );
    for c in curves {
        for (e, (m, s)) in c.mean.iter().zip(&c.std).enumerate() {
            out.push_str(&format!(
                "{},M{},{},{:?},{},{},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6}\n",
                c.config.name,
                c.config.model + 1,
                c.config.reward.name(),
                c.config.mode,
                c.config.transfer_from.map(|t| format!("M{}", t + 1)).unwrap_or_default(),
                e + 1,
                m.score,
                s.score,
                m.engagement,
                s.engagement,
                m.ratio,
                s.ratio,
                m.discounted_return,
                s.discounted_return,
                m.start_value,
                s.start_value
            ));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use sequence_game::Prediction;

    fn models() -> Vec<UserModelTable> {
        vec![
            UserModelTable::tabulate(
                0,
                |i| Prediction {
                    mean: [0.95, 0.85, 0.5][i.level.index()],
                    std: 0.0,
                },
                |_, _| Prediction {
                    mean: 0.5,
                    std: 0.0,
                },
            ),
            UserModelTable::tabulate(
                1,
                |i| Prediction {
                    mean: [0.97, 0.93, 0.45][i.level.index()],
                    std: 0.0,
                },
                |_, o| Prediction {
                    mean: if o == sequence_game::Outcome::Success {
                        -0.4
                    } else {
                        -0.7
                    },
                    std: 0.0,
                },
            ),
        ]
    }

    #[test]
    fn same_seed_same_curves_whatever_the_thread_count() {
        let spec = GridSpec {
            runs: 3,
            epochs: 4,
            sessions_per_epoch: 20,
            seed: 11,
            transfer: true,
        };
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("pool")
            .install(|| run_grid(&models(), &Learning::default(), &spec, &|| {}));
        let two = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .expect("pool")
            .install(|| run_grid(&models(), &Learning::default(), &spec, &|| {}));
        assert_eq!(one, two);
        assert_eq!(one.len(), 8);
        let other = run_grid(
            &models(),
            &Learning::default(),
            &GridSpec { seed: 12, ..spec },
            &|| {},
        );
        assert_ne!(one, other);
    }
}
