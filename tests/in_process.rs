//! The whole suite in one process on a virtual clock (`in_process/suite.rs`): the main job as
//! an ordinary test, the same session file and bag twice for a seed, and the rules that cross
//! nodes: learn, then decide, with a result held on the way; nodes killed and started again
//! mid-session (durable topics delivered again, nothing learned, recorded or played twice);
//! the emergency stop from the therapist's page; a proposal the therapist accepts on the page
//! and one that runs out. The DDS process tests (tests/simulated_session.rs and others) keep
//! what needs the wire.

// Shared with tests/month.rs, which uses parts these tests do not (run directories, stopping
// one node).
#[path = "in_process/suite.rs"]
#[allow(dead_code)]
mod suite;

use bag_file::BagReader;
use qt_therapy_msgs::topics::{
    DECISION, GAME_STATE, SEQUENCE_RESULT, TABLET_ANSWER, THERAPIST_COMMAND,
};
use qt_therapy_msgs::{Decision, GameState, SequenceResult, TherapistCommand};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use suite::{Node, Setup, Suite, virtual_time};
use suite_tests::{SessionBag, whole_session_bag};

/// A directory of this test's own (the policy's decisions name their Q-table file, so two runs
/// compared byte for byte write to the same place); removed by [`done`] when the test passed.
fn out_dir(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("qt_in_process_{name}_{}", std::process::id()))
}

/// A test that passed leaves nothing behind (QT_KEEP_TEST_OUTPUT keeps it).
fn done(out: &Path) {
    if std::env::var_os("QT_KEEP_TEST_OUTPUT").is_none() {
        let _ = std::fs::remove_dir_all(out);
    }
}

/// The files a session leaves, by name: the game manager's session files, the Q-tables.
fn session_files(out: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files = Vec::new();
    for dir in [out.to_path_buf(), out.join("q_tables")] {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in entries.filter_map(Result::ok) {
            let p = e.path();
            if p.is_file() && p.extension().is_some_and(|x| x != "mcap") {
                let name = p.strip_prefix(out).expect("inside").display().to_string();
                files.push((name, std::fs::read(&p).expect("readable")));
            }
        }
    }
    files.sort();
    files
}

/// Every message of a bag: (topic, log time, publish time, sequence, payload).
fn bag_messages(bag: &Path) -> Vec<(String, u64, u64, u32, Vec<u8>)> {
    let reader = BagReader::open(bag).expect("a readable bag");
    assert!(reader.damage().is_none(), "{:?}", reader.damage());
    let topics: std::collections::BTreeMap<u16, String> =
        reader.channels().map(|c| (c.id, c.topic.clone())).collect();
    reader
        .raw_messages()
        .iter()
        .map(|m| {
            (
                topics[&m.channel_id].clone(),
                m.log_time,
                m.publish_time,
                m.sequence,
                m.data.clone(),
            )
        })
        .collect()
}

/// The main job in process: every node, the console's run-session to the session's end, then
/// every node stopped as the launcher stops them; the console's lines.
async fn main_job(out: &Path, setup: Setup) -> Vec<String> {
    let mut suite = Suite::new(out, setup);
    suite.start_all();
    let (code, lines) = suite.run_session(None, false, 1).exit().await;
    assert_eq!(code, 0, "{lines:#?}");
    suite.stop_all().await;
    lines
}

#[test]
fn a_whole_session_in_process_is_the_main_job() {
    let out = out_dir("main_job");
    let started = Instant::now();
    let lines = virtual_time(main_job(&out, Setup::default()));
    let wall = started.elapsed();
    eprintln!(
        "a 10-sequence session in process: {:.3} s of wall time",
        wall.as_secs_f64()
    );
    let context = lines.join("\n");
    assert_eq!(
        lines.iter().filter(|l| l.starts_with("seq ")).count(),
        10,
        "{context}"
    );
    assert!(context.contains("finished: 10 sequences"), "{context}");

    let SessionBag { decisions, .. } = whole_session_bag(&out.join("session.mcap"), &context);
    assert_eq!(decisions.len(), 10, "{context}");
    eprintln!("{context}");
    done(&out);
}

#[test]
fn the_same_seed_gives_the_same_session_files_and_bag() {
    let out = out_dir("same_seed");
    let run = || {
        virtual_time(main_job(&out, Setup::default()));
        let bag = out.join("session.mcap");
        let bytes = std::fs::read(&bag).expect("the bag");
        (session_files(&out), bag_messages(&bag), bytes)
    };
    let (files_a, bag_a, bytes_a) = run();
    let (files_b, bag_b, bytes_b) = run();
    let names: Vec<&str> = files_a.iter().map(|(n, _)| n.as_str()).collect();
    // The session file, its journal and summary, the two Q-tables and the child's belief.
    assert_eq!(names.len(), 6, "{names:?}");
    assert!(
        names.contains(&"q_tables/belief_sim-child-1.json"),
        "{names:?}"
    );
    assert!(names.iter().any(|n| n.ends_with(".jsonl")), "{names:?}");
    for ((name_a, a), (name_b, b)) in files_a.iter().zip(&files_b) {
        assert_eq!(name_a, name_b);
        assert!(
            a == b,
            "{name_a} differs between two runs with the same seed:\n{}\n---\n{}",
            String::from_utf8_lossy(a),
            String::from_utf8_lossy(b)
        );
    }
    assert_eq!(files_a.len(), files_b.len());
    assert!(bag_a.len() > 1000, "{} messages", bag_a.len());
    assert_eq!(bag_a.len(), bag_b.len(), "messages in the two bags");
    for (a, b) in bag_a.iter().zip(&bag_b) {
        assert!(
            a == b,
            "the bags part at {} (log time {}) against {} (log time {})",
            a.0,
            a.1,
            b.0,
            b.1
        );
    }
    // Timestamps are the virtual clock's, so the bag files are the same byte for byte.
    assert!(
        bytes_a == bytes_b,
        "the bag files differ ({} and {} bytes)",
        bytes_a.len(),
        bytes_b.len()
    );
    eprintln!(
        "two runs: {} session files, {} bag messages and the bag file ({} bytes) the same",
        files_a.len(),
        bag_a.len(),
        bytes_a.len()
    );
    done(&out);
}

