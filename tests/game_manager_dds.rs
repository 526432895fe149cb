//! The `game_manager` binary plays a whole session over real DDS against the scripted test
//! peer (policy, tablet, camera, therapist), both processes inside a private loopback-only
//! network namespace (`tests/loopback-netns` at the workspace root): ten live lines in its log,
//! ten fsync'd records and a summary in the session directory, results over DDS.

use game_manager::session_file::{SessionSummary, read_records};
use std::path::Path;
use std::time::Duration;
use suite_tests::json_lines;

use suite_tests::{run_in_loopback_netns, workspace_bin, workspace_root};

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

/// What a run of the game manager beside the scripted peer left: their outputs, and all of it
/// as one text for assertion messages.
struct Played {
    gm_err: String,
    peer_out: String,
    context: String,
}

/// Runs the game manager (parameters in `d`) and the peer with `peer_args` inside a loopback
/// network namespace until the peer exits, then SIGINTs the game manager; both must exit 0.
/// None where no namespace can be made (the test then skips, saying why).
fn play_with_peer(d: &Path, peer_args: &str) -> Option<Played> {
    let script = format!(
        r#"
        export ROS_LOCALHOST_ONLY=1 QT_PARAMS_DIR={d}
        {gm} run --sessions-dir {d}/sessions >{d}/gm.out 2>{d}/gm.err &
        G=$!
        {peer} {peer_args} >{d}/peer.out 2>{d}/peer.err
        P=$?
        kill -INT $G; wait $G; RC=$?
        echo "{{\"peer\":$P,\"game_manager\":$RC}}"
        "#,
        d = d.display(),
        gm = workspace_bin("game_manager").display(),
        peer = env!("CARGO_BIN_EXE_game_manager_test_peer"),
    );
    let out = run_in_loopback_netns(&script, Duration::from_secs(200))?;
    let read = |f: &str| std::fs::read_to_string(d.join(f)).unwrap_or_default();
    let (gm_out, gm_err, peer_out) = (read("gm.out"), read("gm.err"), read("peer.out"));
    let context = format!(
        "script: {}\n{}\ngame_manager stdout:\n{gm_out}\nstderr:\n{gm_err}\npeer:\n{peer_out}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
        read("peer.err")
    );
    let exit = json_lines(&String::from_utf8_lossy(&out.stdout));
    assert_eq!(
        exit.last()
            .map(|e| (e["peer"].clone(), e["game_manager"].clone())),
        Some((0.into(), 0.into())),
        "{context}"
    );
    Some(Played {
        gm_err,
        peer_out,
        context,
    })
}

