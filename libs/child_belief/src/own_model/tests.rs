//! The child's own GPs against the closed-form Gaussian update.

use super::*;
use sequence_game::{Feedback, Level};

fn flat(p: f64, e: f64) -> UserModelTable {
    UserModelTable::tabulate(
        0,
        |_| Prediction { mean: p, std: 0.0 },
        |_, _| Prediction { mean: e, std: 0.0 },
    )
}

fn at(level: Level, feedback: Feedback, previous_score: i8) -> ModelInput {
    ModelInput {
        level,
        feedback,
        previous_score,
    }
}

#[test]
fn one_answer_moves_its_input_and_its_neighbours_by_their_correlation() {
    let params = OwnModelParams::default();
    let mut b = OwnModel::new(&flat(0.6, 0.2), params).expect("belief");
    let x = at(Level::TWO, Feedback::None, 2);
    b.observe(&Observation::new(x, Outcome::Failure, -0.4).expect("observation"));
    let posterior = b.posterior();
    let (success, engagement) = (&posterior.success, &posterior.engagement);
    // Scalar update at the input: m + k / (k + σ²) (y − m).
    let k = params.success_sd.powi(2);
    let gain = k / (k + params.answer_noise);
    assert!((success[x.index()].0 - (0.6 + gain * (0.0 - 0.6))).abs() < 1e-12);
    // At the next level, same feedback and score, the correlation ρ_L scales the move.
    let y = at(Level::THREE, Feedback::None, 2);
    let moved = 0.6 + params.level_correlation * gain * (0.0 - 0.6);
    assert!((success[y.index()].0 - moved).abs() < 1e-12);
    // Engagement after a wrong answer moves; after a right one, by the outcome correlation.
    let ke = params.engagement_sd.powi(2);
    let ge = ke / (ke + params.engagement_noise.powi(2));
    let e_wrong = engagement[x.engagement_index(Outcome::Failure)].0;
    assert!((e_wrong - (0.2 + ge * (-0.4 - 0.2))).abs() < 1e-12);
    let e_right = engagement[x.engagement_index(Outcome::Success)].0;
    assert!((e_right - (0.2 + params.outcome_correlation * ge * (-0.4 - 0.2))).abs() < 1e-12);
    // Its posterior σ shrinks where it saw the answer, least far away.
    let far = at(Level::ONE, Feedback::Challenging, -3);
    assert!(success[x.index()].1 < success[y.index()].1);
    assert!(success[y.index()].1 < success[far.index()].1);
    assert!((success[x.index()].1 - (k * (1.0 - gain)).sqrt()).abs() < 1e-9);
    // The predictive model a plan is solved on: each value the clamped Gaussian's mean.
    let t = b.predictive();
    let (m, sd) = success[x.index()];
    assert!((t.success(x).mean - clamped_normal_mean(m, sd, 0.0, 1.0)).abs() < 1e-12);
    assert!((t.success(x).std - sd).abs() < 1e-12);
}

#[test]
fn repeated_answers_pool_and_forgetting_weighs_the_latest_most() {
    let params = OwnModelParams::default();
    let x = at(Level::ONE, Feedback::Encouraging, 1);
    let mut b = OwnModel::new(&flat(0.5, 0.0), params).expect("belief");
    for outcome in [
        Outcome::Success,
        Outcome::Success,
        Outcome::Failure,
        Outcome::Success,
    ] {
        b.observe(&Observation::new(x, outcome, 0.0).expect("observation"));
    }
    // Four answers with mean 0.75: the same as one of noise σ² / 4.
    let k = params.success_sd.powi(2);
    let gain = k / (k + params.answer_noise / 4.0);
    assert!((b.posterior().success[x.index()].0 - (0.5 + gain * 0.25)).abs() < 1e-12);
    // With forgetting 0.5 the weights are 1/8, 1/4, 1/2, 1: the latest right answer counts most.
    let forgetful = OwnModelParams {
        forgetting: 0.5,
        ..params
    };
    let mut f = OwnModel::new(&flat(0.5, 0.0), forgetful).expect("belief");
    for outcome in [
        Outcome::Failure,
        Outcome::Failure,
        Outcome::Failure,
        Outcome::Success,
    ] {
        f.observe(&Observation::new(x, outcome, 0.0).expect("observation"));
    }
    let w = 1.0 + 0.5 + 0.25 + 0.125;
    let ybar = 1.0 / w;
    let g = k / (k + params.answer_noise / w);
    assert!((f.posterior().success[x.index()].0 - (0.5 + g * (ybar - 0.5))).abs() < 1e-12);
}

