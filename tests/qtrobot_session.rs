//! The game manager driving QTrobot through its services over real DDS, against a stand-in
//! robot (tests/bin/qtrobot_peer.rs) that takes a robot's time for each call. V2
//! (`robot_backend: qtrobot`): a whole session, in which the game waits for the robot to finish
//! every call; the robot answering `false` once and hanging past the call timeout once, each
//! pausing the session with the reason (the scripted therapist resumes), and nothing skipped:
//! every sequence the child answered was shown to it whole. V3 (`qtrobot_ros2`): the gateway's
//! services, a failure pausing the session the same way, and an emergency stop cutting the
//! robot's speech short through the gateway's cancel. All processes in one loopback-only
//! network namespace.

use std::path::Path;
use std::time::Duration;
use suite_tests::{json_lines, run_in_loopback_netns, workspace_bin, workspace_root};

fn write_params(d: &Path, backend: &str) {
    let shipped = std::fs::read_to_string(workspace_root().join("params/game_manager.yaml"))
        .expect("params/game_manager.yaml");
    let qtrobot = shipped
        .replace("time_scale: 1.0", "time_scale: 0.05")
        .replace(
            "robot_backend: \"topics\"",
            &format!("robot_backend: \"{backend}\""),
        )
        .replace("robot_call_timeout_s: 60.0", "robot_call_timeout_s: 2.0")
        .replace(
            r#"watched_nodes: ["behaviour_policy", "engagement_classifier", "tablet_bridge", "bag_recorder"]"#,
            r#"watched_nodes: ["game_manager_test_peer"]"#,
        );
    assert!(qtrobot.contains(&format!("\"{backend}\"")) && qtrobot.contains("timeout_s: 2.0"));
    std::fs::write(d.join("game_manager.yaml"), qtrobot).expect("writes");
    for peer in ["game_manager_test_peer", "qtrobot_peer"] {
        std::fs::write(
            d.join(format!("{peer}.yaml")),
            format!("{peer}:\n  ros__parameters: {{}}\n"),
        )
        .expect("writes");
    }
}

#[test]
fn a_session_waits_for_the_robot_and_pauses_when_it_fails() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    write_params(d, "qtrobot");
    let script = format!(
        r#"
        export ROS_LOCALHOST_ONLY=1 QT_PARAMS_DIR={d} RUST_BACKTRACE=0
        {robot} --echo-emotions --fail-say "Well done" --hang-say "angry" --hang-ms 3500 >{d}/robot.out 2>{d}/robot.err &
        R=$!
        {gm} run --sessions-dir {d}/sessions >{d}/gm.out 2>{d}/gm.err &
        G=$!
        {peer} --session qt-1 --resume-paused --answer-delay-ms 200 >{d}/peer.out 2>{d}/peer.err
        P=$?
        kill -INT $G; wait $G; RC=$?
        kill -INT $R; wait $R
        echo "{{\"peer\":$P,\"game_manager\":$RC}}"
        "#,
        d = d.display(),
        robot = env!("CARGO_BIN_EXE_qtrobot_peer"),
        gm = workspace_bin("game_manager").display(),
        peer = env!("CARGO_BIN_EXE_game_manager_test_peer"),
    );
    let Some(out) = run_in_loopback_netns(&script, Duration::from_secs(240)) else {
        return;
    };
    let read = |f: &str| std::fs::read_to_string(d.join(f)).unwrap_or_default();
    let context = format!(
        "script: {}\n{}\ngame manager:\n{}\nrobot:\n{}\npeer:\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
        read("gm.err"),
        read("robot.err"),
        read("peer.out"),
    );
    let exit = json_lines(&String::from_utf8_lossy(&out.stdout));
    assert_eq!(
        exit.last()
            .map(|e| (e["peer"].clone(), e["game_manager"].clone())),
        Some((0.into(), 0.into())),
        "{context}"
    );
    let peer = json_lines(&read("peer.out"));
    let results: Vec<&serde_json::Value> = peer.iter().filter(|e| e["event"] == "result").collect();
    assert_eq!(results.len(), 10, "{context}");
    // Every answer was right: the child saw each sequence whole, none skipped.
    assert!(results.iter().all(|r| r["outcome"] == 1), "{context}");

    // The two failures paused the session with their reasons, and the therapist resumed.
    let resumed: Vec<String> = peer
        .iter()
        .filter(|e| e["event"] == "resuming")
        .filter_map(|e| e["status"].as_str().map(String::from))
        .collect();
    assert!(
        resumed
            .iter()
            .any(|s| s.contains("the robot did not finish")
                && s.contains("/qt_robot/speech/say answered that it failed")),
        "{resumed:?}\n{context}"
    );
    assert!(
        resumed
            .iter()
            .any(|s| s.contains("the robot did not finish")
                && s.contains("did not answer within 2s")),
        "{resumed:?}\n{context}"
    );

    // The game waited for the robot: every face is a call taking 150 ms, and the next one
    // (the next word, the next feedback) was asked for only after it returned. At this
    // time_scale the estimated times would put words 50 ms apart.
    let robot = json_lines(&read("robot.out"));
    let faces: Vec<i64> = robot
        .iter()
        .filter(|e| e["service"] == "emotion" && e["event"] == "start")
        .filter_map(|e| e["at_ns"].as_i64())
        .collect();
    let closest = faces.windows(2).map(|w| w[1] - w[0]).min().unwrap_or(0);
    assert!(
        faces.len() >= 30 && closest >= 140_000_000,
        "{} faces, closest {} ms apart\n{context}",
        faces.len(),
        closest / 1_000_000
    );
    let says: Vec<&serde_json::Value> = robot.iter().filter(|e| e["service"] == "say").collect();
    let words = says
        .iter()
        .filter(|e| {
            e["event"] == "end"
                && ["happy", "disgusted", "sad", "angry"].contains(&e["arg"].as_str().unwrap_or(""))
        })
        .count();
    assert!(words >= 10 * 3, "{words} words said\n{context}");
    assert!(
        read("gm.err").contains("QTrobot's services reachable"),
        "{context}"
    );
}

