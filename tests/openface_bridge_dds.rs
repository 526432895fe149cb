//! The OpenFace bridge over real DDS: rows appended to a CSV while the bridge follows it reach
//! the real engagement classifier and come out as per-frame estimates, in order and none lost,
//! stamped with OpenFace's spacing; a row written in two halves is one frame; a bad row is
//! named and skipped; the file truncated by a new OpenFace run is read again, on a new clock.
//! The classifier's seconds also come out the ROS4HRI way, the face a tracked person. Every
//! process runs in one private loopback-only network namespace.

use std::fmt::Write as _;
use std::time::Duration;
use suite_tests::{json_lines, run_in_loopback_netns, workspace_bin};

/// The columns OpenFace writes with -pose -aus -gaze, in its order (landmarks left out; the
/// bridge maps by name).
fn header() -> String {
    let mut names: Vec<String> = ["frame", "face_id", "timestamp", "confidence", "success"]
        .map(String::from)
        .to_vec();
    names.extend(
        qt_therapy_msgs::OPENFACE_FEATURES[24..]
            .iter()
            .map(|s| s.to_string()),
    );
    names.extend(
        qt_therapy_msgs::OPENFACE_FEATURES[..6]
            .iter()
            .map(|s| s.to_string()),
    );
    names.push("AU01_r".into());
    names.extend(
        qt_therapy_msgs::OPENFACE_FEATURES[6..24]
            .iter()
            .map(|s| s.to_string()),
    );
    names.join(", ")
}

/// Frame `frame` at OpenFace time `t` (s): a face looking at the camera.
fn row(frame: u32, t: f64) -> String {
    let mut f = format!("{frame}, 0, {t:.3}, 0.98, 1");
    // gaze (8), pose (6), AU01_r, AU flags (18)
    for v in [0.02, 0.1, -0.99, -0.03, 0.1, -0.99, 0.0, 0.1] {
        let _ = write!(f, ", {v}");
    }
    for v in [10.0, 20.0, 450.0, 0.05, -0.02, 0.01] {
        let _ = write!(f, ", {v}");
    }
    f.push_str(", 0.3");
    for k in 0..18 {
        f.push_str(if k % 3 == 0 { ", 1" } else { ", 0" });
    }
    f
}

/// A run's rows at 30 fps from frame 1, the first at OpenFace time `t0` (a webcam run starts
/// when its first frame is read, a little after 0).
fn rows(n: u32, t0: f64) -> Vec<String> {
    (1..=n)
        .map(|k| row(k, t0 + f64::from(k - 1) / 30.0))
        .collect()
}

