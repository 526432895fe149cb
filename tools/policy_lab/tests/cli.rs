//! The `policy_lab` binary end to end: experiments write their curves, tables and figures
//! (and the tables they write reproduce the same curves); train writes a Q-table file the node
//! reads; bad input is refused by name and nothing is overwritten.

use std::path::Path;
use std::process::{Command, Output};

fn bin(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_policy_lab"))
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
fn train_writes_a_q_table_file_the_node_reads() {
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
    let table = q_learning::QTableFile::load(&file).expect("a Q-table file");
    assert_eq!(table.owner, q_learning::QTableOwner::Cluster(1));
    assert!(
        table
            .provenance
            .starts_with("policy_lab train: transferred from cluster 0"),
        "{}",
        table.provenance
    );
    assert_eq!(table.updates, 0);
    assert!(table.table != q_learning::QTable::default(), "trained");
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
    let _running_node =
        instance_lock::InstanceLock::acquire(dir.path(), "behaviour_policy", "Q-tables")
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
    let models = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../nodes/user_model/models/migrave_study_c2.json");
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
fn evaluate_refuses_what_the_sample_bags_cannot_tell() {
    let dir = tempfile::tempdir().expect("tempdir");
    let broken = dir.path().join("broken.mcap");
    std::fs::write(&broken, b"not a bag").expect("write");
    // A recording cut off at 60 %: read up to the damage, and the damage named.
    let whole = std::fs::read("../../bags/cluster0_seed7.mcap").expect("sample bag");
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &whole[..whole.len() * 6 / 10]).expect("write");
    let out = dir.path().join("evaluate");
    let run = |q_table: &str, temperature: &str, extra: &[&str]| {
        let mut args = vec![
            "evaluate",
            "--bags",
            "../../bags",
            path(&broken),
            path(&cut),
            "--q-table",
            q_table,
            "--temperature",
            temperature,
            "--bootstrap",
            "200",
            "--output",
            path(&out),
        ];
        args.extend(extra);
        bin(&args)
    };
    // The case: cluster 1's table at T = 2 puts 72 % of its probability on actions the
    // greedy sessions never took. It used to print `WIS 24.55 [24.55, 24.55]`.
    let o = run("../../bags/q_tables/cluster_1.json", "2", &[]);
    let (stdout, stderr) = (
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    assert!(!o.status.success(), "{stdout}");
    assert!(stderr.contains("refusing to estimate"), "{stderr}");
    assert!(
        stderr.contains("in 100 % of its sessions (72 % of its probability per decision)"),
        "{stderr}"
    );
    assert!(stderr.contains("--max-off-support"), "{stderr}");
    assert!(
        stderr.contains("1 whole session(s) played by the policy, fewer than the 50 needed"),
        "{stderr}"
    );
    assert!(!stdout.contains("[  24.55,   24.55]"), "{stdout}");
    assert!(!out.join("evaluation.json").exists());
    // What was read, skipped, damaged and left out is said before the refusal.
    assert!(
        stdout.contains("bags: 4 read (1 damaged), 1 skipped"),
        "{stdout}"
    );
    assert!(
        stdout.contains("skipped") && stdout.contains("broken.mcap"),
        "{stdout}"
    );
    assert!(
        stdout.contains("damaged: ") && stdout.contains("cut.mcap") && stdout.contains("truncated"),
        "{stdout}"
    );
    // The cut copy holds the first sequences of a session the whole bag has: counted once.
    assert!(stdout.contains("sessions: 3 recorded, 1 evaluated, 2 left out (67 %): 1 stopped before the end, 1 a sequence the therapist chose"), "{stdout}");
    assert!(
        stdout.contains("the therapist chose sequence 3"),
        "{stdout}"
    );
    assert!(stdout.contains("lean toward the sessions"), "{stdout}");
    // The table the sessions were planned near: the child's belief left it in one of the
    // evaluated session's ten decisions, where the table would have challenged (its
    // probability is 1 there), so a tenth of its probability is off the log; and lowering
    // the limit does not bring back a zero-width interval from one session.
    let o = run("../../bags/q_tables/cluster_0.json", "greedy", &[]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(stderr.contains("fewer than the 50 needed"), "{stderr}");
    assert!(
        stderr.contains("(10 % of its probability per decision)"),
        "{stderr}"
    );
    let o = run(
        "../../bags/q_tables/cluster_0.json",
        "greedy",
        &["--min-sessions", "2"],
    );
    assert!(!o.status.success());
    // The cut bag alone: its damage named, its session incomplete, nothing to evaluate.
    let o = bin(&[
        "evaluate",
        "--bags",
        path(&cut),
        "--q-table",
        "../../bags/q_tables/cluster_0.json",
    ]);
    let (stdout, stderr) = (
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    assert!(!o.status.success());
    assert!(
        stdout.contains("bags: 1 read (1 damaged), 0 skipped"),
        "{stdout}"
    );
    assert!(
        stdout.contains("is truncated")
            && stdout.contains("read up to it (7 decisions, 6 results), nothing after"),
        "{stdout}"
    );
    assert!(
        stdout.contains("incomplete: sequences [1, 2, 3, 4, 5, 6] of 10"),
        "{stdout}"
    );
    assert!(stderr.contains("no whole session"), "{stderr}");
    fails(
        &[
            "evaluate",
            "--bags",
            "../../bags",
            "--q-table",
            "../../bags/q_tables/cluster_0.json",
            "--min-sessions",
            "1",
        ],
        "at least 2",
    );
    fails(
        &[
            "evaluate",
            "--bags",
            "../../bags",
            "--q-table",
            "../../bags/q_tables/cluster_0.json",
            "--max-off-support",
            "5",
        ],
        "between 0 and 1",
    );
    fails(
        &[
            "evaluate",
            "--bags",
            path(dir.path().join("none").as_path()),
            "--q-table",
            "../../bags/q_tables/cluster_0.json",
        ],
        "no such bag or folder",
    );
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).expect("dir");
    std::fs::copy(&broken, empty.join("broken.mcap")).expect("copy");
    fails(
        &[
            "evaluate",
            "--bags",
            path(&empty),
            "--q-table",
            "../../bags/q_tables/cluster_0.json",
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

/// Writes `sessions` into a bag the way the suite records them: the policy's Decision per
/// sequence (`q_learning::messages::decision_message`), the game manager's
/// SequenceResult (`nodes/game_manager/src/game/play.rs`) and, for the sequences in
/// `fallbacks`, a GameState with `policy_fallback` (`nodes/game_manager/src/game/mod.rs`,
/// `publish_state`: set for every state published while the fallback's sequence plays).
fn write_bag(
    file: &Path,
    sessions: &[(q_learning::mdp::LoggedSession, Vec<[f64; 5]>)],
    fallbacks: &[(&str, u8)],
) {
    use bag_file::{BagWriter, WriterOptions};
    use qt_therapy_msgs::topics::{DECISION, GAME_STATE, SEQUENCE_RESULT};
    use qt_therapy_msgs::{BehaviourState, Decision, GameState, SequenceResult};
    let mut w = BagWriter::create(file, &WriterOptions::default()).expect("bag");
    let decisions = w.add_topic(DECISION).expect("topic");
    let results = w.add_topic(SEQUENCE_RESULT).expect("topic");
    let states = w.add_topic(GAME_STATE).expect("topic");
    let mut t = 1_000_000_000u64;
    for (s, full) in sessions {
        for (step, p) in s.steps.iter().zip(full) {
            let (level, feedback) = step.action.apply(step.state).expect("allowed");
            let state = BehaviourState::from_state(step.state);
            t += 1_000_000;
            let decision = Decision {
                session_id: s.session_id.clone(),
                step: step.step,
                state: state.clone(),
                action: step.action.index() as u8,
                level: level.get(),
                feedback: feedback as u8,
                q_values: vec![0.0; 5],
                probabilities: p.to_vec(),
                temperature: 2.0,
                ..Default::default()
            };
            w.write(decisions, t, &decision).expect("write");
            if fallbacks.contains(&(s.session_id.as_str(), step.step)) {
                let g = GameState {
                    phase: GameState::SAYING_SEQUENCE,
                    session_id: s.session_id.clone(),
                    sequence_index: step.step,
                    level: level.get(),
                    policy_fallback: true,
                    ..Default::default()
                };
                t += 1_000_000;
                w.write(states, t, &g).expect("write");
            }
            t += 1_000_000;
            let result = SequenceResult {
                session_id: s.session_id.clone(),
                sequence_index: step.step,
                sequences_planned: 10,
                state,
                action: step.action.index() as u8,
                level: level.get(),
                feedback: feedback as u8,
                outcome: step.outcome.sign(),
                activity_result: step.outcome.activity_result(level) as f32,
                engagement: step.engagement as f32,
                engagement_per_second: vec![step.engagement as f32],
                ..Default::default()
            };
            w.write(results, t, &result).expect("write");
        }
    }
    w.finish().expect("finish");
}

#[test]
fn evaluate_estimates_from_enough_sessions_and_gives_no_interval_that_means_nothing() {
    use q_learning::mdp::simulate_sessions;
    use q_learning::mdp::{TargetPolicy, TargetTemperature};
    use q_learning::reference_tables::per_level_reference_tables;
    let dir = tempfile::tempdir().expect("tempdir");
    let table = q_learning::QTableFile::load(Path::new("../../bags/q_tables/cluster_0.json"))
        .expect("sample table")
        .table;
    // 60 sessions logged by a softmax (every action in the support), in two bags.
    let logging = TargetPolicy::new(table, TargetTemperature::Fixed(2.0)).expect("policy");
    let (log, full) = simulate_sessions(&per_level_reference_tables()[0], &logging, 60, 5);
    let sessions: Vec<_> = log.into_iter().zip(full).collect();
    write_bag(&dir.path().join("a.mcap"), &sessions[..30], &[]);
    // In the second, the game manager played its fallback at sequence 4 of one session, and
    // the policy's late decision (the same action) was recorded too.
    let late = sessions[30].0.session_id.clone();
    write_bag(
        &dir.path().join("b.mcap"),
        &sessions[30..],
        &[(late.as_str(), 4)],
    );
    let out = dir.path().join("evaluate");
    let judge = |temperature: &str| {
        ok(&[
            "evaluate",
            "--bags",
            path(dir.path()),
            "--q-table",
            "../../bags/q_tables/cluster_0.json",
            "--temperature",
            temperature,
            "--bootstrap",
            "300",
            "--output",
            path(&out),
        ])
    };
    let shown = judge("1");
    assert!(
        shown.contains("bags: 2 read (0 damaged), 0 skipped"),
        "{shown}"
    );
    assert!(
        shown.contains("sessions: 60 recorded, 59 evaluated, 1 left out (2 %): 0 stopped before the end, 0 a sequence the therapist chose, 1 a sequence the fallback played"),
        "{shown}"
    );
    assert!(
        shown.contains(&format!(
            "left out {late}: the game manager played its fallback for sequence 4 (GameState policy_fallback); the decision recorded for it came too late to play"
        )),
        "{shown}"
    );
    assert!(
        shown.contains("would leave the actions the logged policy took in 0.0 % of its sessions"),
        "{shown}"
    );
    // A policy near the logger's: every estimate with its interval.
    assert!(shown.contains("new policy, weighted IS"), "{shown}");
    assert!(!shown.contains("no interval"), "{shown}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("evaluation.json")).expect("json"))
            .expect("valid json");
    assert_eq!(json["sessions_evaluated"], 59);
    assert_eq!(json["left_out"][0]["kind"], "Fallback");
    let estimates = json["estimates"].as_array().expect("estimates");
    assert_eq!(estimates.len(), 6);
    for e in estimates {
        match e["interval"].as_array() {
            Some(i) => assert!(i[0].as_f64() < i[1].as_f64(), "{e}"),
            None => assert!(e["no_interval"].is_string(), "{e}"),
        }
    }
    assert!(out.join("evaluation.png").is_file());
    // A cooler policy agrees with the softmax logger all ten times in few sessions: the
    // weighted estimate rests on a handful of them and gets no interval (one resting on a
    // session or two is as narrow as it is wrong); the per-decision estimate keeps its own.
    let shown = judge("0.5");
    let line = |name: &str| {
        shown
            .lines()
            .find(|l| l.starts_with(name))
            .unwrap_or_else(|| panic!("{name} in {shown}"))
            .to_string()
    };
    assert!(line("new policy, per-decision IS").contains('['), "{shown}");
    assert!(
        line("new policy, weighted IS").contains("(no interval)"),
        "{shown}"
    );
    assert!(
        shown.contains("no interval for the new policy, weighted IS: rests on"),
        "{shown}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("evaluation.json")).expect("json"))
            .expect("valid json");
    let weighted: Vec<&serde_json::Value> = json["estimates"]
        .as_array()
        .expect("estimates")
        .iter()
        .filter(|e| e["estimator"] == "new policy, weighted IS")
        .collect();
    assert_eq!(weighted.len(), 2);
    assert!(weighted.iter().all(|e| e["interval"].is_null()));
    // Judging the logging policy itself: weight 1 everywhere, every interval given.
    let shown = ok(&[
        "evaluate",
        "--bags",
        path(dir.path()),
        "--q-table",
        "../../bags/q_tables/cluster_0.json",
        "--temperature",
        "2",
        "--min-sessions",
        "59",
        "--output",
        path(&out),
    ]);
    assert!(!shown.contains("no interval"), "{shown}");
    assert!(
        shown.contains("effective sample size 59.0 of 59 sessions"),
        "{shown}"
    );
    // One more session required than there are: refused.
    let o = bin(&[
        "evaluate",
        "--bags",
        path(dir.path()),
        "--q-table",
        "../../bags/q_tables/cluster_0.json",
        "--min-sessions",
        "60",
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("59 whole session(s)"));
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
fn evaluate_in_simulation_sweeps_logged_exploration_and_repeats_exactly() {
    let dir = tempfile::tempdir().expect("tempdir");
    let run = |out: &Path| {
        ok(&[
            "evaluate-in-simulation",
            "--user-models",
            "../../nodes/user_model/models/migrave_study_c2.json",
            "--logging-q-table",
            "../../bags/q_tables/cluster_0.json",
            "--logging-temperature",
            "epsilon:0.1,epsilon:0.3",
            "--q-table",
            "../../bags/q_tables/cluster_0.json",
            "--temperature",
            "1",
            "--sessions",
            "30,60",
            "--seeds",
            "4",
            "--bootstrap",
            "50",
            "--output",
            path(out),
        ])
    };
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let shown = run(&a);
    for words in [
        "ε-greedy, ε = 0.1",
        "judged policy 15.855",
        "WIS RMSE",
        "eps=0.3",
    ] {
        assert!(shown.contains(words), "{words}: {shown}");
    }
    run(&b);
    let csv = |d: &Path| std::fs::read_to_string(d.join("sweep.csv")).expect("sweep.csv");
    assert_eq!(csv(&a), csv(&b), "the same seeds give the same sweep");
    // A header and one row per (logging policy, sessions).
    assert_eq!(csv(&a).lines().count(), 1 + 2 * 2);
    assert!(
        csv(&a)
            .lines()
            .nth(1)
            .is_some_and(|l| l.starts_with("eps=0.1,30,4,"))
    );
    fails(
        &[
            "evaluate-in-simulation",
            "--logging-q-table",
            "../../bags/q_tables/cluster_0.json",
            "--logging-temperature",
            "epsilon:2",
            "--q-table",
            "../../bags/q_tables/cluster_0.json",
        ],
        "`epsilon:E` with E in [0, 1]",
    );
}

#[test]
fn supervision_measures_the_rules_on_the_study_or_says_where_it_looked() {
    fails(
        &[
            "supervision",
            "--study",
            "/nonexistent/study",
            "--seeds",
            "1",
        ],
        "/nonexistent/study: no such folder",
    );
    let study = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/migrave-study");
    if !study.is_dir() {
        eprintln!("skipped: {} is absent", study.display());
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let shown = ok(&[
        "supervision",
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
        "--bootstrap",
        "200",
        "--output",
        path(dir.path()),
    ]);
    for words in [
        "20 children",
        "never (the policy alone)",
        "T > 100 or σ (paper fit) > 0.3",
        "σ (fitted noise) > 0.1",
        "at random, 10 % of decisions",
        "every decision",
        "vs random, same rate",
    ] {
        assert!(shown.contains(words), "{words}: {shown}");
    }
    // Every decision proposed: 10 a session; the policy alone: none.
    assert!(
        shown
            .lines()
            .any(|l| l.starts_with("every decision") && l.contains(" 10.00 ")),
        "{shown}"
    );
    let csv = std::fs::read_to_string(dir.path().join("supervision.csv")).expect("csv");
    assert!(
        csv.starts_with("child,cluster,rule,proposals_per_session,"),
        "{csv}"
    );
    // Per child, the rules measured and the matched random ones.
    assert!(csv.lines().count() > 1 + 20 * 14, "{csv}");
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("supervision.json")).expect("json"),
    )
    .expect("JSON");
    assert_eq!(json[0]["proposals"], 0.0);
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
        "6",
        "--seeds",
        "3",
        "--pretrain-epochs",
        "5",
        "--pretrain-runs",
        "1",
        "--bootstrap",
        "500",
        "--output",
        path(dir.path()),
    ]);
    assert!(shown.contains("20 children"), "{shown}");
    for words in [
        "cluster policy",
        "per-user table",
        "from scratch",
        "optimal for the child's model",
        "the most any policy can expect",
        "per_user − cluster, score, sessions 1-6",
        "  without ",
        "W/T/L",
    ] {
        assert!(shown.contains(words), "{words}: {shown}");
    }
    assert!(!shown.contains("ceiling"), "{shown}");
    let lines = |f: &str| {
        std::fs::read_to_string(dir.path().join(f))
            .expect("csv")
            .lines()
            .count()
    };
    // 20 children x 4 policies x 3 seeds x 6 sessions, and the header.
    assert_eq!(lines("per_child.csv"), 1 + 20 * 4 * 3 * 6);
    assert_eq!(lines("per_child_children.csv"), 1 + 20);
    // 3 comparisons x 4 windows, each with and without its most influential child.
    assert_eq!(lines("per_child_paired.csv"), 1 + 3 * 4 * 2);
    for f in ["per_child.png", "per_child_paired.png"] {
        assert!(dir.path().join(f).is_file(), "{f}");
    }
}

#[test]
fn the_shipped_child_belief_prior_is_what_the_study_gives() {
    fails(
        &["child-belief-prior", "--study", "/nonexistent/study"],
        "/nonexistent/study: no such folder",
    );
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let study = root.join("../shared/data/migrave-study");
    if !study.is_dir() {
        eprintln!("skipped: {} is absent", study.display());
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let made = dir.path().join("prior.json");
    // Run from the repository root, as the README's command, so the provenance is the same.
    let out = Command::new(env!("CARGO_BIN_EXE_policy_lab"))
        .current_dir(&root)
        .args(["child-belief-prior", "--output", path(&made)])
        .output()
        .expect("runs");
    let shown = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{shown}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        shown.contains("20 children (per cluster [11, 9])"),
        "{shown}"
    );
    let shipped = root.join("nodes/behaviour_policy/models/child_belief_prior_c2.json");
    assert!(
        std::fs::read(&made).expect("made") == std::fs::read(&shipped).expect("shipped"),
        "{} is not what `policy_lab child-belief-prior` gives now",
        shipped.display()
    );
}
