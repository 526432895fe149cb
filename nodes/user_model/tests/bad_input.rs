//! Bad input is refused with an error naming the record or field, and nothing is written
//! half-way: too few users for c clusters, a cluster of one user, NaN or out-of-range values,
//! a truncated or wrong-version model file.

use user_model::data::{InteractionRecord, write_csv};
use user_model::simulate::{StudySpec, simulate_study};
use user_model::{FitOptions, UserModelError, UserModelSet, fit};

fn study() -> Vec<InteractionRecord> {
    simulate_study(&StudySpec::default())
}

#[test]
fn too_few_users_for_the_clusters() {
    let records: Vec<_> = study()
        .into_iter()
        .filter(|r| r.user_id.as_str() <= "sim-03")
        .collect();
    let e = fit(&records, &FitOptions::default()).expect_err("3 users, 2 clusters");
    assert!(matches!(
        e,
        UserModelError::TooFewUsers {
            users: 3,
            clusters: 2
        }
    ));
    assert!(
        e.to_string().contains("3 users cannot make 2 clusters"),
        "{e}"
    );
    let e = fit(
        &study(),
        &FitOptions {
            clusters: 0,
            ..Default::default()
        },
    )
    .expect_err("no clusters");
    assert!(e.to_string().contains("clusters"), "{e}");
}

#[test]
fn a_cluster_of_one_user_is_named() {
    let mut records = study();
    // One user far from both groups: never succeeds, neutral engagement.
    let mut outlier: Vec<InteractionRecord> = records
        .iter()
        .filter(|r| r.user_id == "sim-01")
        .cloned()
        .collect();
    for r in outlier.iter_mut() {
        r.user_id = "outlier".into();
        r.outcome = sequence_game::Outcome::Failure;
        r.score = r.outcome.score(r.level);
        r.engagement = Some(0.0);
    }
    records.extend(outlier);
    let e = fit(
        &records,
        &FitOptions {
            clusters: 3,
            ..Default::default()
        },
    )
    .expect_err("a cluster of one");
    match &e {
        UserModelError::ClusterTooSmall { users, .. } => assert_eq!(users, &["outlier"]),
        other => panic!("{other}"),
    }
    assert!(e.to_string().contains("1 user(s) (outlier)"), "{e}");
}

#[test]
fn nan_and_out_of_range_records_are_named() {
    let mut records = study();
    records[41].engagement = Some(f64::NAN);
    let e = fit(&records, &FitOptions::default()).expect_err("NaN");
    assert!(e.to_string().contains("record 42, field engagement"), "{e}");
    let mut records = study();
    records[7].engagement_per_second[2] = -1.5;
    let e = fit(&records, &FitOptions::default()).expect_err("out of range");
    assert!(
        e.to_string()
            .contains("record 8, field engagement_per_second"),
        "{e}"
    );
    let mut records = study();
    records[3].previous_score = 6;
    let e = fit(&records, &FitOptions::default()).expect_err("PS");
    assert!(
        e.to_string().contains("record 4, field previous_score"),
        "{e}"
    );
    let mut records = study();
    records[9].response_time = f64::INFINITY;
    let e = fit(&records, &FitOptions::default()).expect_err("response time");
    assert!(
        e.to_string().contains("record 10, field response_time"),
        "{e}"
    );
}

#[test]
fn a_user_without_engagement_at_a_level_is_named() {
    let mut records = study();
    for r in records
        .iter_mut()
        .filter(|r| r.user_id == "sim-05" && r.level.get() == 2)
    {
        r.engagement = None;
    }
    let e = fit(&records, &FitOptions::default()).expect_err("missing level");
    assert!(
        e.to_string()
            .contains("user sim-05 has no level-2 sequence"),
        "{e}"
    );
}

fn saved_model(dir: &std::path::Path) -> (std::path::PathBuf, String) {
    let set = fit(&study(), &FitOptions::default()).expect("fits");
    let path = dir.join("model.json");
    set.save(&path).expect("saves");
    let text = std::fs::read_to_string(&path).expect("reads");
    (path, text)
}

#[test]
fn truncated_wrong_version_and_bad_field_model_files_are_named() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (path, text) = saved_model(dir.path());
    let bad = dir.path().join("bad.json");

    std::fs::write(&bad, &text[..text.len() / 2]).expect("writes");
    let e = UserModelSet::load(&bad).expect_err("truncated").to_string();
    assert!(e.contains("bad.json") && e.contains("truncated"), "{e}");

    std::fs::write(&bad, text.replacen("\"version\": 2", "\"version\": 1", 1)).expect("writes");
    let e = UserModelSet::load(&bad).expect_err("version");
    assert!(matches!(e, UserModelError::Version { found: 1, .. }), "{e}");
    assert!(
        e.to_string()
            .contains("format version 1; this program reads version 2"),
        "{e}"
    );

    std::fs::write(
        &bad,
        text.replacen(
            "\"format\": \"qt_therapy user models\"",
            "\"format\": \"other\"",
            1,
        ),
    )
    .expect("writes");
    let e = UserModelSet::load(&bad).expect_err("format").to_string();
    assert!(e.contains("field format"), "{e}");

    let mut value: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    value["clusters"][1]["engagement"]["targets"][0] = serde_json::json!(3.5);
    std::fs::write(&bad, value.to_string()).expect("writes");
    let e = UserModelSet::load(&bad).expect_err("target").to_string();
    assert!(e.contains("field clusters[1].engagement.targets[0]"), "{e}");

    let mut value: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    value["clusters"][0]["success"]["kernel"]["alpha"] = serde_json::json!("wide");
    std::fs::write(&bad, value.to_string()).expect("writes");
    let e = UserModelSet::load(&bad).expect_err("alpha").to_string();
    assert!(e.contains("field clusters[0].success.kernel"), "{e}");

    let mut value: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    value["pca"]["components"][1] = serde_json::json!([0.0, 1.0]);
    std::fs::write(&bad, value.to_string()).expect("writes");
    let e = UserModelSet::load(&bad).expect_err("pca").to_string();
    assert!(e.contains("field pca.components[1]"), "{e}");

    let mut value: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    value["centres"].as_array_mut().expect("centres").pop();
    std::fs::write(&bad, value.to_string()).expect("writes");
    let e = UserModelSet::load(&bad).expect_err("centres").to_string();
    assert!(e.contains("field centres"), "{e}");

    // The good file was never touched.
    assert_eq!(std::fs::read_to_string(&path).expect("reads"), text);
    UserModelSet::load(&path).expect("still loads");
}

#[test]
fn saving_replaces_the_whole_file_or_nothing() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (path, text) = saved_model(dir.path());
    // A failed fit never reaches save; a failed CSV write leaves the old file and no temp file.
    let csv = dir.path().join("records.csv");
    write_csv(&csv, &study()).expect("writes");
    let before = std::fs::read(&csv).expect("reads");
    let mut records = study();
    records[199].time = f64::NAN;
    let e = write_csv(&csv, &records).expect_err("NaN time");
    assert!(e.to_string().contains("record 200, field time"), "{e}");
    assert_eq!(std::fs::read(&csv).expect("reads"), before);
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .expect("lists")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names.len(), 2, "{names:?}");
    // Saving over an existing model replaces it with a complete file.
    let other = fit(
        &study(),
        &FitOptions {
            seed: 8,
            optimise: false,
            ..Default::default()
        },
    )
    .expect("fits");
    other.save(&path).expect("saves");
    assert_ne!(std::fs::read_to_string(&path).expect("reads"), text);
    assert_eq!(
        UserModelSet::load(&path).expect("loads").tables(),
        other.tables()
    );
}
