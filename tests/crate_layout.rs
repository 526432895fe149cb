//! The workspace's layout rules, read from `cargo metadata`: nodes live in `nodes/`, what they
//! share in `libs/`, offline programs in `tools/`. No node crate depends on another node's crate
//! (shared code moves down to a library), no tool depends on a node's crate (what a tool
//! shares with a node is a library's: `tools/policy_lab` studies `libs/q_learning`, not
//! `nodes/behaviour_policy`), no library depends on a node or a tool, and only the
//! node shell and the nodes reach DDS: a library or tool that only reads bags or files never
//! builds ros2-client or RustDDS (`qt_therapy_msgs` keeps them behind its `dds` feature).

use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};

const DDS_CRATES: [&str; 2] = ["ros2-client", "rustdds"];

struct Package {
    /// Directory relative to the workspace root, e.g. `nodes/game_manager`.
    dir: String,
    deps: Vec<Dep>,
}

struct Dep {
    name: String,
    /// The workspace directory of a path dependency.
    path: Option<String>,
    /// `dev`, `build`, or None for a normal dependency.
    kind: Option<String>,
    /// Features asked for.
    features: Vec<String>,
    /// Behind a feature of the depending crate.
    optional: bool,
}

fn packages() -> BTreeMap<String, Package> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = std::process::Command::new(cargo)
        .args([
            "metadata",
            "--format-version",
            "1",
            "--no-deps",
            "--offline",
        ])
        .current_dir(suite_tests::workspace_root())
        .output()
        .expect("cargo metadata runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let m: Value = serde_json::from_slice(&out.stdout).expect("metadata is JSON");
    let root = format!("{}/", m["workspace_root"].as_str().expect("root"));
    let rel = |p: &str| {
        let p = p.strip_prefix(&root).unwrap_or(p);
        p.strip_suffix("/Cargo.toml").unwrap_or(p).to_string()
    };
    let mut all = BTreeMap::new();
    for p in m["packages"].as_array().expect("packages") {
        let deps = p["dependencies"]
            .as_array()
            .expect("dependencies")
            .iter()
            .map(|d| {
                let features = d["features"]
                    .as_array()
                    .map(|f| {
                        f.iter()
                            .filter_map(|x| x.as_str().map(String::from))
                            .collect()
                    })
                    .unwrap_or_default();
                Dep {
                    name: d["name"].as_str().expect("name").to_string(),
                    path: d["path"].as_str().map(rel),
                    kind: d["kind"].as_str().map(String::from),
                    features,
                    optional: d["optional"].as_bool().unwrap_or(false),
                }
            })
            .collect();
        let name = p["name"].as_str().expect("name").to_string();
        let dir = rel(p["manifest_path"].as_str().expect("manifest"));
        all.insert(name, Package { dir, deps });
    }
    all
}

fn top(dir: &str) -> &str {
    dir.split('/').next().unwrap_or(dir)
}

#[test]
fn no_node_crate_depends_on_another_node_crate() {
    let all = packages();
    let mut wrong = Vec::new();
    for (name, p) in &all {
        for Dep {
            name: dep,
            path,
            kind,
            ..
        } in &p.deps
        {
            let Some(path) = path else { continue };
            let bad = match top(&p.dir) {
                "nodes" => top(path) == "nodes" || top(path) == "tools",
                "tools" => top(path) == "nodes",
                "libs" | "msgs" => top(path) == "nodes" || top(path) == "tools",
                _ => false,
            };
            if bad {
                wrong.push(format!("{name} ({}) -> {dep} ({path}) {kind:?}", p.dir));
            }
        }
    }
    assert!(wrong.is_empty(), "crates that break the layout: {wrong:#?}");
    for dir in [
        "nodes/game_manager",
        "libs/sequence_game",
        "tools/session_report",
    ] {
        assert!(all.values().any(|p| p.dir == dir), "{dir} not found");
    }
}

#[test]
fn only_the_node_shell_and_the_nodes_reach_dds() {
    let all = packages();
    let by_dir: BTreeMap<&str, &str> = all
        .iter()
        .map(|(n, p)| (p.dir.as_str(), n.as_str()))
        .collect();
    // Every workspace package a package builds with (normal and build dependencies), itself
    // included, and whether any of them asks for DDS.
    let reaches_dds = |start: &str| -> Option<String> {
        let mut seen = BTreeSet::new();
        let mut todo = vec![start.to_string()];
        while let Some(n) = todo.pop() {
            if !seen.insert(n.clone()) {
                continue;
            }
            let p = &all[&n];
            for d in &p.deps {
                if d.kind.as_deref() == Some("dev") {
                    continue;
                }
                // An optional DDS dependency is reached only through a feature, checked below.
                if DDS_CRATES.contains(&d.name.as_str()) && !d.optional {
                    return Some(format!("{n} depends on {}", d.name));
                }
                if d.name == "qt_therapy_msgs" && d.features.iter().any(|f| f == "dds") {
                    return Some(format!("{n} turns on qt_therapy_msgs/dds"));
                }
                if let Some(path) = &d.path {
                    todo.push(by_dir[path.as_str()].to_string());
                }
            }
        }
        None
    };
    let mut wrong = Vec::new();
    for (name, p) in &all {
        let may = p.dir == "libs/node_shell" || matches!(top(&p.dir), "nodes" | "tests" | "bench");
        if may {
            continue;
        }
        if let Some(why) = reaches_dds(name) {
            wrong.push(format!("{name} ({}): {why}", p.dir));
        }
    }
    assert!(wrong.is_empty(), "DDS outside the nodes: {wrong:#?}");
    assert!(
        reaches_dds("node_shell").is_some(),
        "the check must see the node shell's DDS"
    );
}