/// The update count a decision's `model_used` names (`... (path, 7 updates)`).
fn updates(d: &Decision) -> Option<u64> {
    let tail = d.model_used.rsplit_once(", ")?.1;
    tail.strip_suffix(" updates)")?.parse().ok()
}

/// The game manager's session records (the session file's JSON lines).
fn records(out: &Path) -> Vec<serde_json::Value> {
    let jsonl = std::fs::read_dir(out)
        .expect("out dir")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "jsonl"))
        .expect("a session file");
    suite_tests::json_lines(&std::fs::read_to_string(jsonl).expect("readable"))
}

#[test]
fn a_decision_waits_for_the_result_it_follows_when_the_result_is_slow() {
    // Every result reaches the policy 0.6 s after the game manager sent it, while the request
    // for the next decision goes at once: the policy must hold each request until it has
    // learned the result (result_wait_s is 1 s; the game manager waits 2 s for an answer).
    let out = out_dir("learn_first");
    let delay = Duration::from_millis(600);
    let lines = virtual_time(async {
        let mut suite = Suite::new(&out, Setup::default());
        suite
            .bus
            .delay(SEQUENCE_RESULT.name, Node::Policy.name(), delay);
        suite.start_all();
        let (code, lines) = suite.run_session(None, false, 1).exit().await;
        assert_eq!(code, 0, "{lines:#?}");
        suite.stop_all().await;
        lines
    });
    let context = lines.join("\n");
    let reader = BagReader::open(&out.join("session.mcap")).expect("the bag");
    let results = reader
        .messages::<SequenceResult>(SEQUENCE_RESULT.name)
        .expect("results");
    let decisions = reader
        .messages::<Decision>(DECISION.name)
        .expect("decisions");
    let states = reader
        .messages::<GameState>(GAME_STATE.name)
        .expect("states");
    assert_eq!(decisions.len(), 10, "{context}");
    let first = updates(&decisions[0].message).expect("an update count");
    let ns = |d: Duration| d.as_nanos() as u64;
    for d in &decisions[1..] {
        let step = d.message.step;
        let result = results
            .iter()
            .find(|r| r.message.sequence_index == step - 1)
            .expect("the result it follows");
        let reaches_policy = result.publish_time + ns(delay);
        let asked = states
            .iter()
            .find(|s| s.message.phase == GameState::DECIDING && s.message.sequence_index == step)
            .expect("the game manager's request")
            .publish_time;
        assert!(
            asked < reaches_policy,
            "step {step}: asked {asked}, before the result reached the policy at {reaches_policy}"
        );
        assert!(
            d.publish_time >= reaches_policy,
            "step {step} decided at {} before its result reached the policy at {reaches_policy}",
            d.publish_time
        );
        assert_eq!(
            updates(&d.message),
            Some(first + u64::from(step) - 1),
            "step {step} decided by a table that had not learned every earlier result: {}",
            d.message.model_used
        );
    }
    // Each decision went out in time: none of the game manager's fallbacks.
    let records = records(&out);
    assert_eq!(records.len(), 10);
    assert!(
        records.iter().all(|r| r["policy_fallback"] == false),
        "{context}"
    );
    done(&out);
}

#[test]
fn a_result_slower_than_the_wait_is_refused_with_its_reason_and_the_session_goes_on() {
    // 1.5 s is past result_wait_s (1 s): the policy refuses the decision saying why, the game
    // manager plays its fallback with that reason in the session file, and the results are
    // still learned, each once.
    let out = out_dir("learn_first_refused");
    virtual_time(async {
        let mut suite = Suite::new(&out, Setup::default());
        suite.bus.delay(
            SEQUENCE_RESULT.name,
            Node::Policy.name(),
            Duration::from_millis(1500),
        );
        suite.start_all();
        let (code, lines) = suite.run_session(None, false, 1).exit().await;
        assert_eq!(code, 0, "{lines:#?}");
        // The last result is still on its way to the policy.
        tokio::time::sleep(Duration::from_secs(2)).await;
        suite.stop_all().await;
    });
    let records = records(&out);
    assert_eq!(records.len(), 10);
    for r in &records[1..] {
        assert_eq!(r["policy_fallback"], true, "{r}");
        let reason = r["decision_reason"].as_str().unwrap_or_default();
        assert!(
            reason.contains("has not reached the policy within 1.0 s"),
            "sequence {}: {reason}",
            r["result"]["sequence_index"]
        );
    }
    let table: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("q_tables/cluster_0.json")).expect("Q-table"),
    )
    .expect("json");
    assert_eq!(table["updates"], 10, "every result learned once");
    done(&out);
}

/// The game manager's node_loss_timeout_s (params/game_manager.yaml), and the tablet bridge's
/// game_manager_loss_timeout_s (params/tablet_bridge.yaml).
const LOSS_TIMEOUT_S: f64 = 4.0;
/// The launch files' respawn_delay: longer than the loss timeout, so each kill is a loss.
const RESPAWN_DELAY: Duration = Duration::from_secs(5);

