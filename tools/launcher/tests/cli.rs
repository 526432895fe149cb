//! The `launch` binary with plain shell commands as nodes (no DDS, so no namespace): output
//! prefixed per node and forwarded before the node's exit is reported, a dying node reported
//! and the launch's exit code set, a grandchild holding the output open not holding up the
//! launch, a node that cannot start named while the others are stopped, and a broken launch
//! file refused before anything starts.

use std::path::Path;
use std::process::{Command, Output};

fn launch(dir: &Path, file_text: &str) -> Output {
    let file = dir.join("test.launch.yaml");
    std::fs::write(&file, file_text).expect("writes the launch file");
    Command::new(env!("CARGO_BIN_EXE_launch"))
        .arg(&file)
        .args(["--grace", "2"])
        .arg("--log-dir")
        .arg(dir.join("logs"))
        .current_dir(dir)
        // Keep anyhow's error report to the message a user sees.
        .env_remove("RUST_BACKTRACE")
        .env_remove("RUST_LIB_BACKTRACE")
        .output()
        .expect("runs launch")
}

fn text(out: &Output) -> (String, String) {
    (
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn output_is_prefixed_per_node_and_a_dying_node_sets_the_exit_code() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = launch(
        dir.path(),
        "launch:\n\
         - executable:\n    cmd: sh -c 'echo hello; echo oops >&2; exit 3'\n    name: first\n\
         - executable:\n    cmd: sh -c 'sleep 0.5; echo second done'\n    name: second\n",
    );
    let (stdout, stderr) = text(&out);
    let context = format!("stdout:\n{stdout}\nstderr:\n{stderr}");
    assert_eq!(out.status.code(), Some(1), "{context}");
    assert!(stdout.lines().any(|l| l == "[first] hello"), "{context}");
    assert!(
        stdout.lines().any(|l| l == "[second] second done"),
        "{context}"
    );
    // A node's last lines come before the report of its exit (which can end the launch).
    let oops = stderr.find("[first] oops");
    let died = stderr.find("[launch] first died (exit code 3)");
    assert!(oops.is_some() && died.is_some() && oops < died, "{context}");
    assert!(stderr.contains("[launch] second finished"), "{context}");
}

#[test]
fn output_log_goes_to_the_node_log_file_only_and_both_to_both() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = launch(
        dir.path(),
        "launch:\n\
         - executable:\n    cmd: sh -c 'echo quiet out; echo quiet err >&2'\n    name: quiet\n    output: log\n\
         - executable:\n    cmd: sh -c 'echo loud'\n    name: loud\n    output: both\n\
         - executable:\n    cmd: sh -c 'echo plain'\n    name: plain\n",
    );
    let (stdout, stderr) = text(&out);
    let context = format!("stdout:\n{stdout}\nstderr:\n{stderr}");
    assert_eq!(out.status.code(), Some(0), "{context}");
    assert!(
        !stdout.contains("quiet") && !stderr.contains("[quiet] quiet"),
        "{context}"
    );
    assert!(stdout.lines().any(|l| l == "[loud] loud"), "{context}");
    assert!(stdout.lines().any(|l| l == "[plain] plain"), "{context}");
    let logs = dir.path().join("logs");
    let read = |name: &str| std::fs::read_to_string(logs.join(format!("{name}.log")));
    let quiet = read("quiet").expect("quiet.log");
    assert!(
        quiet.contains("quiet out\n") && quiet.contains("quiet err\n"),
        "{quiet}"
    );
    assert_eq!(read("loud").expect("loud.log"), "loud\n");
    assert!(read("plain").is_err(), "a screen-only node has no log file");
    assert!(stderr.contains("output of quiet, loud in"), "{context}");
}

#[test]
fn a_grandchild_holding_the_output_open_does_not_hold_up_the_launch() {
    let dir = tempfile::tempdir().expect("temp dir");
    let started = std::time::Instant::now();
    let out = launch(
        dir.path(),
        "launch:\n\
         - executable:\n    cmd: sh -c 'sleep 20 & echo parent done'\n    name: parent\n",
    );
    let (stdout, stderr) = text(&out);
    let context = format!("stdout:\n{stdout}\nstderr:\n{stderr}");
    assert_eq!(out.status.code(), Some(0), "{context}");
    assert!(
        stdout.lines().any(|l| l == "[parent] parent done"),
        "{context}"
    );
    assert!(stderr.contains("[launch] parent finished"), "{context}");
    // The sleeping grandchild keeps the pipe open for 20 s; the launch is over long before.
    assert!(
        started.elapsed() < std::time::Duration::from_secs(15),
        "took {:?}\n{context}",
        started.elapsed()
    );
}

#[test]
fn a_node_that_cannot_start_is_named_and_the_others_are_stopped() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = launch(
        dir.path(),
        "launch:\n\
         - executable:\n    cmd: /nonexistent/program --flag\n    name: ghost\n\
         - executable:\n    cmd: sleep 30\n    name: sleeper\n",
    );
    let (stdout, stderr) = text(&out);
    let context = format!("stdout:\n{stdout}\nstderr:\n{stderr}");
    assert_ne!(out.status.code(), Some(0), "{context}");
    assert!(
        stderr.contains("could not start ghost (/nonexistent/program)"),
        "{context}"
    );
    // Stopped by the launcher, long before its 30 s were up.
    assert!(
        stderr.contains("[launch] sleeper stopped (signal SIGINT)"),
        "{context}"
    );
}

#[test]
fn a_broken_launch_file_is_refused_by_name_before_anything_starts() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = launch(
        dir.path(),
        "launch:\n\
         - executable:\n    cmd: touch started\n    name: toucher\n\
         - executable:\n    name: no_command\n",
    );
    let (stdout, stderr) = text(&out);
    let context = format!("stdout:\n{stdout}\nstderr:\n{stderr}");
    assert_eq!(out.status.code(), Some(1), "{context}");
    assert!(stderr.contains("test.launch.yaml"), "{context}");
    assert!(stderr.contains("missing field `cmd`"), "{context}");
    assert!(
        !dir.path().join("started").exists(),
        "the valid first node ran although the file is broken: {context}"
    );
}
