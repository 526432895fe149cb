//! The belief arms on the synthetic study (user_models' simulated one): the child's own model
//! never in their library, runs repeat exactly, every arm meets the same child as
//! `per_child`'s policies, and identification is bounded by the child's optimum.

use super::*;
use crate::child_study::per_child::{Arm, cases, run_child};
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
        sessions: 6,
        seeds: 3,
        seed: 5,
    }
}

fn library(s: &StudySpec) -> Vec<LibraryCase> {
    let records = simulate_study(&SyntheticStudy::default());
    let cases = cases(&records, &s.fit).expect("cases");
    library_cases(&records, &cases, &s.fit).expect("library cases")
}

fn arm(representation: Representation, planning: Planning, start: Start) -> BeliefArm {
    BeliefArm {
        representation,
        planning,
        start,
    }
}

#[test]
fn the_childs_own_model_is_never_in_their_library() {
    let s = spec();
    let lib = library(&s);
    let b = BeliefSpec::default();
    for (i, case) in lib.iter().enumerate() {
        for start in [Start::Cluster, Start::Population] {
            let (models, prior) = library_for(&lib, i, start, &b);
            assert_eq!(models.len(), prior.len());
            // The clusters' models and the 19 others.
            assert_eq!(models.len(), s.fit.clusters + lib.len() - 1);
            assert!(models.iter().all(|m| m.name != case.case.user));
            assert!(models.iter().all(|m| m.table != case.case.child_model));
        }
        // From the cluster, the cluster's own models weigh more than the other cluster's.
        let (models, prior) = library_for(&lib, i, Start::Cluster, &b);
        let own = models
            .iter()
            .position(|m| m.name == format!("cluster {}", case.case.cluster))
            .expect("the cluster's model");
        assert!(prior.iter().all(|w| *w <= prior[own]));
        assert!(case.others.iter().all(|(u, _)| u != &case.case.user));
    }
}

#[test]
fn belief_arms_repeat_exactly() {
    let s = spec();
    let lib = library(&s);
    let b = BeliefSpec::default();
    for a in [
        arm(Representation::Library, Planning::Mean, Start::Population),
        arm(Representation::Library, Planning::Sampling, Start::Cluster),
        arm(Representation::OwnModel, Planning::Cautious, Start::Cluster),
        arm(
            Representation::OwnModelLearned,
            Planning::Guarded,
            Start::Cluster,
        ),
    ] {
        let once = run_belief_arm(&lib, 1, &a, &b, &s).expect("runs");
        assert_eq!(once, run_belief_arm(&lib, 1, &a, &b, &s).expect("runs"));
        assert_eq!(once.len(), s.seeds);
        assert!(once.iter().all(|r| r.len() == s.sessions));
    }
}

#[test]
fn a_belief_arm_whose_baseline_plays_every_session_plays_the_cluster_policys() {
    // Common random numbers: the same draws, ties and answers as `per_child`'s cluster arm,
    // for every seed and session.
    let s = spec();
    let lib = library(&s);
    let b = BeliefSpec {
        baseline_sessions: s.sessions,
        ..BeliefSpec::default()
    };
    let a = arm(
        Representation::OwnModelLearned,
        Planning::Guarded,
        Start::Cluster,
    );
    for i in 0..3 {
        let ours = run_belief_arm(&lib, i, &a, &b, &s).expect("runs");
        let cluster = run_child(&lib[i].case, i, &s).runs[Arm::Cluster as usize].clone();
        for (x, y) in ours.iter().flatten().zip(cluster.iter().flatten()) {
            assert_eq!(
                (x.score, x.engagement, x.discounted_return),
                (y.score, y.engagement, y.discounted_return)
            );
        }
    }
}

#[test]
fn identification_lies_between_the_cluster_models_plan_and_the_childs_optimum() {
    let s = spec();
    let lib = library(&s);
    let b = BeliefSpec::default();
    for i in 0..4 {
        let id = identification(&lib, i, &s, &b);
        let eps = 1e-9;
        assert!(
            id.best_known.discounted_return >= id.cluster_model_optimal.discounted_return - eps
        );
        assert!(id.best_known.discounted_return <= id.optimal.discounted_return + eps);
        assert!(id.cluster_policy.discounted_return <= id.optimal.discounted_return + eps);
        assert_ne!(id.best_known_model, lib[i].case.user);
    }
}
