//! `behaviour_policy run` as a process over DDS, fed bad input (issue 4, "Bad input"): an
//! unknown cluster, a cluster whose Q-table file is corrupt, states outside the space, NaN
//! engagement and a result out of place in its session are refused with a clear error, the
//! corrupt file is never written, and the node keeps serving the good cluster exactly as the
//! in-process policy does; with per-user tables it makes and teaches the user's own table;
//! with child beliefs it keeps each child's belief across a restart. DDS
//! multicasts, so each runs itself again inside a private loopback-only network namespace
//! (tests/loopback-netns), where it starts the node. And the learn-first gate (a request held
//! for the result it follows) through the node's own loop on the in-process bus.

use behaviour_policy::{BehaviourPolicyParams, PersistentPolicy};
use q_learning::messages::transition;
use q_learning::{Mode, QTable, QTableFile, QTableOwner};
use qt_therapy_msgs::{BehaviourState, DecideActionRequest, SequenceResult};
use sequence_game::State;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::time::{Duration, Instant};

/// Set in the copy of this test that runs inside the network namespace.
const IN_NAMESPACE: &str = "BEHAVIOUR_POLICY_TEST_IN_LOOPBACK_NETNS";

#[test]
fn the_node_refuses_bad_input_over_dds_and_keeps_serving() {
    let Some(stdout) = loopback_netns::test_inside_namespace(
        "the_node_refuses_bad_input_over_dds_and_keeps_serving",
        IN_NAMESPACE,
        Duration::from_secs(120),
        bad_input_inside_the_namespace,
    ) else {
        return;
    };
    assert!(
        stdout.contains(
            "over DDS: 4 decisions refused, 7 results not learned, 1 learned, then 1 decision \
             equal to the in-process policy's; the corrupt file unchanged"
        ),
        "{stdout}"
    );
}

#[test]
fn with_per_user_tables_the_node_makes_and_teaches_the_users_own_table_over_dds() {
    let Some(stdout) = loopback_netns::test_inside_namespace(
        "with_per_user_tables_the_node_makes_and_teaches_the_users_own_table_over_dds",
        IN_NAMESPACE,
        Duration::from_secs(120),
        per_user_inside_the_namespace,
    ) else {
        return;
    };
    assert!(
        stdout.contains(
            "over DDS, per user: user_u1.json made from cluster 0's table at u1's first \
             decision, both learned the result once"
        ),
        "{stdout}"
    );
    assert!(
        stdout.contains("over DDS, a second node on the same q_table_dir: refused"),
        "{stdout}"
    );
}

#[test]
fn with_child_beliefs_the_node_keeps_each_childs_belief_across_a_restart_over_dds() {
    let Some(stdout) = loopback_netns::test_inside_namespace(
        "with_child_beliefs_the_node_keeps_each_childs_belief_across_a_restart_over_dds",
        IN_NAMESPACE,
        Duration::from_secs(180),
        child_belief_inside_the_namespace,
    ) else {
        return;
    };
    assert!(
        stdout.contains(
            "over DDS, child belief: u1's first decision planned on a new belief, its result \
             learned into belief_u1.json, and after a restart the next decision planned on it \
             as the in-process core plans; u2's damaged file named, kept aside, u2 new"
        ),
        "{stdout}"
    );
}

