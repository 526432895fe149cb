//! Helpers for the cross-node tests: where the workspace and its binaries are, running a
//! script inside a private loopback-only network namespace (DDS multicasts; nothing may leave
//! the machine), and deadlines on every wait.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// The workspace root.
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."))
}

/// A binary of another package of the workspace, built by `cargo build --workspace --bins`
/// (the README's test command does that first). Panics with that advice when it is missing.
pub fn workspace_bin(name: &str) -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root().join("target"));
    let profile = if cfg!(debug_assertions) {
        "debug"
    } else {
        "release"
    };
    let path = target.join(profile).join(name);
    assert!(
        path.exists(),
        "{} is not built: run `cargo build --workspace --bins` first (the README's test command does)",
        path.display()
    );
    path
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

/// Runs `script` with bash inside one private loopback-only network namespace, killing it
/// after `deadline`. Returns None (after saying why) where namespaces cannot be made.
pub fn run_in_loopback_netns(script: &str, deadline: Duration) -> Option<Output> {
    if !can_make_network_namespace() {
        eprintln!(
            "skipping: this machine cannot create a network namespace (need root or user namespaces)"
        );
        return None;
    }
    let netns = workspace_root().join("tests/loopback-netns");
    let mut child = Command::new(netns)
        .args(["timeout", "--signal=KILL"])
        .arg(format!("{}", deadline.as_secs().max(1)))
        .args(["bash", "-c", script])
        .current_dir(workspace_root())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("starting tests/loopback-netns");
    // `timeout` inside the namespace enforces the deadline; this is the backstop.
    let started = Instant::now();
    loop {
        match child.try_wait() {
            Ok(Some(_)) => break,
            Ok(None) if started.elapsed() > deadline + Duration::from_secs(10) => {
                let _ = child.kill();
                break;
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(50)),
            Err(_) => break,
        }
    }
    Some(
        child
            .wait_with_output()
            .expect("collecting the namespace's output"),
    )
}

/// The JSON lines of `text` (others ignored).
pub fn json_lines(text: &str) -> Vec<serde_json::Value> {
    text.lines()
        .filter_map(|l| serde_json::from_str(l.trim()).ok())
        .collect()
}
