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
            reward: crate::Reward::RePlusBetaE,
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
fn the_policies_differ_in_what_they_learn_and_runs_repeat() {
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
    let v = |arm: usize| -> Vec<f64> {
        results
            .iter()
            .flat_map(|r| r.runs[arm].iter().flatten().map(|m| m.start_value))
            .collect()
    };
    let cluster = v(0);
    for r in &results {
        let first = r.runs[0][0][0].start_value;
        assert!(r.runs[0].iter().flatten().all(|m| m.start_value == first));
    }
    assert_ne!(cluster, v(1));
    // Trained on the child's own model, the ceiling gets at least what the cluster's policy
    // gets against that model.
    let all = 0..s.sessions;
    let ceiling = summary(
        &results,
        Arm::ChildModel,
        Metric::Return,
        all.clone(),
        &|_| true,
    );
    let group = summary(&results, Arm::Cluster, Metric::Return, all, &|_| true);
    assert!(ceiling.mean >= group.mean - 0.5, "{ceiling:?} vs {group:?}");
    let c = curve(&results, Arm::Scratch, Metric::Score);
    assert_eq!(c.len(), s.sessions);
}