#[test]
fn a_value_the_gp_puts_beyond_the_range_counts_as_the_bound() {
    // E[clamp(X, 0, 1)], X ~ N(μ, σ²): the bound's mass counts as the bound.
    assert_eq!(clamped_normal_mean(0.4, 0.0, 0.0, 1.0), 0.4);
    assert_eq!(clamped_normal_mean(1.3, 0.0, 0.0, 1.0), 1.0);
    // At μ = 1 with small σ: 1 − σ / √(2π).
    let s = 0.05;
    let want = 1.0 - s / std::f64::consts::TAU.sqrt();
    assert!((clamped_normal_mean(1.0, s, 0.0, 1.0) - want).abs() < 1e-6);
    // Far inside the range, the mean itself; symmetric about the middle of [−1, 1].
    assert!((clamped_normal_mean(0.1, 0.05, -1.0, 1.0) - 0.1).abs() < 1e-9);
    let (a, b) = (
        clamped_normal_mean(0.7, 0.5, -1.0, 1.0),
        clamped_normal_mean(-0.7, 0.5, -1.0, 1.0),
    );
    assert!((a + b).abs() < 1e-9 && a < 0.7);
    // Against a sampled mean: μ = 0.9, σ = 0.3 on [0, 1].
    let mut rng = <ChaCha8Rng as rand::SeedableRng>::seed_from_u64(2);
    let n = 200_000;
    let z = standard_normals(&mut rng, n);
    let sampled = z
        .iter()
        .map(|z| (0.9 + 0.3 * z).clamp(0.0, 1.0))
        .sum::<f64>()
        / n as f64;
    assert!(
        (clamped_normal_mean(0.9, 0.3, 0.0, 1.0) - sampled).abs() < 0.002,
        "{sampled}"
    );
}

#[test]
fn samples_stay_in_range_and_centre_on_the_posterior() {
    let mut b = OwnModel::new(&flat(0.5, 0.0), OwnModelParams::default()).expect("belief");
    let x = at(Level::THREE, Feedback::None, -1);
    b.observe(&Observation::new(x, Outcome::Success, 0.9).expect("observation"));
    let mean = b.predictive().success(x).mean;
    // Samples are clamped, so their mean is the clamped Gaussian's mean: the predictive.
    let mut rng = <ChaCha8Rng as rand::SeedableRng>::seed_from_u64(4);
    let n = 2000;
    let mut total = 0.0;
    for _ in 0..n {
        let s = b.sample(&mut rng);
        s.validate().expect("a sample is a valid table");
        total += s.success(x).mean;
    }
    // Clamping to [0, 1] moves the sample mean only a little here (σ ≈ 0.2 around 0.7).
    assert!(
        (total / f64::from(n) - mean).abs() < 0.03,
        "{} vs {mean}",
        total / f64::from(n)
    );
}

#[test]
fn bad_parameters_are_refused() {
    let bad = OwnModelParams {
        level_correlation: 1.5,
        ..OwnModelParams::default()
    };
    assert!(matches!(
        OwnModel::new(&flat(0.5, 0.0), bad),
        Err(BeliefError::Parameter {
            what: "level_correlation",
            ..
        })
    ));
    let broken = flat(2.0, 0.0);
    assert!(OwnModel::new(&broken, OwnModelParams::default()).is_err());
}
