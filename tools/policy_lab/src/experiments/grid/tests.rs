//! The grid: same seed, same curves whatever the thread count; seeds tied to configurations;
//! transfer starting from the source's best run.

use super::*;
use q_learning::reference_tables::per_level_reference_tables;
use q_learning::training::EpochScheme;

fn spec(runs: usize, epochs: usize) -> GridSpec {
    GridSpec {
        runs,
        seed: 11,
        run: RunSpec {
            epochs,
            sessions_per_epoch: 20,
            scheme: EpochScheme::Blocks,
            state_lags_result: true,
        },
        learning: Learning::default(),
        clusters: vec![0, 1],
        rewards: Reward::ALL.to_vec(),
        transfer: true,
    }
}

fn in_pool(threads: usize, spec: &GridSpec) -> GridResult {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("pool")
        .install(|| run_grid(&per_level_reference_tables(), spec, &|| {}))
}

#[test]
fn same_seed_same_curves_with_one_or_two_threads() {
    let s = spec(4, 5);
    let one = in_pool(1, &s);
    let two = in_pool(2, &s);
    assert_eq!(one, two);
    let names: Vec<&str> = one.curves.iter().map(|c| c.config.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "M1 RE",
            "M1 RE+bE",
            "M1 lE",
            "M2 RE",
            "M2 RE+bE",
            "M2 lE",
            "M1->M2 RE+bE exploit",
            "M2->M1 RE+bE exploit"
        ]
    );
    assert_eq!(one.iterations, 8 * 4 * 5 * 20 * 10);
    let other = in_pool(2, &GridSpec { seed: 12, ..s });
    assert_ne!(one.curves, other.curves);
}

#[test]
fn a_configuration_gets_the_same_seeds_in_a_smaller_grid() {
    let full = in_pool(2, &spec(3, 4));
    let only = in_pool(
        2,
        &GridSpec {
            clusters: vec![1],
            rewards: vec![Reward::LambdaE],
            transfer: false,
            ..spec(3, 4)
        },
    );
    assert_eq!(only.curves.len(), 1);
    let same = full
        .curves
        .iter()
        .find(|c| c.config.name == "M2 lE")
        .expect("in the full grid");
    assert_eq!(&only.curves[0], same);
}

#[test]
fn transfer_starts_from_the_best_source_run_and_does_not_explore() {
    let s = spec(5, 6);
    let models = per_level_reference_tables();
    let grid = in_pool(2, &s);
    let source = grid
        .curves
        .iter()
        .find(|c| c.config.name == "M1 RE+bE")
        .expect("source");
    // Retrain the source's runs one by one: the curve's best run is the argmax of final return.
    let learning = Learning {
        reward: Reward::RePlusBetaE,
        ..s.learning
    };
    let settings = SessionSettings {
        learning,
        mode: Mode::Explore,
        state_lags_result: true,
    };
    let user = SimulatedUser::new(&models[0], &learning);
    let runs: Vec<Run> = (0..s.runs)
        .map(|r| {
            train_run(
                &user,
                &settings,
                QTable::default(),
                &s.run,
                source.config.run_seed(s.seed, r),
            )
        })
        .collect();
    let best = best_run(&runs).expect("runs");
    assert_eq!(source.best_run, best);
    assert!(
        runs.iter()
            .all(|r| r.final_return <= runs[best].final_return)
    );
    let transfer = grid
        .curves
        .iter()
        .find(|c| c.config.name == "M1->M2 RE+bE exploit")
        .expect("transfer");
    assert_eq!(transfer.config.transfer_from, Some(0));
    assert_eq!(transfer.config.cluster, 1);
    assert!(transfer.mean.iter().all(|e| e.explored == 0.0));
    // Its first epoch already plays the transferred greedy policy: ratio well above random.
    assert!(transfer.mean[0].ratio > 0.0);
}

#[test]
fn std_is_the_population_std_across_runs() {
    let runs: Vec<Run> = [1.0, 3.0]
        .iter()
        .map(|&x| Run {
            epochs: vec![EpochMetrics {
                score: x,
                ..Default::default()
            }],
            q_table: QTable::default(),
            final_return: x,
        })
        .collect();
    let c = summarise(
        Config {
            name: "x".into(),
            cluster: 0,
            reward: Reward::Re,
            mode: Mode::Explore,
            transfer_from: None,
        },
        &runs,
    );
    assert_eq!((c.mean[0].score, c.std[0].score), (2.0, 1.0));
    assert_eq!((c.best_run, c.best_return), (1, 3.0));
}

#[test]
fn interleaved_runs_equal_single_runs() {
    let models = per_level_reference_tables();
    let s = spec(2, 3);
    let learning = Learning {
        reward: Reward::Re,
        ..s.learning
    };
    let settings = SessionSettings {
        learning,
        mode: Mode::Explore,
        state_lags_result: true,
    };
    let user = SimulatedUser::new(&models[0], &learning);
    let together = train_runs(&user, &settings, &QTable::default(), &s.run, [5, 6, 7]);
    let apart = [5, 6, 7].map(|seed| train_run(&user, &settings, QTable::default(), &s.run, seed));
    assert_eq!(together, apart);
}
