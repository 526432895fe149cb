//! The main job as a test: every node of the suite as its own process over DDS in one loopback
//! namespace, a simulated child, the recorder; the session must run its 10 sequences, the bag
//! must hold them in order with their decisions and per-second engagement, and the report must
//! be written. Then the same session with six nodes killed (SIGKILL) and respawned mid-session:
//! each loss seen within the timeout, the robot silent while held, the session resumed and
//! whole, the policy's Q-table carried over; the game manager's own respawn takes the session
//! over from its files and goes on at the therapist's resume, nothing played or done twice.
//! And five sessions back to back (the soak's short version): every reliable message counted,
//! nothing lost, duplicated or growing. (The same seed at two time scales is played in process:
//! tests/in_process.rs.)

use qt_therapy_msgs::std_msgs::StringMsg;
use qt_therapy_msgs::topics::{
    DECISION, GAME_STATE, ROBOT_EMOTION, ROBOT_GESTURE, ROBOT_SPEECH, SEQUENCE_RESULT, TABLET_TASK,
    THERAPIST_COMMAND,
};
use qt_therapy_msgs::{Decision, GameState, SequenceResult, TabletTask, TherapistCommand};
use std::path::Path;
use std::sync::Mutex;
use std::time::{Duration, Instant};
use suite_tests::{SessionBag, run_in_loopback_netns, whole_session_bag, workspace_bin};

/// One whole suite at a time: two on a small machine could starve heartbeats.
static SUITE: Mutex<()> = Mutex::new(());

#[test]
fn a_whole_simulated_session_over_dds() {
    let _one = SUITE.lock().unwrap_or_else(|e| e.into_inner());
    let Some(job) = run_main_job(0.05, "simulated_session") else {
        return;
    };
    let (out, launch_stdout) = (&job.out, &job.launch_stdout);
    let read = |f: &str| std::fs::read_to_string(out.join(f)).unwrap_or_default();
    let tail = |text: String| {
        let lines: Vec<&str> = text.lines().collect();
        lines[lines.len().saturating_sub(40)..].join("\n")
    };
    let context = format!(
        "{launch_stdout}\nstdout:\n{}\nstderr (tail):\n{}\ngame manager log (tail):\n{}",
        read("stdout.log"),
        tail(read("stderr.log")),
        tail(read("logs/game_manager.log")),
    );
    assert!(launch_stdout.contains("launch_exit=0"), "{context}");
    let stdout = read("stdout.log");
    assert_eq!(
        stdout
            .lines()
            .filter(|l| l.starts_with("[therapist] seq "))
            .count(),
        10,
        "{context}"
    );
    assert!(stdout.contains("finished: 10 sequences"), "{context}");
    // The terminal shows each sequence once, with no colour codes, and no node's log records:
    // those are in the nodes' log files.
    assert!(!stdout.contains('\u{1b}'), "{context}");
    assert!(!stdout.contains("[game_manager]"), "{context}");
    let gm_log = read("logs/game_manager.log");
    assert_eq!(
        gm_log.lines().filter(|l| l.contains(": seq ")).count(),
        10,
        "the game manager logs each sequence once: {context}"
    );
    assert!(!gm_log.contains('\u{1b}'), "no colour in a log file");

    // The simulated child answered and its face was seen by the classifier.
    let SessionBag {
        results, decisions, ..
    } = whole_session_bag(&out.join("session.mcap"), &context);
    let session = &results[0].session_id;
    assert!(
        results
            .iter()
            .filter(|r| !r.engagement_per_second.is_empty())
            .count()
            >= 8,
        "{context}"
    );
    // Every sequence but fallbacks was set up by a decision of the policy.
    assert!(
        decisions
            .iter()
            .filter(|d| &d.session_id == session)
            .count()
            >= 9,
        "{context}"
    );
    // Algorithm 1's order: each decision was made by a table that had learned every earlier
    // result of the session (its update count, in model_used, one more per step). The main
    // job's bag once showed decisions 5-8 made before the result before them was learned.
    let updates = |d: &Decision| -> Option<u64> {
        let tail = d.model_used.rsplit_once(", ")?.1;
        tail.strip_suffix(" updates)")?.parse().ok()
    };
    let ours: Vec<&Decision> = decisions
        .iter()
        .filter(|d| &d.session_id == session)
        .collect();
    let first = ours
        .iter()
        .find(|d| d.step == 1)
        .and_then(|d| updates(d))
        .expect("step 1's decision names its update count");
    for d in &ours {
        assert_eq!(
            updates(d),
            Some(first + u64::from(d.step) - 1),
            "step {} decided by a table with {:?} updates (step 1: {first}): {context}",
            d.step,
            d.model_used
        );
    }

    // The report the main job writes next to the bag.
    let report = std::process::Command::new(workspace_bin("session_report"))
        .arg(out.join("session.mcap"))
        .output()
        .expect("session_report runs");
    assert!(
        report.status.success(),
        "{}",
        String::from_utf8_lossy(&report.stderr)
    );
    let html = read("report.html");
    assert_eq!(
        html.matches("<svg").count(),
        2,
        "level and engagement figures"
    );
    assert_eq!(
        html.matches("<tr").count(),
        11,
        "a header and a row per sequence"
    );
    let _ = std::fs::remove_dir_all(out);
}