#[test]
fn appended_rows_reach_the_classifier_in_order_through_a_restart() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    let write = |name: &str, lines: &[String]| {
        let text: String = lines.iter().map(|l| format!("{l}\n")).collect();
        std::fs::write(d.join(name), text).expect("writes a chunk");
    };
    // Run 1: the header and 60 rows in chunks of 5 (a camera's pace), row 23 written in two
    // halves, a line of garbage after row 40. Run 2: OpenFace started again: truncated, a
    // header and 30 rows.
    let first = rows(60, 0.033);
    write("header", &[header()]);
    for (k, chunk) in first.chunks(5).enumerate() {
        write(&format!("run1_{k:02}"), chunk);
    }
    write("garbage", &["this is not a row".to_string()]);
    let second = rows(30, 0.041);
    for (k, chunk) in second.chunks(5).enumerate() {
        write(&format!("run2_{k:02}"), chunk);
    }
    // Row 23 (chunk 4, its third line) cut in the middle.
    let chunk4 = std::fs::read_to_string(d.join("run1_04")).expect("reads");
    let cut = chunk4.find("23, 0,").expect("row 23") + 30;
    std::fs::write(d.join("run1_04a"), &chunk4[..cut]).expect("writes");
    std::fs::write(d.join("run1_04b"), &chunk4[cut..]).expect("writes");

    let mut appends = String::new();
    for k in 0..12 {
        if k == 4 {
            appends.push_str(
                "cat run1_04a >> webcam.csv; sleep 0.3; cat run1_04b >> webcam.csv; sleep 0.15\n",
            );
        } else {
            let _ = writeln!(appends, "cat run1_{k:02} >> webcam.csv; sleep 0.15");
        }
        if k == 7 {
            appends.push_str("cat garbage >> webcam.csv\n");
        }
    }
    appends.push_str("sleep 1; : > webcam.csv; cat header >> webcam.csv\n");
    for k in 0..6 {
        let _ = writeln!(appends, "cat run2_{k:02} >> webcam.csv; sleep 0.15");
    }
    let script = format!(
        r#"
        export ROS_LOCALHOST_ONLY=1 QT_PARAMS_DIR=params RUST_BACKTRACE=0
        cd {d}
        {probe} --params-file {root}/tests/params/dds_probe.yaml estimates --person face_cam_front_0 > est.out 2> est.err &
        P=$!
        {classifier} run --params-file {root}/params/engagement_classifier.yaml \
          --param model_file:={root}/nodes/engagement_classifier/models/synthetic_engagement.json > cls.out 2> cls.err &
        C=$!
        {bridge} --params-file {root}/params/openface_bridge.yaml --csv webcam.csv \
          --param frame_id:=cam_front > bridge.out 2> bridge.err &
        B=$!
        # Discovery first: the frames are best effort, so nobody must be late for them.
        sleep 3
        cat header > webcam.csv
        {appends}
        sleep 2
        kill -INT $B; wait $B; echo "bridge_exit=$?"
        kill -INT $C $P; wait $C $P
        "#,
        d = d.display(),
        root = suite_tests::workspace_root().display(),
        probe = env!("CARGO_BIN_EXE_dds_probe"),
        classifier = workspace_bin("engagement_classifier").display(),
        bridge = workspace_bin("openface_bridge").display(),
    );
    let Some(out) = run_in_loopback_netns(&script, Duration::from_secs(120)) else {
        return;
    };
    let read = |f: &str| std::fs::read_to_string(d.join(f)).unwrap_or_default();
    let context = format!(
        "script:\n{}\n{}\nbridge:\n{}\nclassifier:\n{}\nprobe:\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
        read("bridge.err"),
        read("cls.err"),
        read("est.err"),
    );
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("bridge_exit=0"),
        "{context}"
    );
    let estimates: Vec<serde_json::Value> = json_lines(&read("est.out"))
        .into_iter()
        .filter(|e| e["event"] == "estimate")
        .collect();
    // None lost: every row of both runs, once.
    assert_eq!(estimates.len(), first.len() + second.len(), "{context}");
    assert!(
        estimates
            .iter()
            .all(|e| e["frame_id"] == "cam_front" && e["face_id"] == "0")
    );
    let stamps: Vec<i64> = estimates
        .iter()
        .map(|e| e["stamp_ns"].as_i64().expect("stamp"))
        .collect();
    // In order, with OpenFace's own spacing within each run (its timestamps have 1 ms steps).
    let spacing = |from: usize, to: usize| {
        for k in from + 1..to {
            let gap = stamps[k] - stamps[k - 1];
            let t0 = if from == 0 { 0.033 } else { 0.041 };
            let ms = |j: usize| ((t0 + j as f64 / 30.0) * 1000.0).round();
            let want = (ms(k - from) - ms(k - 1 - from)) * 1e6;
            assert_eq!(gap, want as i64, "frame {k}: {context}");
        }
    };
    spacing(0, first.len());
    spacing(first.len(), stamps.len());
    // The second run is on a clock of its own: anchored when its first row was read, after
    // the first run's last frame.
    assert!(stamps[first.len()] > stamps[first.len() - 1], "{context}");
    // The same seconds the ROS4HRI way: the camera's face is a tracked person (no session
    // runs), with a level per second.
    let events = json_lines(&read("est.out"));
    assert!(
        events
            .iter()
            .any(|e| e["event"] == "tracked" && e["ids"] == serde_json::json!(["face_cam_front_0"])),
        "{context}"
    );
    let levels: Vec<i64> = events
        .iter()
        .filter(|e| e["event"] == "engagement_status")
        .filter_map(|e| e["level"].as_i64())
        .collect();
    assert!(
        levels.len() >= 3,
        "a level per second: {levels:?} {context}"
    );
    assert!(levels.iter().all(|l| (0..=4).contains(l)), "{levels:?}");
    let bridge_log = read("bridge.err");
    assert!(
        bridge_log.contains("skipped a bad OpenFace CSV row at line 42")
            && bridge_log.contains("fields, the header has"),
        "{context}"
    );
    assert!(
        bridge_log.contains("the OpenFace CSV was truncated"),
        "{context}"
    );
    assert!(
        bridge_log
            .contains("91 rows: 90 published, 0 without a face, 0 below min_confidence, 1 bad"),
        "{context}"
    );
}
