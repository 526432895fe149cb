//! The launcher starts and stops real node processes from ROS 2 YAML launch files: a two-node
//! pair that ends itself, Ctrl-C stopping everything, and a dying node reported (and
//! respawned when asked). All inside one loopback-only network namespace per test.

use std::time::Duration;
use suite_tests::{json_lines, run_in_loopback_netns, workspace_bin};

fn paths() -> (String, String) {
    (
        workspace_bin("launch").display().to_string(),
        env!("CARGO_BIN_EXE_dds_probe").to_string(),
    )
}

#[test]
fn two_node_launch_runs_and_ends_when_its_last_node_finishes() {
    let (launch, probe) = paths();
    let script = format!(
        "{launch} tests/launch/probe_pair.launch.yaml probe:={probe}; echo \"launcher_exit=$?\""
    );
    let Some(out) = run_in_loopback_netns(&script, Duration::from_secs(90)) else {
        return;
    };
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let context = format!("stdout:\n{stdout}\nstderr:\n{stderr}");
    assert!(stdout.contains("launcher_exit=0"), "{context}");
    // Output is prefixed with the node's name, and both nodes did their part over DDS.
    let from = |name: &str| -> Vec<serde_json::Value> {
        let prefix = format!("[{name}] ");
        json_lines(
            &stdout
                .lines()
                .filter_map(|l| l.strip_prefix(&prefix))
                .collect::<Vec<_>>()
                .join("\n"),
        )
    };
    let answers = from("responder")
        .iter()
        .filter(|e| e["event"] == "answer")
        .count();
    assert_eq!(answers, 3, "{context}");
    assert_eq!(
        from("caller")
            .iter()
            .filter(|e| e["event"] == "response")
            .count(),
        2,
        "{context}"
    );
    assert!(
        stderr.contains("[launch] caller finished (exit code 0): stopping the launch"),
        "{context}"
    );
    assert!(
        stderr.contains("[launch] responder stopped (exit code 0)"),
        "{context}"
    );
}

#[test]
fn ctrl_c_stops_every_node_and_a_dying_node_is_reported() {
    let (launch, probe) = paths();
    let script = format!(
        r#"
        O=$(mktemp); E=$(mktemp)
        {launch} tests/launch/probe_servers.launch.yaml probe:={probe} >$O 2>$E &
        L=$!
        for i in $(seq 200); do [ "$(grep -c '"ready"' $O)" -ge 2 ] && break; sleep 0.1; done
        kill -INT $L; wait $L; echo "launcher_exit=$?"
        cat $O; cat $E >&2
        "#
    );
    let Some(out) = run_in_loopback_netns(&script, Duration::from_secs(90)) else {
        return;
    };
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let context = format!("stdout:\n{stdout}\nstderr:\n{stderr}");
    // A node died during the launch, so the launch as a whole failed.
    assert!(stdout.contains("launcher_exit=1"), "{context}");
    assert!(stdout.contains("[fragile] about to fail"), "{context}");
    assert!(
        stderr.contains("[launch] fragile died (exit code 3)"),
        "{context}"
    );
    assert!(
        stderr.contains("[launch] Ctrl-C: stopping all nodes"),
        "{context}"
    );
    for node in ["first", "second"] {
        assert!(
            stdout.contains(&format!(
                "[{node}] {{\"dropped_answers\":0,\"event\":\"stopped\"}}"
            )),
            "{context}"
        );
        assert!(
            stderr.contains(&format!("[launch] {node} stopped (exit code 0)")),
            "{context}"
        );
    }
}

#[test]
fn a_node_marked_respawn_is_restarted() {
    let (launch, probe) = paths();
    let script = format!(
        r#"
        O=$(mktemp); E=$(mktemp)
        {launch} tests/launch/probe_servers.launch.yaml probe:={probe} respawn:=true >$O 2>$E &
        L=$!
        for i in $(seq 200); do [ "$(grep -c 'restart 3' $E)" -ge 1 ] && break; sleep 0.1; done
        kill -TERM $L; wait $L; echo "launcher_exit=$?"
        cat $O; cat $E >&2
        "#
    );
    let Some(out) = run_in_loopback_netns(&script, Duration::from_secs(90)) else {
        return;
    };
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let context = format!("stdout:\n{stdout}\nstderr:\n{stderr}");
    assert!(
        stderr.contains("fragile died (exit code 3); respawning in 0.2 s (restart 3)"),
        "{context}"
    );
    assert!(stderr.contains("[launch] restarted fragile"), "{context}");
    assert!(
        stderr.contains("[launch] SIGTERM: stopping all nodes"),
        "{context}"
    );
    assert!(
        stdout.matches("[fragile] about to fail").count() >= 3,
        "{context}"
    );
    assert!(stdout.contains("launcher_exit=0"), "{context}");
}
