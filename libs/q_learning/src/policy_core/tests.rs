//! The live policy: explained decisions, feedback refused at the first sequence, the update
//! formula, and bad input refused without touching the table.

use super::*;
use crate::learning::Reward;

fn state(l: i64, f: i64, ps: i64) -> State {
    State::new(l, f, ps).expect("valid state")
}

fn core(mode: Mode) -> PolicyCore {
    PolicyCore::new(QTable::default(), Learning::default(), mode, 9, 0)
}

#[test]
fn first_sequence_never_gets_feedback_even_from_a_non_start_state() {
    let mut c = core(Mode::Explore);
    let s = state(2, 0, 2);
    // Make feedback overwhelmingly attractive in s.
    c.table.q[s.index()] = [0.0, 0.0, 0.0, 1e9, 1e9];
    for _ in 0..200 {
        let d = c.decide(s, 1).expect("decides");
        assert!(!d.action.is_feedback());
        assert_eq!(d.allowed_actions, 3);
        assert_eq!((d.probabilities[3], d.probabilities[4]), (0.0, 0.0));
        let d = c.decide(State::START, 1).expect("decides");
        assert!(!d.action.is_feedback());
    }
    let d = c.decide(s, 2).expect("decides");
    assert!(d.action.is_feedback());
    assert_eq!(d.allowed_actions, 5);
    assert_eq!(c.decide(s, 0), Err(PolicyError::Step(0)));
}

#[test]
fn a_decision_explains_itself() {
    let mut c = core(Mode::Explore);
    let s = state(1, 1, -1);
    c.table.q[s.index()] = [1.0, 2.0, 0.5, -1.0, 3.0];
    c.table.visits[s.index()] = 59; // T = 300 - 5 * 59 = 5
    let d = c.decide(s, 4).expect("decides");
    assert_eq!(d.temperature, 5.0);
    assert_eq!(d.q_values, [1.0, 2.0, 0.5, -1.0, 3.0]);
    let z: f64 = d.q_values.iter().map(|q| (q / 5.0).exp()).sum();
    for a in 0..5 {
        assert!((d.probabilities[a] - (d.q_values[a] / 5.0).exp() / z).abs() < 1e-12);
    }
    assert_eq!(d.explored, d.action != Action::Challenge);
    assert_eq!(d.action.apply(s), Some((d.level, d.feedback)));
    // Over many draws both explored and greedy choices appear, in about the right share.
    let greedy = (0..4000)
        .filter(|_| !c.decide(s, 4).expect("decides").explored)
        .count() as f64
        / 4000.0;
    assert!((greedy - d.probabilities[4]).abs() < 0.03, "{greedy}");
}

#[test]
fn exploitation_is_greedy_with_random_ties_and_never_explores() {
    let mut c = core(Mode::Exploit);
    let s = state(3, 0, 3);
    c.table.q[s.index()] = [0.2, 0.7, 0.7, 0.1, 0.7];
    let mut seen = [0usize; 5];
    for _ in 0..3000 {
        let d = c.decide(s, 5).expect("decides");
        assert!(!d.explored);
        assert_eq!(d.probabilities, [0.0, 1.0 / 3.0, 1.0 / 3.0, 0.0, 1.0 / 3.0]);
        seen[d.action.index()] += 1;
    }
    assert_eq!((seen[0], seen[3]), (0, 0));
    for a in [1, 2, 4] {
        assert!((900..1100).contains(&seen[a]), "{seen:?}");
    }
}

