//! The decision problem of a session: the optimal policy against known answers and against
//! every other policy, its exact value against sampling, and sessions played here equal to
//! the simulator's own on the same draws; a Q-table's policy with the live policy's
//! probabilities.

use super::*;
use crate::QTableFile;
use crate::learning::{Mode, QTable, Reward};
use crate::reference_tables::per_level_reference_tables;
use crate::simulation::{
    SessionDraws, SessionSettings, SimulatedRun, SimulatedUser, run_session_with,
};
use sequence_game::Prediction;

fn table(cluster: usize) -> QTable {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(format!("../../bags/q_tables/cluster_{cluster}.json"));
    QTableFile::load(&path).expect("sample Q-table").table
}

fn learning() -> Learning {
    Learning {
        reward: Reward::RePlusBetaE,
        ..Learning::default()
    }
}

fn policies() -> Vec<TargetPolicy> {
    let mut v = Vec::new();
    for c in [0, 1] {
        for t in [
            TargetTemperature::Greedy,
            TargetTemperature::Fixed(0.5),
            TargetTemperature::Fixed(2.0),
        ] {
            v.push(TargetPolicy::new(table(c), t).expect("policy"));
        }
    }
    v.push(TargetPolicy::new(QTable::default(), TargetTemperature::Greedy).expect("uniform"));
    v
}

#[test]
fn a_child_who_always_succeeds_is_best_served_by_level_three() {
    let model = UserModelTable::tabulate(
        0,
        |_| Prediction {
            mean: 1.0,
            std: 0.0,
        },
        |_, _| Prediction {
            mean: 0.0,
            std: 0.0,
        },
    );
    let l = Learning {
        reward: Reward::Re,
        ..Learning::default()
    };
    let best = optimal_policy(&model, &l, Objective::Return);
    let expected: f64 = (0..10).map(|t| 3.0 * l.gamma.powi(t)).sum();
    assert!((best.value.discounted_return - expected).abs() < 1e-12);
    assert_eq!(best.value.score, 30.0);
    assert_eq!(
        optimal_policy(&model, &l, Objective::Score).value.score,
        30.0
    );
    assert_eq!(
        best.probabilities(State::START, 1),
        [0.0, 0.0, 1.0, 0.0, 0.0]
    );
}

#[test]
fn no_policy_expects_more_than_the_optimal_one() {
    let l = learning();
    for model in &per_level_reference_tables() {
        let best_return = optimal_policy(model, &l, Objective::Return);
        let best_score = optimal_policy(model, &l, Objective::Score);
        // Its value is its own exact value.
        assert_eq!(exact_value(model, &best_return, &l), best_return.value);
        assert_eq!(exact_value(model, &best_score, &l), best_score.value);
        for p in policies() {
            let v = exact_value(model, &p, &l);
            assert!(
                v.discounted_return <= best_return.value.discounted_return + 1e-9,
                "{v:?} vs {:?}",
                best_return.value
            );
            assert!(v.score <= best_score.value.score + 1e-9);
        }
        // Each objective's optimum is at most as good as the other's on the other's terms.
        assert!(best_score.value.discounted_return <= best_return.value.discounted_return + 1e-9);
        assert!(best_return.value.score <= best_score.value.score + 1e-9);
    }
}

#[test]
fn the_optimal_value_is_what_sampling_converges_to() {
    let l = learning();
    let model = &per_level_reference_tables()[1];
    let best = optimal_policy(model, &l, Objective::Return);
    let (log, _) = simulate_sessions(model, &best, 20_000, 3);
    let returns: Vec<f64> = log
        .iter()
        .map(|s| session_metrics(s, &l).discounted_return)
        .collect();
    let n = returns.len() as f64;
    let mean = returns.iter().sum::<f64>() / n;
    let sd = (returns.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    assert!(
        (mean - best.value.discounted_return).abs() < 4.0 * sd / n.sqrt(),
        "sampled {mean} ± {}, exact {:?}",
        sd / n.sqrt(),
        best.value
    );
}

#[test]
fn a_session_played_here_is_the_simulators_on_the_same_draws() {
    // The simulator (learning switched off) and play_session given the same uniforms play
    // the same session: greedy with ties split alike, and softmax at each state's T_s.
    let l = Learning {
        alpha: 0.0,
        ..learning()
    };
    let model = &per_level_reference_tables()[0];
    let user = SimulatedUser::new(model, &l);
    for (q, mode, temperature) in [
        (table(0), Mode::Exploit, TargetTemperature::Greedy),
        (QTable::default(), Mode::Exploit, TargetTemperature::Greedy),
        (
            table(1),
            Mode::Explore,
            TargetTemperature::PerState(l.temperature),
        ),
    ] {
        let settings = SessionSettings {
            learning: l,
            mode,
            state_lags_result: false,
        };
        let policy = TargetPolicy::new(q.clone(), temperature).expect("policy");
        let mut run = SimulatedRun::seeded(q, 0);
        for key in 0..200 {
            let d = SessionDraws::new(key);
            let simulated = run_session_with(&mut run, &user, &settings, false, &d);
            let (session, _) = play_session(model, &policy, String::new(), |k| {
                (d.action[k], d.answer[k])
            });
            let here = session_metrics(&session, &l);
            assert_eq!(
                (here.score, here.max_score, here.engagement),
                (simulated.score, simulated.max_score, simulated.engagement),
                "{mode:?} session {key}"
            );
            assert!((here.discounted_return - simulated.discounted_return).abs() < 1e-12);
        }
    }
}

#[test]
fn the_policy_probabilities_are_the_live_policys() {
    use crate::PolicyCore;
    let t = table(0);
    let mut core = PolicyCore::new(t.clone(), learning(), Mode::Explore, 1, 0);
    let policy =
        TargetPolicy::new(t, TargetTemperature::PerState(learning().temperature)).expect("policy");
    for state in State::all() {
        for s in [1, 2, 10] {
            let d = core.decide(state, s).expect("decides");
            assert_eq!(d.probabilities, policy.probabilities(state, s));
        }
    }
    // And the live policy's logged exploration, greedy ties included.
    let mut t = table(0);
    t.q[5] = [0.5, 0.5, 0.1, 0.5, -1.0];
    let mut core = PolicyCore::new(t.clone(), learning(), Mode::EpsilonGreedy(0.1), 1, 0);
    let policy = TargetPolicy::new(t, TargetTemperature::EpsilonGreedy(0.1)).expect("policy");
    for state in State::all() {
        for s in [1, 2, 10] {
            let d = core.decide(state, s).expect("decides");
            assert_eq!(d.probabilities, policy.probabilities(state, s));
        }
    }
    assert_eq!(
        TargetPolicy::new(QTable::default(), TargetTemperature::EpsilonGreedy(1.5)),
        Err(TargetPolicyError::Epsilon(1.5))
    );
    assert_eq!(
        TargetPolicy::new(QTable::default(), TargetTemperature::Fixed(0.0)),
        Err(TargetPolicyError::Temperature(0.0))
    );
}
