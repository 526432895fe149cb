//! The tight loop checked against a plain transcription of Algorithm 1 written with the game's
//! types (State, Action, ModelInput, UserModelTable), and against cases with known answers.

use super::*;
use crate::learning::{Reward, TemperatureSchedule};
use crate::reference_tables::per_level_reference_tables;
use rand::SeedableRng;
use sequence_game::{Action, Level, Prediction, State};

/// Algorithm 1 as the paper writes it, one sequence at a time, with no precomputation.
fn plain_session(
    table: &mut QTable,
    model: &UserModelTable,
    s: &SessionSettings,
    count_visits: bool,
    rng: &mut ChaCha8Rng,
) -> SessionMetrics {
    let mut state = State::START;
    let mut cs: i8 = 0;
    let mut m = SessionMetrics::default();
    for t in 0..SEQUENCES_PER_SESSION {
        let allowed = state.allowed_actions();
        let q: Vec<f64> = allowed
            .iter()
            .map(|a| table.row(state)[a.index()])
            .collect();
        let action = match s.mode {
            Mode::Explore => {
                let temp = s.learning.temperature.at(table.visits[state.index()]);
                let max = q.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
                let e: Vec<f64> = q.iter().map(|x| ((x - max) / temp).exp()).collect();
                let target = rng.random::<f64>() * e.iter().sum::<f64>();
                let mut acc = 0.0;
                let mut pick = allowed.len() - 1;
                for (i, w) in e.iter().enumerate() {
                    acc += w;
                    if target < acc {
                        pick = i;
                        break;
                    }
                }
                allowed[pick]
            }
            Mode::Exploit => {
                let max = q.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
                let ties: Vec<Action> = allowed
                    .iter()
                    .zip(&q)
                    .filter(|(_, x)| **x == max)
                    .map(|(a, _)| *a)
                    .collect();
                let k = if ties.len() > 1 {
                    rng.random_range(0..ties.len() as u32) as usize
                } else {
                    0
                };
                ties[k]
            }
            Mode::EpsilonGreedy(epsilon) => {
                // One uniform: below ε it picks among all allowed actions, above among the
                // greedy ties, each share split evenly.
                let u = rng.random::<f64>();
                let max = q.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
                let ties: Vec<Action> = allowed
                    .iter()
                    .zip(&q)
                    .filter(|(_, x)| **x == max)
                    .map(|(a, _)| *a)
                    .collect();
                if u < epsilon {
                    allowed[(u / epsilon * allowed.len() as f64) as usize]
                } else {
                    ties[((u - epsilon) / (1.0 - epsilon) * ties.len() as f64) as usize]
                }
            }
        };
        if count_visits {
            table.visits[state.index()] += 1;
        }
        let (level, feedback) = action.apply(state).expect("allowed action");
        let input = ModelInput::new(level, feedback, cs).expect("valid input");
        let p = model.success(input).mean;
        let outcome = Outcome::from_correct(p >= rng.random::<f64>());
        let re = outcome.activity_result(level);
        let e = model.engagement(input, outcome).mean;
        let r = s.learning.reward(re, e);
        let new_cs = outcome.score(level);
        let ps = if s.state_lags_result { cs } else { new_cs };
        let next = State::new(level.get().into(), feedback as i64, ps.into()).expect("state");
        let bootstrap = if t + 1 == SEQUENCES_PER_SESSION {
            0.0
        } else {
            table
                .row(next)
                .iter()
                .cloned()
                .fold(f64::NEG_INFINITY, f64::max)
        };
        let old = table.row(state)[action.index()];
        table.q[state.index()][action.index()] =
            old + s.learning.alpha * (r + s.learning.gamma * bootstrap - old);
        m.score += f64::from(new_cs);
        m.max_score += f64::from(level.get());
        m.engagement += e / SEQUENCES_PER_SESSION as f64;
        m.discounted_return += s.learning.gamma.powi(t as i32) * r;
        cs = new_cs;
        state = next;
    }
    m
}

fn settings(reward: Reward, mode: Mode, lag: bool) -> SessionSettings {
    SessionSettings {
        learning: Learning {
            reward,
            // Cool fast so both softmax regimes (hot and greedy-ish) are exercised.
            temperature: TemperatureSchedule {
                initial: 5.0,
                minimum: 0.05,
                decay_per_visit: 0.05,
            },
            ..Learning::default()
        },
        mode,
        state_lags_result: lag,
    }
}

#[test]
fn tight_loop_equals_the_plain_algorithm_step_for_step() {
    let models = per_level_reference_tables();
    for (k, model) in models.iter().enumerate() {
        for reward in Reward::ALL {
            for mode in [Mode::Explore, Mode::Exploit, Mode::EpsilonGreedy(0.2)] {
                for lag in [true, false] {
                    let s = settings(reward, mode, lag);
                    let user = SimulatedUser::new(model, &s.learning);
                    let mut plain = QTable::default();
                    let mut r2 = ChaCha8Rng::seed_from_u64(k as u64 * 7 + 1);
                    let mut fast = SimulatedRun::new(QTable::default(), r2.clone());
                    for session in 0..300 {
                        let count = session % 10 == 0;
                        let a = run_session(&mut fast, &user, &s, count);
                        let b = plain_session(&mut plain, model, &s, count, &mut r2);
                        assert_eq!(a.score, b.score, "{reward} {mode:?} lag {lag} #{session}");
                        assert_eq!(a.max_score, b.max_score);
                        assert!((a.engagement - b.engagement).abs() < 1e-12);
                        assert!((a.discounted_return - b.discounted_return).abs() < 1e-9);
                    }
                    let fast = fast.table();
                    for (x, y) in fast.q.iter().flatten().zip(plain.q.iter().flatten()) {
                        assert!((x - y).abs() < 1e-12, "{reward} {mode:?} lag {lag}");
                    }
                    assert_eq!(fast.visits, plain.visits);
                }
            }
        }
    }
}

