//! Fitting the real MigrAVE study (beside the repository in ../shared) gives the paper's two
//! clusters of 11 and 9 users, alike in success and far apart in engagement; the saved file
//! loads back to identical predictions; bad input is refused by name.

use std::path::PathBuf;
use user_model::{FitOptions, UserModelError, UserModelSet, fit};

fn study() -> Option<PathBuf> {
    let dir = std::env::var_os("QT_SHARED_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared"))
        .join("data/migrave-study");
    if dir.join("sequences.csv").exists() {
        Some(dir)
    } else {
        eprintln!("skipping: ../shared not found");
        None
    }
}

#[test]
fn real_study_gives_the_papers_clusters_and_round_trips() {
    let Some(dir) = study() else { return };
    let records = user_model::data::read_study(&dir).expect("reads the study");
    assert_eq!(records.len(), 200);
    let set = fit(&records, &FitOptions::default()).expect("fits");
    let mut sizes: Vec<usize> = set.file().clusters.iter().map(|c| c.users.len()).collect();
    sizes.sort();
    assert_eq!(sizes, [9, 11]);
    let (a, b) = (
        &set.file().clusters[0].levels,
        &set.file().clusters[1].levels,
    );
    for l in 0..3 {
        assert!(
            (a[l].success_mean - b[l].success_mean).abs() < 0.15,
            "level {} success",
            l + 1
        );
        assert!(
            (a[l].engagement_mean - b[l].engagement_mean).abs() > 0.9,
            "level {} engagement",
            l + 1
        );
    }
    let dir = tempfile_dir();
    let path = dir.join("m.json");
    set.save(&path).expect("saves");
    let back = UserModelSet::load(&path).expect("loads");
    assert_eq!(
        back.tables(),
        set.tables(),
        "a loaded model predicts exactly as the fitted one"
    );
    let _ = std::fs::remove_dir_all(dir);
}

fn tempfile_dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("user_model_test_{}", std::process::id()));
    std::fs::create_dir_all(&d).expect("temp dir");
    d
}

#[test]
fn bad_input_is_refused_by_name() {
    let records = user_model::simulate::simulate_study(&Default::default());
    let few: Vec<_> = records
        .iter()
        .filter(|r| r.user_id <= "sim-03".to_string())
        .cloned()
        .collect();
    assert!(matches!(
        fit(&few, &FitOptions::default()),
        Err(UserModelError::TooFewUsers {
            users: 3,
            clusters: 2
        })
    ));
    let e = fit(
        &records,
        &FitOptions {
            clusters: 9,
            ..Default::default()
        },
    )
    .err()
    .expect("too many clusters");
    assert!(e.to_string().contains("user"), "{e}");
    let dir = tempfile_dir();
    let path = dir.join("bad.json");
    std::fs::write(
        &path,
        "{\"format\": \"qt_therapy user models\", \"version\": 99}",
    )
    .expect("write");
    assert!(matches!(
        UserModelSet::load(&path),
        Err(UserModelError::Version { found: 99, .. })
    ));
    std::fs::write(&path, "{\"format\": \"qt_therapy user mod").expect("write");
    let e = UserModelSet::load(&path).err().expect("truncated");
    assert!(
        e.to_string().contains("bad.json") && e.to_string().contains("truncated"),
        "{e}"
    );
    let csv = dir.join("records.csv");
    user_model::data::write_csv(&csv, &records).expect("writes");
    let text = std::fs::read_to_string(&csv).expect("read").replacen(
        "sim-01,sim-01-s1,",
        "sim-01,sim-01-s1,NaN-time,",
        1,
    );
    std::fs::write(&csv, text).expect("write");
    let e = user_model::data::read_csv(&csv).err().expect("bad record");
    assert!(e.to_string().contains("record 1"), "{e}");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn synthetic_study_round_trips_through_csv_and_fits_two_groups() {
    let records = user_model::simulate::simulate_study(&Default::default());
    let dir = tempfile_dir().join("csv");
    let path = dir.join("synthetic.csv");
    user_model::data::write_csv(&path, &records).expect("writes");
    let back = user_model::data::read_csv(&path).expect("reads");
    assert_eq!(back.len(), records.len());
    let set = fit(&back, &FitOptions::default()).expect("fits");
    let mut sizes: Vec<usize> = set.file().clusters.iter().map(|c| c.users.len()).collect();
    sizes.sort();
    assert_eq!(sizes, [9, 11]);
    let v = [0.95, 0.5, 0.9, 0.6, 0.5, 0.55];
    let engaged_cluster = set.assign_cluster(&v).expect("assigns");
    assert!(set.file().clusters[engaged_cluster].levels[0].engagement_mean > 0.0);
    assert!(set.assign_cluster(&[2.0, 0.0, 0.0, 0.0, 0.0, 0.0]).is_err());
    let _ = std::fs::remove_dir_all(dir);
}