#[test]
fn killed_nodes_are_started_again_and_nothing_is_learned_recorded_or_played_twice() {
    // The kill test's session (tests/reliability/kill_session.launch.yaml) in process: six
    // nodes killed mid-session, each started again 5 s later as a new instance. Durable topics
    // hand the new ones what they missed, and what they had already done before is not done
    // again. The DDS kill test (tests/simulated_session.rs) keeps the SIGKILLed processes.
    let out = out_dir("kills");
    let mut setup = Setup::default();
    setup.more.insert(
        Node::GameManager,
        vec![
            "watched_nodes:=[behaviour_policy,engagement_classifier,user_model,tablet_bridge,bag_recorder]"
                .into(),
        ],
    );
    let kills = [
        (Node::Policy, 1),
        (Node::Recorder, 3),
        (Node::GameManager, 4),
        (Node::Classifier, 5),
        (Node::UserModel, 7),
        (Node::Bridge, 8),
    ];
    let (lines, killed_at, page_seen, q_before) = virtual_time(async {
        let mut suite = Suite::new(&out, setup);
        suite.start_all();
        let mut therapist_page = suite.page(tablet_bridge::protocol::Role::Therapist).await;
        therapist_page
            .send(serde_json::json!({"type": "login", "pin": "1234"}))
            .await;
        let therapist = suite.run_session(None, false, 1);
        let clock = suite.bus.clock();
        let mut killed_at = Vec::new();
        let mut page_seen = Vec::new();
        let mut q_before = None;
        for (node, after) in kills {
            therapist
                .wait_for_line(&format!("seq {after:>2}/"), Duration::from_secs(600))
                .await;
            if node == Node::Policy {
                q_before = Some(
                    std::fs::read_to_string(out.join("q_tables/cluster_0.json")).expect("Q-table"),
                );
            }
            suite.kill(node).await;
            killed_at.push((node, clock.now_nanos()));
            if node == Node::GameManager {
                // The therapist's page shows it lost, within the timeout.
                let lost = therapist_page
                    .wait_for(Duration::from_secs(5), |m| {
                        m["status"]
                            .as_str()
                            .is_some_and(|s| s.starts_with("game manager lost"))
                    })
                    .await;
                assert!(
                    lost.is_some(),
                    "the page did not show the game manager lost"
                );
                page_seen.push(clock.now_nanos());
            }
            tokio::time::sleep(RESPAWN_DELAY).await;
            suite.start(node);
            if node == Node::GameManager {
                // Taken over paused; the therapist resumes it from a second console.
                therapist
                    .wait_for_line("  [paused] recovered", Duration::from_secs(30))
                    .await;
                let session = therapist.lines()[0]
                    .split(' ')
                    .nth(1)
                    .expect("the session id")
                    .to_string();
                let (mut bus, _) = suite.join("therapist_resume");
                let mut console = therapist_console::console::Console::new(&mut bus, |_: &str| {})
                    .expect("a console");
                let resume = console.command(qt_therapy_msgs::TherapistCommand::RESUME, &session);
                assert_eq!(console.send(resume).await.expect("answered"), 0);
            }
            if node == Node::Bridge {
                therapist_page = suite.page(tablet_bridge::protocol::Role::Therapist).await;
            }
        }
        let (code, lines) = therapist.exit().await;
        assert_eq!(code, 0, "{}", lines.join("\n"));
        suite.stop_all().await;
        (lines, killed_at, page_seen, q_before.expect("copied"))
    });
    let context = lines.join("\n");
    assert!(context.contains("finished: 10 sequences"), "{context}");
    let killed = |n: Node| killed_at.iter().find(|(k, _)| *k == n).expect("killed").1;

    // One session file: ten records, one per sequence, a finished summary, one recovery.
    let records = records(&out);
    let indices: Vec<u64> = records
        .iter()
        .filter_map(|r| r["result"]["sequence_index"].as_u64())
        .collect();
    assert_eq!(indices, (1..=10).collect::<Vec<u64>>(), "{context}");
    let journal = std::fs::read_dir(&out)
        .expect("out")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "journal"))
        .expect("a journal");
    let journal = std::fs::read_to_string(journal).expect("readable");
    assert_eq!(
        journal.matches(r#""entry":"recovered""#).count(),
        1,
        "{journal}"
    );

    // The bag (the recorder killed and started again in it): each result once, in order;
    // each task once but the one the game manager's kill interrupted.
    let reader = BagReader::open(&out.join("session.mcap")).expect("one readable bag");
    let results: Vec<u8> = reader
        .messages::<SequenceResult>(SEQUENCE_RESULT.name)
        .expect("results")
        .iter()
        .map(|m| m.message.sequence_index)
        .collect();
    assert_eq!(results, (1..=10).collect::<Vec<u8>>(), "{context}");
    let states = reader
        .messages::<GameState>(GAME_STATE.name)
        .expect("states");
    let recovered = states
        .iter()
        .find(|m| {
            m.message
                .status
                .starts_with("recovered after a game manager restart")
        })
        .expect("the game manager took the session over");
    assert_eq!(recovered.message.phase, GameState::PAUSED);
    let interrupted = recovered.message.sequence_index;
    let tasks: Vec<(u8, u32)> = reader
        .messages::<qt_therapy_msgs::TabletTask>(qt_therapy_msgs::topics::TABLET_TASK.name)
        .expect("tasks")
        .iter()
        .map(|m| (m.message.sequence_index, m.message.sequence_id))
        .collect();
    let mut task_indices: Vec<u8> = tasks.iter().map(|t| t.0).collect();
    task_indices.dedup_by(|a, b| a == b && *a == interrupted);
    assert_eq!(
        task_indices,
        (1..=10).collect::<Vec<u8>>(),
        "tasks: {tasks:?}"
    );
    let mut ids: Vec<u32> = tasks.iter().map(|t| t.1).collect();
    ids.dedup();
    assert_eq!(ids.len(), tasks.len(), "a task id sent twice: {tasks:?}");

    // Each watched node's loss: seen at its timeout, the robot silenced then and silent until
    // it was back.
    let robot: Vec<(u64, String)> = [
        qt_therapy_msgs::topics::ROBOT_SPEECH.name,
        qt_therapy_msgs::topics::ROBOT_EMOTION.name,
        qt_therapy_msgs::topics::ROBOT_GESTURE.name,
    ]
    .iter()
    .flat_map(|t| {
        reader
            .messages::<qt_therapy_msgs::std_msgs::StringMsg>(t)
            .expect("robot topic")
    })
    .map(|m| (m.publish_time, m.message.data))
    .collect();
    for node in [
        Node::Policy,
        Node::Classifier,
        Node::UserModel,
        Node::Bridge,
    ] {
        let name = node.name();
        let lost = states
            .iter()
            .find(|m| m.message.status.starts_with(&format!("node lost: {name}")))
            .unwrap_or_else(|| panic!("no GameState names {name} lost: {context}"));
        assert_eq!(lost.message.phase, GameState::PAUSED);
        let back = states
            .iter()
            .find(|m| {
                m.publish_time > lost.publish_time
                    && m.message.status.contains(&format!("{name} is back"))
            })
            .unwrap_or_else(|| panic!("no GameState says {name} is back"));
        let detected_s = (lost.publish_time as i64 - killed(node)) as f64 * 1e-9;
        // Its last heartbeat at most 0.1 s before the kill, then the timeout.
        assert!(
            detected_s > LOSS_TIMEOUT_S - 0.15 && detected_s <= LOSS_TIMEOUT_S + 0.1,
            "{name}: lost {detected_s:.3} s after the kill"
        );
        assert!(
            robot
                .iter()
                .any(|(t, d)| d.is_empty() && t.abs_diff(lost.publish_time) < 500_000_000),
            "{name}: the robot was not silenced at the loss"
        );
        let acted: Vec<&(u64, String)> = robot
            .iter()
            .filter(|(t, d)| *t > lost.publish_time && *t < back.publish_time && !d.is_empty())
            .collect();
        assert!(
            acted.is_empty(),
            "{name}: the robot acted while held: {acted:?}"
        );
        eprintln!(
            "{name}: killed, lost in GameState {detected_s:.3} s later, held {:.1} s",
            (back.publish_time - lost.publish_time) as f64 * 1e-9
        );
    }
    // The game manager's kill: shown lost on the page within the timeout; nothing played from
    // the kill to the therapist's resume.
    let shown_s = (page_seen[0] - killed(Node::GameManager)) as f64 * 1e-9;
    assert!(
        shown_s > LOSS_TIMEOUT_S - 0.15 && shown_s <= LOSS_TIMEOUT_S + 0.1,
        "the page showed the game manager lost {shown_s:.3} s after the kill"
    );
    let resumed = states
        .iter()
        .find(|m| {
            m.publish_time > recovered.publish_time
                && m.message.command_outcome == GameState::COMMAND_CARRIED_OUT
        })
        .expect("the resume carried out");
    let acted: Vec<&(u64, String)> = robot
        .iter()
        .filter(|(t, d)| {
            *t as i64 > killed(Node::GameManager) && *t < resumed.publish_time && !d.is_empty()
        })
        .collect();
    assert!(
        acted.is_empty(),
        "the robot acted before the resume: {acted:?}"
    );
    assert_eq!(
        states
            .iter()
            .filter(|m| m.message.status.starts_with("session started"))
            .count(),
        1,
        "one start"
    );

    // Decisions: at most one per step but the interrupted one, and every sequence the policy
    // set up has its decision in the bag (durable: the recorder started again got those it
    // missed, and wrote none twice).
    let mut decided = [0u32; 11];
    for d in reader
        .messages::<Decision>(DECISION.name)
        .expect("decisions")
    {
        decided[usize::from(d.message.step)] += 1;
    }
    for (step, n) in decided.iter().enumerate().skip(1) {
        let most = if step == usize::from(interrupted) {
            2
        } else {
            1
        };
        assert!(*n <= most, "step {step} decided {n} times: {decided:?}");
    }
    for r in &records {
        if r["policy_fallback"] == false && r["result"]["overridden"] != true {
            let step = r["result"]["sequence_index"].as_u64().expect("index") as usize;
            assert!(
                decided[step] > 0,
                "no decision in the bag for sequence {step}"
            );
        }
    }

    // The policy started again went on from its file: every result learned once.
    let updates = |text: &str| -> u64 {
        let v: serde_json::Value = serde_json::from_str(text).expect("json");
        v["updates"].as_u64().expect("updates")
    };
    let before = updates(&q_before);
    let after = updates(&std::fs::read_to_string(out.join("q_tables/cluster_0.json")).expect("Q"));
    assert!(
        (1..10).contains(&before) && after == 10,
        "Q-table updates: {before} before the kill, {after} of 10 at the end"
    );
    eprintln!(
        "game manager: the page showed it lost {shown_s:.3} s after the kill, recovered at \
         sequence {interrupted}; decisions per step {:?}; Q-table updates {before} before the \
         policy's kill, {after} at the end",
        &decided[1..]
    );
    done(&out);
}