#[test]
fn learns_level_three_for_a_user_who_always_succeeds() {
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
    let s = SessionSettings {
        learning: Learning::default(),
        mode: Mode::Explore,
        state_lags_result: true,
    };
    let user = SimulatedUser::new(&model, &s.learning);
    let mut run = SimulatedRun::seeded(QTable::default(), 3);
    for session in 0..20_000 {
        run_session(&mut run, &user, &s, session % 100 == 0);
    }
    let greedy = SessionSettings {
        mode: Mode::Exploit,
        ..s
    };
    let m = run_session(&mut run, &user, &greedy, false);
    assert_eq!((m.score, m.max_score, m.explored), (30.0, 30.0, 0));
    let best = run.table().row(State::START);
    assert!(best[Level::THREE.index()] > best[Level::ONE.index()]);
}

#[test]
fn a_user_who_always_fails_scores_minus_the_levels_played() {
    let model = UserModelTable::tabulate(
        0,
        |_| Prediction {
            mean: 0.0,
            std: 0.0,
        },
        |_, o| Prediction {
            mean: if o == Outcome::Failure { -0.5 } else { 0.5 },
            std: 0.0,
        },
    );
    let s = settings(Reward::RePlusBetaE, Mode::Explore, true);
    let user = SimulatedUser::new(&model, &s.learning);
    let mut run = SimulatedRun::seeded(QTable::default(), 5);
    for _ in 0..50 {
        let m = run_session(&mut run, &user, &s, true);
        assert_eq!(m.score, -m.max_score);
        assert_eq!(m.engagement, -0.5);
        // Every step pays RE + βE = -1 - 1.5.
        let expected: f64 = (0..10).map(|t| -2.5 * 0.95f64.powi(t)).sum();
        assert!((m.discounted_return - expected).abs() < 1e-9);
    }
}

#[test]
fn interleaved_sessions_equal_separate_sessions() {
    let models = per_level_reference_tables();
    for mode in [Mode::Explore, Mode::Exploit] {
        let s = settings(Reward::RePlusBetaE, mode, true);
        let user = SimulatedUser::new(&models[1], &s.learning);
        let mut apart: Vec<SimulatedRun> = (0..3)
            .map(|i| SimulatedRun::seeded(QTable::default(), i))
            .collect();
        let mut together: [SimulatedRun; 3] =
            std::array::from_fn(|i| SimulatedRun::seeded(QTable::default(), i as u64));
        for session in 0..200 {
            let count = session % 7 == 0;
            let one: Vec<SessionMetrics> = apart
                .iter_mut()
                .map(|r| run_session(r, &user, &s, count))
                .collect();
            let all = run_sessions(&mut together, &user, &s, count);
            assert_eq!(one, all);
        }
        for (a, b) in apart.iter().zip(&together) {
            assert_eq!(a.table(), b.table());
        }
    }
}

#[test]
fn policies_given_the_same_draws_meet_the_same_child() {
    // A child whose P(success) is 0.5 and whose engagement is ±0.5 by outcome, whatever the
    // sequence: with the same draws every policy sees the same right/wrong pattern (so the
    // same engagement), since the answer to sequence k is decided by answer[k] alone.
    let model = UserModelTable::tabulate(
        0,
        |_| Prediction {
            mean: 0.5,
            std: 0.0,
        },
        |_, o| Prediction {
            mean: if o == Outcome::Failure { -0.5 } else { 0.5 },
            std: 0.0,
        },
    );
    let greedy = settings(Reward::RePlusBetaE, Mode::Exploit, false);
    let softmax = settings(Reward::RePlusBetaE, Mode::Explore, false);
    let user = SimulatedUser::new(&model, &greedy.learning);
    let trained = {
        let mut run = SimulatedRun::seeded(QTable::default(), 1);
        for _ in 0..300 {
            run_session(&mut run, &user, &softmax, true);
        }
        run.into_table()
    };
    let mut differ = false;
    for key in 0..20 {
        let draws = SessionDraws::new(key);
        let rights = draws.answer.iter().filter(|u| **u <= 0.5).count() as f64;
        let engagement = 0.5 * (2.0 * rights - 10.0) / 10.0;
        let mut played = Vec::new();
        for (table, s) in [
            (QTable::default(), &softmax),
            (QTable::default(), &greedy),
            (trained.clone(), &greedy),
            (trained.clone(), &softmax),
        ] {
            // The run's own stream is never used: two different seeds give the same session.
            let a = run_session_with(
                &mut SimulatedRun::seeded(table.clone(), 1),
                &user,
                s,
                true,
                &draws,
            );
            let b = run_session_with(&mut SimulatedRun::seeded(table, 99), &user, s, true, &draws);
            assert_eq!(a, b);
            assert!((a.engagement - engagement).abs() < 1e-12, "{a:?}");
            played.push(a);
        }
        differ |= played.iter().any(|m| m.max_score != played[0].max_score);
    }
    // ...while what the policies played differs.
    assert!(differ);
    // Ties among greedy actions split [0, 1) evenly.
    assert_eq!(
        [0.0, 0.33, 0.34, 0.99, 1.0].map(|u| SessionDraws::tie_of(u, 3)),
        [0, 0, 1, 2, 2]
    );
}
