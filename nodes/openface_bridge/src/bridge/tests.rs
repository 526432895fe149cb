//! The core on CSV text: rows become messages stamped from OpenFace's clock, lost faces and low
//! confidence are skipped and counted, every bad-row kind is named once with its line number,
//! a rewritten file is not published twice, and a new run starts a new clock.

use super::*;
use crate::test_csv::{header, row};
use qt_therapy_msgs::Validate;

const S: i64 = 1_000_000_000;
const WALL: i64 = 1_800_000_000 * S;

fn bridge(stamp: StampSource, min_confidence: f64) -> Bridge {
    let params = OpenFaceBridgeParams {
        csv_path: "-".into(),
        frame_id: "cam_front".into(),
        min_confidence,
        ..Default::default()
    };
    Bridge::new(&params, stamp)
}

fn published(out: &[Output]) -> Vec<&OpenFaceFeatures> {
    out.iter()
        .filter_map(|o| match o {
            Output::Publish(m) => Some(m),
            Output::Log(..) => None,
        })
        .collect()
}

fn logs(out: &[Output]) -> Vec<&str> {
    out.iter()
        .filter_map(|o| match o {
            Output::Log(_, l) => Some(l.as_str()),
            Output::Publish(_) => None,
        })
        .collect()
}

/// Feeds `lines` from line 1, each read `lag` after the previous; returns every output.
fn feed(b: &mut Bridge, lines: &[String], from_ns: i64, lag: i64) -> Vec<Output> {
    let mut out = Vec::new();
    for (i, l) in lines.iter().enumerate() {
        out.extend(
            b.line(l, i as u64 + 1, from_ns + i as i64 * lag)
                .expect("the header maps"),
        );
    }
    out
}

#[test]
fn rows_become_messages_stamped_from_openfaces_clock() {
    let mut b = bridge(StampSource::OpenFace, 0.0);
    let lines = vec![
        header(),
        row(1, 0.000, 0.98, true),
        row(2, 0.033, 0.97, true),
        row(3, 0.067, 0.96, true),
    ];
    // The bridge reads the rows late and unevenly: the stamps keep OpenFace's spacing.
    let out = feed(&mut b, &lines, WALL, S / 2);
    let m = published(&out);
    assert_eq!(m.len(), 3);
    let stamps: Vec<i64> = m.iter().map(|m| m.header.stamp.to_nanos()).collect();
    assert_eq!(
        stamps,
        [
            WALL + S / 2,
            WALL + S / 2 + 33_000_000,
            WALL + S / 2 + 67_000_000
        ]
    );
    assert!(
        m.iter()
            .all(|m| m.header.frame_id == "cam_front" && m.face_id == "0")
    );
    assert!((m[1].confidence - 0.97).abs() < 1e-6);
    // Features in the message's order: pose first (frame / 1000), AU flags 1.
    assert_eq!(m[1].features.len(), 32);
    assert!((m[1].features[0] - 0.002).abs() < 1e-6);
    assert_eq!(m[1].features[6], 1.0, "AU01_c");
    assert!(m.iter().all(|m| m.validate().is_ok()));
    assert_eq!(b.counts().published, 3);

    let mut r = bridge(StampSource::Receipt, 0.0);
    let stamps: Vec<i64> = published(&feed(&mut r, &lines, WALL, S / 2))
        .iter()
        .map(|m| m.header.stamp.to_nanos())
        .collect();
    assert_eq!(stamps, [WALL + S / 2, WALL + S, WALL + 3 * S / 2]);
}

#[test]
fn lost_faces_and_low_confidence_are_skipped_and_counted() {
    let mut b = bridge(StampSource::OpenFace, 0.8);
    let lines = vec![
        header(),
        row(1, 0.0, 0.9, true),
        row(2, 0.033, 0.2, false),
        row(3, 0.067, 0.5, true),
        row(4, 0.1, 0.85, true),
    ];
    let out = feed(&mut b, &lines, WALL, 0);
    assert_eq!(published(&out).len(), 2);
    let c = b.counts();
    assert_eq!(
        (c.rows, c.published, c.lost_face, c.low_confidence, c.bad),
        (4, 2, 1, 1, 0)
    );
    assert!(
        b.report()
            .starts_with("4 rows: 2 published, 1 without a face, 1 below")
    );
}

