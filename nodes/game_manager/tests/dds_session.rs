//! The `game_manager` binary plays a whole session over real DDS against the scripted test
//! peer (policy, tablet, camera, therapist), both processes inside a private loopback-only
//! network namespace (`tests/loopback-netns` at the workspace root): ten live lines on stdout,
//! ten fsync'd records and a summary in the session directory, results over DDS.

use game_manager::session_file::{SessionSummary, read_records};
use std::path::Path;
use std::time::Duration;

use loopback_netns::{run_in_loopback_netns, workspace_root};

/// The shipped parameters, twenty times faster, and a parameter file for the peer, in `d`.
fn write_params(d: &Path) {
    let shipped = std::fs::read_to_string(workspace_root().join("params/game_manager.yaml"))
        .expect("params/game_manager.yaml");
    let fast = shipped
        .replace("time_scale: 1.0", "time_scale: 0.05")
        .replace("engagement_wait_s: 1.5", "engagement_wait_s: 1.2")
        // The peer stands in for the policy, tablets and camera: it is the node to watch.
        .replace(
            r#"watched_nodes: ["behaviour_policy", "engagement_classifier", "tablet_bridge", "bag_recorder"]"#,
            r#"watched_nodes: ["game_manager_test_peer"]"#,
        );
    assert!(fast.contains("game_manager_test_peer"));
    std::fs::write(d.join("game_manager.yaml"), fast).expect("write params");
    std::fs::write(
        d.join("game_manager_test_peer.yaml"),
        "game_manager_test_peer:\n  ros__parameters: {}\n",
    )
    .expect("write params");
}

fn json_lines(text: &str) -> Vec<serde_json::Value> {
    text.lines()
        .filter_map(|l| serde_json::from_str(l.trim()).ok())
        .collect()
}

#[test]
fn a_whole_session_over_dds_is_played_recorded_and_shown_live() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    write_params(d);
    let script = format!(
        r#"
        export ROS_LOCALHOST_ONLY=1 QT_PARAMS_DIR={d}
        {gm} run --sessions-dir {d}/sessions >{d}/gm.out 2>{d}/gm.err &
        G=$!
        {peer} --session dds-1 --wrong 3 --silent 5 --override-level 3 >{d}/peer.out 2>{d}/peer.err
        P=$?
        kill -INT $G; wait $G; RC=$?
        echo "{{\"peer\":$P,\"game_manager\":$RC}}"
        "#,
        d = d.display(),
        gm = env!("CARGO_BIN_EXE_game_manager"),
        peer = env!("CARGO_BIN_EXE_game_manager_test_peer"),
    );
    let Some(out) = run_in_loopback_netns(&script, Duration::from_secs(200)) else {
        return;
    };
    let read = |f: &str| std::fs::read_to_string(d.join(f)).unwrap_or_default();
    let (gm_out, peer_out) = (read("gm.out"), read("peer.out"));
    let context = format!(
        "script: {}\n{}\ngame_manager stdout:\n{gm_out}\nstderr:\n{}\npeer:\n{peer_out}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
        read("gm.err"),
        read("peer.err")
    );
    let exit = json_lines(&String::from_utf8_lossy(&out.stdout));
    assert_eq!(
        exit.last()
            .map(|e| (e["peer"].clone(), e["game_manager"].clone())),
        Some((0.into(), 0.into())),
        "{context}"
    );

    // The live view: a start line, ten sequence lines, an end line.
    let live: Vec<&str> = gm_out.lines().filter(|l| l.starts_with("seq ")).collect();
    assert_eq!(live.len(), 10, "{context}");
    assert!(live[2].contains("answer wrong"), "{context}");
    assert!(live[4].contains("answer timeout"), "{context}");
    assert!(live[1].contains("therapist override"), "{context}");
    assert!(
        live[0].contains("policy greedy") && live[3].contains("policy explored"),
        "{context}"
    );
    assert!(gm_out.contains("all sequences played"), "{context}");

    // The results crossed over DDS.
    let peer = json_lines(&peer_out);
    let results: Vec<&serde_json::Value> = peer.iter().filter(|e| e["event"] == "result").collect();
    assert_eq!(results.len(), 10, "{context}");
    let outcomes: Vec<i64> = results
        .iter()
        .filter_map(|r| r["outcome"].as_i64())
        .collect();
    assert_eq!(outcomes, vec![1, 1, -1, 1, -1, 1, 1, 1, 1, 1], "{context}");
    assert_eq!(
        (
            results[1]["level"].clone(),
            results[1]["overridden"].clone()
        ),
        (3.into(), true.into())
    );
    // The peer's camera reports 0.5 every second; at this speed the robot talks for 0.5 to
    // 2 s per sequence, so most (not all) sequences hold a window midpoint.
    let with_e: Vec<&&serde_json::Value> = results
        .iter()
        .filter(|r| r["seconds"].as_u64().is_some_and(|n| n >= 1))
        .collect();
    assert!(with_e.len() >= 5, "{context}");
    assert!(
        with_e.iter().all(|r| r["engagement"].as_f64() == Some(0.5)),
        "{context}"
    );
    // The duplicated start was rejected and reported (GameState is keep-last-1, so the log is
    // the reliable witness here).
    let gm_err = read("gm.err");
    assert!(
        gm_err.contains("rejected command 1 (start) for session \"dds-1\": duplicate command id 1"),
        "{context}"
    );
    let first_speech = peer.iter().find(|e| e["event"] == "speech");
    assert!(
        first_speech.is_some_and(|s| s["data"].as_str().is_some_and(|t| t.starts_with("Hello!")))
    );

    // Nothing lost: ten records and the summary on disk.
    let records = read_records(&d.join("sessions/dds-1.jsonl")).expect("session file");
    assert_eq!(records.records.len(), 10, "{context}");
    assert!(!records.torn_tail);
    assert!(
        records.records.iter().all(|r| !r.policy_fallback),
        "{context}"
    );
    let summary: SessionSummary =
        serde_json::from_str(&read("sessions/dds-1.summary.json")).expect("summary file");
    assert_eq!(
        (summary.sequences_played, summary.correct, summary.timeouts),
        (10, 8, 1)
    );
}

