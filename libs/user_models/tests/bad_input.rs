//! Bad input is refused with an error naming the record or field, and nothing is written
//! half-way: too few users for c clusters, a cluster of one user, NaN or out-of-range values,
//! a truncated or wrong-version model file; a truncated session bag (the sequences before the
//! damage, and a warning naming the record), a bag without the topics the records need.

mod common;

use user_models::data::bag::read_bag;
use user_models::data::{DataError, InteractionRecord, read_any, write_csv};
use user_models::simulate::{StudySpec, simulate_study};
use user_models::{FitOptions, UserModelError, UserModelSet, fit};

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
    assert!(
        matches!(
            e,
            UserModelError::File(versioned_json::FileError::Version { found: 1, .. })
        ),
        "{e}"
    );
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

#[test]
fn a_truncated_bag_gives_the_sequences_before_the_damage_and_names_the_record() {
    let records = common::at_bag_precision(&study());
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("session.mcap");
    // Small chunks, so a cut loses only the end.
    let options = bag_file::WriterOptions {
        chunk_size: 8 * 1024,
        ..Default::default()
    };
    common::write_bag_with(&path, &records, &options);
    let whole = read_bag(&path).expect("reads the whole bag");
    assert_eq!((whole.records.len(), whole.warnings.len()), (200, 0));
    let bytes = std::fs::read(&path).expect("reads");
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 6 / 10]).expect("writes");
    let read = read_bag(&cut).expect("reads what precedes the damage");
    let n = read.records.len();
    assert!(n > 50 && n < 200, "{n} records");
    // Exactly the first n sequences (written in time order), each whole.
    assert_eq!(read.records, records[..n]);
    assert_eq!(read.warnings.len(), 1, "{:?}", read.warnings);
    let w = &read.warnings[0];
    assert!(
        w.contains("cut.mcap is damaged")
            && w.contains(&format!("the {n} sequence results before the damage"))
            && w.contains("record #")
            && w.contains("truncated"),
        "{w}"
    );
    // Cut inside the first chunk: nothing to learn from, said clearly.
    std::fs::write(&cut, &bytes[..200]).expect("writes");
    let e = read_bag(&cut).expect_err("nothing left").to_string();
    assert!(e.contains("cut.mcap: no topic"), "{e}");
    std::fs::write(&cut, b"not a bag at all").expect("writes");
    let e = read_any(&cut).expect_err("not MCAP").to_string();
    assert!(e.contains("cut.mcap: not an MCAP file"), "{e}");
}

#[test]
fn a_bag_without_the_needed_topics_is_named() {
    use qt_therapy_msgs::topics::{GAME_STATE, HEARTBEAT, SEQUENCE_RESULT, TABLET_TASK};
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("heartbeats.mcap");
    let mut w =
        bag_file::BagWriter::create(&path, &bag_file::WriterOptions::default()).expect("creates");
    let beat = w.add_topic(HEARTBEAT).expect("topic");
    w.write(beat, 1, &qt_therapy_msgs::Heartbeat::default())
        .expect("writes");
    w.finish().expect("finishes");
    let e = read_bag(&path).expect_err("no results");
    assert!(matches!(e, DataError::MissingTopic { .. }), "{e}");
    assert!(
        e.to_string().contains(
            "heartbeats.mcap: no topic \"/qt_therapy/game/sequence_result\" in the bag, which user-model data needs"
        ),
        "{e}"
    );
    // Results without the engagement topic: named too.
    let records = common::at_bag_precision(&study()[..10]);
    let full = dir.path().join("full.mcap");
    common::write_bag(&full, &records);
    let reader = bag_file::BagReader::open(&full).expect("opens");
    let path = dir.path().join("no_engagement.mcap");
    let mut w =
        bag_file::BagWriter::create(&path, &bag_file::WriterOptions::default()).expect("creates");
    let states = w.add_topic(GAME_STATE).expect("topic");
    let results = w.add_topic(SEQUENCE_RESULT).expect("topic");
    let tasks = w.add_topic(TABLET_TASK).expect("topic");
    for m in reader.topic(GAME_STATE).expect("states") {
        w.write(states, m.log_time, &m.message).expect("writes");
    }
    for m in reader.topic(TABLET_TASK).expect("tasks") {
        w.write(tasks, m.log_time, &m.message).expect("writes");
    }
    for m in reader.topic(SEQUENCE_RESULT).expect("results") {
        w.write(results, m.log_time, &m.message).expect("writes");
    }
    w.finish().expect("finishes");
    let e = read_bag(&path).expect_err("no engagement").to_string();
    assert!(
        e.contains("no topic \"/qt_therapy/engagement/expected\"")
            && e.contains("per-second engagement"),
        "{e}"
    );
    assert_eq!(read_bag(&full).expect("reads").records, records);
}