/// Algorithm 1's order (issue 33, item 1): the game manager's request for step 2 can reach the
/// policy before sequence 1's result (a service and a topic). The call is sent first and the
/// result 600 ms later: the answer must come after the result and be the decision of a table
/// that has learned it, as the in-process policy's. Before `after_sequence` and the node's
/// wait, it was answered at once from the table without the result (0 updates). The node's
/// own run loop (`node::run`, the code the process runs) on the in-process bus, on the wall
/// clock: what is tested is the node's gate, which does not need DDS (the DDS shell's service
/// and topic are tested above and in tests/dds_processes.rs).
#[test]
fn a_decision_waits_for_the_result_it_follows() {
    use node_shell::Bus;
    use node_shell::clock::Clock;
    use node_shell::in_process::InProcessBus;
    use qt_therapy_msgs::topics::{BEHAVIOUR_POLICY_NODE, DECIDE_ACTION, SEQUENCE_RESULT};

    let dir = tempfile::tempdir().expect("temp dir");
    let q_tables = dir.path().join("q_tables");
    std::fs::create_dir_all(&q_tables).expect("mkdir");
    cluster_0_file()
        .save(&q_tables.join("cluster_0.json"))
        .expect("writes cluster 0");
    let node_params = write_node_params(dir.path(), &q_tables, "    result_wait_s: 1.5\n");
    let options = node_shell::ShellOptions {
        params_file: Some(node_params),
        namespace: "/".into(),
        ..Default::default()
    };
    let (node_params, params_path) = options
        .parameters::<BehaviourPolicyParams>(BEHAVIOUR_POLICY_NODE)
        .expect("the node's parameters");

    // The in-process policy, learning first.
    let params = BehaviourPolicyParams::default();
    let expected_dir = dir.path().join("expected");
    std::fs::create_dir_all(&expected_dir).expect("mkdir");
    cluster_0_file()
        .save(&expected_dir.join("cluster_0.json"))
        .expect("writes");
    let (mut expected, _) = PersistentPolicy::open(
        &expected_dir,
        QTableOwner::Cluster(0),
        params.learning().expect("learning"),
        Mode::Exploit,
        params.seed(),
        || Err("the file is there".into()),
    )
    .expect("opens the copy");
    let first = good_result("order", 0);
    expected
        .learn_sequence("order", 1, &transition(&first).expect("valid"))
        .expect("learns");
    let next_state = State::new(2, 0, 2).expect("state after a2 solved");
    let expected_decision = expected.decide(next_state, 2).expect("decides");

    // The node's log, read after it stopped (its summary of the gate).
    let log = std::sync::Arc::new(std::sync::Mutex::new(Vec::<u8>::new()));
    let writer = {
        let log = log.clone();
        move || LogLine(log.clone())
    };
    let subscriber = tracing_subscriber::fmt()
        .with_writer(writer)
        .with_ansi(false)
        .finish();
    let _logging = tracing::subscriber::set_default(subscriber);
    let node_log =
        || String::from_utf8_lossy(&log.lock().unwrap_or_else(|e| e.into_inner())).to_string();

    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    tokio::task::LocalSet::new().block_on(&runtime, async {
        let bus = InProcessBus::new(Clock::wall());
        let (mut policy_bus, policy_stop) = bus.join(BEHAVIOUR_POLICY_NODE).expect("joins");
        let node = tokio::task::spawn_local(async move {
            let outcome =
                behaviour_policy::node::run(&mut policy_bus, node_params, &params_path).await;
            policy_bus.stop().await;
            outcome
        });
        let (mut probe, _) = bus.join("behaviour_policy_probe").expect("joins");
        let decide = std::sync::Arc::new(probe.client(DECIDE_ACTION).expect("client"));
        let results = probe.publisher(SEQUENCE_RESULT).expect("publisher");
        assert!(
            probe.wait_for_service(&decide, Duration::from_secs(30)).await,
            "no DecideAction server:\n{}",
            node_log()
        );
        assert!(
            results.wait_for_subscribers(&probe, Duration::from_secs(30)).await,
            "the node does not subscribe to results"
        );
        let step_two = DecideActionRequest {
            session_id: "order".into(),
            after_sequence: 1,
            ..request(0, 2, BehaviourState::from_state(next_state))
        };
        let sent = Instant::now();
        let call = {
            let decide = decide.clone();
            tokio::task::spawn_local(
                async move { decide.call(step_two, Duration::from_secs(10)).await },
            )
        };
        tokio::time::sleep(Duration::from_millis(600)).await;
        let result_sent = sent.elapsed();
        assert!(results.send(first.clone()), "publishes");
        let r = call.await.expect("joins").expect("answers");
        let answered = sent.elapsed();
        assert!(r.ok, "{}: {}", r.error, node_log());
        assert!(
            answered >= result_sent,
            "answered {answered:?} after the call, before the result ({result_sent:?})"
        );
        let d = &r.decision;
        assert!(
            d.model_used.ends_with("cluster_0.json, 1 updates)"),
            "decided before learning: {}",
            d.model_used
        );
        assert_eq!(
            (d.action, d.q_values.clone(), d.probabilities.clone()),
            (
                expected_decision.action.index() as u8,
                expected_decision.q_values.to_vec(),
                expected_decision.probabilities.to_vec()
            )
        );
        // A call whose result never comes: refused after result_wait_s, naming it.
        let lost = DecideActionRequest {
            session_id: "order".into(),
            after_sequence: 2,
            ..request(0, 3, BehaviourState::from_state(next_state))
        };
        let asked = Instant::now();
        let r = decide
            .call(lost, Duration::from_secs(10))
            .await
            .expect("answers");
        assert!(!r.ok);
        assert!(
            r.error.contains("the result of sequence 2 of session \"order\" has not reached the policy within 1.5 s"),
            "{}",
            r.error
        );
        assert!(asked.elapsed() >= Duration::from_millis(1400), "{:?}", asked.elapsed());
        eprintln!(
            "ordering: result sent {} ms after the call, answered at {} ms",
            result_sent.as_millis(),
            answered.as_millis()
        );
        drop(results);
        probe.stop().await;
        // As SIGINT asks the process.
        policy_stop.stop();
        node.await.expect("the node's task").expect("the node ends cleanly");
    });
    let text = node_log();
    assert!(
        text.contains("2 held, 1 answered once it was learned, 1 refused after result_wait_s"),
        "{text}"
    );
}