/// One run of the main job's launch file (seed 7, cluster 0) in a loopback namespace: its
/// output directory and what the script printed.
struct MainJobRun {
    out: std::path::PathBuf,
    launch_stdout: String,
}

/// None where namespaces cannot be made.
fn run_main_job(time_scale: f64, dir: &str) -> Option<MainJobRun> {
    let launch = workspace_bin("launch");
    let bin = launch.parent().expect("target dir").display().to_string();
    let out = std::env::temp_dir().join(format!("{dir}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(&out).expect("out dir");
    let o = out.display();
    let script = format!(
        "{} launch_scripts/simulated_session.launch.yaml --log-dir {o}/logs bin:={bin} out:={o} time_scale:={time_scale} cluster:=0 > {o}/stdout.log 2> {o}/stderr.log; echo \"launch_exit=$?\"",
        launch.display()
    );
    let result = run_in_loopback_netns(&script, Duration::from_secs(240))?;
    Some(MainJobRun {
        out,
        launch_stdout: String::from_utf8_lossy(&result.stdout).to_string(),
    })
}

/// The soak's short version (bench/soak/soak.sh runs the long one): five sessions back to
/// back on one running suite; every reliable message of the bag counted by its publisher's
/// sequence number (none lost or duplicated), every session complete (10 results, tasks,
/// answers, decisions, its start acknowledged once, its session file), the policy learned
/// from all 50 results, and no node's open files or memory grew.
#[test]
fn sessions_back_to_back_lose_nothing() {
    let _one = SUITE.lock().unwrap_or_else(|e| e.into_inner());
    let soak = workspace_bin("soak");
    let out = std::env::temp_dir().join(format!("soak_{}", std::process::id()));
    let script = format!(
        "{} --sessions 5 --sample-every 1 --max-rss-growth-pct 25 --out {}; echo \"soak_exit=$?\"",
        soak.display(),
        out.display()
    );
    let Some(result) = run_in_loopback_netns(&script, Duration::from_secs(150)) else {
        return;
    };
    let stdout = String::from_utf8_lossy(&result.stdout).to_string();
    let context = format!(
        "{stdout}\nstderr:\n{}",
        String::from_utf8_lossy(&result.stderr)
    );
    assert!(stdout.contains("soak_exit=0"), "{context}");
    assert!(
        stdout.contains("VERDICT: PASS (5 of 5 sessions finished"),
        "{context}"
    );
    assert_eq!(
        stdout
            .lines()
            .filter(|l| l.starts_with("[soak] session ") && l.contains(" ok "))
            .count(),
        5,
        "{context}"
    );
    // Every row of the count: nothing lost, nothing duplicated.
    let all = stdout
        .lines()
        .find(|l| l.trim_start().starts_with("all "))
        .unwrap_or_else(|| panic!("no total row: {context}"));
    let numbers: Vec<u64> = all
        .split_whitespace()
        .skip(1)
        .filter_map(|n| n.parse().ok())
        .collect();
    assert!(
        numbers.len() == 3 && numbers[0] > 2000 && numbers[1] == 0 && numbers[2] == 0,
        "{all}"
    );
    assert!(
        stdout.contains("policy Q-table updates during the soak: 50 (sequence results: 50)"),
        "{context}"
    );
    let _ = std::fs::remove_dir_all(&out);
}

/// The game manager's node_loss_timeout_s (params/game_manager.yaml), and the tablet bridge's
/// game_manager_loss_timeout_s (params/tablet_bridge.yaml).
const LOSS_TIMEOUT_S: f64 = 4.0;

/// Kills the game manager with SIGKILL once the console printed sequence `after`'s line; the
/// tablet bridge must show it lost; the launcher respawns it 5 s later and it takes the session
/// over, paused; then the therapist resumes it from a second console, as on the tablet.
fn kill_game_manager_step(after: u8, bin: &str) -> String {
    format!(
        r#"wait_for '^\[therapist\] seq +{after}[/ ]' || fail
pid=$(grep -oE "(started|restarted) game_manager \(pid [0-9]+\)" "$o/stderr.log" | tail -1 | grep -oE '[0-9]+')
[ -n "$pid" ] || {{ echo "no pid for game_manager"; fail; }}
echo "killed game_manager pid $pid at $EPOCHREALTIME"
kill -KILL "$pid"
wait_for 'game manager lost' "$o/stderr.log" && echo "bridge showed game_manager lost at $EPOCHREALTIME"
wait_for 'recovered after a game manager restart' || fail
session=$(grep -oE '^\[therapist\] session [^ ]+ started' "$o/stdout.log" | head -1 | cut -d' ' -f3)
ROS_LOCALHOST_ONLY=1 QT_PARAMS_DIR=params {bin}/therapist resume --session "$session" > "$o/resume.log" 2>&1 || {{ cat "$o/resume.log"; fail; }}
echo "resumed session $session at $EPOCHREALTIME"
"#
    )
}

/// Kills `node` with SIGKILL once the console printed sequence `after`'s line, then waits
/// until the game manager says it is back (the launcher respawns it 5 s later).
fn kill_step(node: &str, after: u8) -> String {
    format!(
        r#"wait_for '^\[therapist\] seq +{after}[/ ]' || fail
pid=$(grep -oE "(started|restarted) {node} \(pid [0-9]+\)" "$o/stderr.log" | tail -1 | grep -oE '[0-9]+')
[ -n "$pid" ] || {{ echo "no pid for {node}"; fail; }}
cp "$o/q_tables/cluster_0.json" "$o/q_table_before_{node}.json" 2>/dev/null
echo "killed {node} pid $pid at $EPOCHREALTIME"
kill -KILL "$pid"
wait_for 'node lost: {node}' && echo "console showed {node} lost at $EPOCHREALTIME"
wait_for '{node} is back' || fail
"#
    )
}

#[test]
fn a_session_survives_sigkilled_nodes() {
    let _one = SUITE.lock().unwrap_or_else(|e| e.into_inner());
    let launch = workspace_bin("launch");
    let bin = launch.parent().expect("target dir").display().to_string();
    let out = std::env::temp_dir().join(format!("kill_session_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(&out).expect("out dir");
    let o = out.display();
    // (node, killed after the console printed this sequence)
    let kills = [
        ("behaviour_policy", 1),
        ("bag_recorder", 3),
        ("game_manager", 4),
        ("engagement_classifier", 5),
        ("user_model", 7),
        ("tablet_bridge", 8),
    ];
    let steps: String = kills
        .iter()
        .map(|(n, a)| match *n {
            "game_manager" => kill_game_manager_step(*a, &bin),
            _ => kill_step(n, *a),
        })
        .collect();
    let script = format!(
        r#"o={o}
wait_for() {{ for _ in $(seq 1 1200); do grep -qE -- "$1" "${{2:-$o/stdout.log}}" && return 0; sleep 0.05; done; echo "no line matching $1 within 60 s"; return 1; }}
{} tests/reliability/kill_session.launch.yaml bin:={bin} out:=$o time_scale:=0.1 > $o/stdout.log 2> $o/stderr.log &
launch=$!
fail() {{ kill -INT $launch; wait $launch; echo "launch_exit=failed"; exit 1; }}
{steps}
wait $launch
echo "launch_exit=$?"
"#,
        launch.display()
    );
    let started = Instant::now();
    let Some(result) = run_in_loopback_netns(&script, Duration::from_secs(170)) else {
        return;
    };
    let wall = started.elapsed();
    let read = |f: &str| std::fs::read_to_string(out.join(f)).unwrap_or_default();
    let script_out = String::from_utf8_lossy(&result.stdout).to_string();
    let context = format!(
        "{script_out}\nstdout:\n{}\nstderr (tail):\n{}",
        read("stdout.log"),
        {
            let e = read("stderr.log");
            let lines: Vec<&str> = e.lines().collect();
            lines[lines.len().saturating_sub(60)..].join("\n")
        }
    );
    assert!(script_out.contains("launch_exit=0"), "{context}");
    let stdout = read("stdout.log");
    assert!(stdout.contains("finished: 10 sequences"), "{context}");

    // The session files: one session (the respawned game manager went on in its files), ten
    // records, one per sequence, and a finished summary.
    let jsonls: Vec<std::path::PathBuf> = std::fs::read_dir(&out)
        .expect("out dir")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "jsonl"))
        .collect();
    assert_eq!(jsonls.len(), 1, "one session file: {jsonls:?}\n{context}");
    let jsonl = jsonls[0].clone();
    let session_id = script_out
        .lines()
        .find_map(|l| l.strip_prefix("resumed session "))
        .and_then(|r| r.split(" at ").next())
        .unwrap_or_else(|| panic!("no resume: {context}"))
        .to_string();
    assert_eq!(
        jsonl.file_stem().and_then(|s| s.to_str()),
        Some(session_id.as_str())
    );
    let journal = std::fs::read_to_string(jsonl.with_extension("journal")).expect("journal");
    assert_eq!(
        journal.matches(r#""entry":"recovered""#).count(),
        1,
        "{journal}"
    );
    let records = suite_tests::json_lines(&std::fs::read_to_string(&jsonl).expect("read"));
    let indices: Vec<u64> = records
        .iter()
        .filter_map(|r| r["result"]["sequence_index"].as_u64())
        .collect();
    assert_eq!(indices, (1..=10).collect::<Vec<u64>>(), "{context}");
    let summary: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(jsonl.with_extension("summary.json")).expect("summary"),
    )
    .expect("summary json");
    assert_eq!(summary["end"], "finished", "{summary}");

    // The bag: every result and every task once, in order.
    let reader = bag_file::BagReader::open(&out.join("session.mcap")).expect("a readable bag");
    let results: Vec<u8> = reader
        .messages::<SequenceResult>(SEQUENCE_RESULT.name)
        .expect("results")
        .iter()
        .map(|m| m.message.sequence_index)
        .collect();
    assert_eq!(results, (1..=10).collect::<Vec<u8>>(), "{context}");
    let states = reader
        .messages::<GameState>(GAME_STATE.name)
        .expect("game states");
    // The sequence the game manager's kill interrupted: the respawn took the session over
    // there, after every result published before the kill.
    let killed_at = |node: &str| -> f64 {
        script_out
            .lines()
            .find_map(|l| {
                l.strip_prefix(&format!("killed {node} pid "))
                    .and_then(|r| r.split(" at ").nth(1))
                    .and_then(|t| t.trim().parse().ok())
            })
            .unwrap_or_else(|| panic!("no kill time for {node}: {context}"))
    };
    let gm_killed_at = killed_at("game_manager");
    let recovered = states
        .iter()
        .find(|m| {
            m.message
                .status
                .starts_with("recovered after a game manager restart")
        })
        .unwrap_or_else(|| panic!("no recovered GameState: {context}"));
    let interrupted = recovered.message.sequence_index;
    let results_before_kill = reader
        .messages::<SequenceResult>(SEQUENCE_RESULT.name)
        .expect("results")
        .iter()
        .filter(|m| m.message.header.stamp.as_secs_f64() < gm_killed_at)
        .count();
    assert_eq!(
        usize::from(interrupted),
        results_before_kill + 1,
        "{context}"
    );
    let tasks: Vec<(u8, u32)> = reader
        .messages::<TabletTask>(TABLET_TASK.name)
        .expect("tasks")
        .iter()
        .map(|m| (m.message.sequence_index, m.message.sequence_id))
        .collect();
    // Each task once, task ids never reused. If the kill came after the interrupted
    // sequence's task went out, that sequence is played again from its start after the resume,
    // with a new task id: its index (only its) may appear twice.
    let mut indices: Vec<u8> = tasks.iter().map(|t| t.0).collect();
    let mut ids: Vec<u32> = tasks.iter().map(|t| t.1).collect();
    indices.dedup_by(|a, b| a == b && *a == interrupted);
    ids.dedup();
    assert_eq!(indices, (1..=10).collect::<Vec<u8>>(), "tasks: {tasks:?}");
    assert_eq!(ids.len(), tasks.len(), "a task id sent twice: {tasks:?}");

    // Privacy: the bag holds the suite's features and events, never an image or a sound
    // (ROS4HRI's lists of persons are ids only; a person's topics say it is anonymous and its
    // engagement level; `--all` records the graph's /rosout and /parameter_events too).
    let types: std::collections::BTreeSet<String> = reader
        .channels()
        .map(|c| c.type_name().to_string())
        .collect();
    assert!(
        types.iter().all(|t| t.starts_with("qt_therapy_msgs/")
            || [
                "std_msgs/msg/String",
                "std_msgs/msg/Bool",
                "rcl_interfaces/msg/Log",
                "rcl_interfaces/msg/ParameterEvent",
                "hri_msgs/msg/IdsList",
                "hri_msgs/msg/EngagementLevel"
            ]
            .contains(&t.as_str())),
        "unexpected types in the bag: {types:?}"
    );
    eprintln!("bag channel types: {types:?}");

    // Each kill: seen within the timeout, the robot silent while held, then resumed.
    let robot: Vec<(u64, String)> = [ROBOT_SPEECH.name, ROBOT_EMOTION.name, ROBOT_GESTURE.name]
        .iter()
        .flat_map(|t| reader.messages::<StringMsg>(t).expect("robot topic"))
        .map(|m| (m.log_time, m.message.data))
        .collect();
    let speech: Vec<(u64, String)> = reader
        .messages::<StringMsg>(ROBOT_SPEECH.name)
        .expect("robot speech")
        .into_iter()
        .map(|m| (m.log_time, m.message.data))
        .collect();
    // The recorder cannot record its own loss; the console printed it, and its respawn carried
    // the dead one's file over (the results and tasks above are each in the one bag once).
    let console = read("stdout.log");
    assert!(
        console.contains("node lost: bag_recorder") && console.contains("bag_recorder is back"),
        "{context}"
    );
    // Its detection, as the console showed it (the script polls every 50 ms).
    let recorder_lost_s = script_out
        .lines()
        .find_map(|l| l.strip_prefix("console showed bag_recorder lost at "))
        .and_then(|t| t.trim().parse::<f64>().ok())
        .unwrap_or_else(|| panic!("the console did not show the recorder lost: {context}"))
        - killed_at("bag_recorder");
    assert!(
        recorder_lost_s > LOSS_TIMEOUT_S - 0.3 && recorder_lost_s <= LOSS_TIMEOUT_S + 1.0,
        "the console showed the recorder lost {recorder_lost_s:.3} s after the kill"
    );
    eprintln!("bag_recorder: SIGKILL -> the console showed it lost {recorder_lost_s:.3} s");
    for (node, _) in kills
        .iter()
        .filter(|(n, _)| !["bag_recorder", "game_manager"].contains(n))
    {
        let killed_at = killed_at(node);
        let lost = states
            .iter()
            .find(|m| m.message.status.starts_with(&format!("node lost: {node}")))
            .unwrap_or_else(|| panic!("no GameState names {node} lost: {context}"));
        assert_eq!(lost.message.phase, GameState::PAUSED);
        let back = states
            .iter()
            .find(|m| {
                m.log_time > lost.log_time && m.message.status.contains(&format!("{node} is back"))
            })
            .unwrap_or_else(|| panic!("no GameState says {node} is back: {context}"));
        let detected_s = lost.message.header.stamp.as_secs_f64() - killed_at;
        let shown_s = lost.log_time as f64 * 1e-9 - killed_at;
        let held_s = (back.log_time - lost.log_time) as f64 * 1e-9;
        // Detection is due at the last heartbeat (at most 0.1 s before the kill) + timeout;
        // the game manager's timer and a loaded machine may add a little.
        assert!(
            detected_s > LOSS_TIMEOUT_S - 0.3 && detected_s <= LOSS_TIMEOUT_S + 0.5,
            "{node}: detected {detected_s:.3} s after the kill"
        );
        // Silenced at the loss: an empty utterance cuts off whatever the robot was saying.
        let silenced = speech
            .iter()
            .any(|(t, d)| d.is_empty() && t.abs_diff(lost.log_time) < 500_000_000);
        assert!(
            silenced,
            "{node}: no empty utterance when it was found lost: {context}"
        );
        let said: Vec<&(u64, String)> = robot
            .iter()
            .filter(|(t, d)| *t > lost.log_time && *t < back.log_time && !d.is_empty())
            .collect();
        assert!(
            said.is_empty(),
            "{node}: the robot acted while held: {said:?}"
        );
        let after_back = results_after(&reader, back.log_time);
        eprintln!(
            "{node}: SIGKILL -> lost in GameState {detected_s:.3} s (recorded {shown_s:.3} s), \
             held {held_s:.1} s, {after_back} results after it was back"
        );
    }

    // The game manager's own kill: shown lost by the tablet bridge within the timeout; the
    // respawn took the session over paused, the robot silent until the therapist's resume;
    // no command carried out twice, no sequence decided more than once but the interrupted one.
    let killed_at = gm_killed_at;
    let bridge_lost_s = script_out
        .lines()
        .find_map(|l| l.strip_prefix("bridge showed game_manager lost at "))
        .and_then(|t| t.trim().parse::<f64>().ok())
        .unwrap_or_else(|| panic!("the bridge did not show the game manager lost: {context}"))
        - killed_at;
    assert!(
        bridge_lost_s > LOSS_TIMEOUT_S - 0.3 && bridge_lost_s <= LOSS_TIMEOUT_S + 1.0,
        "the bridge showed the game manager lost {bridge_lost_s:.3} s after the kill"
    );
    let stderr = read("stderr.log");
    assert!(
        stderr.contains("game manager back (pid"),
        "the bridge did not show the game manager back: {context}"
    );
    assert_eq!(
        (
            recovered.message.phase,
            recovered.message.session_id.as_str()
        ),
        (GameState::PAUSED, session_id.as_str())
    );
    let commands = reader
        .messages::<TherapistCommand>(THERAPIST_COMMAND.name)
        .expect("commands");
    let resume = commands
        .iter()
        .find(|m| m.message.command == TherapistCommand::RESUME)
        .unwrap_or_else(|| panic!("no resume in the bag: {context}"));
    let tag = format!("(command {})", resume.message.command_id);
    let carried_out: Vec<&bag_file::Stamped<GameState>> = states
        .iter()
        .filter(|m| m.message.status.contains(&tag) && !m.message.status.starts_with("rejected"))
        .collect();
    assert_eq!(carried_out.len(), 1, "resume carried out once: {context}");
    let starts = states
        .iter()
        .filter(|m| m.message.status.starts_with("session started"))
        .count();
    assert_eq!(starts, 1, "one start");
    let acted: Vec<&(u64, String)> = robot
        .iter()
        .filter(|(t, d)| {
            *t as f64 * 1e-9 > killed_at && *t < carried_out[0].log_time && !d.is_empty()
        })
        .collect();
    assert!(
        acted.is_empty(),
        "the robot acted before the resume: {acted:?}"
    );
    let mut decided = [0u32; 11];
    for d in reader
        .messages::<Decision>(DECISION.name)
        .expect("decisions")
    {
        if let Some(n) = decided.get_mut(usize::from(d.message.step)) {
            *n += 1;
        }
    }
    assert!(
        decided.iter().enumerate().all(|(step, n)| *n
            <= if step == usize::from(interrupted) {
                2
            } else {
                1
            }),
        "decisions per step: {decided:?}"
    );
    // Decisions are durable: the respawned recorder was sent those made while it was down, so
    // every sequence the policy set up has its decision (Q-values and all) in the bag.
    let sequences_where = |keep: &dyn Fn(&serde_json::Value) -> bool| -> Vec<usize> {
        records
            .iter()
            .filter(|r| keep(r))
            .filter_map(|r| r["result"]["sequence_index"].as_u64())
            .map(|i| i as usize)
            .collect()
    };
    let missing: Vec<usize> =
        sequences_where(&|r| r["policy_fallback"] == false && r["result"]["overridden"] != true)
            .into_iter()
            .filter(|&i| decided[i] == 0)
            .collect();
    assert!(
        missing.is_empty(),
        "no decision in the bag for sequences {missing:?} (decisions per step {decided:?})"
    );
    let fallbacks = sequences_where(&|r| r["policy_fallback"] == true);
    eprintln!(
        "game_manager: SIGKILL -> bridge showed it lost {bridge_lost_s:.3} s; recovered at \
         sequence {interrupted}, resumed {:.1} s after the kill ({}); decisions per step {:?}, \
         policy fallbacks at sequences {fallbacks:?}",
        carried_out[0].log_time as f64 * 1e-9 - killed_at,
        respawn_readiness(&stderr, "game_manager"),
        &decided[1..]
    );

    // The policy's Q-table: the respawned policy went on from the file its predecessor saved.
    let updates = |p: &Path| -> u64 {
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(p).expect("Q-table file"))
                .expect("Q-table json");
        v["updates"].as_u64().expect("updates")
    };
    let before = updates(&out.join("q_table_before_behaviour_policy.json"));
    let after = updates(&out.join("q_tables/cluster_0.json"));
    // Results are transient-local: the respawned policy is sent what it missed (and what it
    // had already learned, which it skips), so every sequence is learned from exactly once.
    assert!(
        (1..10).contains(&before) && after == 10,
        "Q-table updates: {before} before the kill, {after} of 10 at the end"
    );
    // A respawn that ignored the file would also end at 10 (relearning 1..10 from the re-sent
    // results); only one that loaded it knows it has learned from sequence 1 already.
    let respawned_policy = stderr
        .split("restarted behaviour_policy (pid")
        .nth(1)
        .expect("the launcher restarted the policy");
    assert!(
        respawned_policy.contains("already learned from this sequence"),
        "the respawned policy did not skip a result its file had learned: {context}"
    );
    eprintln!(
        "Q-table updates: {before} before the policy's SIGKILL, {after} of 10 at the end; \
         whole run {:.1} s",
        wall.as_secs_f64()
    );
    if std::env::var_os("QT_KEEP_TEST_OUTPUT").is_none() {
        let _ = std::fs::remove_dir_all(&out);
    }
}

/// How long the respawned `node` took from its start to "game manager ready", and what it
/// logged about the policy meanwhile: the part of a slow resume spent in the node itself
/// (it waits up to policy_startup_wait_s for the DecideAction service) rather than in the
/// therapist console finding it.
fn respawn_readiness(stderr: &str, node: &str) -> String {
    let Some(respawn) = stderr.split(&format!("restarted {node} (pid")).nth(1) else {
        return "no respawn logged".into();
    };
    let prefix = format!("[{node}] ");
    // Seconds of the day of a line `[node] 2026-12-02T12:27:38.436650Z  INFO message`.
    let time_of = |line: &str| -> Option<f64> {
        let time = line.strip_prefix(&prefix)?.split_whitespace().next()?;
        let clock = time.split('T').nth(1)?.trim_end_matches('Z');
        let mut parts = clock.split(':');
        let (h, m, sec) = (parts.next()?, parts.next()?, parts.next()?);
        Some(
            h.parse::<f64>().ok()? * 3600.0
                + m.parse::<f64>().ok()? * 60.0
                + sec.parse::<f64>().ok()?,
        )
    };
    let find = |words: &str| {
        respawn
            .lines()
            .find(|l| l.starts_with(&prefix) && l.contains(words))
    };
    let (Some(started), Some(ready)) = (find("node started"), find("game manager ready")) else {
        return "respawn not ready in the log".into();
    };
    let policy = if find("behaviour policy reachable").is_some() {
        "the policy found"
    } else {
        "the policy not found"
    };
    match (time_of(started), time_of(ready)) {
        (Some(a), Some(b)) => format!(
            "respawn ready {:.1} s after its start, {policy}",
            (b - a).rem_euclid(86_400.0)
        ),
        _ => format!("respawn ready, {policy}"),
    }
}

/// Sequence results recorded after `t` (log time, ns).
fn results_after(reader: &bag_file::BagReader, t: u64) -> usize {
    reader
        .messages::<SequenceResult>(SEQUENCE_RESULT.name)
        .map(|m| m.iter().filter(|r| r.log_time > t).count())
        .unwrap_or(0)
}