#[test]
fn a_killed_node_loses_no_scored_sequence_and_a_stopped_one_writes_its_summary() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    write_params(d);
    // The peer gives up after 8 s (mid-session); the node is then killed (a crash), started
    // again, and stopped by SIGINT in the middle of a second session of the same id.
    let script = format!(
        r#"
        export ROS_LOCALHOST_ONLY=1 QT_PARAMS_DIR={d}
        {gm} run --sessions-dir {d}/sessions >{d}/gm1.out 2>{d}/gm1.err &
        G=$!
        {peer} --session s --timeout-s 8 >{d}/peer1.out 2>{d}/peer1.err
        kill -KILL $G; wait $G
        {gm} run --sessions-dir {d}/sessions >{d}/gm2.out 2>{d}/gm2.err &
        G=$!
        {peer} --session s --timeout-s 8 >{d}/peer2.out 2>{d}/peer2.err
        kill -INT $G; wait $G; RC=$?
        echo "{{\"game_manager\":$RC}}"
        "#,
        d = d.display(),
        gm = env!("CARGO_BIN_EXE_game_manager"),
        peer = env!("CARGO_BIN_EXE_game_manager_test_peer"),
    );
    let Some(out) = run_in_loopback_netns(&script, Duration::from_secs(120)) else {
        return;
    };
    let read = |f: &str| std::fs::read_to_string(d.join(f)).unwrap_or_default();
    let context = format!(
        "script: {}\n{}\ngm1: {}\ngm2: {}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
        read("gm1.out"),
        read("gm2.out"),
        read("gm2.err")
    );
    let exit = json_lines(&String::from_utf8_lossy(&out.stdout));
    assert_eq!(
        exit.last().map(|e| e["game_manager"].clone()),
        Some(0.into()),
        "{context}"
    );
    let seen = |f: &str| {
        json_lines(&read(f))
            .iter()
            .filter(|e| e["event"] == "result")
            .count()
    };

    // The crash: every result the peer saw is on disk (written before it was published).
    let crashed = read_records(&d.join("sessions/s.jsonl")).expect("first session file");
    assert!(seen("peer1.out") >= 1, "{context}");
    assert!(crashed.records.len() >= seen("peer1.out"), "{context}");
    assert!(
        !d.join("sessions/s.summary.json").exists(),
        "a crash writes no summary"
    );

    // The restart: same session id, new files; SIGINT saves the summary.
    let second = read_records(&d.join("sessions/s-2.jsonl")).expect("second session file");
    assert!(
        second.records.len() >= seen("peer2.out") && !second.records.is_empty(),
        "{context}"
    );
    let summary: SessionSummary =
        serde_json::from_str(&read("sessions/s-2.summary.json")).expect("summary of the second");
    assert_eq!(
        summary.end,
        game_manager::session_file::SessionEnd::NodeShutdown
    );
    assert_eq!(usize::from(summary.sequences_played), second.records.len());
}