/// The session's summary file.
fn summary(out: &Path) -> serde_json::Value {
    let path = std::fs::read_dir(out)
        .expect("out dir")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| p.to_string_lossy().ends_with(".summary.json"))
        .expect("a summary");
    serde_json::from_str(&std::fs::read_to_string(path).expect("readable")).expect("json")
}

#[test]
fn the_emergency_stop_on_the_therapists_page_silences_the_robot_and_ends_everything() {
    // The therapist taps the emergency stop on their page while the robot says sequence 3:
    // the bridge sends it, the game manager stops the robot mid-sentence (an empty
    // utterance), the child's page closes its task, nothing more is asked of the policy or
    // the robot, the session file says so, and the console following the session ends.
    let out = out_dir("emergency_stop");
    let (lines, pressed_at, child_seen, therapist_seen) = virtual_time(async {
        let mut suite = Suite::new(&out, Setup::default());
        suite.start_all();
        let mut page = suite.page(tablet_bridge::protocol::Role::Therapist).await;
        page.send(serde_json::json!({"type": "login", "pin": "1234"}))
            .await;
        let mut child = suite.page(tablet_bridge::protocol::Role::Child).await;
        let therapist = suite.run_session(None, false, 1);
        therapist
            .wait_for_line("  [saying sequence] sequence 3", Duration::from_secs(600))
            .await;
        let pressed_at = suite.bus.clock().now_nanos();
        page.send(
            serde_json::json!({"type": "command", "pin": "1234", "command": "emergency_stop"}),
        )
        .await;
        let sent = page
            .wait_for(Duration::from_secs(1), |m| m["type"] == "command_sent")
            .await
            .expect("the bridge sent the command");
        assert_eq!(sent["command"], "emergency_stop");
        let (code, lines) = therapist.exit().await;
        assert_eq!(code, 3, "{}", lines.join("\n"));
        // A while later nothing has moved.
        tokio::time::sleep(Duration::from_secs(30)).await;
        suite.stop_all().await;
        child.read();
        page.read();
        (lines, pressed_at, child.seen, page.seen)
    });
    let context = lines.join("\n");
    assert!(
        lines
            .last()
            .is_some_and(|l| l.ends_with("emergency stopped")),
        "{context}"
    );
    let reader = BagReader::open(&out.join("session.mcap")).expect("the bag");
    let commands = reader
        .messages::<qt_therapy_msgs::TherapistCommand>(
            qt_therapy_msgs::topics::THERAPIST_COMMAND.name,
        )
        .expect("commands");
    let stop = commands
        .iter()
        .find(|c| c.message.command == qt_therapy_msgs::TherapistCommand::EMERGENCY_STOP)
        .expect("the emergency stop in the bag");
    assert!(stop.publish_time as i64 >= pressed_at);
    // At once: the same instant on the virtual clock, as nothing stands between the tap and
    // the robot but the bridge and the game manager.
    assert_eq!(
        stop.publish_time as i64, pressed_at,
        "the bridge sent it when tapped"
    );
    let states = reader
        .messages::<GameState>(GAME_STATE.name)
        .expect("states");
    let stopped = states
        .iter()
        .find(|s| s.message.phase == GameState::EMERGENCY_STOPPED)
        .expect("the game manager stopped");
    assert_eq!(
        stopped.publish_time, stop.publish_time,
        "stopped when the command came"
    );
    let speech = reader
        .messages::<qt_therapy_msgs::std_msgs::StringMsg>(
            qt_therapy_msgs::topics::ROBOT_SPEECH.name,
        )
        .expect("speech");
    let silence = speech
        .iter()
        .find(|m| m.publish_time >= stop.publish_time)
        .expect("an utterance after the stop");
    assert_eq!(silence.message.data, "", "the robot cut short");
    assert_eq!(silence.publish_time, stop.publish_time);
    let robot_after: Vec<String> = [
        qt_therapy_msgs::topics::ROBOT_SPEECH.name,
        qt_therapy_msgs::topics::ROBOT_EMOTION.name,
        qt_therapy_msgs::topics::ROBOT_GESTURE.name,
    ]
    .iter()
    .flat_map(|t| {
        reader
            .messages::<qt_therapy_msgs::std_msgs::StringMsg>(t)
            .expect("robot topic")
    })
    .filter(|m| m.publish_time > stop.publish_time && !m.message.data.is_empty())
    .map(|m| m.message.data)
    .collect();
    assert!(
        robot_after.is_empty(),
        "the robot acted after the stop: {robot_after:?}"
    );
    assert!(
        states.iter().all(|s| s.publish_time <= stop.publish_time
            || s.message.phase == GameState::EMERGENCY_STOPPED),
        "the game went on after the stop"
    );
    let tasks_after = reader
        .messages::<qt_therapy_msgs::TabletTask>(qt_therapy_msgs::topics::TABLET_TASK.name)
        .expect("tasks")
        .iter()
        .filter(|t| t.publish_time > stop.publish_time)
        .count();
    assert_eq!(tasks_after, 0);
    let decisions_after = reader
        .messages::<Decision>(DECISION.name)
        .expect("decisions")
        .iter()
        .filter(|d| d.publish_time > stop.publish_time)
        .count();
    assert_eq!(decisions_after, 0, "the policy was asked after the stop");
    // The child's page: its task closed, saying why; the therapist's: the game stopped.
    assert!(
        child_seen.iter().any(|m| m["type"] == "no_task"
            && m["reason"]
                .as_str()
                .is_some_and(|r| r.contains("emergency_stopped"))),
        "{child_seen:#?}"
    );
    assert!(
        therapist_seen
            .iter()
            .any(|m| m["type"] == "game" && m["phase"] == "emergency_stopped")
    );
    let summary = summary(&out);
    assert_eq!(summary["end"], "emergency_stopped", "{summary}");
    assert_eq!(summary["sequences_played"], 2, "{summary}");
    assert_eq!(summary["interrupted_sequence"], 3, "{summary}");
    done(&out);
}

