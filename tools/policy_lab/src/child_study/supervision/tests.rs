//! The supervision study on the synthetic study: with no proposal the cluster policy plays
//! exactly `per_child`'s sessions, a therapist asked every decision plays the child's
//! score-optimal policy on the same draws, rules count and replace as they say, and runs
//! repeat exactly.

use super::*;
use crate::child_study::per_child::{Arm, Metric, Window, run_child as per_child_run};
use q_learning::mdp::play_session;
use user_models::simulate::{StudySpec as SyntheticStudy, simulate_study};

fn spec() -> StudySpec {
    StudySpec {
        fit: FitOptions {
            optimise: false,
            ..FitOptions::default()
        },
        learning: Learning {
            reward: q_learning::Reward::RePlusBetaE,
            ..Learning::default()
        },
        pretrain_epochs: 10,
        pretrain_runs: 1,
        sessions: 6,
        seeds: 3,
        seed: 5,
    }
}

/// Every child of the synthetic study, fitted once for all the tests (40 fits).
fn all_cases() -> &'static [SupervisionCase] {
    static CASES: std::sync::OnceLock<Vec<SupervisionCase>> = std::sync::OnceLock::new();
    CASES.get_or_init(|| {
        let records = simulate_study(&SyntheticStudy::default());
        cases(&records, &spec().fit).expect("cases")
    })
}

fn some_cases() -> Vec<SupervisionCase> {
    all_cases()[..3].to_vec()
}

const TRIGGERS: [Trigger; 6] = [
    Trigger::Never,
    Trigger::Always,
    Trigger::Random(0.3),
    Trigger::Rule {
        above_temperature: 100.0,
        above_success_std: 0.3,
        sigma: Sigma::Paper,
    },
    Trigger::Rule {
        above_temperature: f64::INFINITY,
        above_success_std: 0.1,
        sigma: Sigma::FittedNoise,
    },
    // Every temperature is at least 0.5: every decision proposed.
    Trigger::Rule {
        above_temperature: 0.0,
        above_success_std: f64::INFINITY,
        sigma: Sigma::Paper,
    },
];

#[test]
fn each_case_has_the_clusters_model_in_both_fits() {
    let all = all_cases();
    assert_eq!(all.len(), 20);
    for c in all {
        assert_eq!(c.fitted_noise_model.cluster, c.child.cluster);
        // Same inputs, another noise: the paper's σ is about 0 where the fitted one is not.
        assert_ne!(
            c.fitted_noise_model, c.child.cluster_model,
            "{}",
            c.child.user
        );
    }
}

#[test]
fn rules_propose_and_replace_as_they_say_on_the_same_child() {
    let s = spec();
    let cases = some_cases();
    for (i, case) in cases.iter().enumerate() {
        let r = run_child(case, i, &s, &TRIGGERS, Objective::Score);
        // No proposal: exactly per_child's cluster policy, session by session means.
        let alone = per_child_run(&case.child, i, &s);
        let window = Window {
            metric: Metric::Score,
            sessions: 0..s.sessions,
        };
        let per_seed = crate::child_study::per_child::per_seed(&alone, Arm::Cluster, &window);
        for (seed, (never, expected)) in r.runs[0].iter().zip(&per_seed).enumerate() {
            assert_eq!(never.proposals, 0.0);
            assert!((never.score - expected).abs() < 1e-12, "seed {seed}");
        }
        // Every decision proposed: the child's score-optimal policy on the same draws.
        let therapist = optimal_policy(&case.child.child_model, &s.learning, Objective::Score);
        for (seed, always) in r.runs[1].iter().enumerate() {
            let scores: Vec<f64> = (0..s.sessions)
                .map(|k| {
                    let d = session_draws(&s, i, seed, k);
                    let (session, _) =
                        play_session(&case.child.child_model, &therapist, String::new(), |j| {
                            (d.action[j], d.answer[j])
                        });
                    session
                        .steps
                        .iter()
                        .map(|st| {
                            let (level, _) = st.action.apply(st.state).expect("allowed");
                            f64::from(st.outcome.score(level))
                        })
                        .sum()
                })
                .collect();
            assert!((always.score - mean(&scores)).abs() < 1e-12, "seed {seed}");
            assert_eq!(always.proposals, SEQUENCES_PER_SESSION as f64);
        }
        // A temperature limit of 0 proposes every decision too.
        assert_eq!(r.runs[5], r.runs[1]);
        for runs in &r.runs {
            for x in runs {
                assert!(x.replaced <= x.proposals && x.proposals <= 10.0, "{x:?}");
            }
        }
        // About 30 % of the decisions at random (3 seeds x 6 sessions x 10 decisions).
        let random = mean(&r.runs[2].iter().map(|x| x.proposals).collect::<Vec<_>>());
        assert!((1.5..4.5).contains(&random), "{random}");
    }
}

#[test]
fn the_study_repeats_and_summarises_against_the_policy_alone() {
    let s = spec();
    let cases = some_cases();
    let a = run_study(&cases, &s, &TRIGGERS, Objective::Score, &|| {});
    let b = run_study(&cases, &s, &TRIGGERS, Objective::Score, &|| {});
    assert_eq!(a, b);
    let summary = summarise(&a, &TRIGGERS, 0, 500, 1);
    assert_eq!(summary.len(), TRIGGERS.len());
    let never = &summary[0];
    assert_eq!((never.proposals, never.protected.all.mean), (0.0, 0.0));
    assert_eq!(never.protected_per_proposal, None);
    let always = &summary[1];
    assert_eq!(always.proposals, 10.0);
    // The therapist who knows the child never does worse in expectation; over these few
    // sessions, better than the cluster policy on average.
    assert!(always.protected.all.mean > 0.0, "{always:?}");
    assert!(
        (always.score - never.score - always.protected.all.mean).abs() < 1e-9,
        "protected = score difference"
    );
    assert_eq!(summarise(&a, &TRIGGERS, 0, 500, 1), summary);
    // A rule that proposes is matched with proposals at random at its rate.
    let matched = matched_random(&summary);
    assert_eq!(matched[0], None);
    assert_eq!(matched[1], None, "every decision is no rule");
    assert_eq!(
        matched[3],
        Some(Trigger::Random(summary[3].proposals / 10.0)),
        "{summary:?}"
    );
    // A therapist after the child's best return protects return where one after score
    // protects score: they play the session's other optimum.
    let c = run_study(&cases, &s, &TRIGGERS, Objective::Return, &|| {});
    let by_return = summarise(&c, &TRIGGERS, 0, 500, 1);
    assert!(by_return[1].discounted_return >= by_return[0].discounted_return - 1e-9);
    assert_ne!(c, a);
}

#[test]
fn triggers_name_their_limits() {
    assert_eq!(TRIGGERS[3].name(), "T > 100 or σ (paper fit) > 0.3");
    assert_eq!(
        Trigger::sigma(0.15, Sigma::FittedNoise).name(),
        "σ (fitted noise) > 0.15"
    );
    assert_eq!(Trigger::temperature(100.0).name(), "T > 100");
    assert_eq!(Trigger::Random(0.2).name(), "at random, 20 % of decisions");
}
