//! `bag info` on a finished bag, on a recording that never wrote its summary, and on a
//! truncated bag: the text has `ros2 bag info`'s lines, the JSON its numbers, and damage is
//! reported (exit status 2 with --strict) after what was readable.

#[path = "../../../libs/bag_file/tests/common/mod.rs"]
mod common;

use bag_file::{BagWriter, Compression, WriterOptions, partial_path};
use common::session_bytes;
use std::process::Command;

fn bag_info(args: &[&str]) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_bag"))
        .arg("info")
        .args(args)
        .output()
        .expect("runs bag");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
    )
}

#[test]
fn info_reports_topics_counts_duration_and_damage() {
    let dir = tempfile::tempdir().expect("tempdir");
    let options = WriterOptions {
        compression: Compression::Zstd,
        chunk_size: 8 * 1024,
        compression_threads: 0,
    };
    let (bytes, expected) = session_bytes(&options);
    let path = dir.path().join("session.mcap");
    std::fs::write(&path, &bytes).expect("write");
    let p = path.to_str().expect("utf-8 path");

    let (code, text) = bag_info(&[p]);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains(&format!("Messages:          {}", expected.len())),
        "{text}"
    );
    assert!(text.contains("Duration:          3.005000000s"), "{text}");
    assert!(text.contains("ROS Distro:        jazzy"), "{text}");
    assert!(text.contains("Closed cleanly:    yes"), "{text}");
    assert!(text.contains("Topic information: Topic: "), "{text}");
    assert!(
        text.contains("Type: qt_therapy_msgs/msg/OpenFaceFeatures | Count: 90 | Serialization Format: cdr | QoS: features"),
        "{text}"
    );

    let (code, json) = bag_info(&[p, "--json"]);
    assert_eq!(code, 0);
    let v: serde_json::Value = serde_json::from_str(json.trim()).expect("one JSON object");
    assert_eq!(v["messages"], expected.len());
    assert_eq!(
        v["topics"].as_array().map(Vec::len),
        Some(qt_therapy_msgs::topics::all_topics().len())
    );
    assert_eq!(v["profile"], "ros2");
    assert_eq!(v["compression"][0][0], "zstd");

    // A recording killed after a flush: no summary, every flushed message.
    let live = dir.path().join("live.mcap");
    let mut w = BagWriter::create(&live, &options).expect("create");
    let written = common::write_session(&mut w);
    w.flush_chunk().expect("flush");
    let partial = partial_path(&live);
    let copy = dir.path().join("killed.mcap");
    std::fs::copy(&partial, &copy).expect("copy");
    drop(w);
    let (code, text) = bag_info(&[copy.to_str().expect("utf-8"), "--strict"]);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains(&format!("Messages:          {}", written.len())),
        "{text}"
    );
    assert!(text.contains("Closed cleanly:    no"), "{text}");

    // Truncated in the middle: what precedes is counted, the cut record named.
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).expect("write");
    let c = cut.to_str().expect("utf-8");
    let (code, text) = bag_info(&[c]);
    assert_eq!(code, 0);
    assert!(text.contains("Damage:            "), "{text}");
    assert!(text.contains("is truncated"), "{text}");
    let (code, _) = bag_info(&[c, "--strict"]);
    assert_eq!(code, 2);
    let (code, _) = bag_info(&[dir.path().join("missing.mcap").to_str().expect("utf-8")]);
    assert_ne!(code, 0);
}
