//! Checks on the real MigrAVE data beside the repository (`../shared`, or `QT_SHARED_DIR`);
//! each test passes with a note when the data is not there.

use engagement_classifier::features::canonical_index;
use engagement_classifier::plot::{EngagementPlot, engagement_svg};
use engagement_classifier::repair::DecimalRepair;
use engagement_classifier::study::load_study_session;
use engagement_classifier::table::{LoadOptions, NeutralLabel, load_labelled_csv};
use std::path::{Path, PathBuf};

fn shared() -> Option<PathBuf> {
    let dir = std::env::var_os("QT_SHARED_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared"));
    if dir.join("data").is_dir() {
        Some(dir)
    } else {
        println!("skipping: ../shared not found");
        None
    }
}

#[test]
fn the_dirty_frames_load_and_every_lost_decimal_point_is_restored() {
    let Some(shared) = shared() else { return };
    let path = shared.join("data/migrave-engagement/frames.csv");
    let options = LoadOptions {
        neutral_label: NeutralLabel::Engaged,
        decimal_repair: DecimalRepair::Magnitude,
    };
    let (table, report) = load_labelled_csv(&path, &options).expect("frames load");
    assert_eq!(report.rows_read, 3690);
    assert_eq!(report.neutral_rows, 1270);
    assert_eq!(report.dotless_values.iter().sum::<usize>(), 4325);
    assert_eq!(report.dotless_rows, 2581);
    assert_eq!(report.set_missing, 0);
    assert_eq!(table.participant_ids(), vec!["1", "2", "3", "4"]);
    assert!(table.rows.iter().flatten().all(|v| v.is_finite()));
    // After repair every value is in a physical range: angles in radians, gaze angles small,
    // positions within 2 m of the camera.
    let max_abs = |name: &str| {
        let c = canonical_index(name).expect("feature");
        table.rows.iter().map(|r| r[c].abs()).fold(0.0, f64::max)
    };
    for name in ["pose_Rx", "pose_Ry", "pose_Rz"] {
        assert!(
            max_abs(name) <= std::f64::consts::PI + 0.01,
            "{name} {}",
            max_abs(name)
        );
    }
    for name in ["gaze_angle_x", "gaze_angle_y"] {
        assert!(max_abs(name) < 1.6, "{name} {}", max_abs(name));
    }
    for name in ["pose_Tx", "pose_Ty", "pose_Tz", "gaze_0_z", "gaze_1_z"] {
        assert!(max_abs(name) < 2000.0, "{name} {}", max_abs(name));
    }
    // Policy drop keeps only the +-1 frames.
    let drop = LoadOptions {
        neutral_label: NeutralLabel::Drop,
        ..options
    };
    let (table, _) = load_labelled_csv(&path, &drop).expect("frames load");
    assert_eq!(table.len(), 3690 - 1270);
}

#[test]
fn smoothing_reproduces_the_authors_notebook_on_the_study_series() {
    let Some(shared) = shared() else { return };
    let dir = shared.join("data/migrave-study");
    let session = load_study_session(&dir, "03DEQR1O", 0.75).expect("session loads");
    // engagement_per_second.csv holds the raw values; the authors' merger notebook prints
    // ewm(alpha=0.75).mean() of them: -0.333333 -0.866667 0.250794 0.814902 0.953861.
    let printed = [-0.333333, -0.866667, 0.250794, 0.814902, 0.953861];
    for (s, p) in session.smoothed.iter().zip(printed) {
        assert!((s - p).abs() < 5e-7, "{s} vs {p}");
    }
}

#[test]
fn the_study_session_of_the_authors_example_participant_plots() {
    let Some(shared) = shared() else { return };
    let dir = shared.join("data/migrave-study");
    let session = load_study_session(&dir, "1CZ1CL1P", 0.75).expect("session loads");
    assert_eq!(session.answers.len(), 10);
    // lengths 7 7 5 5 3 3 3 5 5 7: stages end at answers 2, 4, 7, 9 and 10
    let lengths: Vec<u8> = session.stage_ends.iter().map(|s| s.1).collect();
    assert_eq!(lengths, vec![7, 5, 3, 5, 7]);
    assert_eq!(session.stage_ends[0].0, session.answers[1]);
    let svg = engagement_svg(&EngagementPlot {
        title: "1CZ1CL1P",
        seconds: &session.seconds,
        engagement: &session.engagement,
        smoothed: &session.smoothed,
        answers: &session.answers,
        stage_ends: &session.stage_ends,
    })
    .expect("draws");
    assert!(svg.contains("L = 3"));
    let err = load_study_session(&dir, "NOBODY", 0.75).expect_err("unknown participant");
    assert!(err.to_string().contains("1CZ1CL1P"), "{err}");
}
