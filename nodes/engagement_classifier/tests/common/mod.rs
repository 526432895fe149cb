//! What the classifier's process tests share: the workspace, and `engagement_classifier run`
//! as a child process killed if the test ends first.

#![allow(dead_code)] // each test binary uses its own part

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

pub fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The node process, killed if the test ends before it does.
pub struct Node(pub Child);

impl Drop for Node {
    fn drop(&mut self) {
        if let Ok(None) = self.0.try_wait() {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

impl Node {
    /// Waits for the process to end; None if it is still running at `deadline`.
    pub fn wait_for_exit(&mut self, deadline: Duration) -> Option<std::process::ExitStatus> {
        let started = Instant::now();
        while started.elapsed() < deadline {
            if let Ok(Some(status)) = self.0.try_wait() {
                return Some(status);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        None
    }

    /// SIGINT, as the launcher and Ctrl-C stop a node.
    pub fn interrupt(&self) {
        let sent = Command::new("kill")
            .args(["-INT", &self.0.id().to_string()])
            .status()
            .expect("kill runs");
        assert!(sent.success());
    }
}

/// `engagement_classifier run` with `params_file` and `--param` overrides, from the workspace
/// root; its output in `log_dir/node.out` and `node.err`.
pub fn classifier(params_file: &Path, log_dir: &Path, overrides: &[&str]) -> Node {
    let file = |name: &str| std::fs::File::create(log_dir.join(name)).expect("log file");
    let mut command = Command::new(env!("CARGO_BIN_EXE_engagement_classifier"));
    command.arg("run").arg("--params-file").arg(params_file);
    for o in overrides {
        command.args(["--param", o]);
    }
    let child = command
        .current_dir(workspace())
        // Should it ever join the graph, it stays on this machine; and its start-up line shows.
        .env("ROS_LOCALHOST_ONLY", "1")
        .env("RUST_LOG", "info")
        .stdin(Stdio::null())
        .stdout(file("node.out"))
        .stderr(file("node.err"))
        .spawn()
        .expect("starts engagement_classifier run");
    Node(child)
}