#[test]
fn every_bad_row_kind_is_named_once_with_its_line_and_counted() {
    let mut b = bridge(StampSource::OpenFace, 0.0);
    let good = row(1, 0.0, 0.9, true);
    let out = b.line(&good, 1, WALL).expect("not a header");
    assert_eq!(
        logs(&out),
        [
            "skipped a bad OpenFace CSV row at line 1: a row before any header (rows like it are skipped and counted without another word)"
        ]
    );
    feed(&mut b, &[header()], WALL, 0);
    let short: String = good.split(", ").take(40).collect::<Vec<_>>().join(", ");
    let with = |column: usize, value: &str| {
        let mut f: Vec<String> = good.split(", ").map(String::from).collect();
        f[column] = value.to_string();
        f.join(", ")
    };
    let pose_tx = 5 + 8 + 5 * 56;
    let cases = [
        (short.clone(), "40 fields, the header has"),
        (with(pose_tx, "abc"), "pose_Tx = \"abc\" is not a number"),
        (with(pose_tx, "nan"), "pose_Tx = NaN is not finite"),
        (with(4, "0.5"), "success = 0.5 is not 0 or 1"),
        (with(3, "1.7"), "confidence = 1.7 is not in [0, 1]"),
        (with(1, ""), "face_id is empty"),
        ("x".repeat(70_000), "longer than 65536 bytes"),
    ];
    for (k, (line, says)) in cases.iter().enumerate() {
        let line_no = 10 + k as u64;
        let out = b.line(line, line_no, WALL).expect("not a header");
        assert!(published(&out).is_empty(), "{says}");
        let told = logs(&out);
        assert_eq!(told.len(), 1, "{says}: {told:?}");
        assert!(
            told[0].contains(&format!("line {line_no}: {says}")),
            "{}",
            told[0]
        );
        // The same kind again: counted, not told again.
        let again = b.line(line, line_no + 100, WALL).expect("not a header");
        assert!(again.is_empty(), "{says}: {again:?}");
    }
    // Another value that is not finite is the same kind: counted without a word.
    assert!(b.line(&with(2, "inf"), 50, WALL).expect("row").is_empty());
    assert_eq!(b.counts().bad, 1 + 2 * cases.len() as u64 + 1);
    // Good rows still flow.
    assert_eq!(published(&b.line(&good, 99, WALL).expect("row")).len(), 1);
}

#[test]
fn a_header_without_a_needed_column_is_refused_by_name() {
    let mut b = bridge(StampSource::OpenFace, 0.0);
    let no_pose = header().replace("pose_Rz, ", "");
    assert_eq!(
        b.line(&no_pose, 1, WALL),
        Err(HeaderError::Missing("pose_Rz".into()))
    );
}

#[test]
fn a_rewritten_file_is_not_published_twice_and_a_new_run_gets_a_new_clock() {
    let mut b = bridge(StampSource::OpenFace, 0.0);
    let run: Vec<String> = std::iter::once(header())
        .chain((1..=8).map(|f| row(f, f64::from(f - 1) / 30.0, 0.9, true)))
        .collect();
    assert_eq!(published(&feed(&mut b, &run, WALL, S / 30)).len(), 8);
    // OpenFace ends and rewrites the file (post-processed AUs), all of it at once: the same
    // frames and timestamps, and two more it had not flushed.
    b.restarted("replaced");
    let mut rewritten = run.clone();
    rewritten.extend((9..=10).map(|f| row(f, f64::from(f - 1) / 30.0, 0.9, true)));
    let out = feed(&mut b, &rewritten, WALL + 10 * S, 0);
    let again = published(&out);
    assert_eq!(again.len(), 2, "only frames 9 and 10 are new");
    // Stamped on the first run's clock: frame 1 was read one line after the header (S / 30
    // after WALL), frame 9 is OpenFace's 0.267 s after it.
    assert_eq!(
        again[0].header.stamp.to_nanos(),
        WALL + S / 30 + 267_000_000
    );
    assert_eq!(b.counts().already_published, 8);
    assert!(
        logs(&out)
            .iter()
            .any(|l| l.contains("OpenFace rewrote its run"))
    );

    // OpenFace started again on the same video: the same timestamps, but at the camera's
    // pace, so a new run with a new clock.
    b.restarted("truncated");
    let again_video: Vec<String> = std::iter::once(header())
        .chain((1..=6).map(|f| row(f, f64::from(f - 1) / 30.0, 0.95, true)))
        .collect();
    let m: Vec<i64> = published(&feed(&mut b, &again_video, WALL + 60 * S, S / 30))
        .iter()
        .map(|m| m.header.stamp.to_nanos())
        .collect();
    assert_eq!(m.len(), 6, "held until five rows decided, then all of them");
    assert_eq!(m[0], WALL + 60 * S + S / 30);
    assert_eq!(m[1], m[0] + 33_000_000);

    // A webcam run: other timestamps from its first row on: decided at once.
    b.restarted("truncated");
    let out = feed(
        &mut b,
        &[header(), row(1, 0.041, 0.95, true)],
        WALL + 90 * S,
        0,
    );
    assert_eq!(published(&out).len(), 1);
    assert_eq!(b.counts().runs, 4);
    assert_eq!(b.counts().already_published, 8);
}
