//! The parameter file, and the command-line tools run as a user runs them.

use engagement_classifier::EngagementClassifierParams;
use std::path::{Path, PathBuf};
use std::process::Command;

fn manifest() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn workspace() -> PathBuf {
    manifest().join("../..")
}

fn tool() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_engagement_classifier"));
    c.current_dir(workspace());
    c
}

#[test]
fn the_params_file_holds_the_defaults() {
    let path = workspace().join("params/engagement_classifier.yaml");
    let params = EngagementClassifierParams::from_yaml_file(&path).expect("params file reads");
    assert_eq!(params, EngagementClassifierParams::default());
    assert!(
        workspace().join(&params.model_file).exists(),
        "model_file points at a file"
    );
}

#[test]
fn bad_parameters_are_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let write = |body: &str| {
        let path = dir.path().join("p.yaml");
        let text = format!("engagement_classifier:\n  ros__parameters:\n    {body}\n");
        std::fs::write(&path, text).expect("write");
        EngagementClassifierParams::from_yaml_file(&path)
            .expect_err("refused")
            .to_string()
    };
    assert!(write("smoothing_alpha: 0.0").contains("smoothing_alpha"));
    assert!(write("max_lateness_s: 1.5").contains("max_lateness_s"));
    assert!(write("neutral_label: \"maybe\"").contains("neutral_label"));
    assert!(write("decimal_repair: \"guess\"").contains("decimal_repair"));
    assert!(write("min_confidence_typo: 0.5").contains("min_confidence_typo"));
}

#[test]
fn the_tools_read_a_parameter_file_as_the_node_does() {
    // Shared `/**` sections and the node's own section, merged as ROS 2 (and the node) do.
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("p.yaml");
    std::fs::write(
        &path,
        "/**:\n  ros__parameters:\n    seed: 3\n    smoothing_alpha: 0.5\n\
         engagement_classifier:\n  ros__parameters:\n    smoothing_alpha: 0.25\n",
    )
    .expect("write");
    let params = EngagementClassifierParams::from_yaml_file(&path).expect("reads");
    assert_eq!((params.seed, params.smoothing_alpha), (3, 0.25));
    std::fs::write(&path, "game_manager:\n  ros__parameters: {}\n").expect("write");
    let err = EngagementClassifierParams::from_yaml_file(&path)
        .expect_err("no section for the classifier")
        .to_string();
    assert!(err.contains("engagement_classifier"), "{err}");
}

#[test]
fn predict_writes_margin_and_probability_per_row() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("pred.csv");
    let fixtures = manifest().join("tests/fixtures");
    let status = tool()
        .args(["predict", "--model"])
        .arg(fixtures.join("xgb_preprocessed.json"))
        .arg("--input")
        .arg(fixtures.join("rows.csv"))
        .arg("--output")
        .arg(&out)
        .status()
        .expect("runs");
    assert!(status.success());
    let ours = csv::Reader::from_path(&out).expect("output").into_records();
    let want = csv::Reader::from_path(fixtures.join("xgb_preprocessed_expected.csv"))
        .expect("fixture")
        .into_records();
    let mut n = 0;
    for (a, b) in ours.zip(want) {
        let (a, b) = (a.expect("row"), b.expect("row"));
        for i in 0..2 {
            let (x, y): (f64, f64) = (a[i].parse().expect("num"), b[i].parse().expect("num"));
            assert!((x - y).abs() <= 1e-6, "row {n}: {x} vs {y}");
        }
        n += 1;
    }
    assert_eq!(n, 200);
}

#[test]
fn predict_refuses_a_model_that_is_not_xgboost_json() {
    let fixtures = manifest().join("tests/fixtures");
    let output = tool()
        .args(["predict", "--model"])
        .arg(fixtures.join("rows.csv"))
        .arg("--input")
        .arg(fixtures.join("rows.csv"))
        .output()
        .expect("runs");
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("not an XGBoost JSON model") && stderr.contains("rows.csv"),
        "{stderr}"
    );
}

#[test]
fn synthesize_train_and_cross_validate_from_the_command_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("synthetic.csv");
    let model = dir.path().join("model.json");
    let run = |args: &[&str]| {
        let out = tool().args(args).output().expect("runs");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).to_string()
    };
    let data_s = data.to_str().expect("utf-8 path");
    run(&[
        "synthesize",
        "--participants",
        "3",
        "--frames-per-participant",
        "120",
        "--output",
        data_s,
    ]);
    run(&[
        "train",
        "--data",
        data_s,
        "--output",
        model.to_str().expect("utf-8"),
    ]);
    let loaded = engagement_classifier::EngagementModel::load(&model).expect("model loads");
    assert_eq!(loaded.tree_count(), 100);
    let report = run(&["cross-validate", "--data", data_s]);
    assert!(
        report.contains("S01") && report.contains("mean accuracy"),
        "{report}"
    );
}
