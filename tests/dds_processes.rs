//! Two separate processes talk over real DDS (RustDDS through the node shell) inside a private
//! loopback network namespace: a topic carries messages one way, a service call goes and
//! comes back, and malformed or out-of-range messages are dropped while the node keeps serving.

use std::time::Duration;
use suite_tests::{json_lines, run_in_loopback_netns, workspace_bin};

#[test]
fn topic_and_service_cross_process_boundaries_and_bad_input_is_dropped() {
    let probe = env!("CARGO_BIN_EXE_dds_probe");
    let _ = workspace_bin; // the probe is this package's own binary
    let dir = std::env::temp_dir().join(format!("dds_processes_{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let d = dir.display();
    let script = format!(
        r#"
        P={probe}; export ROS_LOCALHOST_ONLY=1
        $P --params-file tests/params/dds_probe.yaml responder >{d}/responder.out 2>{d}/responder.err &
        R=$!
        $P --params-file tests/params/dds_probe.yaml caller --count 5 --linger 60 >{d}/caller.out 2>{d}/caller.err &
        C=$!
        # The caller stays until stopped, so that what it sent is delivered (repeated if lost):
        # wait (at most 30 s) for it to be done, the five valid answers and the three kinds of
        # drop to have been printed, or for the caller to have failed; then stop both.
        for i in $(seq 300); do
          kill -0 $C 2>/dev/null || break
          grep -q '"done"' {d}/caller.out && [ "$(grep -c '"answer"' {d}/responder.out)" -ge 5 ] &&
            [ "$(grep -c 'dropped a message.*tablet/answer' {d}/responder.err)" -ge 3 ] && break
          sleep 0.1
        done
        # SIGTERM here (the launcher and the other DDS tests stop nodes with SIGINT): both end a
        # node cleanly, with exit code 0.
        kill -TERM $C; wait $C; C=$?
        kill -TERM $R; wait $R; RC=$?
        echo "{{\"event\":\"exit\",\"caller\":$C,\"responder\":$RC}}"
        "#
    );
    let Some(out) = run_in_loopback_netns(&script, Duration::from_secs(90)) else {
        return;
    };
    let read = |f: &str| std::fs::read_to_string(dir.join(f)).unwrap_or_default();
    let (responder, caller, responder_err) = (
        read("responder.out"),
        read("caller.out"),
        read("responder.err"),
    );
    let context = format!(
        "script stdout:\n{}\nresponder:\n{responder}\n{responder_err}\ncaller:\n{caller}\n{}",
        String::from_utf8_lossy(&out.stdout),
        read("caller.err")
    );

    let exit = json_lines(&String::from_utf8_lossy(&out.stdout));
    assert_eq!(
        exit.last()
            .map(|e| (e["caller"].clone(), e["responder"].clone())),
        Some((0.into(), 0.into())),
        "{context}"
    );

    // The topic: exactly the five valid answers, in order.
    let answers: Vec<u64> = json_lines(&responder)
        .iter()
        .filter(|e| e["event"] == "answer")
        .filter_map(|e| e["sequence_id"].as_u64())
        .collect();
    assert_eq!(answers, vec![1, 2, 3, 4, 5], "{context}");

    // The service: the valid request is answered from its own fields, the invalid one refused
    // with the reason, without reaching the node's handler.
    let responses: Vec<serde_json::Value> = json_lines(&caller)
        .into_iter()
        .filter(|e| e["event"] == "response")
        .collect();
    assert_eq!(responses.len(), 2, "{context}");
    assert_eq!(responses[0]["ok"], true);
    assert_eq!(responses[0]["p"], 0.75);
    assert_eq!(responses[0]["e"], -0.5);
    assert_eq!(responses[0]["cluster"], 1.0);
    assert_eq!(responses[1]["ok"], false);
    assert!(
        responses[1]["error"]
            .as_str()
            .unwrap_or("")
            .contains("level = 4"),
        "{context}"
    );
    let requests = json_lines(&responder)
        .iter()
        .filter(|e| e["event"] == "request")
        .count();
    assert_eq!(requests, 1, "{context}");

    // The bad answers were dropped and counted (four out of range, one undecodable), each
    // kind logged once with the topic and reason, and the responder kept serving and exited
    // cleanly.
    let stopped = json_lines(&responder)
        .into_iter()
        .find(|e| e["event"] == "stopped");
    assert_eq!(
        stopped.map(|e| e["dropped_answers"].clone()),
        Some(5.into()),
        "{context}"
    );
    let drop_lines: Vec<&str> = responder_err
        .lines()
        .filter(|l| l.contains("dropped") && l.contains("/qt_therapy/tablet/answer"))
        .collect();
    assert_eq!(drop_lines.len(), 3, "{context}");
    for reason in ["joyful", "response_time", "undecodable"] {
        assert_eq!(
            drop_lines.iter().filter(|l| l.contains(reason)).count(),
            1,
            "{reason}: {context}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A node's `/rosout` records reach a reader that joins later (the topic is transient-local),
/// but its writer keeps a bounded number: RustDDS 0.15.1 evicts nothing from a transient-local
/// writer that no reader has acknowledged, so without the shell's resource limit a node
/// nobody reads `/rosout` from kept every line it ever logged (the soak's memory growth).
#[test]
fn rosout_reaches_a_late_reader_and_its_writer_keeps_a_bounded_history() {
    let probe = env!("CARGO_BIN_EXE_dds_probe");
    let dir = std::env::temp_dir().join(format!("dds_rosout_{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let d = dir.display();
    // 500 lines with nobody reading; the writer trims on its cache-cleaning timer (6 s), so
    // the reader joins after 8 s.
    let script = format!(
        r#"
        P={probe}; export ROS_LOCALHOST_ONLY=1
        $P --params-file tests/params/dds_probe.yaml logger --lines 500 >{d}/logger.out 2>{d}/logger.err &
        L=$!
        for i in $(seq 200); do grep -q '"logged"' {d}/logger.out && break; sleep 0.1; done
        sleep 8
        $P --params-file tests/params/dds_probe.yaml rosout-reader --seconds 4 >{d}/reader.out 2>{d}/reader.err
        R=$?
        kill -INT $L; wait $L; LC=$?
        echo "{{\"event\":\"exit\",\"reader\":$R,\"logger\":$LC}}"
        "#
    );
    let Some(out) = run_in_loopback_netns(&script, Duration::from_secs(90)) else {
        return;
    };
    let read = |f: &str| std::fs::read_to_string(dir.join(f)).unwrap_or_default();
    let context = format!(
        "script stdout:\n{}\nlogger:\n{}\n{}\nreader:\n{}",
        String::from_utf8_lossy(&out.stdout),
        read("logger.out"),
        read("logger.err"),
        read("reader.err")
    );
    let exit = json_lines(&String::from_utf8_lossy(&out.stdout));
    assert_eq!(
        exit.last()
            .map(|e| (e["reader"].clone(), e["logger"].clone())),
        Some((0.into(), 0.into())),
        "{context}"
    );
    let lines: Vec<u32> = json_lines(&read("reader.out"))
        .iter()
        .filter_map(|e| {
            e["msg"]
                .as_str()?
                .strip_prefix("rosout probe line ")?
                .parse()
                .ok()
        })
        .collect();
    // The newest line arrives; at most the shell's limit (100) of the 500 are kept.
    assert!(
        lines.contains(&500),
        "last line missing: {lines:?}\n{context}"
    );
    assert!(
        lines.len() <= 100,
        "{} of 500 lines re-delivered: the writer kept them all\n{context}",
        lines.len()
    );
}
