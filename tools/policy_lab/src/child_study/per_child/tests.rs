//! The per-child study on a synthetic study (user_models' simulated one): leave-one-out cases
//! leave the child out, the policies differ in what they learn, runs are reproducible.

use super::*;
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
        pretrain_epochs: 20,
        pretrain_runs: 2,
        sessions: 8,
        seeds: 3,
        seed: 5,
    }
}

#[test]
fn each_child_is_left_out_of_the_models_that_place_them() {
    let records = simulate_study(&SyntheticStudy::default());
    let s = spec();
    let cases = cases(&records, &s.fit).expect("cases");
    let users = user_models::fit::user_vectors(&records).expect("vectors");
    assert_eq!(cases.len(), users.len());
    for (case, (user, _)) in cases.iter().zip(&users) {
        assert_eq!(&case.user, user);
        assert!(case.cluster < s.fit.clusters);
    }
    // The child's own model comes from their records alone: changing another child's
    // records leaves it as it was, and it differs from their cluster's.
    let first = &cases[0];
    let mut changed = records.clone();
    for r in changed.iter_mut().filter(|r| r.user_id != first.user) {
        r.engagement = r.engagement.map(|e| -e);
    }
    let again = user_models::fit::fit_user(&first.user, &changed, &s.fit).expect("fits");
    assert_eq!(again, first.child_model);
    assert_ne!(first.child_model.success, first.cluster_model.success);
    assert!(user_models::fit::fit_user("nobody", &records, &s.fit).is_err());
}

#[test]
fn every_policy_meets_the_same_child_and_runs_repeat() {
    let records = simulate_study(&SyntheticStudy::default());
    let s = spec();
    let cases = cases(&records, &s.fit).expect("cases");
    let picked = &cases[..4];
    let results = run_study(picked, &s, &|| {});
    assert_eq!(results, run_study(picked, &s, &|| {}));
    for r in &results {
        assert_eq!(r.runs.len(), Arm::ALL.len());
        for arm in &r.runs {
            assert_eq!(arm.len(), s.seeds);
            assert!(arm.iter().all(|run| run.len() == s.sessions));
        }
    }
    // The cluster's policy does not change with the child's sessions; its per-user copy does.
    let v = |arm: Arm| -> Vec<f64> {
        results
            .iter()
            .flat_map(|r| r.runs[arm as usize].iter().flatten().map(|m| m.start_value))
            .collect()
    };
    for r in &results {
        let first = r.runs[0][0][0].start_value;
        assert!(r.runs[0].iter().flatten().all(|m| m.start_value == first));
    }
    assert_ne!(v(Arm::Cluster), v(Arm::PerUser));
    // Common random numbers: a per-user table that cannot learn (α = 0) is the cluster's
    // policy, and plays exactly its sessions, ties and the child's answers included (with a
    // stream per policy, as before, they differed).
    let still = StudySpec {
        learning: Learning {
            alpha: 0.0,
            ..s.learning
        },
        ..s.clone()
    };
    for (i, case) in picked.iter().enumerate() {
        let r = run_child(case, i, &still);
        assert_eq!(r.runs[Arm::Cluster as usize], r.runs[Arm::PerUser as usize]);
        // A cluster table pretrained with α = 0 is all ties: the draws broke them, and the
        // sessions still vary.
        let scores: Vec<f64> = r.runs[0].iter().flatten().map(|m| m.score).collect();
        assert!(scores.iter().any(|x| *x != scores[0]), "{scores:?}");
    }
}

#[test]
fn the_optimal_policy_bounds_what_the_others_can_expect() {
    let records = simulate_study(&SyntheticStudy::default());
    let s = StudySpec {
        seeds: 20,
        sessions: 20,
        ..spec()
    };
    let cases = cases(&records, &s.fit).expect("cases");
    let mut spread = 0.0f64;
    for (i, case) in cases.iter().take(4).enumerate() {
        let r = run_child(case, i, &s);
        let cluster_table = cluster_table(case, i, &s);
        let greedy = q_learning::mdp::TargetPolicy::new(
            cluster_table,
            q_learning::mdp::TargetTemperature::Greedy,
        )
        .expect("policy");
        let cluster = q_learning::mdp::exact_value(&case.child_model, &greedy, &s.learning);
        assert!(cluster.discounted_return <= r.bounds.optimal.discounted_return + 1e-9);
        assert!(cluster.score <= r.bounds.best_score + 1e-9);
        // Played on the draws, the optimal policy's mean return is its exact value, within
        // four standard errors of the 400 sessions.
        let all = Window {
            metric: Metric::Return,
            sessions: 0..s.sessions,
        };
        let returns: Vec<f64> = r.runs[Arm::Optimal as usize]
            .iter()
            .flatten()
            .map(|m| m.discounted_return)
            .collect();
        let se = crate::stats::sample_std(&returns) / (returns.len() as f64).sqrt();
        let got = child_mean(&r, Arm::Optimal, &all);
        assert!(
            (got - r.bounds.optimal.discounted_return).abs() <= 4.0 * se + 1e-6,
            "{got} vs {:?} (se {se})",
            r.bounds
        );
        spread = spread.max(se);
    }
    // Some child's answers vary, so the check above is not only about sure answers.
    assert!(spread > 0.05, "{spread}");
}

#[test]
fn paired_comparisons_are_by_child_and_repeat() {
    let records = simulate_study(&SyntheticStudy::default());
    let s = spec();
    let cases = cases(&records, &s.fit).expect("cases");
    let results = run_study(&cases[..5], &s, &|| {});
    let window = &Window::standard(s.sessions)[0];
    for (a, b) in COMPARISONS {
        let c = paired(&results, a, b, window, 500, 3);
        assert_eq!(c, paired(&results, a, b, window, 500, 3));
        assert_eq!(c.per_unit.len(), 5);
        assert_eq!(c.all.wins + c.all.ties + c.all.losses, 5);
        // Each child's difference is the difference of their means.
        for (u, r) in c.per_unit.iter().zip(&results) {
            assert_eq!(u.unit, r.user);
            let d = child_mean(r, a, window) - child_mean(r, b, window);
            assert!((u.difference - d).abs() < 1e-9);
        }
        let mean_of_children =
            mean_over_children(&results, a, window) - mean_over_children(&results, b, window);
        assert!((c.all.mean - mean_of_children).abs() < 1e-9);
        assert!(c.most_influential.is_some());
    }
    let curve = curve(&results, Arm::Scratch, Metric::Score);
    assert_eq!(curve.len(), s.sessions);
    assert!(curve.iter().all(|(m, i)| i.is_some_and(|i| i.contains(*m))));
}
