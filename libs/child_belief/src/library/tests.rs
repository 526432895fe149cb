//! The posterior over known models against hand-computed Bayes updates.

use super::*;
use sequence_game::{Feedback, Level};

/// A model with one P(success) and one engagement (after either outcome) everywhere.
fn flat(p: f64, e: f64) -> UserModelTable {
    UserModelTable::tabulate(
        0,
        |_| Prediction { mean: p, std: 0.0 },
        |_, _| Prediction { mean: e, std: 0.0 },
    )
}

fn known(name: &str, table: UserModelTable) -> KnownModel {
    KnownModel {
        name: name.into(),
        table,
    }
}

fn input() -> ModelInput {
    ModelInput {
        level: Level::TWO,
        feedback: Feedback::None,
        previous_score: 1,
    }
}

fn params() -> LibraryParams {
    LibraryParams {
        engagement_sd: 0.5,
        success_floor: 0.05,
        forgetting: 1.0,
    }
}

#[test]
fn one_answer_reweighs_the_models_by_bayes_rule() {
    let models = vec![
        known("able", flat(0.9, 0.5)),
        known("struggling", flat(0.2, -0.5)),
    ];
    let mut b = ModelPosterior::new(models, &[3.0, 1.0], params()).expect("library");
    let w0 = b.weights();
    assert!(
        (w0[0] - 0.75).abs() < 1e-12 && (w0[1] - 0.25).abs() < 1e-12,
        "{w0:?}"
    );
    let o = Observation::new(input(), Outcome::Success, 0.3).expect("observation");
    b.observe(&o);
    // Prior 3 : 1, likelihoods P(right) · N(0.3; mean, 0.5).
    let lik = |p: f64, e: f64| p * (-0.5 * ((0.3 - e) / 0.5f64).powi(2)).exp();
    let (a, s) = (0.75 * lik(0.9, 0.5), 0.25 * lik(0.2, -0.5));
    let w = b.weights();
    assert!((w[0] - a / (a + s)).abs() < 1e-12, "{w:?}");
    assert!((w[1] - s / (a + s)).abs() < 1e-12, "{w:?}");
    assert_eq!(b.observations(), 1);
    // A wrong answer at low engagement moves the weight back.
    b.observe(&Observation::new(input(), Outcome::Failure, -0.6).expect("observation"));
    let (a2, s2) = (
        a * 0.1 * (-0.5 * ((-0.6 - 0.5) / 0.5f64).powi(2)).exp(),
        s * 0.8 * (-0.5 * ((-0.6 + 0.5) / 0.5f64).powi(2)).exp(),
    );
    assert!((b.weights()[1] - s2 / (a2 + s2)).abs() < 1e-12);
    assert_eq!(b.most_likely().0.name, "struggling");
}

#[test]
fn a_model_that_called_the_answer_impossible_is_floored_not_ruled_out() {
    let models = vec![
        known("never", flat(0.0, 0.0)),
        known("always", flat(1.0, 0.0)),
    ];
    let mut b = ModelPosterior::new(models, &[1.0, 1.0], params()).expect("library");
    b.observe(&Observation::new(input(), Outcome::Success, 0.0).expect("observation"));
    let w = b.weights();
    assert!((w[0] - 0.05).abs() < 1e-12, "{w:?}");
    // And forgetting pulls the weights back towards the prior.
    let forgetful = LibraryParams {
        forgetting: 0.5,
        ..params()
    };
    let models = vec![
        known("never", flat(0.0, 0.0)),
        known("always", flat(1.0, 0.0)),
    ];
    let mut f = ModelPosterior::new(models, &[1.0, 1.0], forgetful).expect("library");
    let right = Observation::new(input(), Outcome::Success, 0.0).expect("observation");
    f.observe(&right);
    f.observe(&right);
    // ln odds: 0.5 · ln(19) + ln(19), against 2 · ln(19) without forgetting.
    let odds = (1.5 * 19f64.ln()).exp();
    assert!((f.weights()[1] - odds / (1.0 + odds)).abs() < 1e-12);
}

#[test]
fn the_predictive_model_is_the_posterior_mixture() {
    let models = vec![known("a", flat(0.8, 0.6)), known("b", flat(0.4, -0.2))];
    let b = ModelPosterior::new(models, &[1.0, 3.0], params()).expect("library");
    let t = b.predictive();
    t.validate().expect("a valid table");
    let s = t.success(input());
    assert!((s.mean - (0.25 * 0.8 + 0.75 * 0.4)).abs() < 1e-12);
    assert!((s.std - (0.25 * 0.75f64).sqrt() * 0.4).abs() < 1e-12);
    // E after a right answer: weighted by w_m P_m(right).
    let (wa, wb) = (0.25 * 0.8, 0.75 * 0.4);
    let e = t.engagement(input(), Outcome::Success).mean;
    assert!((e - (wa * 0.6 + wb * -0.2) / (wa + wb)).abs() < 1e-12);
    // Posterior sampling draws each model with its weight.
    let mut rng = <ChaCha8Rng as rand::SeedableRng>::seed_from_u64(1);
    let draws = 4000;
    let a = (0..draws)
        .filter(|_| b.sample(&mut rng).success(input()).mean == 0.8)
        .count();
    let share = a as f64 / draws as f64;
    assert!((share - 0.25).abs() < 0.03, "{share}");
}

#[test]
fn bad_libraries_and_observations_are_refused_by_name() {
    assert_eq!(
        ModelPosterior::new(vec![], &[], params()),
        Err(BeliefError::EmptyLibrary)
    );
    let bad = known("broken", flat(1.5, 0.0));
    assert!(matches!(
        ModelPosterior::new(vec![bad], &[1.0], params()),
        Err(BeliefError::Model { name, .. }) if name == "broken"
    ));
    let ok = || vec![known("a", flat(0.5, 0.0))];
    assert!(ModelPosterior::new(ok(), &[0.0], params()).is_err());
    assert!(ModelPosterior::new(ok(), &[f64::NAN], params()).is_err());
    let sd0 = LibraryParams {
        engagement_sd: 0.0,
        ..params()
    };
    assert!(ModelPosterior::new(ok(), &[1.0], sd0).is_err());
    assert_eq!(
        Observation::new(input(), Outcome::Success, 1.5),
        Err(BeliefError::Engagement(1.5))
    );
    assert!(Observation::new(input(), Outcome::Success, f64::NAN).is_err());
}
