//! The player and the recorder over real DDS, as separate processes inside one private
//! loopback-only network namespace (tests/loopback-netns): a bag written in-process is played
//! into a recorder and comes back with the same message contents and timing; a second pass
//! plays it 4x faster, filtered, remapped and from an offset; a third recorder is killed with
//! SIGKILL mid-session and its file still holds everything but the last second; a recorder
//! respawned on the same output carries that file over and finishes one whole bag.

#[path = "../../../libs/bag_file/tests/common/mod.rs"]
mod common;

use bag_file::{BagReader, Compression, RawMessage, WriterOptions, partial_path};
use qt_therapy_msgs::Heartbeat;
use qt_therapy_msgs::topics::{HEARTBEAT, OPENFACE_FEATURES, ROBOT_EMOTION, ROBOT_SPEECH};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;

fn workspace() -> PathBuf {
    loopback_netns::workspace_root()
}

/// Payloads per topic, leaving out the heartbeats of the bag tools themselves and the ROS 2
/// builtin topics.
fn payloads(reader: &BagReader) -> BTreeMap<String, Vec<&RawMessage>> {
    let mut out: BTreeMap<String, Vec<&RawMessage>> = BTreeMap::new();
    for (c, m) in reader.iter() {
        // `--all` records the graph's own topics too (the player's and recorder's log lines on
        // /rosout, /parameter_events): not part of the played session.
        if c.topic == "/rosout" || c.topic == "/parameter_events" {
            continue;
        }
        if c.topic == HEARTBEAT.name
            && bag_file::cdr::decode::<Heartbeat>(&m.data)
                .is_ok_and(|h| h.node_name.starts_with("bag_"))
        {
            continue;
        }
        out.entry(c.topic.clone()).or_default().push(m);
    }
    out
}

fn span_s(messages: &[&RawMessage]) -> f64 {
    match (messages.first(), messages.last()) {
        (Some(a), Some(b)) => (b.log_time - a.log_time) as f64 * 1e-9,
        _ => 0.0,
    }
}

