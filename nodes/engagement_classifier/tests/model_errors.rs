//! Model files we must refuse, each with an error that names the problem and the file.

use engagement_classifier::{EngagementModel, ModelError};
use serde_json::Value;
use std::path::Path;

fn fixture_model() -> Value {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/xgb_plain.json");
    serde_json::from_str(&std::fs::read_to_string(path).expect("fixture")).expect("json")
}

fn load(v: &Value) -> Result<EngagementModel, ModelError> {
    EngagementModel::from_json(&v.to_string(), Path::new("models/bad.json"))
}

fn message(v: &Value) -> String {
    let err = load(v).expect_err("must be refused");
    let text = err.to_string();
    assert!(
        text.contains("models/bad.json"),
        "error does not name the file: {text}"
    );
    text
}

#[test]
fn the_unmodified_fixture_loads() {
    assert!(load(&fixture_model()).is_ok());
}

#[test]
fn not_json_or_not_an_xgboost_model() {
    let err = EngagementModel::from_json("col_a,col_b\n1,2\n", Path::new("models/bad.json"));
    assert!(matches!(err, Err(ModelError::NotXgboostJson { .. })));
    let text = message(&serde_json::json!({"weights": [1, 2, 3]}));
    assert!(text.contains("not an XGBoost JSON model"), "{text}");
    let err = EngagementModel::load(Path::new("/nonexistent/model.json")).expect_err("io");
    assert!(err.to_string().contains("/nonexistent/model.json"), "{err}");
}

#[test]
fn other_objectives_are_named() {
    let mut m = fixture_model();
    m["learner"]["objective"]["name"] = "reg:squarederror".into();
    let text = message(&m);
    assert!(
        text.contains("reg:squarederror") && text.contains("binary:logistic"),
        "{text}"
    );
    m["learner"]["objective"]["name"] = "multi:softprob".into();
    assert!(message(&m).contains("multi:softprob"));
}

#[test]
fn other_boosters_are_named() {
    let mut m = fixture_model();
    m["learner"]["gradient_booster"]["name"] = "dart".into();
    assert!(message(&m).contains("dart"));
}

#[test]
fn feature_count_other_than_32_is_refused() {
    let mut m = fixture_model();
    m["learner"]["learner_model_param"]["num_feature"] = "31".into();
    let text = message(&m);
    assert!(
        text.contains("31 features") && text.contains("32"),
        "{text}"
    );
    let mut m = fixture_model();
    let names = m["learner"]["feature_names"].as_array_mut().expect("names");
    names.pop();
    assert!(message(&m).contains("31 features"));
}

#[test]
fn features_are_matched_by_name() {
    let mut m = fixture_model();
    m["learner"]["feature_names"] = Value::Array(Vec::new());
    assert!(message(&m).contains("no feature_names"));
    let mut m = fixture_model();
    m["learner"]["feature_names"][5] = "of_confidence".into();
    assert!(message(&m).contains("of_confidence"));
    let mut m = fixture_model();
    let first = m["learner"]["feature_names"][0].clone();
    m["learner"]["feature_names"][1] = first;
    assert!(message(&m).contains("appears twice"));
}

#[test]
fn broken_trees_and_categorical_splits_are_refused() {
    let trees = |m: &mut Value| m["learner"]["gradient_booster"]["model"]["trees"][3].clone();
    let mut m = fixture_model();
    let mut tree = trees(&mut m);
    tree["left_children"][0] = 100000.into();
    m["learner"]["gradient_booster"]["model"]["trees"][3] = tree;
    let text = message(&m);
    assert!(text.contains("tree 3"), "{text}");
    let mut m = fixture_model();
    let mut tree = trees(&mut m);
    tree["split_type"][0] = 1.into();
    m["learner"]["gradient_booster"]["model"]["trees"][3] = tree;
    assert!(message(&m).contains("categorical"));
}

#[test]
fn a_bad_preprocessing_attribute_is_named() {
    let mut m = fixture_model();
    m["learner"]["attributes"]["engagement_preprocessing"] = r#"{"format": "zscore/9"}"#.into();
    let text = message(&m);
    assert!(text.contains("engagement_preprocessing"), "{text}");
}
