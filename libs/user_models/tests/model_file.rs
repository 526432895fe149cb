//! The model file: a fitted set saves and loads back to identical predictions, the committed
//! synthetic model is what the synthetic study fits to, tables hold every prediction, and new
//! users are assigned to the nearest cluster.

use sequence_game::{ModelInput, Outcome};
use std::path::Path;
use user_models::simulate::{StudySpec, simulate_study};
use user_models::{FitOptions, Kernel, UserModelSet, fit};

#[test]
fn save_then_load_predicts_identically_for_every_kernel() {
    let records = simulate_study(&StudySpec::default());
    let dir = tempfile::tempdir().expect("temp dir");
    for kernel in [
        Kernel::AUTHORS,
        Kernel::Rbf { length_scale: 1.0 },
        Kernel::Matern {
            length_scale: 1.0,
            nu: 2.5,
        },
    ] {
        let set = fit(
            &records,
            &FitOptions {
                kernel,
                ..Default::default()
            },
        )
        .expect("fits");
        let path = dir.path().join(format!("{}.json", kernel.name()));
        set.save(&path).expect("saves");
        let back = UserModelSet::load(&path).expect("loads");
        assert_eq!(back.file(), set.file());
        assert_eq!(back.tables(), set.tables(), "{kernel:?}");
    }
}

#[test]
fn a_fitted_noise_is_kept_in_the_file_and_bad_group_sizes_are_named() {
    let records = simulate_study(&StudySpec::default());
    let dir = tempfile::tempdir().expect("temp dir");
    let set = fit(
        &records,
        &FitOptions {
            noise_model: user_models::NoiseModel::FittedPerSequence,
            ..Default::default()
        },
    )
    .expect("fits");
    for c in &set.file().clusters {
        for g in [&c.success, &c.engagement] {
            let sizes = g.group_sizes.as_ref().expect("group sizes");
            assert_eq!(sizes.len(), g.targets.len());
            assert!(sizes.iter().all(|n| *n >= 1));
            assert!(g.noise > 1e-5 && g.noise < 1.0, "noise {}", g.noise);
        }
    }
    let path = dir.path().join("fitted.json");
    set.save(&path).expect("saves");
    let back = UserModelSet::load(&path).expect("loads");
    assert_eq!(back.file(), set.file());
    assert_eq!(back.tables(), set.tables());
    // The paper's fit writes no group sizes: its files stay as they were.
    let paper = fit(&records, &FitOptions::default()).expect("fits");
    let paper_path = dir.path().join("paper.json");
    paper.save(&paper_path).expect("saves");
    let text = std::fs::read_to_string(&paper_path).expect("reads");
    assert!(!text.contains("group_sizes"));
    // A group of no sequences, or sizes that do not match the targets, are named.
    let text = std::fs::read_to_string(&path).expect("reads");
    let bad = dir.path().join("bad.json");
    for (change, field) in [
        (serde_json::json!([0]), "clusters[0].success.group_sizes"),
        (
            serde_json::Value::Null,
            "clusters[0].success.group_sizes[0]",
        ),
    ] {
        let mut value: serde_json::Value = serde_json::from_str(&text).expect("JSON");
        let sizes = &mut value["clusters"][0]["success"]["group_sizes"];
        if change.is_null() {
            sizes[0] = serde_json::json!(0);
        } else {
            *sizes = change;
        }
        std::fs::write(&bad, value.to_string()).expect("writes");
        let e = UserModelSet::load(&bad).expect_err("refused").to_string();
        assert!(e.contains(&format!("field {field}")), "{e}");
    }
}

#[test]
fn tables_hold_clamped_predictions_with_uncertainty() {
    let set = fit(
        &simulate_study(&StudySpec::default()),
        &FitOptions::default(),
    )
    .expect("fits");
    let tables = set.tables();
    assert_eq!(tables.len(), 2);
    for t in &tables {
        t.validate().expect("valid table");
        // Unobserved inputs are uncertain, observed ones less so.
        let observed: Vec<f64> = set.file().clusters[t.cluster]
            .success
            .inputs
            .iter()
            .filter_map(|x| {
                ModelInput::all()
                    .find(|i| &user_models::model::encode(*i, None) == x)
                    .map(|i| t.success(i).std)
            })
            .collect();
        let max_std = t.success.iter().map(|p| p.std).fold(0.0, f64::max);
        assert!(observed.iter().all(|s| *s < 1e-3), "{observed:?}");
        assert!(max_std > 0.01, "{max_std}");
        for i in ModelInput::all() {
            for o in Outcome::ALL {
                assert_eq!(t.engagement(i, o), t.engagement[i.engagement_index(o)]);
            }
        }
    }
}

#[test]
fn committed_synthetic_model_is_what_the_synthetic_study_fits_to() {
    let committed = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../nodes/user_model/models/synthetic_study_c2.json");
    let model = UserModelSet::load(&committed).expect("loads");
    let set = fit(
        &simulate_study(&StudySpec::default()),
        &FitOptions::default(),
    )
    .expect("fits");
    let mut fresh = set.file().clone();
    fresh.provenance = model.file().provenance.clone();
    assert_eq!(&fresh, model.file());
    assert_eq!(set.tables(), model.tables());
}

#[test]
fn new_users_go_to_the_nearest_cluster() {
    let set = fit(
        &simulate_study(&StudySpec::default()),
        &FitOptions::default(),
    )
    .expect("fits");
    let engaged = set
        .assign_cluster(&[0.95, 0.5, 0.9, 0.6, 0.5, 0.55])
        .expect("assigns");
    let disengaged = set
        .assign_cluster(&[0.95, -0.6, 0.9, -0.5, 0.5, -0.7])
        .expect("assigns");
    assert_ne!(engaged, disengaged);
    assert!(set.file().clusters[engaged].levels[0].engagement_mean > 0.0);
    assert!(set.file().clusters[disengaged].levels[0].engagement_mean < 0.0);
    let e = set
        .assign_cluster(&[1.2, 0.0, 0.5, 0.0, 0.5, 0.0])
        .expect_err("P > 1");
    assert!(e.to_string().contains("value 0 = 1.2"), "{e}");
    assert!(
        set.assign_cluster(&[0.5, f64::NAN, 0.5, 0.0, 0.5, 0.0])
            .is_err()
    );
}

#[test]
fn a_file_with_more_training_rows_than_input_groups_is_refused_before_refitting() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../nodes/user_model/models/synthetic_study_c2.json");
    let text = std::fs::read_to_string(&path).expect("reads");
    let mut value: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    // Refitting is cubic in the rows: a few thousand would hang the loading node.
    let success = &mut value["clusters"][0]["success"];
    let row = success["inputs"][0].clone();
    let target = success["targets"][0].clone();
    let groups = ModelInput::all().count();
    success["inputs"] = serde_json::Value::Array(vec![row; groups + 1]);
    success["targets"] = serde_json::Value::Array(vec![target; groups + 1]);
    let e = UserModelSet::from_json_str(&value.to_string(), &path)
        .expect_err("too many rows")
        .to_string();
    assert!(
        e.contains("field clusters[0].success.inputs") && e.contains("at most one per"),
        "{e}"
    );
    UserModelSet::from_json_str(&text, &path).expect("the shipped model loads");
}
