//! Counterfactual evaluation: the estimators by hand on a tiny log, the logging policy judged
//! on its own log, the exact value against sampling, coverage where the truth is known, the
//! support diagnostic, and bad logs refused by name.

use super::*;
use q_learning::learning::Reward;
use q_learning::mdp::TargetTemperature;
use q_learning::reference_tables::per_level_reference_tables;
use q_learning::{QTable, QTableFile};
use sequence_game::{ACTION_COUNT, Level, Outcome};

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

fn softmax(cluster: usize, t: f64) -> TargetPolicy {
    TargetPolicy::new(table(cluster), TargetTemperature::Fixed(t)).expect("policy")
}

fn greedy(cluster: usize) -> TargetPolicy {
    TargetPolicy::new(table(cluster), TargetTemperature::Greedy).expect("policy")
}

fn step(state: State, step: u8, action: usize, p: f64, success: bool, e: f64) -> LoggedStep {
    LoggedStep {
        state,
        step,
        action: Action::ALL[action],
        logged_probability: p,
        outcome: Outcome::from_correct(success),
        engagement: e,
    }
}

#[test]
fn the_estimators_by_hand_on_a_two_sequence_log() {
    // The new policy: a1 always at the start (Q), then at (1, 0, +1) a2 always.
    let mut q = QTable::default();
    q.q[State::START.index()] = [5.0, 0.0, 0.0, 0.0, 0.0];
    let after_one = State::after(Level::ONE, sequence_game::Feedback::None, Outcome::Success);
    q.q[after_one.index()] = [0.0, 5.0, 0.0, 0.0, 0.0];
    let target = TargetPolicy::new(q, TargetTemperature::Greedy).expect("policy");
    let l = Learning {
        reward: Reward::Re,
        gamma: 0.5,
        ..Learning::default()
    };
    // Session A: a1 (p 0.5) right, a2 (p 0.25) right: rewards 1, 2; weight 2 * 4 = 8.
    // Session B: a2 (p 0.5) wrong, then anything: weight 0.
    let a = LoggedSession {
        session_id: "a".into(),
        steps: vec![
            step(State::START, 1, 0, 0.5, true, 0.0),
            step(after_one, 2, 1, 0.25, true, 0.0),
        ],
    };
    let after_two_wrong = State::after(Level::TWO, sequence_game::Feedback::None, Outcome::Failure);
    let b = LoggedSession {
        session_id: "b".into(),
        steps: vec![
            step(State::START, 1, 1, 0.5, false, 0.0),
            step(after_two_wrong, 2, 0, 0.5, true, 0.0),
        ],
    };
    let e = evaluate(&[a, b], None, &target, &l, 200, 1).expect("evaluates");
    assert_eq!(e.weights, vec![8.0, 0.0]);
    // Logged: A returns 1 + 0.5 * 2 = 2, score 1 + 2 = 3; B returns -1 + 0.5 = -0.5 (RE is -1
    // on any failure), score -2 + 1 = -1.
    assert_eq!(e.discounted_return.logged.value, 0.75);
    assert_eq!(e.score.logged.value, 1.0);
    // WIS: all weight on A.
    assert_eq!(e.discounted_return.weighted_is.map(|x| x.value), Some(2.0));
    assert_eq!(e.score.weighted_is.map(|x| x.value), Some(3.0));
    // PDIS: A gives 2 * 1 + 0.5 * 8 * 2 = 10, B 0: mean 5; score 2 * 1 + 8 * 2 = 18: mean 9.
    assert_eq!(e.discounted_return.per_decision_is.value, 5.0);
    assert_eq!(e.score.per_decision_is.value, 9.0);
    assert_eq!(e.effective_sample_size, 1.0);
    assert_eq!(e.sessions_with_weight, 1);
    assert_eq!(e.decisions, 4);
    // The new policy's probability of the logged actions: 1, 1, 0, then uniform ties at
    // (2, 0, -2) over a1..a5 (all Q 0): 0.2.
    assert!((e.mean_new_probability - 2.2 / 4.0).abs() < 1e-12);
    // Bootstrap intervals hold their point estimate.
    for x in [e.discounted_return.logged, e.score.per_decision_is] {
        assert!(x.low <= x.value && x.value <= x.high, "{x:?}");
    }
}