#[test]
fn epsilon_greedy_logs_the_probabilities_it_draws_with() {
    let mut c = core(Mode::EpsilonGreedy(0.2));
    let s = state(2, 1, -2);
    // Two greedy ties: the tie-break is part of the logged probabilities.
    c.table.q[s.index()] = [0.2, 0.7, 0.7, 0.1, 0.3];
    let expected = [0.04, 0.44, 0.44, 0.04, 0.04];
    let draws = 40_000;
    let mut seen = [0usize; 5];
    for _ in 0..draws {
        let d = c.decide(s, 6).expect("decides");
        assert_eq!(d.mode, Mode::EpsilonGreedy(0.2));
        for (p, e) in d.probabilities.iter().zip(expected) {
            assert!((p - e).abs() < 1e-12, "{:?}", d.probabilities);
        }
        assert!((d.probabilities.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        // Explored means a non-greedy action, whichever branch of the draw picked it.
        assert_eq!(d.explored, !matches!(d.action.index(), 1 | 2), "{d:?}");
        seen[d.action.index()] += 1;
    }
    // Each action as often as its logged probability says (4 standard errors).
    for (a, e) in expected.iter().enumerate() {
        let share = seen[a] as f64 / f64::from(draws);
        let se = (e * (1.0 - e) / f64::from(draws)).sqrt();
        assert!((share - e).abs() < 4.0 * se, "a{}: {share} vs {e}", a + 1);
    }
}

#[test]
fn epsilon_greedy_explores_only_among_the_allowed_actions() {
    let mut c = core(Mode::EpsilonGreedy(crate::learning::MAX_EPSILON));
    let s = state(3, 0, 3);
    // Feedback would win if it were allowed; at the first sequence it is not.
    c.table.q[s.index()] = [0.0, 0.5, 0.0, 1e9, 1e9];
    let mut seen = [0usize; 5];
    for _ in 0..6000 {
        for (from, step) in [(s, 1), (State::START, 1), (State::START, 4)] {
            let d = c.decide(from, step).expect("decides");
            assert_eq!(d.allowed_actions, 3);
            assert_eq!((d.probabilities[3], d.probabilities[4]), (0.0, 0.0));
            assert!(!d.action.is_feedback(), "{d:?}");
            seen[d.action.index()] += 1;
        }
    }
    // Every allowed action is explored: each has probability at least ε / 3 = 0.1.
    assert!(seen[..3].iter().all(|n| *n > 1500), "{seen:?}");
    // From a later sequence all five are allowed, feedback included.
    let d = c.decide(s, 2).expect("decides");
    assert_eq!(d.allowed_actions, 5);
    assert!(d.probabilities.iter().all(|p| *p >= 0.06), "{d:?}");
}

#[test]
fn learn_applies_algorithm_1_and_skips_the_bootstrap_at_the_end() {
    let learning = Learning {
        reward: Reward::RePlusBetaE,
        ..Learning::default()
    };
    let mut c = PolicyCore::new(QTable::default(), learning, Mode::Exploit, 1, 0);
    let s = state(1, 0, 1);
    let next = state(2, 0, 2);
    c.table.q[next.index()] = [0.0, 4.0, 0.0, 0.0, -2.0];
    let t = Transition {
        state: s,
        action: Action::SetLevel(Level::TWO),
        activity_result: 2.0,
        engagement: 0.5,
        next_state: next,
        is_last: false,
    };
    let u = c.learn(&t).expect("learns");
    assert_eq!(u.reward, 3.5);
    assert!((u.new_q - 0.05 * (3.5 + 0.95 * 4.0)).abs() < 1e-12);
    assert_eq!(c.q_table().visits[s.index()], 2);
    let u = c.learn(&Transition { is_last: true, ..t }).expect("learns");
    assert!((u.new_q - (u.old_q + 0.05 * (3.5 - u.old_q))).abs() < 1e-12);
    assert_eq!(c.updates(), 2);
}

#[test]
fn bad_input_is_refused_and_changes_nothing() {
    let mut c = core(Mode::Explore);
    let s = state(2, 0, -2);
    let good = Transition {
        state: s,
        action: Action::Encourage,
        activity_result: -1.0,
        engagement: 0.1,
        next_state: state(2, 1, -2),
        is_last: false,
    };
    let before = c.q_table().clone();
    let outside = State {
        level: 7,
        feedback: Feedback::None,
        previous_score: 0,
    };
    let cases = [
        (
            Transition {
                engagement: f64::NAN,
                ..good
            },
            "engagement NaN",
        ),
        (
            Transition {
                engagement: 1.5,
                ..good
            },
            "engagement 1.5",
        ),
        (
            Transition {
                activity_result: f64::INFINITY,
                ..good
            },
            "activity result inf",
        ),
        (
            Transition {
                state: outside,
                ..good
            },
            "state (L=7",
        ),
        (
            Transition {
                next_state: state(3, 1, -2),
                ..good
            },
            "does not follow",
        ),
        (
            Transition {
                state: State::START,
                ..good
            },
            "not allowed in",
        ),
        (
            Transition {
                next_state: State::START,
                action: Action::SetLevel(Level::ONE),
                ..good
            },
            "start state",
        ),
    ];
    for (t, words) in cases {
        let e = c.learn(&t).expect_err(words);
        assert!(e.to_string().contains(words), "{e} lacks {words:?}");
    }
    assert_eq!(c.q_table(), &before);
    assert_eq!(c.updates(), 0);
    assert!(matches!(
        c.decide(outside, 2),
        Err(PolicyError::StateOutsideSpace { level: 7, .. })
    ));
    c.learn(&good).expect("the good one learns");
}

#[test]
fn q_values_stay_finite_even_with_absurd_constants() {
    let learning = Learning {
        alpha: 1e300,
        ..Learning::default()
    };
    let mut c = PolicyCore::new(QTable::default(), learning, Mode::Explore, 1, 0);
    let t = Transition {
        state: State::START,
        action: Action::SetLevel(Level::THREE),
        activity_result: 3.0,
        engagement: 0.0,
        next_state: state(3, 0, 0),
        is_last: false,
    };
    c.learn(&t).expect("first update is finite");
    let e = c.learn(&t).expect_err("overflows");
    assert!(matches!(e, PolicyError::NotFinite { .. }), "{e}");
    assert!(c.q_table().q.iter().flatten().all(|q| q.is_finite()));
}