#[test]
fn a_whole_session_over_dds_is_played_recorded_and_shown_live() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    write_params(d);
    let Some(played) = play_with_peer(d, "--session dds-1 --wrong 3 --silent 5 --override-level 3")
    else {
        return;
    };
    let Played {
        gm_err,
        peer_out,
        context,
    } = played;
    let read = |f: &str| std::fs::read_to_string(d.join(f)).unwrap_or_default();

    // The live view, logged once each: a start line, ten sequence lines, an end line.
    let live: Vec<&str> = gm_err.lines().filter(|l| l.contains(": seq ")).collect();
    assert_eq!(live.len(), 10, "{context}");
    assert!(live[2].contains("answer wrong"), "{context}");
    assert!(live[4].contains("answer timeout"), "{context}");
    assert!(live[1].contains("therapist override"), "{context}");
    assert!(
        live[0].contains("policy greedy") && live[3].contains("policy explored"),
        "{context}"
    );
    assert!(gm_err.contains("all sequences played"), "{context}");

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
fn proposals_to_the_therapist_are_accepted_replaced_or_run_out_over_dds() {
    // Supervised autonomy with the shipped user models for the σ rule (its threshold above any
    // σ: the policy's temperature alone decides what is proposed here).
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    write_params(d);
    let models = workspace_root().join("nodes/user_model/models/migrave_study_c2.json");
    let params = std::fs::read_to_string(d.join("game_manager.yaml")).expect("params");
    let supervised = params
        .replace("supervised_autonomy: false", "supervised_autonomy: true")
        .replace(
            "propose_above_success_std: 0.3",
            "propose_above_success_std: 1.0",
        )
        // 2 s after time_scale.
        .replace("proposal_countdown_s: 5.0", "proposal_countdown_s: 40.0")
        .replace(
            r#"user_model_file: "nodes/user_model/models/migrave_study_c2.json""#,
            &format!("user_model_file: {:?}", models.display().to_string()),
        );
    assert!(
        supervised.contains("supervised_autonomy: true")
            && supervised.contains(&*models.to_string_lossy())
    );
    std::fs::write(d.join("game_manager.yaml"), supervised).expect("write params");
    let Some(Played {
        peer_out, context, ..
    }) = play_with_peer(
        d,
        "--session dds-sup --unsure 2,3,4,6 --proposal-replies accept,level3,wait,challenge",
    )
    else {
        return;
    };
    let read = |f: &str| std::fs::read_to_string(d.join(f)).unwrap_or_default();
    let peer = json_lines(&peer_out);
    let proposals: Vec<(i64, i64)> = peer
        .iter()
        .filter(|e| e["event"] == "proposal")
        .filter_map(|e| Some((e["step"].as_i64()?, e["status"].as_i64()?)))
        .collect();
    // PROPOSED (0), then ACCEPTED (1), REPLACED (2), TIMED_OUT (3), REPLACED.
    assert_eq!(
        proposals,
        vec![
            (2, 0),
            (2, 1),
            (3, 0),
            (3, 2),
            (4, 0),
            (4, 3),
            (6, 0),
            (6, 2)
        ],
        "{context}"
    );
    let all: Vec<&serde_json::Value> = peer.iter().filter(|e| e["event"] == "proposal").collect();
    assert!(
        all.iter()
            .all(|p| p["success_std"].as_f64().is_some_and(|s| s >= 0.0)),
        "the σ of the shipped user models is in every proposal: {context}"
    );
    assert_eq!(
        (
            all[3]["played_level"].clone(),
            all[7]["played_feedback"].clone()
        ),
        (3.into(), 2.into()),
        "{context}"
    );
    let results: Vec<&serde_json::Value> = peer.iter().filter(|e| e["event"] == "result").collect();
    assert_eq!(results.len(), 10, "{context}");
    let overridden: Vec<bool> = results
        .iter()
        .filter_map(|r| r["overridden"].as_bool())
        .collect();
    assert_eq!(
        overridden,
        vec![
            false, false, true, false, false, true, false, false, false, false
        ],
        "{context}"
    );
    assert_eq!(results[2]["level"], 3, "{context}");
    let records = read_records(&d.join("sessions/dds-sup.jsonl")).expect("session file");
    assert!(
        records.records[1]
            .decision_reason
            .contains("accepted after"),
        "{context}"
    );
    assert!(
        records.records[3]
            .decision_reason
            .contains("ran out after 2.0 s: played"),
        "{context}"
    );
    let summary: SessionSummary =
        serde_json::from_str(&read("sessions/dds-sup.summary.json")).expect("summary file");
    assert_eq!(
        (
            summary.proposals,
            summary.proposals_accepted,
            summary.proposals_replaced,
            summary.proposals_timed_out
        ),
        (4, 1, 2, 1),
        "{context}"
    );
}

