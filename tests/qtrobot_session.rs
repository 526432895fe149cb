//! The game manager driving QTrobot through its services over real DDS, against a stand-in
//! robot (tests/bin/qtrobot_peer.rs) that takes a robot's time for each call. V2
//! (`robot_backend: qtrobot`): a whole session, in which the game waits for the robot to finish
//! every call; the robot answering `false` once and hanging past the call timeout once, each
//! pausing the session with the reason (the scripted therapist resumes), and nothing skipped:
//! every sequence the child answered was shown to it whole. V3 (`qtrobot_ros2`): the stand-in
//! serves the gateway's services one call at a time, as LuxAI's gateway does; the game asks it
//! for one call at a time in the order the game needs (each word's face, then the word), the
//! task reaches the tablet as the last word ends, a failure pauses the session, and the
//! emergency stop silences the robot within 0.5 s through a second gateway process, or, without
//! one, once the call under way ends. All processes in one loopback-only network namespace.

use std::path::Path;
use std::time::Duration;
use suite_tests::{json_lines, run_in_loopback_netns, workspace_bin, workspace_root};

fn write_params(d: &Path, backend: &str, call_timeout: &str) {
    let shipped = std::fs::read_to_string(workspace_root().join("params/game_manager.yaml"))
        .expect("params/game_manager.yaml");
    let qtrobot = shipped
        .replace("time_scale: 1.0", "time_scale: 0.05")
        .replace(
            "robot_backend: \"topics\"",
            &format!("robot_backend: \"{backend}\""),
        )
        .replace(
            "robot_call_timeout_s: 60.0",
            &format!("robot_call_timeout_s: {call_timeout}"),
        )
        .replace(
            r#"watched_nodes: ["behaviour_policy", "engagement_classifier", "tablet_bridge", "bag_recorder"]"#,
            r#"watched_nodes: ["game_manager_test_peer"]"#,
        );
    assert!(
        qtrobot.contains(&format!("\"{backend}\""))
            && qtrobot.contains(&format!("timeout_s: {call_timeout}"))
    );
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
    write_params(d, "qtrobot", "2.0");
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

/// What one V3 run left: the processes' outputs, the robot's and the peer's events, the
/// session file's records, and the whole context for a failure message.
struct V3Run {
    peer: Vec<serde_json::Value>,
    robot: Vec<serde_json::Value>,
    records: Vec<serde_json::Value>,
    gm_err: String,
    context: String,
}

/// Plays a session with the game manager on `qtrobot_ros2` beside `qtrobot_peer --v3
/// {robot_args}` and `game_manager_test_peer --session {session} {peer_args}`, in one
/// loopback-only network namespace; None where namespaces are not allowed.
fn play_v3(session: &str, robot_args: &str, peer_args: &str) -> Option<V3Run> {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    // Above the longest call (the introduction, 7.8 s at 60 ms a character), as the gateway's
    // own rpc_timeout (30 s) is below the shipped 60 s.
    write_params(d, "qtrobot_ros2", "20.0");
    let script = format!(
        r#"
        export ROS_LOCALHOST_ONLY=1 QT_PARAMS_DIR={d} RUST_BACKTRACE=0
        {robot} --v3 {robot_args} >{d}/robot.out 2>{d}/robot.err &
        R=$!
        {gm} run --sessions-dir {d}/sessions >{d}/gm.out 2>{d}/gm.err &
        G=$!
        {peer} --session {session} {peer_args} >{d}/peer.out 2>{d}/peer.err
        P=$?
        kill -INT $G; wait $G; RC=$?
        # The robot may still be saying a line nothing could stop: let it end (15 s at most).
        said() {{ grep '"service":"say"' {d}/robot.out | grep -c "\"event\":\"$1\""; }}
        for _ in $(seq 150); do [ "$(said start)" = "$(said end)" ] && break; sleep 0.1; done
        kill -INT $R; wait $R
        echo "{{\"peer\":$P,\"game_manager\":$RC}}"
        "#,
        d = d.display(),
        robot = env!("CARGO_BIN_EXE_qtrobot_peer"),
        gm = workspace_bin("game_manager").display(),
        peer = env!("CARGO_BIN_EXE_game_manager_test_peer"),
    );
    let out = run_in_loopback_netns(&script, Duration::from_secs(240))?;
    let read = |f: &str| std::fs::read_to_string(d.join(f)).unwrap_or_default();
    let records = std::fs::read_dir(d.join("sessions"))
        .into_iter()
        .flatten()
        .flatten()
        .filter(|e| e.path().extension().is_some_and(|x| x == "jsonl"))
        .flat_map(|e| json_lines(&std::fs::read_to_string(e.path()).unwrap_or_default()))
        .collect();
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
    Some(V3Run {
        peer: json_lines(&read("peer.out")),
        robot: json_lines(&read("robot.out")),
        records,
        gm_err: read("gm.err"),
        context,
    })
}

impl V3Run {
    /// When the therapist pressed the emergency stop.
    fn pressed(&self) -> i64 {
        self.peer
            .iter()
            .find(|e| e["event"] == "emergency_stop")
            .and_then(|e| e["at_ns"].as_i64())
            .unwrap_or_else(|| panic!("the emergency stop was not pressed\n{}", self.context))
    }

    /// The calls the gateway under `namespace` served: (service, arg, asked, start, end).
    fn calls(&self, namespace: &str) -> Vec<(String, String, i64, i64, i64)> {
        let starts = self
            .robot
            .iter()
            .filter(|e| e["event"] == "start" && e["gateway"] == namespace);
        starts
            .map(|s| {
                let (service, arg) = (&s["service"], &s["arg"]);
                let at = s["at_ns"].as_i64().unwrap_or(0);
                // Its end: the gateway's next end of the same service after its start.
                let end = self
                    .robot
                    .iter()
                    .filter(|e| {
                        e["event"] == "end"
                            && e["gateway"] == namespace
                            && e["service"] == *service
                            && e["at_ns"].as_i64().unwrap_or(0) >= at
                    })
                    .find_map(|e| e["at_ns"].as_i64())
                    .unwrap_or(i64::MAX);
                (
                    service.as_str().unwrap_or("").to_string(),
                    arg.as_str().unwrap_or("").to_string(),
                    s["asked_ns"].as_i64().unwrap_or(0),
                    at,
                    end,
                )
            })
            .collect()
    }

    /// The speech under way when the emergency stop was pressed, and when the robot was
    /// silent (that speech's end; the press itself when none was under way).
    fn silent_after_press(&self) -> (Option<String>, i64) {
        let pressed = self.pressed();
        let speech = self.robot.iter().rfind(|e| {
            e["service"] == "say"
                && e["event"] == "start"
                && e["at_ns"].as_i64().is_some_and(|t| t <= pressed)
        });
        let Some(start) = speech else {
            return (None, pressed);
        };
        let text = start["arg"].as_str().unwrap_or("").to_string();
        let end = self
            .robot
            .iter()
            .find(|e| {
                e["service"] == "say"
                    && e["event"] == "end"
                    && e["arg"] == text.as_str()
                    && e["at_ns"]
                        .as_i64()
                        .is_some_and(|t| t >= start["at_ns"].as_i64().unwrap_or(0))
            })
            .and_then(|e| e["at_ns"].as_i64());
        let end = end.unwrap_or_else(|| {
            panic!(
                "the robot was still saying {text:?} when the run ended\n{}",
                self.context
            )
        });
        (Some(text), end.max(pressed))
    }
}

const MS: i64 = 1_000_000;

#[test]
fn a_qtrobot_v3_is_driven_one_call_at_a_time_and_the_timeline_holds() {
    // The stand-in serves the gateway's services one call at a time, as LuxAI's gateway does,
    // and a second gateway process under /qtrobot_stop (the game manager's stop gateway).
    let Some(run) = play_v3(
        "qt-3",
        "--second-gateway /qtrobot_stop --echo-emotions --ms-per-char 60 --fail-say \"Well done\"",
        "--resume-paused --emergency-stop-at 4 --answer-delay-ms 200",
    ) else {
        return;
    };
    let context = &run.context;
    assert!(
        run.gm_err
            .contains("QTrobot's services reachable (/qtrobot/tts/engine/say/text)"),
        "{context}"
    );
    // Sequences 1..3 played whole and answered right; the session ended emergency-stopped.
    let results: Vec<&serde_json::Value> =
        run.peer.iter().filter(|e| e["event"] == "result").collect();
    assert_eq!(results.len(), 3, "{context}");
    assert!(results.iter().all(|r| r["outcome"] == 1), "{context}");
    assert_eq!(
        run.peer
            .last()
            .map(|e| (e["event"].clone(), e["phase"].clone())),
        Some(("done".into(), 8.into())),
        "{context}"
    );
    // The gateway's `result: false` paused the session with the service's name.
    assert!(
        run.peer.iter().any(|e| e["event"] == "resuming"
            && e["status"].as_str().is_some_and(
                |s| s.contains("/qtrobot/tts/engine/say/text answered that it failed")
            )),
        "{context}"
    );

    // Nothing was asked of the gateway while it served another call: no face, gesture or
    // speech waited behind another (to play late, to count against its call timeout, or to
    // play after a stop).
    let calls = run.calls("/qtrobot");
    let waits: Vec<(String, String, i64)> = calls
        .iter()
        .map(|(service, arg, asked, at, _)| (service.clone(), arg.clone(), at - asked))
        .collect();
    let longest = waits.iter().map(|w| w.2).max().unwrap_or(0);
    eprintln!(
        "{} gateway calls; longest wait in the gateway's queue {} ms",
        calls.len(),
        longest / MS
    );
    assert!(
        waits.iter().all(|w| w.2 < 100 * MS),
        "calls waited in the gateway's queue (ms): {:?}\n{context}",
        waits
            .iter()
            .filter(|w| w.2 >= 100 * MS)
            .map(|w| (&w.0, &w.1, w.2 / MS))
            .collect::<Vec<_>>()
    );

    // The timeline of each sequence: every word shows its face, then says it, one after the
    // other with nothing in between, and the task reaches the tablet once the last word was
    // said, not before and not later than a moment after.
    assert_eq!(run.records.len(), 3, "{context}");
    for record in &run.records {
        let sequence: Vec<&str> = record["result"]["sequence"]
            .as_array()
            .map(|a| a.iter().filter_map(|e| e.as_str()).collect())
            .unwrap_or_default();
        let task = record["task_sent_ns"].as_i64().unwrap_or(0);
        let before: Vec<&(String, String, i64, i64, i64)> =
            calls.iter().filter(|c| c.3 < task).collect();
        let words = &before[before.len().saturating_sub(2 * sequence.len())..];
        let expected: Vec<(String, String)> = sequence
            .iter()
            .flat_map(|e| {
                [
                    ("emotion".to_string(), format!("QT/{e}")),
                    ("say".to_string(), e.to_string()),
                ]
            })
            .collect();
        let played: Vec<(String, String)> =
            words.iter().map(|c| (c.0.clone(), c.1.clone())).collect();
        assert_eq!(played, expected, "{context}");
        let gaps: Vec<i64> = words.windows(2).map(|w| w[1].3 - w[0].4).collect();
        assert!(
            gaps.iter().all(|g| (0..300 * MS).contains(g)),
            "gaps between the words' calls (ms): {:?}\n{context}",
            gaps.iter().map(|g| g / MS).collect::<Vec<_>>()
        );
        let last_end = words.last().map_or(0, |c| c.4);
        assert!(
            (0..500 * MS).contains(&(task - last_end)),
            "task {} ms after the last word ended\n{context}",
            (task - last_end) / MS
        );
    }

    // The emergency stop, pressed as sequence 4's second face showed: the robot was silent
    // within 0.5 s, and nothing more was asked of it but the cancel, through the stop
    // gateway.
    let pressed = run.pressed();
    let (_, silent) = run.silent_after_press();
    assert!(
        silent - pressed < 500 * MS,
        "robot silent {} ms after the press\n{context}",
        (silent - pressed) / MS
    );
    assert!(
        calls.iter().all(|c| c.3 < pressed),
        "the robot was asked for more after the press\n{context}"
    );
    assert!(
        run.calls("/qtrobot_stop")
            .iter()
            .any(|c| c.0 == "cancel" && (0..500 * MS).contains(&(c.3 - pressed))),
        "no cancel through the stop gateway\n{context}"
    );
    // Faces and gestures went through the V3 services, gestures at the configured speed.
    assert!(
        calls.iter().filter(|c| c.0 == "emotion").count() >= 3 * 3,
        "{context}"
    );
    assert!(
        run.robot
            .iter()
            .any(|e| e["service"] == "gesture" && e["event"] == "start" && e["speed"] == 1.0),
        "{context}"
    );
}

#[test]
fn the_emergency_stop_silences_a_v3_mid_sentence_within_half_a_second() {
    // Pressed one second into the introduction (7.8 s of speech at 60 ms a character).
    let Some(run) = play_v3(
        "qt-4",
        "--second-gateway /qtrobot_stop --echo-speech --ms-per-char 60",
        "--emergency-stop-during Hello --emergency-stop-after-ms 1000",
    ) else {
        return;
    };
    let context = &run.context;
    let pressed = run.pressed();
    let (speech, silent) = run.silent_after_press();
    eprintln!(
        "emergency stop 1 s into the introduction: robot silent {} ms after the press",
        (silent - pressed) / MS
    );
    assert!(
        speech.as_deref().is_some_and(|s| s.starts_with("Hello")),
        "the press did not land in the introduction\n{context}"
    );
    assert!(
        silent - pressed < 500 * MS,
        "robot silent {} ms after the press\n{context}",
        (silent - pressed) / MS
    );
    assert!(
        run.robot
            .iter()
            .any(|e| e["service"] == "say" && e["event"] == "end" && e["interrupted"] == true),
        "the introduction was not cut short\n{context}"
    );
    assert!(
        run.calls("/qtrobot").iter().all(|c| c.3 < pressed),
        "the robot was asked for more after the press\n{context}"
    );
    assert_eq!(
        run.peer
            .last()
            .map(|e| (e["event"].clone(), e["phase"].clone())),
        Some(("done".into(), 8.into())),
        "{context}"
    );
}

#[test]
fn without_a_stop_gateway_a_v3_is_silent_once_the_call_under_way_ends() {
    // The same press with one gateway only: the cancel has no free gateway to go through. The
    // robot finishes the sentence under way and is asked for nothing more.
    let Some(run) = play_v3(
        "qt-5",
        "--echo-speech --ms-per-char 60",
        "--emergency-stop-during Hello --emergency-stop-after-ms 1000",
    ) else {
        return;
    };
    let context = &run.context;
    assert!(
        run.gm_err
            .contains("no /qtrobot_stop/tts/engine/cancel server"),
        "no warning about the missing stop gateway\n{context}"
    );
    let pressed = run.pressed();
    let (speech, silent) = run.silent_after_press();
    let intro = speech.unwrap_or_else(|| panic!("no speech at the press\n{context}"));
    eprintln!(
        "without a stop gateway, emergency stop 1 s into the introduction: robot silent {} ms \
         after the press (the rest of the introduction)",
        (silent - pressed) / MS
    );
    // It said the introduction to its end: 60 ms a character, 1 s of it said at the press.
    let rest = (intro.chars().count() as i64 * 60 - 1000) * MS;
    assert!(
        (silent - pressed - rest).abs() < 500 * MS,
        "robot silent {} ms after the press, the introduction's rest is {} ms\n{context}",
        (silent - pressed) / MS,
        rest / MS
    );
    let calls = run.calls("/qtrobot");
    assert!(
        calls.iter().all(|c| c.3 < pressed || c.0 == "cancel"),
        "the robot was asked for more after the press\n{context}"
    );
}
