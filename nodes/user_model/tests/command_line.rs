//! The `user_model` binary from the shell: simulate-study, fit (optimised and fixed
//! hyperparameters, from CSV and from session bags), predict; a failing fit writes nothing;
//! and the node (`run`) answering PredictUser and AssignCluster over DDS.

#[path = "../../../libs/user_models/tests/common/mod.rs"]
mod common;

use std::path::Path;
use std::process::Command;
use user_models::InteractionRecord;
use user_models::data::bag::read_bags;
use user_models::data::{read_csv, read_sources, write_csv};
use user_models::simulate::{StudySpec, simulate_study};

fn user_model(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_user_model"))
        .args(args)
        .output()
        .expect("runs user_model")
}

#[test]
fn simulate_fit_predict() {
    let dir = tempfile::tempdir().expect("temp dir");
    let data = dir.path().join("study.csv");
    let model = dir.path().join("m.json");
    let out = user_model(&[
        "simulate-study",
        "--output",
        data.to_str().expect("path"),
        "--seed",
        "3",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("SYNTHETIC"));
    let out = user_model(&[
        "fit",
        "--data",
        data.to_str().expect("path"),
        "--clusters",
        "2",
        "--seed",
        "5",
        "--output",
        model.to_str().expect("path"),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for f in [
        "m.json",
        "clusters.svg",
        "clusters.png",
        "levels.svg",
        "levels.png",
    ] {
        assert!(dir.path().join(f).exists(), "{f}");
    }
    let out = user_model(&["predict", "--model", model.to_str().expect("path")]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 1 + 2 * 126);
    assert!(lines[0].starts_with("cluster,level,feedback,previous_score,outcome,p_success"));
    for line in &lines[1..] {
        let cells: Vec<f64> = line
            .split(',')
            .map(|c| c.parse().expect("number"))
            .collect();
        assert_eq!(cells.len(), 9);
        assert!((0.0..=1.0).contains(&cells[5]) && cells[6] >= 0.0);
        assert!((-1.0..=1.0).contains(&cells[7]) && cells[8] >= 0.0);
    }
    // Fixed hyperparameters are kept as given.
    let fixed = dir.path().join("fixed.json");
    let out = user_model(&[
        "fit",
        "--data",
        data.to_str().expect("path"),
        "--fixed",
        "--length-scale",
        "0.5",
        "--alpha",
        "2",
        "--output",
        fixed.to_str().expect("path"),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let set = user_models::UserModelSet::load(&fixed).expect("loads");
    for c in &set.file().clusters {
        assert_eq!(
            c.success.kernel,
            user_models::Kernel::RationalQuadratic {
                length_scale: 0.5,
                alpha: 2.0
            }
        );
    }
}

#[test]
fn fit_with_a_fitted_noise_says_so_and_keeps_it_in_the_file() {
    let dir = tempfile::tempdir().expect("temp dir");
    let data = dir.path().join("study.csv");
    write_csv(&data, &simulate_study(&StudySpec::default())).expect("writes");
    let model = dir.path().join("fitted.json");
    let fit = |extra: &[&str]| {
        let mut args = vec![
            "fit",
            "--data",
            data.to_str().expect("path"),
            "--output",
            model.to_str().expect("path"),
            "--figures",
            dir.path().to_str().expect("path"),
        ];
        args.extend_from_slice(extra);
        user_model(&args)
    };
    let out = fit(&["--noise", "fitted"]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        stdout.matches("per sequence (fitted)").count(),
        4,
        "{stdout}"
    );
    // What σ rests on, per cluster.
    assert_eq!(
        stdout
            .matches("σ of P(success) by the cluster's sequences at the input: none: ")
            .count(),
        2,
        "{stdout}"
    );
    let set = user_models::UserModelSet::load(&model).expect("loads");
    assert!(
        set.file().provenance.ends_with("--noise fitted"),
        "{}",
        set.file().provenance
    );
    assert!(set.file().clusters[0].success.group_sizes.is_some());
    // The paper's fit (the default) says nothing of a noise.
    let out = fit(&[]);
    assert!(!String::from_utf8_lossy(&out.stdout).contains("per sequence"));
    for (args, words) in [
        (
            &["--noise", "fitted", "--fixed"][..],
            "use one or the other",
        ),
        (&["--noise", "learned"][..], "is not `paper` or `fitted`"),
    ] {
        let out = fit(args);
        assert!(!out.status.success(), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(words), "{args:?}: {err}");
    }
}

#[test]
fn a_failing_fit_writes_nothing_and_names_the_problem() {
    let dir = tempfile::tempdir().expect("temp dir");
    let data = dir.path().join("study.csv");
    let model = dir.path().join("m.json");
    assert!(
        user_model(&["simulate-study", "--output", data.to_str().expect("path")])
            .status
            .success()
    );
    let out = user_model(&[
        "fit",
        "--data",
        data.to_str().expect("path"),
        "--clusters",
        "11",
        "--output",
        model.to_str().expect("path"),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("20 users cannot make 11 clusters"), "{err}");
    let text = std::fs::read_to_string(&data).expect("reads");
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let mut cells: Vec<&str> = lines[1].split(',').collect();
    cells[3] = "8";
    lines[1] = cells.join(",");
    std::fs::write(&data, lines.join("\n")).expect("writes");
    let out = user_model(&[
        "fit",
        "--data",
        data.to_str().expect("path"),
        "--output",
        model.to_str().expect("path"),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("record 1, field level"), "{err}");
    let names: Vec<_> = std::fs::read_dir(dir.path()).expect("lists").collect();
    assert_eq!(names.len(), 1, "only the data file: {names:?}");
}

/// The synthetic study with every user's 10 sequences split into two sessions of 5 (a morning
/// and an afternoon one), as users who came back.
fn two_sessions_per_user() -> Vec<InteractionRecord> {
    let mut records = simulate_study(&StudySpec::default());
    let mut count = std::collections::HashMap::new();
    for r in records.iter_mut() {
        let n = count.entry(r.user_id.clone()).or_insert(0);
        *n += 1;
        r.session_id = format!("{}-{}", r.user_id, if *n <= 5 { "am" } else { "pm" });
    }
    records
}

/// Equal record lists, or the first difference.
fn assert_same(got: &[InteractionRecord], expected: &[InteractionRecord]) {
    for (i, (g, e)) in got.iter().zip(expected).enumerate() {
        assert_eq!(g, e, "record {i} differs");
    }
    assert_eq!(got.len(), expected.len());
}

/// A model file without its provenance (which names the data files).
fn model_without_provenance(path: &Path) -> serde_json::Value {
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).expect("reads")).expect("JSON");
    v["provenance"] = serde_json::Value::Null;
    v
}

#[test]
fn records_round_trip_through_bags_and_fit_as_from_the_csv() {
    let original = two_sessions_per_user();
    let records = common::at_bag_precision(&original);
    // Only what a bag cannot hold changed: f32 values, times laid end to end in ns.
    assert_eq!(records.len(), 200);
    for (a, b) in original.iter().zip(&records) {
        assert_eq!(
            (
                &a.user_id,
                &a.session_id,
                a.level,
                a.feedback,
                a.previous_score,
                a.outcome
            ),
            (
                &b.user_id,
                &b.session_id,
                b.level,
                b.feedback,
                b.previous_score,
                b.outcome
            )
        );
        assert!((a.response_time - b.response_time).abs() < 1e-5);
        assert!((a.engagement.expect("E") - b.engagement.expect("E")).abs() < 1e-6);
        assert_eq!(a.engagement_per_second.len(), b.engagement_per_second.len());
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let bags = dir.path().join("bags");
    std::fs::create_dir_all(bags.join("day2")).expect("mkdir");
    let (am, pm): (Vec<_>, Vec<_>) = records
        .iter()
        .cloned()
        .partition(|r| r.session_id.ends_with("-am"));
    let (am_bag, pm_bag) = (bags.join("morning.mcap"), bags.join("day2/afternoon.mcap"));
    common::write_bag(&am_bag, &am);
    common::write_bag(&pm_bag, &pm);

    let read = read_bags(&[pm_bag.clone(), am_bag.clone()]).expect("reads the bags");
    assert_eq!(read.warnings, Vec::<String>::new());
    assert_same(&read.records, &records);
    assert_eq!(
        read_sources(std::slice::from_ref(&bags))
            .expect("reads the directory")
            .records,
        records
    );
    // The same session twice (a copied bag): taken once, by the one rule for what arrives
    // twice (docs/session_log.md), and named in a warning.
    let copy = dir.path().join("copy.mcap");
    std::fs::copy(&am_bag, &copy).expect("copies");
    let twice = read_bags(&[am_bag.clone(), copy.clone()]).expect("a session twice is read");
    assert_eq!(twice.records, am);
    assert_eq!(twice.warnings.len(), 1, "{:?}", twice.warnings);
    assert!(
        twice.warnings[0].contains(&format!("{} message(s) delivered again in", am.len()))
            && twice.warnings[0].contains("copy.mcap")
            && twice.warnings[0].contains("morning.mcap"),
        "{:?}",
        twice.warnings
    );
    // The same sequence with another outcome is not a repeat: refused, naming both bags.
    let mut changed = am.clone();
    changed[0].outcome = match changed[0].outcome {
        sequence_game::Outcome::Success => sequence_game::Outcome::Failure,
        _ => sequence_game::Outcome::Success,
    };
    changed[0].score = changed[0].outcome.score(changed[0].level);
    let other = dir.path().join("other.mcap");
    common::write_bag(&other, &changed);
    let e = read_bags(&[am_bag.clone(), other.clone()])
        .expect_err("a sequence twice, differing")
        .to_string();
    assert!(
        e.contains("arrived twice and differs (outcome: ")
            && e.contains("morning.mcap, SequenceResult #1")
            && e.contains("other.mcap, SequenceResult #1"),
        "{e}"
    );
    let single = read_bags(std::slice::from_ref(&am_bag))
        .expect("reads one bag")
        .records;
    assert_eq!(single, am);

    let csv = dir.path().join("records.csv");
    write_csv(&csv, &records).expect("writes");
    assert_eq!(read_csv(&csv).expect("reads"), records);
    let fit_from = |data: &[&Path], model: &str| {
        let model = dir.path().join(model);
        let mut args = vec!["fit".to_string(), "--data".into()];
        args.extend(data.iter().map(|p| p.to_str().expect("path").to_string()));
        args.extend(["--output".into(), model.to_str().expect("path").into()]);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = user_model(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(
            String::from_utf8_lossy(&out.stdout).contains("200 records of 20 users"),
            "{}",
            String::from_utf8_lossy(&out.stdout)
        );
        model
    };
    let from_csv = fit_from(&[&csv], "csv.json");
    let from_dir = fit_from(&[&bags], "dir.json");
    let from_two = fit_from(&[&am_bag, &pm_bag], "two.json");
    let expected = model_without_provenance(&from_csv);
    assert_eq!(model_without_provenance(&from_dir), expected);
    assert_eq!(model_without_provenance(&from_two), expected);
    let set = user_models::UserModelSet::load(&from_dir).expect("loads");
    assert_eq!(
        set.file()
            .clusters
            .iter()
            .map(|c| c.users.len())
            .sum::<usize>(),
        20
    );
}

/// Set in the copy of this test that runs inside the network namespace.
const IN_NAMESPACE: &str = "USER_MODEL_TEST_IN_LOOPBACK_NETNS";

/// `user_model run` as a process over DDS: every PredictUser answer of the synthetic model
/// and every AssignCluster answer for its users equal the in-process `UserModelSet`'s exactly;
/// queries outside the state space get an error response and the node keeps serving. DDS
/// multicasts, so this test runs itself again inside a private loopback-only namespace
/// (tests/loopback-netns), where it starts the node and calls it.
#[test]
fn the_node_answers_over_dds_as_the_model_does_in_process() {
    let Some(stdout) = loopback_netns::test_inside_namespace(
        "the_node_answers_over_dds_as_the_model_does_in_process",
        IN_NAMESPACE,
        std::time::Duration::from_secs(120),
        node_over_dds_inside_the_namespace,
    ) else {
        return;
    };
    assert!(
        stdout.contains("over DDS: 252 predictions and 20 cluster assignments equal"),
        "{stdout}"
    );
}

fn node_over_dds_inside_the_namespace() {
    use node_shell::{NoParameters, NodeShell, ShellOptions};
    use qt_therapy_msgs::topics::{ASSIGN_CLUSTER, PREDICT_USER};
    use qt_therapy_msgs::{AssignClusterRequest, PredictUserRequest};
    use sequence_game::{Feedback, Level, ModelInput, Outcome};
    use std::time::Duration;

    let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/synthetic_study_c2.json");
    let set = user_models::UserModelSet::load(&model).expect("loads the model");
    let dir = tempfile::tempdir().expect("temp dir");
    let node_params = dir.path().join("user_model.yaml");
    std::fs::write(
        &node_params,
        format!(
            "user_model:\n  ros__parameters:\n    model_file: {:?}\n",
            model.to_str().expect("path")
        ),
    )
    .expect("writes");
    let probe_params = dir.path().join("probe.yaml");
    std::fs::write(&probe_params, "user_model_probe:\n  ros__parameters: {}\n").expect("writes");
    let log = dir.path().join("node.log");
    let mut node = Command::new(env!("CARGO_BIN_EXE_user_model"))
        .args(["run", "--params-file", node_params.to_str().expect("path")])
        .stdout(std::fs::File::create(&log).expect("log"))
        .stderr(std::fs::File::create(dir.path().join("node.err")).expect("log"))
        .spawn()
        .expect("starts user_model run");

    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .expect("runtime");
    let checked = runtime.block_on(async {
        let options = ShellOptions {
            params_file: Some(probe_params.clone()),
            namespace: "/".into(),
            service_mapping: "enhanced".into(),
            ..Default::default()
        };
        let (mut shell, NoParameters {}) =
            NodeShell::start("user_model_probe", &options).expect("probe node");
        let predict = shell.client(PREDICT_USER).expect("client");
        let assign = shell.client(ASSIGN_CLUSTER).expect("client");
        let wait = Duration::from_secs(30);
        assert!(
            shell.wait_for_service(&predict, wait).await,
            "no PredictUser server"
        );
        assert!(
            shell.wait_for_service(&assign, wait).await,
            "no AssignCluster server"
        );
        let timeout = Duration::from_secs(10);
        let mut predictions = 0;
        for cluster in 0..set.cluster_count() {
            let table = set.table(cluster as i64).expect("table");
            for level in Level::ALL {
                for feedback in Feedback::ALL {
                    for previous_score in -3i8..=3 {
                        for outcome in [Outcome::Success, Outcome::Failure] {
                            let input = ModelInput::new(level, feedback, previous_score)
                                .expect("in the state space");
                            let (p, e) = (table.success(input), table.engagement(input, outcome));
                            let r = predict
                                .call(
                                    PredictUserRequest {
                                        cluster: cluster as i32,
                                        level: level.get(),
                                        feedback: u8::from(feedback),
                                        previous_score,
                                        outcome: outcome.sign(),
                                    },
                                    timeout,
                                )
                                .await
                                .expect("PredictUser answers");
                            assert!(r.ok, "{}", r.error);
                            assert_eq!(
                                (
                                    r.success_probability,
                                    r.success_std,
                                    r.engagement,
                                    r.engagement_std
                                ),
                                (p.mean, p.std, e.mean, e.std),
                                "cluster {cluster} {input:?} {outcome:?}"
                            );
                            predictions += 1;
                        }
                    }
                }
            }
        }
        let mut assignments = 0;
        for user in &set.file().users {
            let v: [f64; 6] = user.vector.as_slice().try_into().expect("6 values");
            let r = assign
                .call(
                    AssignClusterRequest {
                        user_vector: v.to_vec(),
                    },
                    timeout,
                )
                .await
                .expect("AssignCluster answers");
            assert!(r.ok, "{}", r.error);
            assert_eq!(r.cluster, set.assign_cluster(&v).expect("assigns") as i32);
            assert_eq!(r.cluster as usize, user.cluster, "{}", user.user);
            assert_eq!(r.projection, set.project(&v));
            assignments += 1;
        }
        // Outside the state space: an error response each, then the node still serves.
        let good = PredictUserRequest {
            cluster: 1,
            level: 3,
            feedback: 2,
            previous_score: -3,
            outcome: -1,
        };
        for (bad, says) in [
            (
                PredictUserRequest {
                    level: 4,
                    ..good.clone()
                },
                "level",
            ),
            (
                PredictUserRequest {
                    previous_score: 5,
                    ..good.clone()
                },
                "previous_score",
            ),
            (
                PredictUserRequest {
                    outcome: 0,
                    ..good.clone()
                },
                "outcome",
            ),
            (
                PredictUserRequest {
                    cluster: 7,
                    ..good.clone()
                },
                "cluster",
            ),
        ] {
            let r = predict
                .call(bad, timeout)
                .await
                .expect("answers a bad query");
            assert!(!r.ok && r.error.contains(says), "{says}: {r:?}");
        }
        for bad in [
            vec![0.5; 5],
            vec![0.5, f64::NAN, 0.5, 0.1, 0.5, 0.1],
            vec![1.5, 0.0, 1.0, 0.0, 1.0, 0.0],
        ] {
            let r = assign
                .call(
                    AssignClusterRequest {
                        user_vector: bad.clone(),
                    },
                    timeout,
                )
                .await
                .expect("answers a bad vector");
            assert!(
                !r.ok && !r.error.is_empty() && r.cluster == -1,
                "{bad:?}: {r:?}"
            );
        }
        let r = predict.call(good, timeout).await.expect("still serves");
        let input = ModelInput::new(Level::THREE, Feedback::Challenging, -3).expect("input");
        let table = set.table(1).expect("table");
        assert!(r.ok, "{}", r.error);
        assert_eq!(
            (r.success_probability, r.engagement_std),
            (
                table.success(input).mean,
                table.engagement(input, Outcome::Failure).std
            )
        );
        shell.stop().await;
        (predictions, assignments)
    });
    let _ = node.kill();
    node.wait().expect("node ends");
    println!(
        "over DDS: {} predictions and {} cluster assignments equal the in-process model's",
        checked.0, checked.1
    );
}
