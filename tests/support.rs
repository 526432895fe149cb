//! Helpers for the cross-node tests: where the workspace and its binaries are, running a
//! script inside a private loopback-only network namespace (DDS multicasts; nothing may leave
//! the machine), and deadlines on every wait.

use std::path::PathBuf;

pub use loopback_netns::{can_make_network_namespace, run_in_loopback_netns, workspace_root};

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

/// The JSON lines of `text` (others ignored).
pub fn json_lines(text: &str) -> Vec<serde_json::Value> {
    text.lines()
        .filter_map(|l| serde_json::from_str(l.trim()).ok())
        .collect()
}
