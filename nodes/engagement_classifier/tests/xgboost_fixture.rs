//! Our evaluator and trainer against Python xgboost 3.2, through the fixtures written by
//! `tests/fixtures/make_fixtures.py` (synthetic data; see that script for what each file is).

use engagement_classifier::EngagementModel;
use engagement_classifier::repair::DecimalRepair;
use engagement_classifier::table::{
    LoadOptions, NeutralLabel, load_labelled_csv, read_feature_csv,
};
use engagement_classifier::train::{TrainParams, to_model_file, train};
use engagement_classifier::xgboost_json::parse_base_score;
use std::path::{Path, PathBuf};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// (margin, probability) per row of an `*_expected.csv`.
fn expected(name: &str) -> Vec<(f64, f64)> {
    let mut reader = csv::Reader::from_path(fixture(name)).expect("fixture exists");
    reader
        .records()
        .map(|r| {
            let r = r.expect("csv row");
            let v = |i: usize| r[i].parse::<f64>().expect("number");
            (v(0), v(1))
        })
        .collect()
}

/// Predicts rows.csv with `model` and checks every row against Python to 1e-6; returns the
/// largest differences seen.
fn check_model(model: &EngagementModel, expected_file: &str) -> (f64, f64) {
    let rows = read_feature_csv(&fixture("rows.csv")).expect("rows.csv reads");
    let want = expected(expected_file);
    assert_eq!(rows.len(), want.len());
    assert_eq!(rows.len(), 200);
    assert!(
        rows.iter().flatten().any(|v| v.is_nan()),
        "fixture has missing values"
    );
    let (mut dm, mut dp) = (0f64, 0f64);
    for (i, (row, (margin, prob))) in rows.iter().zip(&want).enumerate() {
        let p = model.predict(row);
        let (em, ep) = (
            (f64::from(p.margin) - margin).abs(),
            (f64::from(p.probability) - prob).abs(),
        );
        assert!(
            em <= 1e-6 && ep <= 1e-6,
            "row {i}: ours {p:?}, xgboost margin {margin} p {prob}"
        );
        assert_eq!(p.label, if *prob > 0.5 { 1 } else { -1 }, "row {i}");
        dm = dm.max(em);
        dp = dp.max(ep);
    }
    (dm, dp)
}

#[test]
fn python_model_with_shuffled_columns_matches_xgboost() {
    let model = EngagementModel::load(&fixture("xgb_plain.json")).expect("loads");
    assert_eq!(model.tree_count(), 100);
    assert!(model.preprocessing().is_none());
    // The model's first column is not our first feature: matching was by name.
    assert_ne!(
        model.model_columns(),
        (0..32).collect::<Vec<_>>().as_slice()
    );
    let (dm, dp) = check_model(&model, "xgb_plain_expected.csv");
    eprintln!("plain: max |margin diff| {dm:e}, max |p diff| {dp:e}");
}

#[test]
fn python_model_with_stored_preprocessing_matches_xgboost_on_raw_rows() {
    let model = EngagementModel::load(&fixture("xgb_preprocessed.json")).expect("loads");
    assert!(model.preprocessing().is_some());
    let (dm, dp) = check_model(&model, "xgb_preprocessed_expected.csv");
    eprintln!("preprocessed: max |margin diff| {dm:e}, max |p diff| {dp:e}");
}

/// Every other fixture has base_score 0.5 (balanced labels), where logit(base_score) = 0 and
/// a wrong intercept would go unseen. Trained on 1 positive label in 5, xgboost fits
/// base_score from the labels.
#[test]
fn python_model_with_a_fitted_base_score_matches_xgboost() {
    let path = fixture("xgb_unbalanced.json");
    let text = std::fs::read_to_string(&path).expect("fixture exists");
    let file: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    let stored = file["learner"]["learner_model_param"]["base_score"]
        .as_str()
        .expect("base_score is a string");
    let base_score = parse_base_score(stored).expect("base_score parses");
    assert!(
        (base_score - 0.5).abs() > 0.1,
        "base_score {stored} is not fitted away from 0.5"
    );
    let model = EngagementModel::from_json(&text, &path).expect("loads");
    assert_eq!(model.tree_count(), 100);
    let (dm, dp) = check_model(&model, "xgb_unbalanced_expected.csv");
    eprintln!("base_score {stored}: max |margin diff| {dm:e}, max |p diff| {dp:e}");
}

#[test]
fn our_trained_model_predicts_what_python_predicts_with_it() {
    let model = EngagementModel::load(&fixture("rust_model.json")).expect("loads");
    check_model(&model, "rust_model_python_expected.csv");
}

fn train_fixture_model() -> engagement_classifier::train::Booster {
    let options = LoadOptions {
        neutral_label: NeutralLabel::Engaged,
        decimal_repair: DecimalRepair::Magnitude,
    };
    let (table, report) = load_labelled_csv(&fixture("train.csv"), &options).expect("loads");
    assert_eq!(report.rows_read, 500);
    assert_eq!(report.dotless_values.iter().sum::<usize>(), 0);
    train(&table, &TrainParams::default(), |_| {})
}

#[test]
fn training_again_gives_the_committed_model_byte_for_byte() {
    let booster = train_fixture_model();
    let file = to_model_file(&booster, "fixture: SYNTHETIC data from make_fixtures.py");
    let ours = serde_json::to_string(&file).expect("serialises");
    let committed = std::fs::read_to_string(fixture("rust_model.json")).expect("fixture exists");
    assert!(
        ours == committed,
        "retrained model differs from tests/fixtures/rust_model.json"
    );
}

#[test]
fn our_trainer_reproduces_python_xgboost_on_the_same_inputs() {
    let booster = train_fixture_model();
    let file = to_model_file(&booster, "retrained");
    let text = serde_json::to_string(&file).expect("serialises");
    let model = EngagementModel::from_json(&text, Path::new("retrained")).expect("loads");
    // Python trained XGBClassifier on our standardised inputs (make_fixtures.py step 4).
    let (dm, dp) = check_model(&model, "python_on_rust_inputs_expected.csv");
    eprintln!("trainer vs xgboost: max |margin diff| {dm:e}, max |p diff| {dp:e}");
}