#[test]
fn a_qtrobot_v3_is_driven_through_its_ros2_gateway_and_silenced_by_the_emergency_stop() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    write_params(d, "qtrobot_ros2");
    // Slow speech (60 ms a character) so the emergency stop lands while the robot speaks.
    let script = format!(
        r#"
        export ROS_LOCALHOST_ONLY=1 QT_PARAMS_DIR={d} RUST_BACKTRACE=0
        {robot} --v3 --echo-emotions --ms-per-char 60 --fail-say "Well done" >{d}/robot.out 2>{d}/robot.err &
        R=$!
        {gm} run --sessions-dir {d}/sessions >{d}/gm.out 2>{d}/gm.err &
        G=$!
        {peer} --session qt-3 --resume-paused --emergency-stop-at 4 --answer-delay-ms 200 >{d}/peer.out 2>{d}/peer.err
        P=$?
        kill -INT $G; wait $G; RC=$?
        kill -INT $R; wait $R
        echo "{{\"peer\":$P,\"game_manager\":$RC}}"
        "#,
        d = d.display(),
        robot = env!("CARGO_BIN_EXE_qtrobot_peer"),
        gm = workspace_bin("game_manager").display(),
        peer = env!("CARGO_BIN_EXE_game_manager_test_peer"),
    );
    let Some(out) = run_in_loopback_netns(&script, Duration::from_secs(240)) else {
        return;
    };
    let read = |f: &str| std::fs::read_to_string(d.join(f)).unwrap_or_default();
    let context = format!(
        "script: {}\n{}\ngame manager:\n{}\nrobot:\n{}\npeer:\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
        read("gm.err"),
        read("robot.out"),
        read("peer.out"),
    );
    let exit = json_lines(&String::from_utf8_lossy(&out.stdout));
    assert_eq!(
        exit.last()
            .map(|e| (e["peer"].clone(), e["game_manager"].clone())),
        Some((0.into(), 0.into())),
        "{context}"
    );
    assert!(
        read("gm.err").contains("QTrobot's services reachable (/qtrobot/tts/engine/say/text)"),
        "{context}"
    );
    let peer = json_lines(&read("peer.out"));
    // Sequences 1..3 played whole and answered right; the session ended emergency-stopped.
    let results: Vec<&serde_json::Value> = peer.iter().filter(|e| e["event"] == "result").collect();
    assert_eq!(results.len(), 3, "{context}");
    assert!(results.iter().all(|r| r["outcome"] == 1), "{context}");
    assert_eq!(
        peer.last()
            .map(|e| (e["event"].clone(), e["phase"].clone())),
        Some(("done".into(), 8.into())),
        "{context}"
    );
    // The gateway's `result: false` paused the session with the service's name.
    assert!(
        peer.iter().any(|e| e["event"] == "resuming"
            && e["status"].as_str().is_some_and(
                |s| s.contains("/qtrobot/tts/engine/say/text answered that it failed")
            )),
        "{context}"
    );

    // The emergency stop cancelled the speech under way on the robot, well before it would
    // have ended.
    let robot = json_lines(&read("robot.out"));
    let pressed = peer
        .iter()
        .find(|e| e["event"] == "emergency_stop")
        .and_then(|e| e["at_ns"].as_i64())
        .expect("the emergency stop was pressed");
    let cancel = robot
        .iter()
        .find(|e| e["service"] == "cancel")
        .and_then(|e| e["at_ns"].as_i64())
        .unwrap_or_else(|| panic!("no cancel call\n{context}"));
    assert!(
        (0..1_000_000_000).contains(&(cancel - pressed)),
        "cancel {} ms after the press\n{context}",
        (cancel - pressed) / 1_000_000
    );
    assert!(
        robot
            .iter()
            .any(|e| e["service"] == "say" && e["interrupted"] == true),
        "no speech cut short\n{context}"
    );
    // Faces and gestures went through the V3 services, gestures at the configured speed.
    let faces = robot
        .iter()
        .filter(|e| e["service"] == "emotion" && e["event"] == "end")
        .count();
    assert!(faces >= 3 * 3, "{faces} faces\n{context}");
    assert!(
        robot
            .iter()
            .any(|e| e["service"] == "gesture" && e["event"] == "start" && e["speed"] == 1.0),
        "{context}"
    );
}
