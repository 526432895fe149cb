//! The `behaviour_policy` binary end to end: experiments write their curves, tables and
//! figures (and the tables they write reproduce the same curves); train and show-q-table
//! round-trip a Q-table file; bad input is refused by name and nothing is overwritten.

use std::path::Path;
use std::process::{Command, Output};

fn bin(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_behaviour_policy"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("runs the binary")
}

fn ok(args: &[&str]) -> String {
    let out = bin(args);
    assert!(
        out.status.success(),
        "{args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn fails(args: &[&str], words: &str) {
    let out = bin(args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{args:?} should fail");
    assert!(err.contains(words), "{args:?}: {err} lacks {words:?}");
}

fn path(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

#[test]
fn experiments_write_curves_tables_and_figures_that_reproduce() {
    let dir = tempfile::tempdir().expect("tempdir");
    let first = dir.path().join("first");
    let small = ["--epochs", "3", "--runs", "3", "--sessions-per-epoch", "10"];
    let mut args = vec![
        "experiments",
        "--per-level-reference",
        "--output",
        path(&first),
    ];
    args.extend(small);
    let shown = ok(&args);
    assert!(shown.contains("M1->M2 RE+bE exploit"), "{shown}");
    let csv = std::fs::read_to_string(first.join("curves.csv")).expect("csv");
    assert_eq!(csv.lines().count(), 1 + 8 * 3);
    for f in [
        "fig4_score.svg",
        "fig4_score.png",
        "fig5_engagement.png",
        "summary.txt",
    ] {
        assert!(first.join(f).is_file(), "{f}");
    }
    // The tables written beside the curves are a user-model file of their own.
    let tables = first.join("user_model_tables.json");
    let second = dir.path().join("second");
    let mut args = vec![
        "experiments",
        "--user-models",
        path(&tables),
        "--no-figures",
        "--output",
        path(&second),
    ];
    args.extend(small);
    ok(&args);
    let again = std::fs::read_to_string(second.join("curves.csv")).expect("csv");
    assert_eq!(csv, again);
}

#[test]
fn train_writes_a_q_table_that_show_q_table_reads() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = dir.path().join("cluster_1.json");
    let shown = ok(&[
        "train",
        "--per-level-reference",
        "--cluster",
        "1",
        "--transfer-from",
        "0",
        "--epochs",
        "2",
        "--runs",
        "2",
        "--output",
        path(&file),
    ]);
    assert!(shown.contains("transferred from cluster 0"), "{shown}");
    let table = ok(&["show-q-table", path(&file)]);
    assert!(table.contains("cluster 1"), "{table}");
    assert!(table.contains("(L=0, F=0, PS=+0)"), "{table}");
    // An existing table (maybe taught by real sessions) is not replaced without --force.
    let before = std::fs::read(&file).expect("read");
    let retrain = [
        "train",
        "--per-level-reference",
        "--cluster",
        "1",
        "--output",
        path(&file),
    ];
    fails(&retrain, "--force");
    assert_eq!(std::fs::read(&file).expect("read"), before);
    // Not even with --force while a node runs on that directory (its lock, held here by this
    // process): the node would overwrite the new table with its own.
    let _running_node = node_shell::instance_lock::InstanceLock::acquire(
        dir.path(),
        "behaviour_policy",
        "Q-tables",
    )
    .expect("free");
    fails(
        &[&retrain[..], &["--force"]].concat(),
        &format!(
            "is in use by another behaviour_policy (pid {})",
            std::process::id()
        ),
    );
    assert_eq!(std::fs::read(&file).expect("read"), before);
}

#[test]
fn bad_input_is_refused_by_name() {
    let dir = tempfile::tempdir().expect("tempdir");
    fails(
        &[
            "experiments",
            "--per-level-reference",
            "--clusters",
            "0,5",
            "--output",
            path(dir.path()),
        ],
        "unknown user model cluster 5",
    );
    fails(
        &[
            "train",
            "--per-level-reference",
            "--cluster",
            "2",
            "--output",
            path(&dir.path().join("x.json")),
        ],
        "unknown user model cluster 2",
    );
    let corrupt = dir.path().join("cluster_0.json");
    std::fs::write(
        &corrupt,
        "{\"format\": \"qt_therapy q_table\", \"version\": 1, \"own",
    )
    .expect("write");
    fails(&["show-q-table", path(&corrupt)], "cluster_0.json");
    let wrong = dir.path().join("models.json");
    std::fs::write(
        &wrong,
        "[{\"cluster\": 0, \"success\": [], \"engagement\": []}]",
    )
    .expect("write");
    fails(
        &[
            "experiments",
            "--user-models",
            path(&wrong),
            "--output",
            path(dir.path()),
        ],
        "models.json",
    );
    fails(
        &[
            "experiments",
            "--per-level-reference",
            "--rewards",
            "RE",
            "--output",
            path(dir.path()),
        ],
        "RE+bE",
    );
    assert!(!dir.path().join("curves.csv").exists());
}

#[test]
fn the_fitted_user_models_in_the_repository_load() {
    let models =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../user_model/models/migrave_study_c2.json");
    if !models.exists() {
        println!("skipping: {} not found", models.display());
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let shown = ok(&[
        "experiments",
        "--user-models",
        path(&models),
        "--epochs",
        "2",
        "--runs",
        "2",
        "--sessions-per-epoch",
        "10",
        "--no-figures",
        "--output",
        path(dir.path()),
    ]);
    assert!(shown.contains("fitted user models"), "{shown}");
}

#[test]
fn evaluate_judges_a_q_table_on_the_sample_bags_and_skips_what_it_cannot_read() {
    let dir = tempfile::tempdir().expect("tempdir");
    let broken = dir.path().join("broken.mcap");
    std::fs::write(&broken, b"not a bag").expect("write");
    let out = dir.path().join("evaluate");
    let shown = ok(&[
        "evaluate",
        "--bags",
        "../../bags",
        path(&broken),
        "--q-table",
        "../../bags/q_tables/cluster_0.json",
        "--temperature",
        "1",
        "--bootstrap",
        "200",
        "--output",
        path(&out),
    ]);
    // One whole session played by the policy; the stopped one and the one the therapist
    // steered are left out with their reasons; the broken file is named and skipped.
    assert!(shown.contains("3 read, 1 skipped"), "{shown}");
    assert!(
        shown.contains("sessions: 1 evaluated, 2 left out"),
        "{shown}"
    );
    assert!(shown.contains("incomplete"), "{shown}");
    assert!(shown.contains("the therapist chose sequence 3"), "{shown}");
    assert!(shown.contains("new policy, weighted IS"), "{shown}");
    // The sessions were played greedily: a softmax policy's other actions were never seen.
    assert!(
        shown.contains("what importance sampling cannot see"),
        "{shown}"
    );
    assert!(shown.contains("WARNING"), "{shown}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("evaluation.json")).expect("json"))
            .expect("valid json");
    assert_eq!(json["sessions"], 1);
    assert_eq!(json["decisions"], 10);
    assert!(out.join("evaluation.png").is_file());

    fails(
        &[
            "evaluate",
            "--bags",
            path(dir.path()),
            "--q-table",
            "../../bags/q_tables/cluster_0.json",
            "--output",
            path(&out),
        ],
        "no whole session",
    );
    fails(
        &[
            "evaluate",
            "--bags",
            "../../bags",
            "--q-table",
            path(&broken),
        ],
        "--q-table",
    );
    fails(
        &[
            "evaluate",
            "--bags",
            "../../bags",
            "--q-table",
            "x.json",
            "--temperature",
            "hot",
        ],
        "greedy",
    );
}

#[test]
fn evaluate_in_simulation_reports_bias_and_coverage_against_the_exact_value() {
    let dir = tempfile::tempdir().expect("tempdir");
    let shown = ok(&[
        "evaluate-in-simulation",
        "--per-level-reference",
        "--logging-q-table",
        "../../bags/q_tables/cluster_0.json",
        "--logging-temperature",
        "2",
        "--q-table",
        "../../bags/q_tables/cluster_0.json",
        "--temperature",
        "1",
        "--sessions",
        "100",
        "--seeds",
        "10",
        "--bootstrap",
        "100",
        "--output",
        path(dir.path()),
    ]);
    assert!(shown.contains("exact value per session"), "{shown}");
    assert!(shown.contains("weighted IS, return"), "{shown}");
    assert!(shown.contains("% of 10"), "{shown}");
    assert!(dir.path().join("validation.json").is_file());
    assert!(dir.path().join("validation.png").is_file());
}

#[test]
fn per_child_runs_on_the_study_or_says_where_it_looked() {
    fails(
        &["per-child", "--study", "/nonexistent/study", "--seeds", "1"],
        "/nonexistent/study: no such folder",
    );
    let study = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/migrave-study");
    if !study.is_dir() {
        eprintln!("skipped: {} is absent", study.display());
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let shown = ok(&[
        "per-child",
        "--study",
        path(&study),
        "--sessions",
        "3",
        "--seeds",
        "2",
        "--pretrain-epochs",
        "5",
        "--pretrain-runs",
        "1",
        "--output",
        path(dir.path()),
    ]);
    assert!(shown.contains("20 children"), "{shown}");
    for arm in [
        "cluster policy",
        "per-user table",
        "from scratch",
        "ceiling",
    ] {
        assert!(shown.contains(arm), "{arm}: {shown}");
    }
    let csv = std::fs::read_to_string(dir.path().join("per_child.csv")).expect("csv");
    // 20 children x 4 policies x 2 seeds x 3 sessions, and the header.
    assert_eq!(csv.lines().count(), 1 + 20 * 4 * 2 * 3);
    assert!(dir.path().join("per_child.png").is_file());
}