#[test]
fn the_logging_policy_judged_on_its_own_log_gets_what_it_got() {
    let model = &per_level_reference_tables()[0];
    let policy = softmax(0, 1.0);
    let (log, full) = simulate_sessions(model, &policy, 300, 4);
    let e = evaluate(&log, Some(&full), &policy, &learning(), 500, 4).expect("evaluates");
    assert!(e.weights.iter().all(|w| (*w - 1.0).abs() < 1e-12));
    let r = e.discounted_return;
    assert!((r.weighted_is.expect("weighted").value - r.logged.value).abs() < 1e-9);
    assert!((r.per_decision_is.value - r.logged.value).abs() < 1e-9);
    assert!((e.effective_sample_size - 300.0).abs() < 1e-6);
    assert_eq!(e.mass_outside_support, Some(0.0));
}

#[test]
fn the_exact_value_is_what_sampling_converges_to() {
    let model = &per_level_reference_tables()[1];
    for policy in [softmax(1, 1.0), greedy(0)] {
        let truth = exact_value(model, &policy, &learning());
        let (log, _) = simulate_sessions(model, &policy, 20_000, 11);
        let e = evaluate(&log, None, &policy, &learning(), 0, 11).expect("evaluates");
        let returns: Vec<f64> = log
            .iter()
            .map(|s| {
                let one = std::slice::from_ref(s);
                evaluate(one, None, &policy, &learning(), 0, 0)
                    .expect("evaluates")
                    .discounted_return
                    .logged
                    .value
            })
            .collect();
        let n = returns.len() as f64;
        let mean = returns.iter().sum::<f64>() / n;
        let sd = (returns.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        assert!((mean - e.discounted_return.logged.value).abs() < 1e-9);
        // Within four standard errors of the sample mean.
        assert!(
            (truth.discounted_return - mean).abs() < 4.0 * sd / n.sqrt(),
            "exact {} vs sampled {mean} ± {}",
            truth.discounted_return,
            sd / n.sqrt()
        );
        assert!(
            (truth.score - e.score.logged.value).abs() < 0.15,
            "{truth:?}"
        );
    }
}

#[test]
fn estimates_of_another_policy_cover_its_exact_value() {
    let model = &per_level_reference_tables()[0];
    let logging = softmax(0, 2.0);
    // The same table, cooler: it takes the greedy action more often and is worth more.
    let target = softmax(0, 1.0);
    let v = validate(
        model,
        &logging,
        &target,
        &learning(),
        300,
        0..40,
        400,
        &|| {},
    )
    .expect("validates");
    assert_eq!(v.seeds, 40);
    // The two policies differ, so a good estimate is not the logged value...
    assert!(v.truth.discounted_return - v.logging_truth.discounted_return > 1.0);
    // ...yet the estimates land near the new policy's truth, their intervals holding it in
    // most seeds (a percentile bootstrap of a ratio covers a little under 95 %).
    for c in [
        v.weighted_is_return,
        v.per_decision_is_return,
        v.weighted_is_score,
        v.per_decision_is_score,
    ] {
        assert_eq!(c.seeds, 40);
        assert!(c.coverage >= 0.85, "{c:?}");
        assert!(c.bias.abs() < 0.5, "{c:?}");
    }
    assert!(
        v.weighted_is_return.rmse < 1.0,
        "{:?}",
        v.weighted_is_return
    );
    assert!(v.mean_effective_sample_size > 20.0 && v.mean_effective_sample_size < 300.0);
    // A policy far from the logging one leaves few sessions that count: ten decisions
    // multiply their ratios.
    let far = validate(
        model,
        &logging,
        &softmax(1, 0.5),
        &learning(),
        300,
        0..10,
        100,
        &|| {},
    )
    .expect("validates");
    assert!(
        far.mean_effective_sample_size < 10.0,
        "{}",
        far.mean_effective_sample_size
    );
}

#[test]
fn a_greedy_log_says_what_it_cannot_see_and_is_refused() {
    let model = &per_level_reference_tables()[0];
    let (log, full) = simulate_sessions(model, &greedy(0), 60, 2);
    let target = softmax(0, 1.0);
    let e = evaluate(&log, Some(&full), &target, &learning(), 100, 2).expect("evaluates");
    let outside = e.mass_outside_support.expect("full distributions given");
    assert!(outside > 0.1, "{outside}");
    // Per session, the chance the new policy stays on the logged actions at every decision.
    let stays: Vec<f64> = log
        .iter()
        .zip(&full)
        .map(|(s, f)| {
            s.steps
                .iter()
                .zip(f)
                .map(|(step, logged)| {
                    let p = target.probabilities(step.state, step.step);
                    (0..ACTION_COUNT)
                        .filter(|a| logged[*a] > 0.0)
                        .map(|a| p[a])
                        .sum::<f64>()
                })
                .product()
        })
        .collect();
    let share = 1.0 - stays.iter().sum::<f64>() / stays.len() as f64;
    let got = e
        .sessions_leaving_support
        .expect("full distributions given");
    assert!((got - share).abs() < 1e-12, "{got} vs {share}");
    assert!(share > 0.5, "{share}");
    // Enough sessions, but off the support: refused, whatever the intervals would say.
    let refusals = e.refusals(&Limits::default());
    assert!(
        matches!(refusals.as_slice(), [Refusal::OffSupport { share: s, .. }] if *s == got),
        "{refusals:?}"
    );
    assert!(refusals[0].to_string().contains("--max-off-support"));
    assert!(
        e.refusals(&Limits {
            max_sessions_leaving_support: 1.0,
            ..Limits::default()
        })
        .is_empty()
    );
    // Without the logged distributions the support cannot be checked: refused too.
    let blind = evaluate(&log, None, &target, &learning(), 10, 2).expect("evaluates");
    assert_eq!(blind.sessions_leaving_support, None);
    assert!(
        blind
            .refusals(&Limits::default())
            .contains(&Refusal::SupportUnknown)
    );
}

#[test]
fn too_few_sessions_are_refused_and_thin_weights_get_no_interval() {
    let model = &per_level_reference_tables()[0];
    let logging = softmax(0, 2.0);
    let (log, full) = simulate_sessions(model, &logging, 300, 8);
    let limits = Limits::default();
    // The logging policy on its own log: every session counts fully.
    let e = evaluate(&log, Some(&full), &logging, &learning(), 100, 8).expect("evaluates");
    assert_eq!(e.sessions_leaving_support, Some(0.0));
    assert!(e.refusals(&limits).is_empty());
    assert!(e.weighted_interval_holds(&limits));
    // A handful of sessions: refused, however close the policies.
    let few =
        evaluate(&log[..5], Some(&full[..5]), &logging, &learning(), 100, 8).expect("evaluates");
    assert_eq!(
        few.refusals(&limits),
        [Refusal::TooFewSessions {
            sessions: 5,
            minimum: limits.min_sessions
        }]
    );
    // A greedy policy within the softmax's support: estimated, but its weighted estimate
    // rests on a few sessions and gets no interval.
    let g = evaluate(&log, Some(&full), &greedy(0), &learning(), 100, 8).expect("evaluates");
    assert!(g.refusals(&limits).is_empty());
    assert!(
        !g.weighted_interval_holds(&limits),
        "{}",
        g.effective_sample_size
    );
}

#[test]
fn bad_logs_are_refused_by_name() {
    let l = learning();
    let target = greedy(0);
    assert_eq!(
        evaluate(&[], None, &target, &l, 10, 0),
        Err(OffPolicyError::NoSessions)
    );
    let bad = |p: f64, e: f64, action: usize| LoggedSession {
        session_id: "s-7".into(),
        steps: vec![step(State::START, 1, action, p, true, e)],
    };
    let err = evaluate(&[bad(0.0, 0.0, 0)], None, &target, &l, 10, 0).unwrap_err();
    assert!(err.to_string().contains("session s-7, sequence 1"), "{err}");
    assert!(matches!(err, OffPolicyError::LoggedProbability { .. }));
    assert!(matches!(
        evaluate(&[bad(f64::NAN, 0.0, 0)], None, &target, &l, 10, 0),
        Err(OffPolicyError::LoggedProbability { .. })
    ));
    assert!(matches!(
        evaluate(&[bad(0.5, 1.5, 0)], None, &target, &l, 10, 0),
        Err(OffPolicyError::Engagement { .. })
    ));
    // Feedback at the first sequence is never allowed.
    assert!(matches!(
        evaluate(&[bad(0.5, 0.0, 3)], None, &target, &l, 10, 0),
        Err(OffPolicyError::ActionNotAllowed { .. })
    ));
}

#[test]
fn logged_exploration_keeps_every_allowed_action_in_the_support_and_judges_the_greedy_policy() {
    let model = &per_level_reference_tables()[0];
    let eps = |e: f64| TargetPolicy::new(table(0), TargetTemperature::EpsilonGreedy(e));
    let logging = eps(0.1).expect("policy");
    // The logged sessions show every allowed action somewhere, so another policy never
    // leaves their support: nothing is refused for it.
    let (log, full) = simulate_sessions(model, &logging, 60, 4);
    for (session, dists) in log.iter().zip(&full) {
        for (s, p) in session.steps.iter().zip(dists) {
            let allowed = allowed_at(s.state, s.step);
            assert!(
                p[..allowed]
                    .iter()
                    .all(|x| *x >= 0.1 / allowed as f64 - 1e-12)
            );
            assert!(p[allowed..].iter().all(|x| *x == 0.0), "{p:?}");
        }
    }
    let e = evaluate(&log, Some(&full), &softmax(1, 1.0), &learning(), 50, 4).expect("evaluates");
    assert_eq!(e.sessions_leaving_support, Some(0.0));
    assert!(e.refusals(&Limits::default()).is_empty());
    // What the live policy plays without exploring (its greedy choice) is judged within a
    // point of its exact score from 200 sessions in most seeds.
    let v = validate(
        model,
        &logging,
        &greedy(0),
        &learning(),
        200,
        0..20,
        200,
        &|| {},
    )
    .expect("validates");
    let c = v.score_closeness(1.0);
    assert_eq!(c.weighted_is.seeds, 20);
    assert!(c.weighted_is.estimate_within >= 0.9, "{c:?}");
    assert!(c.weighted_is.interval_shown >= 0.9, "{c:?}");
    assert!(c.weighted_is.interval_within <= c.weighted_is.interval_shown);
    // The shares are what the seeds' estimates say.
    let by_hand = v
        .per_seed
        .iter()
        .filter(|e| {
            e.score
                .weighted_is
                .is_some_and(|w| (w.value - v.truth.score).abs() <= 1.0)
        })
        .count() as f64
        / 20.0;
    assert_eq!(c.weighted_is.estimate_within, by_hand);
    // Any estimate is within a huge tolerance, and every shown interval inside it.
    let wide = v.score_closeness(1e9);
    assert_eq!(wide.per_decision_is.estimate_within, 1.0);
    assert_eq!(
        wide.per_decision_is.interval_within,
        wide.per_decision_is.interval_shown
    );
    // A greedy log is refused for a softmax policy: no interval is ever shown.
    let greedy_log = validate(
        model,
        &greedy(0),
        &softmax(0, 1.0),
        &learning(),
        60,
        0..5,
        50,
        &|| {},
    )
    .expect("validates");
    let c = greedy_log.score_closeness(1.0);
    assert_eq!(
        (
            c.weighted_is.interval_shown,
            c.per_decision_is.interval_shown
        ),
        (0.0, 0.0)
    );
}
