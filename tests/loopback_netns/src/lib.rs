//! Running a test's DDS processes inside a private loopback-only network namespace
//! (`tests/loopback-netns`): DDS discovery multicasts, and no packet may leave the machine.
//! Two ways in: a bash script of processes, or the calling test itself run again inside.
//! Where the machine cannot make a namespace (no root, no user namespaces) both say so and
//! return None, so the test skips instead of talking to the network; with
//! [`REQUIRE_ALL_TESTS`] set (`tests/run.sh`, hence CI) they fail instead.

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// The workspace root.
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Whether this machine lets us make a network namespace (root, or user namespaces).
pub fn can_make_network_namespace() -> bool {
    let ok = |args: &[&str]| {
        Command::new("unshare")
            .args(args)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success())
    };
    ok(&["-n", "true"]) || ok(&["-rn", "true"])
}

/// Environment variable that turns a skipped test into a failed one. `tests/run.sh` installs
/// everything the tests need and sets it, so CI cannot pass without running the DDS tests.
pub const REQUIRE_ALL_TESTS: &str = "QT_REQUIRE_ALL_TESTS";

/// Skips the calling test (after saying why), or fails it where [`REQUIRE_ALL_TESTS`] is set.
/// Returns true when the test should return early.
pub fn skip_or_fail(why: &str) -> bool {
    skip_unless_required(
        std::env::var_os(REQUIRE_ALL_TESTS).is_some_and(|v| v != "0"),
        why,
    )
}

fn skip_unless_required(required: bool, why: &str) -> bool {
    if required {
        panic!("{why}, and {REQUIRE_ALL_TESTS} is set: this test must run here");
    }
    eprintln!("skipping: {why}");
    true
}

fn cannot() -> bool {
    !can_make_network_namespace()
        && skip_or_fail(
            "this machine cannot create a network namespace (need root or user namespaces)",
        )
}

/// Runs `script` with bash inside one fresh namespace, in the workspace root, killed after
/// `deadline`. None (after saying why) where namespaces cannot be made.
pub fn run_in_loopback_netns(script: &str, deadline: Duration) -> Option<Output> {
    if cannot() {
        return None;
    }
    let child = Command::new(workspace_root().join("tests/loopback-netns"))
        .args(["timeout", "--signal=KILL"])
        .arg(deadline.as_secs().max(1).to_string())
        .args(["bash", "-c", script])
        .current_dir(workspace_root())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("starting tests/loopback-netns");
    Some(wait_with_backstop(child, deadline))
}

/// Runs the test `name` of the current test binary again inside one fresh namespace (exact
/// name, output shown, one thread, ignored tests included), with `env` set so the inner run
/// knows it is inside; in the workspace root, killed after `deadline`. None (after saying why)
/// where namespaces cannot be made.
pub fn rerun_test_inside(name: &str, env: &[(&str, &OsStr)], deadline: Duration) -> Option<Output> {
    if cannot() {
        return None;
    }
    let mut command = Command::new(workspace_root().join("tests/loopback-netns"));
    command
        .args(["timeout", "--signal=KILL"])
        .arg(deadline.as_secs().max(1).to_string())
        .arg(std::env::current_exe().expect("the test binary"))
        .args([
            "--exact",
            name,
            "--include-ignored",
            "--nocapture",
            "--test-threads=1",
        ])
        .current_dir(workspace_root())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    for (k, v) in env {
        command.env(k, v);
    }
    let child = command.spawn().expect("starting tests/loopback-netns");
    Some(wait_with_backstop(child, deadline))
}

/// The whole shape of a test that runs itself again inside a namespace. In the copy running
/// inside (`marker` set in its environment) it calls `inside` and returns None. Outside it
/// reruns the test `name` inside with `marker` set, asserts that run passed (showing its
/// output if not), prints its stdout and returns it. None (after saying why) where namespaces
/// cannot be made.
pub fn test_inside_namespace(
    name: &str,
    marker: &str,
    deadline: Duration,
    inside: impl FnOnce(),
) -> Option<String> {
    if std::env::var_os(marker).is_some() {
        inside();
        return None;
    }
    let out = rerun_test_inside(name, &[(marker, "1".as_ref())], deadline)?;
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    println!("{stdout}");
    Some(stdout)
}

/// `timeout` inside the namespace enforces the deadline; this is the backstop.
fn wait_with_backstop(mut child: std::process::Child, deadline: Duration) -> Output {
    let started = Instant::now();
    while let Ok(None) = child.try_wait() {
        if started.elapsed() > deadline + Duration::from_secs(10) {
            let _ = child.kill();
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    child
        .wait_with_output()
        .expect("collecting the namespace's output")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_test_that_cannot_run_skips_where_nothing_requires_it() {
        assert!(skip_unless_required(false, "no namespace"));
    }

    #[test]
    #[should_panic(expected = "no namespace, and QT_REQUIRE_ALL_TESTS is set")]
    fn a_test_that_cannot_run_fails_where_every_test_is_required() {
        skip_unless_required(true, "no namespace");
    }
}