#[test]
fn played_bags_come_back_through_dds_and_a_killed_recorder_keeps_all_but_the_last_second() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let (bytes, expected) = common::session_bytes(&WriterOptions {
        compression: Compression::Zstd,
        ..WriterOptions::default()
    });
    std::fs::write(d.join("session.mcap"), &bytes).expect("write bag");
    std::fs::create_dir_all(d.join("params")).expect("params dir");
    std::fs::copy(
        workspace().join("params/bag_recorder.yaml"),
        d.join("params/bag_recorder.yaml"),
    )
    .expect("recorder params");
    // Discovery on a busy machine can take seconds; the player waits for it (not longer).
    std::fs::write(
        d.join("params/bag_player.yaml"),
        "bag_player:\n  ros__parameters:\n    wait_for_subscribers_s: 30.0\n    linger_s: 1.5\n",
    )
    .expect("player params");
    let script = format!(
        r#"
        B={bin}; D={d}; export ROS_LOCALHOST_ONLY=1 QT_PARAMS_DIR=$D/params
        $B record -o $D/rec1.mcap --all >$D/rec1.out 2>$D/rec1.err & R=$!
        $B play $D/session.mcap >$D/play1.out 2>$D/play1.err; P1=$?
        kill -INT $R; wait $R; R1=$?
        $B record -o $D/rec2.mcap --topics {emotion} {features} >$D/rec2.out 2>$D/rec2.err & R=$!
        $B play $D/session.mcap --rate 4 --start-offset 0.05 --topics {speech} {features} \
            --remap {speech}:={emotion} >$D/play2.out 2>$D/play2.err; P2=$?
        kill -INT $R; wait $R; R2=$?
        $B record -o $D/rec3.mcap --all >$D/rec3.out 2>$D/rec3.err & R=$!
        $B play $D/session.mcap --loop >$D/play3.out 2>$D/play3.err & P=$!
        for i in $(seq 300); do grep -q playing $D/play3.err && break; sleep 0.1; done
        sleep 4; K=$(date +%s%N); kill -KILL $R; wait $R
        cp $D/rec3.mcap.partial $D/rec3-killed.mcap.partial
        $B record -o $D/rec3.mcap --all >$D/rec3b.out 2>$D/rec3b.err & R=$!
        sleep 3; B0=$(date +%s%N); sleep 2
        kill -INT $R; wait $R; R3=$?
        kill -INT $P; wait $P; P3=$?
        echo "{{\"p1\":$P1,\"r1\":$R1,\"p2\":$P2,\"r2\":$R2,\"p3\":$P3,\"r3\":$R3,\"killed_ns\":$K,\"back_ns\":$B0}}"
        "#,
        bin = env!("CARGO_BIN_EXE_bag"),
        d = d.display(),
        speech = ROBOT_SPEECH.name,
        emotion = ROBOT_EMOTION.name,
        features = OPENFACE_FEATURES.name,
    );
    let Some(out) = loopback_netns::run_in_loopback_netns(&script, Duration::from_secs(240)) else {
        return;
    };
    let read = |f: &str| std::fs::read_to_string(d.join(f)).unwrap_or_default();
    let context = format!(
        "stdout: {}\nstderr: {}\nplay1: {}{}\nrec1: {}{}\nplay2: {}\nrec2: {}\nplay3: {}\nrec3: {}\nrec3b: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
        read("play1.out"),
        read("play1.err"),
        read("rec1.out"),
        read("rec1.err"),
        read("play2.err"),
        read("rec2.err"),
        read("play3.err"),
        read("rec3.err"),
        read("rec3b.err"),
    );
    let status: serde_json::Value = String::from_utf8_lossy(&out.stdout)
        .lines()
        .find_map(|l| serde_json::from_str(l).ok())
        .unwrap_or_else(|| panic!("no status line\n{context}"));
    for key in ["p1", "r1", "p2", "r2", "p3", "r3"] {
        assert_eq!(status[key], 0, "{key}\n{context}");
    }
    let played: serde_json::Value = serde_json::from_str(read("play1.out").trim()).expect("json");
    assert_eq!(played["published"], expected.len(), "{context}");
    assert_eq!(played["failed"], 0, "{context}");

    // 1. Every message comes back with the same content, per topic in order, and the timing
    // of the 3 s session survives within 0.3 s.
    let original = BagReader::open(&d.join("session.mcap")).expect("session");
    let rec1 = BagReader::open(&d.join("rec1.mcap"))
        .expect("rec1")
        .strict()
        .expect("undamaged");
    assert!(rec1.is_complete() && rec1.profile() == Some("ros2"));
    let (want, got) = (payloads(&original), payloads(&rec1));
    assert_eq!(
        want.keys().collect::<Vec<_>>(),
        got.keys().collect::<Vec<_>>(),
        "{context}"
    );
    for (topic, w) in &want {
        let g = &got[topic];
        let same = w.len() == g.len() && w.iter().zip(g.iter()).all(|(a, b)| a.data == b.data);
        assert!(
            same,
            "{topic}: {} played, {} recorded\n{context}",
            w.len(),
            g.len()
        );
        assert!(g.iter().all(|m| m.publish_time <= m.log_time), "{topic}");
    }
    let features = (
        span_s(&want[OPENFACE_FEATURES.name]),
        span_s(&got[OPENFACE_FEATURES.name]),
    );
    assert!((features.0 - features.1).abs() < 0.3, "{features:?}");

    // 2. At rate 4 from 50 ms: the speech lands on the emotion topic, 89 of 90 frames in a
    // quarter of the time.
    let rec2 = BagReader::open(&d.join("rec2.mcap"))
        .expect("rec2")
        .strict()
        .expect("undamaged");
    let shown = rec2
        .messages::<qt_therapy_msgs::std_msgs::StringMsg>(ROBOT_EMOTION.name)
        .expect("emotion");
    assert_eq!(shown.len(), 1, "{context}");
    assert_eq!(
        shown[0].message.data,
        "Listen carefully: happy, sad, angry."
    );
    let frames = payloads(&rec2)
        .remove(OPENFACE_FEATURES.name)
        .unwrap_or_default();
    assert_eq!(frames.len(), 89, "{context}");
    let fast = span_s(&frames);
    assert!(
        (fast - features.0 / 4.0).abs() < 0.2,
        "{fast} s at rate 4\n{context}"
    );

    // 3. Killed: the .partial file is readable and holds what was logged up to a second (plus
    // scheduling slack) before the kill.
    let rec3 = BagReader::open(&partial_path(&d.join("rec3-killed.mcap"))).expect("rec3 partial");
    assert!(!rec3.is_complete());
    if let Some(e) = rec3.damage() {
        assert!(matches!(e, bag_file::BagError::Truncated { .. }), "{e}");
    }
    let killed_ns = status["killed_ns"].as_u64().expect("kill time");
    let (_, last) = rec3
        .time_range()
        .unwrap_or_else(|| panic!("no messages\n{context}"));
    let lost_s = (killed_ns as f64 - last as f64) * 1e-9;
    eprintln!(
        "killed recorder: {} messages kept, the last logged {lost_s:.3} s before SIGKILL",
        rec3.raw_messages().len()
    );
    assert!(
        lost_s < 1.5,
        "the last message kept was logged {lost_s:.2} s before the kill"
    );
    assert!(
        rec3.raw_messages().len() > 100,
        "{}",
        rec3.raw_messages().len()
    );

    // 4. Respawned on the same output: one finished bag that holds every message the killed
    // recorder had on disk (same times, sequence numbers and bytes) and what came after; the
    // dead recorder's file was moved aside, carried over, and removed once the bag was whole.
    let whole = BagReader::open(&d.join("rec3.mcap"))
        .expect("rec3 after the respawn")
        .strict()
        .expect("undamaged");
    assert!(whole.is_complete(), "{context}");
    let key = |r: &BagReader, m: &RawMessage| {
        let topic = r.channel(m.channel_id).map(|c| c.topic.clone());
        (
            topic,
            m.log_time,
            m.publish_time,
            m.sequence,
            m.data.clone(),
        )
    };
    let kept: std::collections::BTreeSet<_> = whole
        .raw_messages()
        .iter()
        .map(|m| key(&whole, m))
        .collect();
    let missing = rec3
        .raw_messages()
        .iter()
        .filter(|m| !kept.contains(&key(&rec3, m)))
        .count();
    assert_eq!(
        missing, 0,
        "messages of the killed recorder not carried over\n{context}"
    );
    // Transient-local topics delivered their history to the new recorder again: kept once.
    let mut once = std::collections::BTreeSet::new();
    let twice = whole
        .raw_messages()
        .iter()
        .filter(|m| {
            whole
                .channel(m.channel_id)
                .and_then(|c| c.offered_qos())
                .is_some_and(|q| q != qt_therapy_msgs::topics::QosKind::Features)
        })
        .filter(|m| !once.insert((m.channel_id, m.publish_time, m.data.clone())))
        .count();
    assert_eq!(twice, 0, "messages recorded twice\n{context}");
    let back_ns = status["back_ns"].as_u64().expect("back time");
    let after = whole
        .raw_messages()
        .iter()
        .filter(|m| m.log_time > back_ns)
        .count();
    assert!(
        after > 10,
        "{after} messages recorded after the respawn\n{context}"
    );
    let leftovers: Vec<_> = std::fs::read_dir(d)
        .expect("dir")
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("rec3.mcap.partial"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    eprintln!(
        "respawned recorder: {} messages carried over, {after} recorded in the last 2 s, one bag",
        rec3.raw_messages().len()
    );
}