#[test]
fn proposals_are_answered_on_the_therapists_page_or_run_out() {
    // Supervised autonomy with every decision proposed (temperature above 0.1): on the
    // therapist's page the first proposal is accepted, the second replaced by level 1, the
    // third by encouraging feedback; the rest run out and play as proposed. What played is
    // what the therapist chose, and every proposal and its fate are in the bag.
    let out = out_dir("proposals");
    let mut setup = Setup::default();
    setup.more.insert(
        Node::GameManager,
        vec![
            "supervised_autonomy:=true".into(),
            "propose_above_temperature:=0.1".into(),
        ],
    );
    let lines = virtual_time(async {
        let mut suite = Suite::new(&out, setup);
        suite.start_all();
        let mut page = suite.page(tablet_bridge::protocol::Role::Therapist).await;
        page.send(serde_json::json!({"type": "login", "pin": "1234"}))
            .await;
        let therapist = suite.run_session(None, false, 1);
        let answers = [
            serde_json::json!({"command": "accept_proposal"}),
            serde_json::json!({"command": "override_level", "level": 1}),
            serde_json::json!({"command": "override_encouraging"}),
        ];
        for (k, answer) in answers.into_iter().enumerate() {
            let step = k as u64 + 1;
            page.wait_for(Duration::from_secs(120), |m| {
                m["type"] == "proposal" && m["step"] == step && m["open"] == true
            })
            .await
            .unwrap_or_else(|| panic!("no proposal for sequence {step} on the page"));
            // The therapist reads the card for a moment (the countdown is 1 s here).
            tokio::time::sleep(Duration::from_millis(300)).await;
            let mut message = answer;
            message["type"] = "command".into();
            message["pin"] = "1234".into();
            message["proposal"] = step.into();
            page.send(message).await;
        }
        let (code, lines) = therapist.exit().await;
        assert_eq!(code, 0, "{}", lines.join("\n"));
        suite.stop_all().await;
        lines
    });
    let context = lines.join("\n");
    let reader = BagReader::open(&out.join("session.mcap")).expect("the bag");
    let settled: Vec<qt_therapy_msgs::ActionProposal> = reader
        .messages::<qt_therapy_msgs::ActionProposal>(qt_therapy_msgs::topics::ACTION_PROPOSAL.name)
        .expect("proposals")
        .into_iter()
        .map(|m| m.message)
        .filter(|p| p.status != qt_therapy_msgs::ActionProposal::PROPOSED)
        .collect();
    use qt_therapy_msgs::ActionProposal as P;
    let fate: Vec<(u8, u8, u8, u8)> = settled
        .iter()
        .map(|p| (p.step, p.status, p.played_level, p.played_feedback))
        .collect();
    assert_eq!(
        fate.len(),
        10,
        "each proposal settled once: {fate:?}\n{context}"
    );
    assert_eq!(fate[0].1, P::ACCEPTED, "{fate:?}");
    assert_eq!((fate[1].1, fate[1].2), (P::REPLACED, 1), "{fate:?}");
    assert_eq!(
        (fate[2].1, fate[2].3),
        (P::REPLACED, 1),
        "encouraging: {fate:?}"
    );
    assert!(fate[3..].iter().all(|f| f.1 == P::TIMED_OUT), "{fate:?}");
    assert!(
        settled[..3]
            .iter()
            .all(|p| p.command_id > 0 && (p.response_time - 0.3).abs() < 1e-3),
        "answered by the page's commands after 0.3 s: {settled:?}"
    );
    // What played: the records say so, sequence by sequence.
    let records = records(&out);
    let played: Vec<(u64, u64)> = records
        .iter()
        .map(|r| {
            (
                r["result"]["level"].as_u64().expect("level"),
                r["result"]["feedback"].as_u64().expect("feedback"),
            )
        })
        .collect();
    assert_eq!(played[1].0, 1, "the therapist's level: {played:?}");
    assert_eq!(played[2].1, 1, "the therapist's encouragement: {played:?}");
    for (p, (level, feedback)) in settled.iter().zip(&played) {
        assert_eq!(
            (u64::from(p.played_level), u64::from(p.played_feedback)),
            (*level, *feedback),
            "sequence {} played other than its proposal says",
            p.step
        );
    }
    // The user models' σ is in every proposal (the game manager reads the shipped models).
    assert!(
        settled.iter().all(|p| p.success_std >= 0.0),
        "a proposal without the user model's σ: {settled:?}"
    );
    let reasons: Vec<&str> = records
        .iter()
        .map(|r| r["decision_reason"].as_str().unwrap_or_default())
        .collect();
    assert!(reasons[0].contains("accepted after 0.3 s"), "{reasons:#?}");
    assert!(
        reasons[3].contains("ran out after 1.0 s: played"),
        "{reasons:#?}"
    );
    let summary = summary(&out);
    assert_eq!(
        (
            summary["proposals"].as_u64(),
            summary["proposals_accepted"].as_u64(),
            summary["proposals_replaced"].as_u64(),
            summary["proposals_timed_out"].as_u64()
        ),
        (Some(10), Some(1), Some(2), Some(7)),
        "{summary}"
    );
    // The console following the session said each proposal and its fate.
    assert!(
        context.contains("proposal for seq 1 accepted after 0.3 s"),
        "{context}"
    );
    assert!(
        context.contains("proposal for seq 2 replaced by L1"),
        "{context}"
    );
    assert!(context.contains("proposal for seq 4 ran out"), "{context}");
    done(&out);
}

