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

/// Under systemd's watchdog (`WATCHDOG_USEC`, `NOTIFY_SOCKET`, here a socket of the test's in
/// the place of systemd's): `WATCHDOG=1` keeps coming while every node is alive, stops while
/// one is stopped (SIGSTOP) and comes again after its SIGCONT; the nodes do not inherit the
/// watchdog's variables; a node still stopped when the launch stops is woken (SIGCONT after
/// its SIGINT) and stops by the SIGINT, not killed after the grace.
#[test]
fn the_watchdog_is_fed_only_while_every_node_is_alive() {
    use nix::sys::signal::{Signal, kill};
    use nix::unistd::Pid;
    use std::os::unix::net::UnixDatagram;
    use std::time::{Duration, Instant};

    let dir = tempfile::tempdir().expect("temp dir");
    let notify = dir.path().join("notify");
    let systemd = UnixDatagram::bind(&notify).expect("binds the notify socket");
    systemd
        .set_read_timeout(Some(Duration::from_millis(50)))
        .expect("timeout");
    let file = dir.path().join("test.launch.yaml");
    std::fs::write(
        &file,
        "launch:\n\
         - executable:\n    cmd: sh -c 'env > frozen.env; echo $$ > frozen.pid; exec sleep 60'\n    name: frozen\n\
         - executable:\n    cmd: sleep 60\n    name: steady\n",
    )
    .expect("writes the launch file");
    let stderr_path = dir.path().join("stderr.log");
    let mut launcher = std::process::Command::new(env!("CARGO_BIN_EXE_launch"))
        .arg(&file)
        .args(["--grace", "5"])
        .current_dir(dir.path())
        .env("NOTIFY_SOCKET", &notify)
        .env("WATCHDOG_USEC", "400000")
        .env_remove("WATCHDOG_PID")
        .stdout(std::process::Stdio::null())
        .stderr(std::fs::File::create(&stderr_path).expect("stderr file"))
        .spawn()
        .expect("runs launch");
    let pid_file = dir.path().join("frozen.pid");
    let deadline = Instant::now() + Duration::from_secs(10);
    let frozen = loop {
        if let Some(pid) = std::fs::read_to_string(&pid_file)
            .ok()
            .and_then(|p| p.trim().parse::<i32>().ok())
        {
            break Pid::from_raw(pid);
        }
        assert!(Instant::now() < deadline, "the node did not start");
        std::thread::sleep(Duration::from_millis(20));
    };
    // Keep-alives received during `window`.
    let count_for = |window: Duration| {
        let end = Instant::now() + window;
        let mut n = 0;
        let mut buf = [0u8; 64];
        while Instant::now() < end {
            if let Ok(len) = systemd.recv(&mut buf) {
                assert_eq!(&buf[..len], b"WATCHDOG=1");
                n += 1;
            }
        }
        n
    };
    let alive = count_for(Duration::from_millis(600));
    kill(frozen, Signal::SIGSTOP).expect("stops the node");
    // One look may have fed just before the stop.
    count_for(Duration::from_millis(250));
    let while_stopped = count_for(Duration::from_millis(800));
    kill(frozen, Signal::SIGCONT).expect("continues the node");
    let after = count_for(Duration::from_millis(600));
    // Stopped again, then the launch stops: the SIGCONT after the SIGINT lets it stop itself.
    kill(frozen, Signal::SIGSTOP).expect("stops the node");
    std::thread::sleep(Duration::from_millis(300));
    kill(
        Pid::from_raw(i32::try_from(launcher.id()).expect("a pid")),
        Signal::SIGINT,
    )
    .expect("interrupts the launcher");
    let status = launcher.wait().expect("the launcher ends");
    let stderr = std::fs::read_to_string(&stderr_path).unwrap_or_default();
    let context =
        format!("alive {alive}, stopped {while_stopped}, after {after}; exit {status:?}\n{stderr}");
    assert!(alive >= 3, "{context}");
    assert_eq!(while_stopped, 0, "{context}");
    assert!(after >= 3, "{context}");
    assert!(
        stderr.contains("feeding systemd's watchdog (WatchdogSec 400ms) while every node is alive"),
        "{context}"
    );
    assert!(
        stderr.contains(&format!(
            "frozen (pid {frozen}) is stopped: not feeding systemd's watchdog"
        )),
        "{context}"
    );
    assert!(
        stderr.contains("every node is alive again: feeding systemd's watchdog"),
        "{context}"
    );
    assert!(
        stderr.contains("[launch] frozen stopped (signal SIGINT)"),
        "{context}"
    );
    assert_eq!(status.code(), Some(0), "{context}");
    let env = std::fs::read_to_string(dir.path().join("frozen.env")).expect("the node's env");
    assert!(
        !env.contains("NOTIFY_SOCKET") && !env.contains("WATCHDOG_USEC"),
        "{env}"
    );
}
