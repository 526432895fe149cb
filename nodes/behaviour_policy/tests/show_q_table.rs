//! `behaviour_policy show-q-table` end to end: a Q-table file in words (whose it is, where it
//! came from, per state its Q-values, greedy action, visits and temperature), and a corrupt
//! file refused by its name.

use std::process::{Command, Output};

fn bin(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_behaviour_policy"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("runs the binary")
}

#[test]
fn a_sample_table_is_shown_state_by_state() {
    let out = bin(&[
        "show-q-table",
        "--all",
        "../../bags/q_tables/cluster_0.json",
    ]);
    let shown = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{shown}");
    assert!(
        shown.starts_with("../../bags/q_tables/cluster_0.json: cluster 0, 0 live updates"),
        "{shown}"
    );
    assert!(
        shown.contains("provenance: pretrained by the node"),
        "{shown}"
    );
    // Every one of the 64 states, the start state with a4 and a5 masked.
    assert_eq!(shown.lines().filter(|l| l.starts_with("(L=")).count(), 64);
    let start = shown
        .lines()
        .find(|l| l.starts_with("(L=0, F=0, PS=+0)"))
        .expect("the start state");
    assert_eq!(start.split_whitespace().filter(|c| *c == "-").count(), 2);
}

#[test]
fn a_corrupt_table_is_refused_by_name() {
    let dir = tempfile::tempdir().expect("tempdir");
    let corrupt = dir.path().join("cluster_0.json");
    std::fs::write(
        &corrupt,
        "{\"format\": \"qt_therapy q_table\", \"version\": 1, \"own",
    )
    .expect("write");
    let out = bin(&["show-q-table", corrupt.to_str().expect("utf-8 path")]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("cluster_0.json") && err.contains("not JSON"),
        "{err}"
    );
}