#[test]
fn what_arrives_twice_is_taken_once() {
    // An answer delivered twice (the child page's, then the same message again, as a
    // publisher sending it anew): the first is scored, the repeat refused as a duplicate. A
    // command delivered twice with its id (a console sending again): carried out once, the
    // repeat answered as already carried out.
    let out = out_dir("twice");
    let (lines, page_answer, mut answers) = virtual_time(async {
        let mut suite = Suite::new(&out, Setup::default());
        suite.start_all();
        let (mut probe, _) = suite.join("twice");
        let answers_seen =
            node_shell::Bus::subscribe(&mut probe, TABLET_ANSWER, 16).expect("answers");
        let answer_again =
            node_shell::Bus::publisher(&mut probe, TABLET_ANSWER).expect("a publisher");
        let commands =
            node_shell::Bus::publisher(&mut probe, THERAPIST_COMMAND).expect("a publisher");
        let mut states = node_shell::Bus::subscribe(&mut probe, GAME_STATE, 1024).expect("states");
        let mut results_seen =
            node_shell::Bus::subscribe(&mut probe, SEQUENCE_RESULT, 16).expect("results");
        let result_again =
            node_shell::Bus::publisher(&mut probe, SEQUENCE_RESULT).expect("a publisher");
        let mut answers_seen = answers_seen;
        let mut child = suite.page(tablet_bridge::protocol::Role::Child).await;
        let therapist = suite.run_session(None, false, 1);
        let task = child
            .wait_for(Duration::from_secs(120), |m| m["type"] == "task")
            .await
            .expect("the first task on the child page");
        // A wrong answer at once, before the simulated child's (seconds later).
        let length = task["length"].as_u64().expect("length") as usize;
        let page_answer = vec!["happy".to_string(); length];
        child
            .send(
                serde_json::json!({"type": "answer", "sequence_id": task["sequence_id"],
                "answer": page_answer, "response_time": 0.5}),
            )
            .await;
        let sent = answers_seen
            .recv()
            .await
            .expect("the page's answer on the bus");
        tokio::time::sleep(Duration::from_millis(100)).await;
        answer_again.send(sent);
        // The same PAUSE twice, then the same RESUME twice, as a console sending again.
        therapist
            .wait_for_line("seq  2/", Duration::from_secs(600))
            .await;
        let session = therapist.lines()[0]
            .split(' ')
            .nth(1)
            .expect("id")
            .to_string();
        // The first result delivered again, as a durable topic's history is to a reader that
        // matches its writer once more: the console, the recorder and every reader of the
        // bag take it once (session_log, docs/session_log.md).
        let first_result = results_seen.recv().await.expect("the first result");
        assert_eq!(first_result.sequence_index, 1);
        result_again.send(first_result);
        tokio::time::sleep(Duration::from_millis(100)).await;
        while states.try_recv().is_ok() {}
        let clock = suite.bus.clock();
        let mut ids = Vec::new();
        for kind in [TherapistCommand::PAUSE, TherapistCommand::RESUME] {
            let c = TherapistCommand {
                header: clock.header_now(),
                command: kind,
                session_id: session.clone(),
                command_id: (clock.now_nanos() / 1_000_000) as u64,
                ..Default::default()
            };
            ids.push(c.command_id);
            for _ in 0..2 {
                commands.send(c.clone());
                tokio::time::sleep(Duration::from_millis(200)).await;
            }
        }
        let mut answers = Vec::new();
        while let Ok(s) = states.try_recv() {
            if ids.contains(&s.command_id) {
                answers.push((s.command_id - ids[0], s.command_outcome));
            }
        }
        let (code, lines) = therapist.exit().await;
        assert_eq!(code, 0, "{}", lines.join("\n"));
        suite.stop_all().await;
        (lines, page_answer, answers)
    });
    let context = lines.join("\n");
    // The console said and counted the result delivered again once.
    assert_eq!(
        lines.iter().filter(|l| l.starts_with("seq ")).count(),
        10,
        "{context}"
    );
    assert!(context.contains("finished: 10 sequences"), "{context}");
    // The bag holds it twice (the recorder writes what it is sent); each reader takes it once.
    let bag = out.join("session.mcap");
    let reader = BagReader::open(&bag).expect("the recorder's bag");
    assert_eq!(
        reader
            .messages::<SequenceResult>(SEQUENCE_RESULT.name)
            .expect("results")
            .len(),
        11
    );
    let log = session_log::SessionLog::read(&reader).expect("no conflict");
    assert_eq!((log.messages.results.len(), log.repeats.len()), (10, 1));
    let report = session_report::SessionLog::from_bag(&reader, None).expect("the report's log");
    assert_eq!(
        report.summary().expect("a summary").tally.sequences,
        10,
        "the report's count"
    );
    let fitted = user_models::data::bag::read_bag(&bag).expect("the user models' records");
    assert_eq!(fitted.records.len(), 10, "{:?}", fitted.warnings);
    assert!(
        fitted
            .warnings
            .iter()
            .any(|w| w.contains("delivered again")),
        "{:?}",
        fitted.warnings
    );
    let evaluated = policy_lab::off_policy::recorded::logged_sessions(&log.messages);
    assert_eq!(
        evaluated.seen(),
        1,
        "one session for the policy's evaluation"
    );
    let records = records(&out);
    assert_eq!(records.len(), 10, "{context}");
    let first = &records[0]["result"];
    assert_eq!(
        first["answer"],
        serde_json::json!(page_answer),
        "the first answer is the one scored: {first}"
    );
    assert_eq!(first["outcome"], -1);
    let summary = summary(&out);
    assert_eq!(
        summary["rejected_answers"], 1,
        "the repeat refused: {summary}"
    );
    // The two repeats, counted where the summary counts commands not carried out.
    assert_eq!(summary["rejected_commands"], 2, "{summary}");
    answers.dedup();
    assert_eq!(
        answers,
        [
            (0, GameState::COMMAND_CARRIED_OUT),
            (0, GameState::COMMAND_ALREADY_CARRIED_OUT),
            (400, GameState::COMMAND_CARRIED_OUT),
            (400, GameState::COMMAND_ALREADY_CARRIED_OUT),
        ]
    );
    let journal = std::fs::read_dir(&out)
        .expect("out")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "journal"))
        .expect("a journal");
    let journal = std::fs::read_to_string(journal).expect("readable");
    assert_eq!(
        journal.matches(r#""command":"pause""#).count() + journal.matches(r#""command":2"#).count(),
        1,
        "{journal}"
    );
    done(&out);
}