#[test]
fn a_killed_node_loses_no_scored_sequence_and_its_restart_goes_on_with_the_same_session() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    write_params(d);
    // The peer gives up after 8 s (mid-session, an override carried out); the node is then
    // killed (a crash) and started again: it takes the session over, paused. A second peer
    // delivers the START and the override again, resumes (id 3, twice), plays for 8 s; then
    // SIGINT stops the node, which saves the summary.
    let script = format!(
        r#"
        export ROS_LOCALHOST_ONLY=1 QT_PARAMS_DIR={d}
        {gm} run --sessions-dir {d}/sessions >{d}/gm1.out 2>{d}/gm1.err &
        G=$!
        {peer} --session s --timeout-s 8 --override-level 3 >{d}/peer1.out 2>{d}/peer1.err
        {gm} run --sessions-dir {d}/sessions >{d}/second.out 2>{d}/second.err
        echo "{{\"second_game_manager\":$?}}"
        kill -KILL $G; wait $G
        cp {d}/sessions/s.jsonl {d}/crashed.jsonl
        {gm} run --sessions-dir {d}/sessions >{d}/gm2.out 2>{d}/gm2.err &
        G=$!
        {peer} --session s --timeout-s 8 --override-level 3 --resume-recovered 3 >{d}/peer2.out 2>{d}/peer2.err
        kill -INT $G; wait $G; RC=$?
        echo "{{\"game_manager\":$RC}}"
        "#,
        d = d.display(),
        gm = workspace_bin("game_manager").display(),
        peer = env!("CARGO_BIN_EXE_game_manager_test_peer"),
    );
    let Some(out) = run_in_loopback_netns(&script, Duration::from_secs(120)) else {
        return;
    };
    let read = |f: &str| std::fs::read_to_string(d.join(f)).unwrap_or_default();
    let context = format!(
        "script: {}\n{}\ngm1: {}\ngm2: {}\n{}\npeer2: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
        read("gm1.out"),
        read("gm2.out"),
        read("gm2.err"),
        read("peer2.out"),
    );
    let exit = json_lines(&String::from_utf8_lossy(&out.stdout));
    assert_eq!(
        exit.last().map(|e| e["game_manager"].clone()),
        Some(0.into()),
        "{context}"
    );
    // A second game manager on the same directory, started while the first ran, refused to
    // start (it would have recovered the first one's session).
    assert_eq!(exit[0]["second_game_manager"], 1, "{context}");
    assert!(
        read("second.err").contains("sessions is in use by another game_manager (pid "),
        "{}",
        read("second.err")
    );
    let seen = |f: &str| -> Vec<u64> {
        json_lines(&read(f))
            .iter()
            .filter(|e| e["event"] == "result")
            .filter_map(|e| e["index"].as_u64())
            .collect()
    };

    // The crash: every result the peer saw is on disk (written before it was published).
    let crashed = read_records(&d.join("crashed.jsonl")).expect("the file at the crash");
    let (before, after) = (seen("peer1.out"), seen("peer2.out"));
    assert!(!before.is_empty(), "{context}");
    assert!(crashed.records.len() >= before.len(), "{context}");

    // The restart took the same session over, paused, and went on at the resume with the
    // sequence after the last one on disk: one session, one set of files.
    assert!(
        read("gm2.err").contains("recovered after a game manager restart"),
        "{context}"
    );
    assert_eq!(
        after.first().copied(),
        Some(crashed.records.len() as u64 + 1),
        "{context}"
    );
    let records = read_records(&d.join("sessions/s.jsonl")).expect("the session file");
    let indices: Vec<u64> = records
        .records
        .iter()
        .map(|r| u64::from(r.result.sequence_index))
        .collect();
    assert_eq!(
        indices,
        (1..=indices.len() as u64).collect::<Vec<_>>(),
        "{context}"
    );
    assert!(
        indices.len() >= crashed.records.len() + after.len(),
        "{context}"
    );
    let mut files: Vec<String> = std::fs::read_dir(d.join("sessions"))
        .expect("sessions dir")
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().to_string())
        .collect();
    files.sort();
    assert_eq!(
        files,
        ["s.journal", "s.jsonl", "s.summary.json"],
        "{context}"
    );

    // Commands carried out before the crash, delivered again, and the resume sent twice: each
    // refused; the resume carried out once; the override used once.
    let gm2 = read("gm2.err");
    for refused in [
        r#"rejected command 1 (start) for session "s": stale command id 1 (last accepted 2)"#,
        r#"rejected command 2 (override level) for session "s": duplicate command id 2"#,
        r#"rejected command 3 (resume) for session "s": duplicate command id 3"#,
    ] {
        assert_eq!(gm2.matches(refused).count(), 1, "{refused}\n{context}");
    }
    assert_eq!(
        gm2.matches(r#"accepted command 3 (resume) for session "s""#)
            .count(),
        1,
        "{context}"
    );
    assert_eq!(
        records
            .records
            .iter()
            .filter(|r| r.result.overridden)
            .count(),
        1,
        "{context}"
    );
    let journal = read("sessions/s.journal");
    assert_eq!(journal.matches(r#""entry":"recovered""#).count(), 1);
    assert_eq!(journal.matches(r#""command_id":3"#).count(), 1);

    // SIGINT saves the summary of the whole session.
    let summary: SessionSummary =
        serde_json::from_str(&read("sessions/s.summary.json")).expect("summary");
    assert_eq!(
        summary.end,
        game_manager::session_file::SessionEnd::NodeShutdown
    );
    assert_eq!(usize::from(summary.sequences_played), records.records.len());
    assert_eq!(summary.overrides, 1);
}