/// A writer of log lines into a shared buffer (the test's tracing subscriber).
struct LogLine(std::sync::Arc<std::sync::Mutex<Vec<u8>>>);

impl std::io::Write for LogLine {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .extend_from_slice(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// The node process; killed if the test ends early, so no node outlives a failed run.
struct NodeProcess(Child);

impl NodeProcess {
    /// SIGINT (the node's clean shutdown), then its exit status within `deadline`.
    fn interrupt(&mut self, deadline: Duration) -> std::process::ExitStatus {
        let sent = Command::new("kill")
            .args(["-INT", &self.0.id().to_string()])
            .status()
            .expect("runs kill");
        assert!(sent.success(), "kill -INT failed");
        let started = Instant::now();
        loop {
            if let Some(status) = self.0.try_wait().expect("node status") {
                return status;
            }
            assert!(
                started.elapsed() < deadline,
                "the node did not stop within {deadline:?} of SIGINT"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl Drop for NodeProcess {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A table with distinct values, so a decision shows which table made it.
fn initial_table() -> QTable {
    let mut table = QTable::default();
    for (i, row) in table.q.iter_mut().enumerate() {
        for (a, q) in row.iter_mut().enumerate() {
            *q = ((i * 7 + a * 3) % 11) as f64 / 10.0;
        }
    }
    table
}

fn cluster_0_file() -> QTableFile {
    QTableFile {
        owner: QTableOwner::Cluster(0),
        provenance: "node_over_dds test".into(),
        updates: 0,
        learned: BTreeMap::new(),
        table: initial_table(),
    }
}

/// Polls `check` every 50 ms until it gives a value or `deadline` passes.
async fn wait_for<T>(deadline: Duration, mut check: impl FnMut() -> Option<T>) -> Option<T> {
    let started = Instant::now();
    loop {
        if let Some(v) = check() {
            return Some(v);
        }
        if started.elapsed() > deadline {
            return None;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// A result the game could send: sequence 1 of `session`, a2 (level 2) from the start state,
/// solved, engagement 0.5.
fn good_result(session: &str, cluster: i32) -> SequenceResult {
    let emotions = |names: &[&str]| names.iter().map(|n| n.to_string()).collect::<Vec<_>>();
    let said = emotions(&["happy", "sad", "angry", "happy", "disgusted"]);
    SequenceResult {
        session_id: session.into(),
        user_id: "u1".into(),
        user_model_cluster: cluster,
        sequence_index: 1,
        state: BehaviourState::from_state(State::START),
        action: 1,
        level: 2,
        feedback: 0,
        sequence: said.clone(),
        answer: said,
        outcome: 1,
        activity_result: 2.0,
        engagement: 0.5,
        engagement_per_second: vec![0.25, 0.75],
        response_time: 3.0,
        sequences_planned: 10,
        ..Default::default()
    }
}

fn request(cluster: i32, step: u8, state: BehaviourState) -> DecideActionRequest {
    DecideActionRequest {
        session_id: "good".into(),
        user_id: "u1".into(),
        user_model_cluster: cluster,
        state,
        step,
        // These calls test the service alone: no result precedes them.
        after_sequence: 0,
    }
}

/// Starts `behaviour_policy run` with its Q-tables in `q_tables` (and `extra` lines of
/// parameters); returns it, the probe node's parameter file and the node's log file.
fn start_node(dir: &Path, q_tables: &Path, extra: &str) -> (NodeProcess, PathBuf, PathBuf) {
    let path = |p: &Path| p.to_str().expect("utf-8 path").to_string();
    let node_params = write_node_params(dir, q_tables, extra);
    let probe_params = dir.join("probe.yaml");
    std::fs::write(
        &probe_params,
        "behaviour_policy_probe:\n  ros__parameters: {}\n",
    )
    .expect("writes");
    let log = dir.join("node.log");
    let node = NodeProcess(
        Command::new(env!("CARGO_BIN_EXE_behaviour_policy"))
            .args(["run", "--params-file", &path(&node_params)])
            .stdout(std::fs::File::create(dir.join("node.out")).expect("log"))
            .stderr(std::fs::File::create(&log).expect("log"))
            .spawn()
            .expect("starts behaviour_policy run"),
    );
    (node, probe_params, log)
}

/// The node's parameter file in `dir`: its Q-tables in `q_tables`, the study's user models
/// (and `extra` lines of parameters).
fn write_node_params(dir: &Path, q_tables: &Path, extra: &str) -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let user_models = root.join("nodes/user_model/models/migrave_study_c2.json");
    let path = |p: &Path| p.to_str().expect("utf-8 path").to_string();
    let node_params = dir.join("behaviour_policy.yaml");
    std::fs::write(
        &node_params,
        format!(
            "behaviour_policy:\n  ros__parameters:\n    user_model_file: {:?}\n    \
             q_table_dir: {:?}\n{extra}",
            path(&user_models),
            path(q_tables)
        ),
    )
    .expect("writes");
    node_params
}

/// A probe node's options.
fn probe_options(probe_params: &Path) -> node_shell::ShellOptions {
    node_shell::ShellOptions {
        params_file: Some(probe_params.to_path_buf()),
        namespace: "/".into(),
        service_mapping: "enhanced".into(),
        ..Default::default()
    }
}

fn bad_input_inside_the_namespace() {
    use qt_therapy_msgs::topics::{DECISION, SEQUENCE_RESULT};

    let dir = tempfile::tempdir().expect("temp dir");
    let q_tables = dir.path().join("q_tables");
    std::fs::create_dir_all(&q_tables).expect("mkdir");
    let good: PathBuf = q_tables.join("cluster_0.json");
    cluster_0_file().save(&good).expect("writes cluster 0");
    // Cluster 1: a table cut off mid-way, as a full disk or a crash of another program leaves it.
    let whole = std::fs::read(&good).expect("reads");
    let corrupt_bytes = whole[..whole.len() / 2].to_vec();
    let corrupt = q_tables.join("cluster_1.json");
    std::fs::write(&corrupt, &corrupt_bytes).expect("writes cluster 1");
    let path = |p: &Path| p.to_str().expect("utf-8 path").to_string();

    let (mut node, probe_params, log) = start_node(dir.path(), &q_tables, "");
    let node_log = || std::fs::read_to_string(&log).unwrap_or_default();

    // What the node must do with the valid result and the valid call: the same as this
    // in-process policy, opened from a copy of the same file with the node's seed.
    let params = BehaviourPolicyParams::default();
    let learning = params.learning().expect("learning constants");
    let expected_dir = dir.path().join("expected");
    std::fs::create_dir_all(&expected_dir).expect("mkdir");
    cluster_0_file()
        .save(&expected_dir.join("cluster_0.json"))
        .expect("writes");
    let (mut expected, _) = PersistentPolicy::open(
        &expected_dir,
        QTableOwner::Cluster(0),
        learning,
        Mode::Exploit,
        params.seed(),
        || Err("the file is there".into()),
    )
    .expect("opens the copy");
    let valid = good_result("good", 0);
    expected
        .learn_sequence(
            &valid.session_id,
            valid.sequence_index,
            &transition(&valid).expect("valid"),
        )
        .expect("learns");
    let next_state = State::new(2, 0, 2).expect("state after a2 solved");
    let expected_decision = expected.decide(next_state, 2).expect("decides");

    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .expect("runtime");
    let (refused_calls, refused_results) = runtime.block_on(async {
        let (mut shell, decide) = probe_with_client(&probe_params, &node_log).await;
        let results = shell.publisher(SEQUENCE_RESULT).expect("publisher");
        let mut decisions = shell.subscribe(DECISION, 16).expect("subscription");
        let timeout = Duration::from_secs(10);
        let start = BehaviourState::from_state(State::START);

        // Calls the node must answer ok = false, naming what is wrong.
        let corrupt_path = path(&corrupt);
        let refused = [
            (
                request(5, 1, start.clone()),
                vec!["unknown user model cluster 5: the policy holds 2"],
            ),
            (
                request(1, 1, start.clone()),
                vec![
                    "cluster 1 is unavailable",
                    corrupt_path.as_str(),
                    "not JSON",
                ],
            ),
            // Outside the state space: refused by the request's validation, before the policy.
            (
                request(
                    0,
                    2,
                    BehaviourState {
                        level: 4,
                        feedback: 0,
                        previous_score: 1,
                    },
                ),
                vec!["DecideAction request: state:"],
            ),
            (
                request(0, 3, start.clone()),
                vec!["does not fit state", "only step 1 starts from (0, 0, 0)"],
            ),
        ];
        for (call, says) in &refused {
            let r = decide
                .call(call.clone(), timeout)
                .await
                .expect("answers a bad call");
            assert!(!r.ok, "{call:?} was answered: {r:?}");
            for words in says {
                assert!(r.error.contains(words), "{:?} lacks {words:?}", r.error);
            }
        }

        // Results the node must not learn from, then one it must.
        let bad_results = [
            SequenceResult {
                engagement: f32::NAN,
                engagement_per_second: vec![f32::NAN],
                ..good_result("bad", 0)
            },
            SequenceResult {
                state: BehaviourState {
                    level: 0,
                    feedback: 2,
                    previous_score: 0,
                },
                ..good_result("bad", 0)
            },
            // Sequence 1 from a state with a level, with feedback: never the game's first.
            SequenceResult {
                state: BehaviourState::from_state(State::new(2, 0, -2).expect("state")),
                action: 3,
                feedback: 1,
                ..good_result("bad", 0)
            },
            // A later sequence from the start state.
            SequenceResult {
                sequence_index: 4,
                ..good_result("bad", 0)
            },
            good_result("c1", 1),
            SequenceResult {
                sequence_index: 2,
                state: BehaviourState::from_state(State::new(2, 0, 2).expect("state")),
                ..good_result("c1", 1)
            },
            good_result("c5", 5),
        ];
        assert!(
            results
                .wait_for_subscribers(&shell, Duration::from_secs(30))
                .await,
            "the node does not subscribe to {}",
            SEQUENCE_RESULT.name
        );
        for r in &bad_results {
            assert!(results.send(r.clone()), "publishes");
        }
        assert!(results.send(valid.clone()), "publishes");
        // One reliable writer: when the valid result is learned, every earlier one was handled.
        let learned = wait_for(Duration::from_secs(20), || {
            QTableFile::load(&good).ok().filter(|f| f.updates > 0)
        })
        .await
        .unwrap_or_else(|| panic!("the valid result was not learned:\n{}", node_log()));
        assert_eq!(learned.updates, 1, "{learned:?}");
        // The same bytes as the in-process policy's file after learning only the valid result.
        assert_eq!(
            std::fs::read_to_string(&good).expect("reads"),
            std::fs::read_to_string(expected.path()).expect("reads"),
            "cluster 0's file is not the in-process policy's after the valid result alone"
        );

        // Still serving: the next decision is the in-process policy's.
        let r = decide
            .call(
                request(0, 2, BehaviourState::from_state(next_state)),
                timeout,
            )
            .await
            .expect("answers a valid call");
        assert!(r.ok, "{}", r.error);
        let d = &r.decision;
        assert_eq!(
            (
                d.step,
                d.action,
                d.level,
                d.feedback,
                d.q_values.clone(),
                d.probabilities.clone(),
                d.temperature,
                d.explored,
                d.exploitation_only
            ),
            (
                2,
                expected_decision.action.index() as u8,
                expected_decision.level.get(),
                expected_decision.feedback as u8,
                expected_decision.q_values.to_vec(),
                expected_decision.probabilities.to_vec(),
                expected_decision.temperature,
                expected_decision.explored,
                true
            )
        );
        assert!(
            d.model_used.starts_with("cluster 0 (")
                && d.model_used.ends_with("cluster_0.json, 1 updates)"),
            "{}",
            d.model_used
        );
        // ...and published as answered (only a decision made is published).
        let published = tokio::time::timeout(timeout, decisions.recv())
            .await
            .expect("a Decision within the deadline")
            .expect("the subscription is open");
        assert_eq!(&published, d);
        drop((decide, results, decisions));
        shell.stop().await;
        (refused.len(), bad_results.len())
    });

    let status = node.interrupt(Duration::from_secs(20));
    let text = node_log();
    assert!(status.success(), "the node exited with {status}:\n{text}");
    assert_eq!(
        std::fs::read(&corrupt).expect("reads"),
        corrupt_bytes,
        "the corrupt file was written"
    );
    let mut names: Vec<String> = std::fs::read_dir(&q_tables)
        .expect("lists")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["cluster_0.json", "cluster_1.json"]);

    // The node said why, once per kind of refusal.
    let count = |words: &str| text.matches(words).count();
    for (words, times) in [
        (format!("Q-table refused: {}", path(&corrupt)), 1),
        ("not learned from: cluster 1 is unavailable".into(), 1),
        ("SequenceResult: engagement = NaN".into(), 1),
        ("SequenceResult: state:".into(), 1),
        (
            "not learned from: sequence 1 took a4 encourage: feedback is not allowed".into(),
            1,
        ),
        (
            "not learned from: sequence 4 starts from (L=0, F=0, PS=+0)".into(),
            1,
        ),
        ("not learned from: unknown user model cluster 5".into(), 1),
        ("DecideAction request: state:".into(), 1),
    ] {
        assert_eq!(count(&words), times, "{words:?} in the node's log:\n{text}");
    }
    println!(
        "over DDS: {refused_calls} decisions refused, {refused_results} results not learned, 1 \
         learned, then 1 decision equal to the in-process policy's; the corrupt file unchanged"
    );
}

fn per_user_inside_the_namespace() {
    use qt_therapy_msgs::topics::SEQUENCE_RESULT;

    let dir = tempfile::tempdir().expect("temp dir");
    let q_tables = dir.path().join("q_tables");
    std::fs::create_dir_all(&q_tables).expect("mkdir");
    let cluster_0 = q_tables.join("cluster_0.json");
    cluster_0_file().save(&cluster_0).expect("writes cluster 0");
    let user_u1 = q_tables.join("user_u1.json");
    let (mut node, probe_params, log) =
        start_node(dir.path(), &q_tables, "    per_user_q_tables: true\n");
    let node_log = || std::fs::read_to_string(&log).unwrap_or_default();

    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .expect("runtime");
    runtime.block_on(async {
        let (mut shell, decide) = probe_with_client(&probe_params, &node_log).await;
        let results = shell.publisher(SEQUENCE_RESULT).expect("publisher");
        let start = BehaviourState::from_state(State::START);
        let r = decide
            .call(request(0, 1, start), Duration::from_secs(10))
            .await
            .expect("answers");
        assert!(r.ok, "{}", r.error);
        assert!(
            r.decision.model_used.starts_with("user u1 (")
                && r.decision.model_used.ends_with("user_u1.json, 0 updates)"),
            "{}",
            r.decision.model_used
        );
        let made = QTableFile::load(&user_u1).expect("the user's table is on disk");
        assert_eq!(made.owner, QTableOwner::User("u1".into()));
        assert_eq!(made.table, initial_table(), "a copy of cluster 0's table");

        // A second copy of the node on the same Q-tables (a launch file run twice) refuses to
        // start, naming the first; the first goes on serving and learning below.
        let second = Command::new(env!("CARGO_BIN_EXE_behaviour_policy"))
            .args(["run", "--params-file"])
            .arg(dir.path().join("behaviour_policy.yaml"))
            .output()
            .expect("runs a second behaviour_policy");
        let said = String::from_utf8_lossy(&second.stderr);
        assert!(!second.status.success(), "a second node started:\n{said}");
        let refusal = format!(
            "is in use by another behaviour_policy (pid {}): two would overwrite each other's \
             Q-tables",
            node.0.id()
        );
        assert!(said.contains(&refusal), "{said}");
        println!("over DDS, a second node on the same q_table_dir: refused ({refusal})");

        assert!(
            results
                .wait_for_subscribers(&shell, Duration::from_secs(30))
                .await,
            "the node does not subscribe to {}",
            SEQUENCE_RESULT.name
        );
        // Sent twice, as a respawned game manager's durable writer would: learned once.
        for _ in 0..2 {
            assert!(results.send(good_result("good", 0)), "publishes");
        }
        let learned = wait_for(Duration::from_secs(20), || {
            let user = QTableFile::load(&user_u1).ok().filter(|f| f.updates > 0)?;
            let cluster = QTableFile::load(&cluster_0)
                .ok()
                .filter(|f| f.updates > 0)?;
            Some((user, cluster))
        })
        .await;
        let (user, cluster) =
            learned.unwrap_or_else(|| panic!("the result was not learned:\n{}", node_log()));
        let told = wait_for(Duration::from_secs(20), || {
            node_log()
                .contains("already learned from this sequence")
                .then_some(())
        })
        .await;
        assert!(
            told.is_some(),
            "the second copy was not seen:\n{}",
            node_log()
        );
        drop((decide, results));
        shell.stop().await;
        // Both started from the same table and learned the same sequence.
        assert_eq!((user.updates, cluster.updates), (1, 1));
        assert_eq!(user.table, cluster.table);
        assert_ne!(user.table, initial_table());
    });
    let status = node.interrupt(Duration::from_secs(20));
    let text = node_log();
    assert!(status.success(), "the node exited with {status}:\n{text}");
    assert!(
        text.contains("already learned from this sequence"),
        "{text}"
    );
    assert_eq!(
        QTableFile::load(&user_u1).expect("loads").updates,
        1,
        "learned once"
    );
    println!(
        "over DDS, per user: user_u1.json made from cluster 0's table at u1's first decision, \
         both learned the result once"
    );
}

fn child_belief_inside_the_namespace() {
    use behaviour_policy::child_beliefs::{BELIEF_FILE, BeliefFile, BeliefSettings, ChildBeliefs};
    use child_belief::prior_file::PriorFile;
    use qt_therapy_msgs::topics::SEQUENCE_RESULT;

    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let prior = root.join("nodes/behaviour_policy/models/child_belief_prior_c2.json");
    let dir = tempfile::tempdir().expect("temp dir");
    let q_tables = dir.path().join("q_tables");
    std::fs::create_dir_all(&q_tables).expect("mkdir");
    cluster_0_file()
        .save(&q_tables.join("cluster_0.json"))
        .expect("writes cluster 0");
    // u2's belief file cut off mid-way (a crash of another program, a bad copy).
    let damaged = q_tables.join("belief_u2.json");
    std::fs::write(
        &damaged,
        b"{\"format\": \"qt_therapy child_belief\", \"vers",
    )
    .expect("writes");
    let extra = format!(
        "    child_belief: true\n    child_belief_prior_file: {:?}\n",
        prior.to_str().expect("utf-8 path")
    );
    let belief_u1 = q_tables.join("belief_u1.json");
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .expect("runtime");

    // First life: u1's first decision, its result learned; u2 is treated as new.
    let (mut node, probe_params, log) = start_node(dir.path(), &q_tables, &extra);
    let node_log = || std::fs::read_to_string(&log).unwrap_or_default();
    let first = runtime.block_on(async {
        let (mut shell, decide) = probe_with_client(&probe_params, &node_log).await;
        let results = shell.publisher(SEQUENCE_RESULT).expect("publisher");
        let start = BehaviourState::from_state(State::START);
        let r = decide
            .call(request(0, 1, start.clone()), Duration::from_secs(10))
            .await
            .expect("answers");
        assert!(r.ok, "{}", r.error);
        let d = r.decision;
        assert!(d.planned_on_belief, "{d:?}");
        assert_eq!((d.belief_observations, d.belief_success.len()), (0, 3));
        assert!(
            d.model_used
                .starts_with("belief of u1 (0 sequences, prior cluster 0"),
            "{}",
            d.model_used
        );
        let u2 = DecideActionRequest {
            user_id: "u2".into(),
            ..request(0, 1, start)
        };
        let r = decide
            .call(u2, Duration::from_secs(10))
            .await
            .expect("answers");
        assert!(r.ok && r.decision.planned_on_belief, "{r:?}");
        assert_eq!(r.decision.belief_observations, 0);

        assert!(
            results
                .wait_for_subscribers(&shell, Duration::from_secs(30))
                .await,
            "the node does not subscribe to {}",
            SEQUENCE_RESULT.name
        );
        assert!(results.send(good_result("good", 0)), "publishes");
        let learned = wait_for(Duration::from_secs(20), || {
            BELIEF_FILE
                .load::<BeliefFile>(&belief_u1)
                .ok()
                .filter(|f| f.observations.len() == 1)
        })
        .await;
        assert!(learned.is_some(), "u1's belief file:\n{}", node_log());
        drop((decide, results));
        shell.stop().await;
        d
    });
    let status = node.interrupt(Duration::from_secs(20));
    let text = node_log();
    assert!(status.success(), "the node exited with {status}:\n{text}");
    assert!(
        text.contains("belief file refused") && text.contains(&damaged.display().to_string()),
        "{text}"
    );
    let aside = q_tables.join("belief_u2.json.damaged");
    assert!(aside.exists(), "the damaged file is kept aside");
    drop(node);

    // Second life: the same directory; the decision after the result is planned on it.
    let (mut node, probe_params, log) = start_node(dir.path(), &q_tables, &extra);
    let node_log = || std::fs::read_to_string(&log).unwrap_or_default();
    let after = BehaviourState::from_state(State::new(2, 0, 2).expect("state"));
    let second = runtime.block_on(async {
        let (shell, decide) = probe_with_client(&probe_params, &node_log).await;
        let r = decide
            .call(
                DecideActionRequest {
                    after_sequence: 1,
                    ..request(0, 2, after.clone())
                },
                Duration::from_secs(10),
            )
            .await
            .expect("answers");
        drop(decide);
        shell.stop().await;
        r
    });
    let status = node.interrupt(Duration::from_secs(20));
    assert!(
        status.success(),
        "the node exited with {status}:\n{}",
        node_log()
    );
    assert!(second.ok, "{}", second.error);
    let d = second.decision;
    assert!(d.planned_on_belief && d.belief_observations == 1, "{d:?}");
    assert_ne!(
        d.belief_success, first.belief_success,
        "the result moved it"
    );

    // The in-process core, taught the same result, plans the same.
    let (_, covariance) = PriorFile::load(&prior).expect("the prior");
    let priors = user_models::UserModelSet::load(
        &root.join("nodes/user_model/models/migrave_study_c2.json"),
    )
    .expect("user models")
    .tables();
    let params = BehaviourPolicyParams::default();
    let core_dir = tempfile::tempdir().expect("temp dir");
    let mut core = ChildBeliefs::new(
        core_dir.path(),
        BeliefSettings {
            covariance,
            own_model: child_belief::OwnModelParams::default(),
            rule: params.child_belief_rule().expect("rule"),
            learning: params.learning().expect("learning"),
            seed: params.seed(),
        },
        priors,
    );
    assert!(core.learn(&good_result("good", 0), 0).expect("learns"));
    // The table the node planned near: cluster 0's, having learned the result.
    let learned_table = QTableFile::load(&q_tables.join("cluster_0.json"))
        .expect("cluster 0")
        .table;
    let planned = core
        .decide(
            "u1",
            "good",
            0,
            &learned_table,
            after.to_state().expect("state"),
            2,
        )
        .expect("plans");
    assert_eq!(d.action, planned.decision.action.index() as u8);
    let success: Vec<f64> = planned.levels.iter().map(|l| l.success).collect();
    assert_eq!(d.belief_success, success);
    println!(
        "over DDS, child belief: u1's first decision planned on a new belief, its result \
         learned into belief_u1.json, and after a restart the next decision planned on it as \
         the in-process core plans; u2's damaged file named, kept aside, u2 new"
    );
}

/// A probe node with a DecideAction client, once the node's server is seen (30 s at most;
/// else the node's log is shown).
async fn probe_with_client(
    probe_params: &Path,
    node_log: &dyn Fn() -> String,
) -> (
    node_shell::NodeShell,
    node_shell::ServiceClient<qt_therapy_msgs::DecideAction>,
) {
    use node_shell::{NoParameters, NodeShell};
    let (mut shell, NoParameters {}) =
        NodeShell::start("behaviour_policy_probe", &probe_options(probe_params))
            .expect("probe node");
    let decide = shell
        .client(qt_therapy_msgs::topics::DECIDE_ACTION)
        .expect("client");
    assert!(
        shell
            .wait_for_service(&decide, Duration::from_secs(30))
            .await,
        "no DecideAction server:\n{}",
        node_log()
    );
    (shell, decide)
}