/// What a sequence was, apart from when: the state, the policy's action, the robot's words,
/// the child's answer, its outcome and score, and whether the game manager set it up itself
/// (the session file's `policy_fallback`). Not its engagement, which follows how the frames
/// fell on the clock (the answer's time is compared apart, unscaled).
#[derive(Debug, PartialEq)]
struct Played {
    index: u8,
    state: (u8, u8, i8),
    action: u8,
    level: u8,
    feedback: u8,
    policy_fallback: Option<bool>,
    sequence: Vec<String>,
    answer: Vec<String>,
    outcome: i8,
    timed_out: bool,
    score: f32,
}

/// The main job in process with seed 7 at `time_scale`: each sequence as played, each answer's
/// time as the tablet reported it divided by the time scale, and each result's engagement.
fn played_at(time_scale: f64) -> (Vec<Played>, Vec<f64>, Vec<f32>) {
    let out = out_dir(&format!("time_scale_{time_scale}"));
    // The policy on its table alone: a plan on the child's belief weighs each sequence's
    // engagement, which differs between time scales by design (below), so it may choose
    // otherwise; with the belief, the same seed at the same time scale gives the same bag
    // (`the_same_seed_gives_the_same_session_files_and_bag`).
    let setup = Setup {
        time_scale,
        more: std::collections::BTreeMap::from([(
            Node::Policy,
            vec!["child_belief:=false".to_string()],
        )]),
        ..Setup::default()
    };
    // One session id for both (the game manager and the child key their draws by it).
    virtual_time(async {
        let mut suite = Suite::new(&out, setup);
        suite.start_all();
        let (code, lines) = suite
            .run_session(Some("main-job-seed-7"), false, 1)
            .exit()
            .await;
        assert_eq!(code, 0, "{lines:#?}");
        suite.stop_all().await;
    });
    let records = records(&out);
    let fallback = |index: u8| {
        records
            .iter()
            .find(|r| r["result"]["sequence_index"] == u64::from(index))
            .and_then(|r| r["policy_fallback"].as_bool())
    };
    let results: Vec<SequenceResult> = BagReader::open(&out.join("session.mcap"))
        .expect("the bag")
        .messages::<SequenceResult>(SEQUENCE_RESULT.name)
        .expect("results")
        .into_iter()
        .map(|m| m.message)
        .collect();
    done(&out);
    let unscaled = results
        .iter()
        .map(|r| f64::from(r.response_time) / time_scale)
        .collect();
    let engagement = results.iter().map(|r| r.engagement).collect();
    let played = results
        .into_iter()
        .map(|r| Played {
            index: r.sequence_index,
            state: (r.state.level, r.state.feedback, r.state.previous_score),
            action: r.action,
            level: r.level,
            feedback: r.feedback,
            policy_fallback: fallback(r.sequence_index),
            sequence: r.sequence,
            answer: r.answer,
            outcome: r.outcome,
            timed_out: r.timed_out,
            score: r.activity_result,
        })
        .collect();
    (played, unscaled, engagement)
}

