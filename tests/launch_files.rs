//! The launcher starts and stops real node processes from ROS 2 YAML launch files: a two-node
//! pair that ends itself, Ctrl-C stopping everything, and a dying node reported (and
//! respawned when asked). All inside one loopback-only network namespace per test. And every
//! launch file in launch_scripts/ parses and starts built binaries with parameters they have.

use std::path::{Path, PathBuf};
use std::time::Duration;
use suite_tests::{json_lines, run_in_loopback_netns, workspace_bin, workspace_root};

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

/// The parameter file a process of a launch file reads: `--params-file`, else the node's own
/// file in the launch's parameter directory (named after the node, as the node shell does).
fn params_file_of(program: &str, args: &[&str]) -> PathBuf {
    if let Some(i) = args.iter().position(|a| *a == "--params-file") {
        return PathBuf::from(args.get(i + 1).copied().unwrap_or_default());
    }
    let binary = Path::new(program)
        .file_name()
        .map(|f| f.to_string_lossy().to_string())
        .unwrap_or_default();
    let node = match (binary.as_str(), args.first().copied()) {
        ("bag", Some("record")) => "bag_recorder".to_string(),
        ("bag", Some("play")) => "bag_player".to_string(),
        ("therapist", _) => "therapist_console".to_string(),
        _ => binary,
    };
    workspace_root().join("params").join(format!("{node}.yaml"))
}

#[test]
fn every_launch_script_starts_built_binaries_with_parameters_they_have() {
    let launch = workspace_bin("launch");
    let bin = launch.parent().expect("target dir").display().to_string();
    let root = workspace_root();
    let mut scripts: Vec<_> = std::fs::read_dir(root.join("launch_scripts"))
        .expect("launch_scripts/")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.to_string_lossy().ends_with(".launch.yaml"))
        .collect();
    scripts.sort();
    assert!(scripts.len() >= 2, "{scripts:?}");
    for script in scripts {
        // Printing parses the file and expands every argument (no DDS, nothing starts).
        let out = std::process::Command::new(&launch)
            .arg("--print")
            .arg(&script)
            .arg(format!("bin:={bin}"))
            .arg("out:=out/launch-check")
            .current_dir(&root)
            .output()
            .expect("launch --print");
        let stdout = String::from_utf8_lossy(&out.stdout);
        let context = format!(
            "{}:\n{stdout}\n{}",
            script.display(),
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(out.status.success(), "{context}");
        let lines: Vec<&str> = stdout.lines().filter(|l| !l.trim().is_empty()).collect();
        assert!(!lines.is_empty(), "{context}");
        for line in lines {
            let (_, command) = line.split_once(": ").expect("name: command");
            let words: Vec<&str> = command.split_whitespace().collect();
            let (program, args) = words.split_first().expect("a program");
            assert!(
                Path::new(program).is_file(),
                "{program} is not built\n{context}"
            );
            // Every `--param key:=value` names a key of the node's parameter file (a typo would
            // stop the node at startup).
            let params = params_file_of(program, args);
            let text = std::fs::read_to_string(&params)
                .unwrap_or_else(|e| panic!("{}: {e}\n{context}", params.display()));
            for pair in args.windows(2).filter(|w| w[0] == "--param") {
                let key = pair[1].split(":=").next().unwrap_or_default();
                assert!(
                    text.contains(&format!("\n    {key}:")),
                    "{line}: {key} is not a parameter in {}",
                    params.display()
                );
            }
        }
    }
}