#[test]
fn the_same_seed_plays_the_same_session_at_any_time_scale() {
    // The main job at time_scale 0.05 and at 0.02: every frame, answer and robot step falls
    // elsewhere on the clock, and the same seed must play the same session: the same states,
    // actions, words, answers, outcomes and scores, every sequence in the session file; the
    // child's answer times drawn at 1x and scaled. The engagement differs (other frames,
    // averaged over other seconds) and is only printed.
    let (base, base_times, base_engagement) = played_at(0.05);
    let (fast, fast_times, fast_engagement) = played_at(0.02);
    for (scale, run) in [(0.05, &base), (0.02, &fast)] {
        assert!(
            run.len() == 10 && run.iter().all(|p| p.policy_fallback.is_some()),
            "time_scale {scale}: {} sequences ({} in the session file)",
            run.len(),
            run.iter().filter(|p| p.policy_fallback.is_some()).count()
        );
    }
    assert_eq!(
        base, fast,
        "time_scale 0.05 (left) and 0.02 (right) played different sessions"
    );
    let times = base_times.iter().zip(&fast_times);
    assert!(
        times.clone().all(|(a, b)| (a - b).abs() < 1e-3),
        "answer times (s, unscaled) at 0.05 and 0.02: {:?}",
        times.collect::<Vec<_>>()
    );
    for (i, p) in base.iter().enumerate() {
        eprintln!(
            "seq {:2}: L{} F{} {} score {:+}, answer time {:5.2} s unscaled | E {:+.2} at 0.05, \
             {:+.2} at 0.02",
            p.index,
            p.level,
            p.feedback,
            if p.outcome > 0 { "right" } else { "wrong" },
            p.score,
            base_times[i],
            base_engagement[i],
            fast_engagement.get(i).copied().unwrap_or(f32::NAN),
        );
    }
}
