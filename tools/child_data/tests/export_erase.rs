//! `qt-therapy-data` on data made by the suite, laid out as the installed service keeps it
//! (docs/install.md): a run whose bag holds two children's sessions and one whose bag holds
//! one, each with the game manager's session files, reports and node logs; per-user and
//! cluster Q-tables; and, given as extra paths, an interaction CSV and a fitted model file.
//!
//! - The bags are the committed sample sessions (`bags/`, recorded over DDS by `bag record`
//!   from the simulated suite: users sim-child-1, -2, -3). The two-child bag is the first two
//!   samples' messages, their channels and bytes as recorded, written into one bag by
//!   `bag_file`'s writer at their own times (16:49 and 17:00 the same day): one run in
//!   which two sessions were played.
//! - Session files, as `nodes/game_manager/src/session_file.rs` writes them (the session file
//!   per sequence, the journal, the summary), filled from each bag's results, commands and
//!   tasks. Log lines as `node_shell`'s tracing format writes the game manager's
//!   (`nodes/game_manager/src/game/session.rs`: "session … started for user …") and the
//!   tablet bridge's (`nodes/tablet_bridge/src/bridge.rs`).
//! - Reports by the `session_report` library, the CSV by `user_models` from the bags, the
//!   model file by `user_models::fit` (one simulated user renamed to sim-child-1), the
//!   Q-tables from `bags/q_tables` with their owner set, a belief file per child as the
//!   behaviour policy writes it.
//!
//! Where the bag check's Python readers are installed (`tests/run.sh` makes the venv), every
//! bag this tool writes is checked in them too.

use bag_file::{BagReader, BagWriter, Stamp, WriterOptions};
use qt_therapy_msgs::topics::{GAME_STATE, SEQUENCE_RESULT, TABLET_TASK, THERAPIST_COMMAND};
use qt_therapy_msgs::{GameState, MessageDefinition, SequenceResult, TherapistCommand};
use std::collections::{BTreeMap, BTreeSet};
use std::io::Read;
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

const A: &str = "sim-child-1";
const B: &str = "sim-child-2";
const C: &str = "sim-child-3";
const SAMPLE_A: &str = "cluster0_seed7.mcap";
const SAMPLE_B: &str = "cluster1_seed11_pause_override.mcap";
const SAMPLE_C: &str = "cluster0_seed3_stopped.mcap";
const RUN1: &str = "sessions/20261204-164914";
const RUN2: &str = "sessions/20261204-165125";

fn workspace() -> PathBuf {
    std::fs::canonicalize(Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")).expect("root")
}

fn sample(name: &str) -> PathBuf {
    workspace().join("bags").join(name)
}

/// A message as a bag holds it: (topic, log time, publish time, sequence, CDR).
type Key = (String, u64, u64, u32, Vec<u8>);

fn keys(reader: &BagReader) -> Vec<Key> {
    reader
        .iter()
        .map(|(c, m)| {
            (
                c.topic.clone(),
                m.log_time,
                m.publish_time,
                m.sequence,
                m.data.clone(),
            )
        })
        .collect()
}

fn open(path: &Path) -> BagReader {
    BagReader::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .strict()
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

struct Fixture {
    _dir: tempfile::TempDir,
    root: PathBuf,
}

impl Fixture {
    fn data(&self) -> PathBuf {
        self.root.join("data")
    }
    fn run1(&self) -> PathBuf {
        self.data().join(RUN1)
    }
    fn run2(&self) -> PathBuf {
        self.data().join(RUN2)
    }
    fn elsewhere(&self) -> PathBuf {
        self.root.join("elsewhere")
    }

    /// Runs the binary on the fixture's places for `user`.
    fn run(&self, command: &str, user: &str, more: &[&str]) -> Output {
        let mut c = Command::new(env!("CARGO_BIN_EXE_child_data"));
        c.arg(command)
            .args(["--user", user, "--data"])
            .arg(self.data())
            .arg(self.elsewhere())
            .args(more)
            .current_dir(&self.root)
            .stdin(Stdio::null());
        c.output().expect("child_data runs")
    }

    /// Every file under the fixture's root, with its bytes.
    fn snapshot(&self) -> BTreeMap<PathBuf, Vec<u8>> {
        let mut out = BTreeMap::new();
        let mut pending = vec![self.root.clone()];
        while let Some(d) = pending.pop() {
            for e in std::fs::read_dir(&d).expect("lists").flatten() {
                let p = e.path();
                if p.is_dir() {
                    pending.push(p);
                } else {
                    out.insert(p.clone(), std::fs::read(&p).expect("reads"));
                }
            }
        }
        out
    }
}

fn text(o: &Output) -> String {
    format!(
        "status {:?}\n--- stdout\n{}--- stderr\n{}",
        o.status.code(),
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// The samples' messages written into one bag at their own times, channels as declared, a
/// chunk closed every second of log time as the recorder's `flush_interval_s: 1` does.
fn concatenate(sources: &[&Path], path: &Path) {
    let mut w = BagWriter::create(path, &WriterOptions::default()).expect("creates");
    let mut flushed = 0;
    for source in sources {
        let r = open(source);
        let mut ids = BTreeMap::new();
        for c in r.channels() {
            ids.insert(c.id, w.add_channel_like(c).expect("channel"));
        }
        for m in r.raw_messages() {
            let stamp = Stamp {
                log_time: m.log_time,
                publish_time: m.publish_time,
                sequence: m.sequence,
            };
            if m.log_time >= flushed + 1_000_000_000 {
                w.flush_chunk().expect("flushes");
                flushed = m.log_time;
            }
            w.write_cdr(ids[&m.channel_id], stamp, &m.data)
                .expect("writes");
        }
    }
    w.finish().expect("finishes");
}

/// The game manager's files of the session recorded in `bag` (`session_file.rs`'s formats);
/// returns the session id. Without `finished`, no summary (a session still running, or cut
/// off by a crash).
fn session_files(bag: &Path, dir: &Path, finished: bool) -> String {
    let r = open(bag);
    let start = r
        .topic(THERAPIST_COMMAND)
        .expect("commands")
        .into_iter()
        .find(|c| c.message.command == TherapistCommand::START)
        .expect("a START");
    let (session, user) = (&start.message.session_id, &start.message.user_id);
    let mut journal = vec![serde_json::json!({
        "entry": "started", "session_id": session, "user_id": user,
        "user_model_cluster": start.message.user_model_cluster,
        "command_id": start.message.command_id, "at_ns": start.log_time,
    })];
    for t in r.topic(TABLET_TASK).expect("tasks") {
        journal.push(serde_json::json!({
            "entry": "task", "session_id": session, "task_id": t.message.sequence_id,
            "sequence_index": t.message.sequence_index, "at_ns": t.log_time,
        }));
    }
    let results = r.topic(SEQUENCE_RESULT).expect("results");
    let records: Vec<serde_json::Value> = results
        .iter()
        .map(|s| {
            serde_json::json!({
                "result": s.message, "policy_fallback": false,
                "decision_reason": "greedy", "talk_start_ns": s.log_time - 5_000_000_000u64,
                "task_sent_ns": s.log_time - 2_000_000_000u64, "answered_ns": s.log_time,
                "rejected_answers": 0,
            })
        })
        .collect();
    let lines = |v: &[serde_json::Value]| -> String {
        v.iter()
            .map(|l| format!("{}\n", serde_json::to_string(l).expect("json")))
            .collect()
    };
    std::fs::write(dir.join(format!("{session}.journal")), lines(&journal)).expect("journal");
    std::fs::write(dir.join(format!("{session}.jsonl")), lines(&records)).expect("records");
    if finished {
        let correct = results.iter().filter(|s| s.message.outcome > 0).count();
        let summary = serde_json::json!({
            "session_id": session, "user_id": user,
            "user_model_cluster": start.message.user_model_cluster, "end": "finished",
            "reason": "all sequences played", "sequences_planned": 10,
            "sequences_played": results.len(), "interrupted_sequence": null,
            "correct": correct, "timeouts": 0, "score": 0, "max_score": 0,
            "mean_engagement": null, "overrides": 0, "proposals": 0,
            "proposals_accepted": 0, "proposals_replaced": 0, "proposals_timed_out": 0,
            "policy_fallbacks": 0, "rejected_commands": 0, "rejected_answers": 0, "seed": 7,
            "language": "en", "started_ns": start.log_time,
            "ended_ns": results.last().map_or(start.log_time, |s| s.log_time),
        });
        std::fs::write(
            dir.join(format!("{session}.summary.json")),
            serde_json::to_string_pretty(&summary).expect("json") + "\n",
        )
        .expect("summary");
    }
    session.clone()
}

fn report(bag: &Path, session: &str, path: &Path) {
    let r = open(bag);
    let log = session_report::SessionLog::from_bag(&r, Some(session)).expect("decodes");
    std::fs::write(path, session_report::report_html(&log).expect("report")).expect("writes");
}

fn q_table(owner: serde_json::Value, learned: &[(&str, u8)], path: &Path) {
    let text = std::fs::read_to_string(workspace().join("bags/q_tables/cluster_0.json"))
        .expect("cluster table");
    let mut v: serde_json::Value = serde_json::from_str(&text).expect("json");
    v["owner"] = owner;
    v["learned"] = learned
        .iter()
        .map(|(s, n)| (s.to_string(), serde_json::json!(n)))
        .collect::<serde_json::Map<_, _>>()
        .into();
    std::fs::write(path, serde_json::to_string_pretty(&v).expect("json")).expect("writes");
}

/// Makes the fixture's files (once per test run: see [`fixture`]).
fn build_fixture() -> (Fixture, [String; 3]) {
    let dir = tempfile::tempdir().expect("temp dir");
    let f = Fixture {
        root: std::fs::canonicalize(dir.path()).expect("canonical"),
        _dir: dir,
    };
    for d in [
        f.run1().join("logs"),
        f.run2().join("logs"),
        f.data().join("q_tables"),
        f.elsewhere(),
    ] {
        std::fs::create_dir_all(d).expect("dirs");
    }
    let bag1 = f.run1().join("session.mcap");
    concatenate(&[&sample(SAMPLE_A), &sample(SAMPLE_B)], &bag1);
    let bag2 = f.run2().join("session.mcap");
    std::fs::copy(sample(SAMPLE_C), &bag2).expect("copies");
    let sa = session_files(&sample(SAMPLE_A), &f.run1(), true);
    let sb = session_files(&sample(SAMPLE_B), &f.run1(), true);
    let sc = session_files(&sample(SAMPLE_C), &f.run2(), true);
    report(&bag1, &sa, &f.run1().join(format!("report-{sa}.html")));
    report(&bag1, &sb, &f.run1().join("report.html"));
    report(&bag2, &sc, &f.run2().join("report.html"));
    // The game manager's lines as a simulated session wrote them (its session span names
    // the session on every line of it; the start line names the user).
    let session_lines = |s: &str, u: &str, run: &Path| {
        format!(
            "2026-12-04T16:49:15.646204Z  INFO session{{id=\"-\" sequence=0}}: session {s:?} \
             started for user {u:?} (cluster 0), command 1796402955444\n\
             2026-12-04T16:49:23.614614Z  INFO session{{id={s:?} sequence=1}}: seq  1/10  level \
             2 (5 emotions)  feedback none         answer right    score +2  E +0.43 ( 4 s)  | \
             policy greedy: level 2 (Q=27.30, p=1.00, T=0.5) [cluster 0 \
             (/var/lib/qt-therapy/q_tables/cluster_0.json, 0 updates)]\n\
             2026-12-04T16:50:16.694103Z  INFO session{{id={s:?} sequence=10}}: session summary \
             written path={}/{s}.summary.json\n",
            run.display()
        )
    };
    let idle = "2026-12-04T16:49:14.940314Z  INFO behaviour policy reachable on \
                /qt_therapy/policy/decide_action\n";
    std::fs::write(
        f.run1().join("logs/game_manager.log"),
        format!(
            "{idle}{}{idle}{}",
            session_lines(&sa, A, &f.run1()),
            session_lines(&sb, B, &f.run1())
        ),
    )
    .expect("log");
    std::fs::write(
        f.run1().join("logs/tablet_bridge.log"),
        format!(
            "2026-12-04T16:49:15.770408Z  INFO page 1: command 1 (Start) sent for session {sa:?}\n\
             2026-12-04T17:00:01.332493Z  INFO page 2: command 1 (Start) sent for session {sb:?}\n\
             2026-12-04T17:00:08.865788Z  INFO page 2: command 2 (Pause) sent for session {sb:?}\n"
        ),
    )
    .expect("log");
    std::fs::write(
        f.run2().join("logs/game_manager.log"),
        format!("{idle}{}", session_lines(&sc, C, &f.run2())),
    )
    .expect("log");
    let q = f.data().join("q_tables");
    q_table(
        serde_json::json!({"cluster": 0}),
        &[(&sa, 10), (&sc, 4)],
        &q.join("cluster_0.json"),
    );
    q_table(
        serde_json::json!({"cluster": 1}),
        &[(&sb, 10)],
        &q.join("cluster_1.json"),
    );
    for (u, s) in [(A, &sa), (B, &sb), (C, &sc)] {
        q_table(
            serde_json::json!({ "user": u }),
            &[(s, 10)],
            &q.join(format!("user_{u}.json")),
        );
        // The behaviour policy's belief about the child (`child_belief`), as the node writes
        // it (nodes/behaviour_policy/src/child_beliefs.rs).
        let belief = serde_json::json!({
            "format": "qt_therapy child_belief", "version": 1, "user_id": u, "prior_cluster": 0,
            "observations": [{"session_id": s, "sequence_index": 1, "level": 2, "feedback": 0,
                "previous_score": 0, "outcome": 1, "engagement": 0.5}],
        });
        std::fs::write(
            q.join(format!("belief_{u}.json")),
            serde_json::to_string_pretty(&belief).expect("JSON"),
        )
        .expect("writes a belief");
    }
    let records =
        user_models::data::bag::read_bags(&[sample(SAMPLE_A), sample(SAMPLE_B), sample(SAMPLE_C)])
            .expect("records from the bags");
    user_models::data::write_csv(&f.elsewhere().join("records.csv"), &records.records)
        .expect("csv");
    let mut study = user_models::simulate::simulate_study(&user_models::simulate::StudySpec {
        engaged_users: 2,
        disengaged_users: 2,
        ..Default::default()
    });
    for r in &mut study {
        if r.user_id == "sim-01" {
            r.user_id = A.into();
        }
    }
    let options = user_models::FitOptions {
        clusters: 1,
        optimise: false,
        kmeans_restarts: 1,
        provenance: "test: a simulated study, one user named as a child".into(),
        ..Default::default()
    };
    user_models::fit(&study, &options)
        .expect("fits")
        .save(&f.elsewhere().join("user_models.json"))
        .expect("saves");
    // The service's state is 0640 (docs/install.md): a rewrite must keep it so.
    for p in f.snapshot().keys() {
        std::fs::set_permissions(p, std::fs::Permissions::from_mode(0o640)).expect("mode");
    }
    (f, [sa, sb, sc])
}

/// A fresh copy of the fixture for one test (files, modes and all), made once and copied.
fn fixture() -> (Fixture, [String; 3]) {
    static TEMPLATE: std::sync::OnceLock<(Fixture, [String; 3])> = std::sync::OnceLock::new();
    let (template, ids) = TEMPLATE.get_or_init(build_fixture);
    let dir = tempfile::tempdir().expect("temp dir");
    let f = Fixture {
        root: std::fs::canonicalize(dir.path()).expect("canonical"),
        _dir: dir,
    };
    for (path, _) in template.snapshot() {
        let to = f
            .root
            .join(path.strip_prefix(&template.root).expect("below"));
        std::fs::create_dir_all(to.parent().expect("parent")).expect("dirs");
        std::fs::copy(&path, &to).expect("copies");
    }
    (f, ids.clone())
}

/// Decoded ids of a message on one of the topics that carry them.
fn carries(topic: &str, data: &[u8], id: &str) -> bool {
    fn d<M: MessageDefinition>(data: &[u8]) -> M {
        bag_file::cdr::decode::<M>(data).expect("decodes")
    }
    if topic == GAME_STATE.name {
        let m: GameState = d(data);
        m.user_id == id || m.session_id == id
    } else if topic == SEQUENCE_RESULT.name {
        let m: SequenceResult = d(data);
        m.user_id == id || m.session_id == id
    } else if topic == THERAPIST_COMMAND.name {
        let m: TherapistCommand = d(data);
        m.user_id == id || m.session_id == id
    } else {
        false
    }
}

/// Where the bag check's Python readers are, if `tests/run.sh` installed them.
fn python_readers() -> Option<PathBuf> {
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace().join("target"));
    let python = target.join("bag-check-venv/bin/python");
    python.exists().then_some(python)
}

/// The bag decodes alike in Python's `mcap` and `rosbags` (tests/bags/check_bag.py).
fn python_reads(bags: &[&Path]) {
    let Some(python) = python_readers() else {
        eprintln!("skipped: no bag-check venv (tests/run.sh makes it) for the Python readers");
        return;
    };
    let out = Command::new(python)
        .arg(workspace().join("tests/bags/check_bag.py"))
        .args(bags)
        .current_dir(workspace())
        .output()
        .expect("python runs");
    assert!(out.status.success(), "check_bag.py: {}", text(&out));
    eprintln!("{}", String::from_utf8_lossy(&out.stdout));
}

fn archive(path: &Path) -> Vec<(String, Vec<u8>)> {
    let gz = flate2::read::GzDecoder::new(std::fs::File::open(path).expect("archive"));
    let mut tar = tar::Archive::new(gz);
    tar.entries()
        .expect("entries")
        .map(|e| {
            let mut e = e.expect("entry");
            let name = e.path().expect("path").display().to_string();
            let mut bytes = Vec::new();
            e.read_to_end(&mut bytes).expect("reads");
            (name, bytes)
        })
        .collect()
}

#[test]
fn export_holds_everything_of_one_child_and_nothing_of_the_others() {
    let (f, [sa, sb, _]) = fixture();
    let before = f.snapshot();
    let out = f.run("export", A, &["--output", "a.tar.gz"]);
    assert!(out.status.success(), "{}", text(&out));
    assert_eq!(
        f.snapshot().len(),
        before.len() + 1,
        "only the archive was added"
    );
    let path = f.root.join("a.tar.gz");
    let mode = std::fs::metadata(&path)
        .expect("archive")
        .permissions()
        .mode()
        & 0o777;
    assert_eq!(mode, 0o600, "the archive is its owner's only");
    let entries = archive(&path);
    let names: Vec<&str> = entries.iter().map(|(n, _)| n.as_str()).collect();
    let top = format!("child-data-{A}");
    assert_eq!(names[0], format!("{top}/MANIFEST.txt"));
    let get = |rel: &str| -> &[u8] {
        entries
            .iter()
            .find(|(n, _)| n.ends_with(rel))
            .map(|(_, b)| b.as_slice())
            .unwrap_or_else(|| panic!("{rel} not in {names:#?}"))
    };
    // Whole files, byte for byte: the session files, the own Q-table, the session's report.
    for rel in [
        format!("{RUN1}/{sa}.jsonl"),
        format!("{RUN1}/{sa}.journal"),
        format!("{RUN1}/{sa}.summary.json"),
        format!("{RUN1}/report-{sa}.html"),
        format!("q_tables/user_{A}.json"),
        format!("q_tables/belief_{A}.json"),
    ] {
        assert_eq!(get(&rel), before[&f.data().join(&rel)].as_slice(), "{rel}");
    }
    // Nothing of the others: no file of theirs, and no text naming them.
    for (n, b) in &entries {
        let t = String::from_utf8_lossy(b);
        assert!(!n.contains(&sb) && !n.contains(B) && !n.contains(C), "{n}");
        if !n.ends_with(".mcap") && !n.ends_with("MANIFEST.txt") {
            assert!(
                !t.contains(B) && !t.contains(&sb) && !t.contains(C),
                "{n} names another"
            );
        }
    }
    assert!(
        !names.iter().any(|n| n.ends_with("/report.html")),
        "{names:#?}"
    );
    // The bag part: every message of the first session, none of the second's, the source's
    // channels as declared.
    let source = open(&f.run1().join("session.mcap"));
    let exported_bag = f.root.join("exported.mcap");
    std::fs::write(&exported_bag, get(&format!("{RUN1}/session.mcap"))).expect("writes");
    let exported = open(&exported_bag);
    let mine: BTreeSet<Key> = keys(&exported).into_iter().collect();
    let all_a: BTreeSet<Key> = keys(&open(&sample(SAMPLE_A))).into_iter().collect();
    assert!(
        mine.is_superset(&all_a),
        "every message of A's sample is A's"
    );
    for (topic, _, _, _, data) in &mine {
        assert!(
            !carries(topic, data, B) && !carries(topic, data, &sb),
            "{topic}"
        );
    }
    let source_keys: BTreeSet<Key> = keys(&source).into_iter().collect();
    assert!(mine.is_subset(&source_keys));
    for c in exported.channels() {
        let s = source.topic_channels(&c.topic);
        assert!(
            s.iter().any(|s| s.metadata == c.metadata
                && s.schema.as_ref().map(|x| &x.data) == c.schema.as_ref().map(|x| &x.data)),
            "{}",
            c.topic
        );
    }
    // CSV: the header and A's rows as written; the log lines of A's session.
    let csv = String::from_utf8_lossy(get("records.csv")).to_string();
    let original_csv =
        String::from_utf8_lossy(&before[&f.elsewhere().join("records.csv")]).to_string();
    let rows: Vec<&str> = csv.lines().collect();
    assert_eq!(rows[0], original_csv.lines().next().expect("header"));
    assert_eq!(rows.len(), 1 + 10, "A's 10 sequences");
    assert!(rows[1..].iter().all(|r| r.starts_with(&format!("{A},"))));
    let gm = String::from_utf8_lossy(get(&format!("{RUN1}/logs/game_manager.log"))).to_string();
    assert_eq!(gm.lines().count(), 3, "{gm}");
    assert!(gm.contains(&format!("started for user \"{A}\"")), "{gm}");
    let tb = String::from_utf8_lossy(get(&format!("{RUN1}/logs/tablet_bridge.log"))).to_string();
    assert_eq!(tb.lines().count(), 1, "the START of A's session: {tb}");
    // Of the model file, A's own entry only.
    let model: serde_json::Value =
        serde_json::from_slice(get("user_models.this-user.json")).expect("json");
    assert_eq!(model["user"]["user"], A);
    assert_eq!(model["cluster_users"], 4);
    // The manifest names every file, where from and what; the command printed it.
    let manifest = String::from_utf8_lossy(get("MANIFEST.txt")).to_string();
    for n in &names[1..] {
        assert!(manifest.contains(n), "{n} not in the manifest:\n{manifest}");
    }
    assert!(manifest.contains(&format!("from {}", f.run1().join("session.mcap").display())));
    assert!(manifest.contains("journalctl"), "{manifest}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains(&manifest[..200]), "{}", text(&out));
    // Cluster tables learned from A's session: named, not exported.
    assert!(manifest.contains("cluster 0's Q-table"), "{manifest}");
    assert!(!names.iter().any(|n| n.contains("cluster_")));
    // The same archive is not overwritten.
    let again = f.run("export", A, &["--output", "a.tar.gz"]);
    assert_eq!(again.status.code(), Some(1), "{}", text(&again));
    assert!(text(&again).contains("already exists"), "{}", text(&again));
    python_reads(&[&exported_bag]);
}

#[test]
fn erase_removes_one_child_and_leaves_the_others_whole() {
    let (f, [sa, sb, sc]) = fixture();
    let before = f.snapshot();
    let source = open(&f.run1().join("session.mcap"));
    let out = f.run("erase", A, &["--yes"]);
    // The fitted model file still names A: done, but something still holds A's data.
    assert_eq!(out.status.code(), Some(3), "{}", text(&out));
    let t = text(&out);
    assert!(t.contains("STILL HOLDS DATA OF THIS USER"), "{t}");
    assert!(
        t.contains("user_models.json") && t.contains("user-model fit"),
        "{t}"
    );
    assert!(
        t.contains(&format!(
            "rewrote {}",
            f.run1().join("session.mcap").display()
        )),
        "{t}"
    );
    let after = f.snapshot();
    let gone: Vec<PathBuf> = before
        .keys()
        .filter(|p| !after.contains_key(*p))
        .cloned()
        .collect();
    let mut expected_gone = vec![
        f.run1().join(format!("{sa}.jsonl")),
        f.run1().join(format!("{sa}.journal")),
        f.run1().join(format!("{sa}.summary.json")),
        f.run1().join(format!("report-{sa}.html")),
        f.data().join(format!("q_tables/user_{A}.json")),
        f.data().join(format!("q_tables/belief_{A}.json")),
    ];
    expected_gone.sort();
    assert_eq!(gone, expected_gone);
    let changed: Vec<PathBuf> = after
        .iter()
        .filter(|(p, b)| before.get(*p).is_some_and(|o| o != *b))
        .map(|(p, _)| p.clone())
        .collect();
    let mut expected_changed = vec![
        f.run1().join("session.mcap"),
        f.run1().join("logs/game_manager.log"),
        f.run1().join("logs/tablet_bridge.log"),
        f.elsewhere().join("records.csv"),
    ];
    expected_changed.sort();
    assert_eq!(changed, expected_changed);
    assert_eq!(
        after.len(),
        before.len() - gone.len(),
        "nothing left beside them"
    );
    for p in &changed {
        let mode = std::fs::metadata(p).expect("meta").permissions().mode() & 0o777;
        assert_eq!(mode, 0o640, "{}", p.display());
    }
    // The bag: B's session whole, byte for byte; nothing of A's; it reads back.
    let bag = open(&f.run1().join("session.mcap"));
    let kept = keys(&bag);
    let b_sample = keys(&open(&sample(SAMPLE_B)));
    let t_b = open(&sample(SAMPLE_B))
        .topic(GAME_STATE)
        .expect("states")
        .into_iter()
        .find(|s| s.message.session_id == sb)
        .expect("B's session starts")
        .log_time;
    let kept_set: BTreeSet<&Key> = kept.iter().collect();
    let from_b_start: Vec<&Key> = b_sample.iter().filter(|k| k.1 >= t_b).collect();
    assert!(
        from_b_start.iter().all(|k| kept_set.contains(k)),
        "B's session intact"
    );
    let earlier: Vec<&Key> = kept.iter().filter(|k| k.1 < t_b).collect();
    // Before B's session began, only its START command (which names it) is B's: the idle
    // time before belongs to A's session, the one it followed.
    assert_eq!(
        earlier.len(),
        1,
        "{:?}",
        earlier.iter().map(|k| &k.0).collect::<Vec<_>>()
    );
    assert_eq!(earlier[0].0, THERAPIST_COMMAND.name);
    assert!(carries(&earlier[0].0, &earlier[0].4, B));
    assert_eq!(kept.len(), from_b_start.len() + 1);
    for (topic, _, _, _, data) in &kept {
        assert!(
            !carries(topic, data, A) && !carries(topic, data, &sa),
            "{topic}"
        );
    }
    // Per topic: what went is what A's sample holds plus the idle time before B's start.
    let count = |ks: &[Key]| {
        let mut m: BTreeMap<String, usize> = BTreeMap::new();
        for k in ks {
            *m.entry(k.0.clone()).or_default() += 1;
        }
        m
    };
    let (all, left) = (count(&keys(&source)), count(&kept));
    let b_counts = count(&b_sample);
    for (topic, n) in &left {
        assert_eq!(
            *n,
            b_counts[topic]
                - b_sample
                    .iter()
                    .filter(|k| &k.0 == topic
                        && k.1 < t_b
                        && !(k.0 == THERAPIST_COMMAND.name && carries(&k.0, &k.4, B)))
                    .count(),
            "{topic}"
        );
        assert!(*n <= all[topic]);
    }
    for (topic, want) in [
        (SEQUENCE_RESULT.name, 10),
        (THERAPIST_COMMAND.name, 4),
        (TABLET_TASK.name, 10),
    ] {
        assert_eq!(left[topic], want, "B's {topic}");
    }
    // The compression stays, and every channel that still has messages, as declared, and
    // those empty in the source too (the recorder took every topic of the graph, some never
    // published); one whose messages all went (the user model info, logged once before B's
    // session began) goes with them.
    assert_eq!(bag.chunks().1.keys().collect::<Vec<_>>(), ["zstd"]);
    let topics: BTreeSet<&str> = bag.channels().map(|c| c.topic.as_str()).collect();
    let source_counts = source.counts();
    let empty_in_source = source
        .channels()
        .filter(|c| source_counts.get(&c.id).copied().unwrap_or(0) == 0)
        .map(|c| c.topic.as_str());
    let with_messages: BTreeSet<&str> = kept
        .iter()
        .map(|k| k.0.as_str())
        .chain(empty_in_source)
        .collect();
    assert_eq!(topics, with_messages);
    // Each channel gone had messages, all of them A's or before B's start (the user model
    // info; A's session's ROS4HRI persons).
    let gone: Vec<&str> = source
        .channels()
        .filter(|c| !topics.contains(c.topic.as_str()))
        .inspect(|c| {
            assert!(
                source_counts.get(&c.id).copied().unwrap_or(0) > 0,
                "{}",
                c.topic
            )
        })
        .map(|c| c.topic.as_str())
        .collect();
    assert!(gone.contains(&"/qt_therapy/user_model/models"), "{gone:?}");
    assert!(
        gone.iter()
            .all(|t| *t == "/qt_therapy/user_model/models" || t.starts_with("/humans/persons/")),
        "{gone:?}"
    );
    for c in bag.channels() {
        let s = source.topic_channels(&c.topic)[0];
        assert_eq!(
            (&s.metadata, &s.schema.as_ref().map(|x| &x.data)),
            (&c.metadata, &c.schema.as_ref().map(|x| &x.data))
        );
    }
    // Text files: A's rows and lines gone, every other byte as it was.
    let csv = String::from_utf8_lossy(&after[&f.elsewhere().join("records.csv")]).to_string();
    let old_csv = String::from_utf8_lossy(&before[&f.elsewhere().join("records.csv")]).to_string();
    let without_a: Vec<&str> = old_csv
        .lines()
        .filter(|l| !l.starts_with(&format!("{A},")))
        .collect();
    assert_eq!(csv.lines().collect::<Vec<_>>(), without_a);
    assert_eq!(csv.lines().count(), 1 + 10 + 4);
    let gm = String::from_utf8_lossy(&after[&f.run1().join("logs/game_manager.log")]).to_string();
    assert!(!gm.contains(A) && !gm.contains(&sa), "{gm}");
    assert!(gm.contains(B) && gm.contains(&sb), "{gm}");
    assert_eq!(gm.lines().count(), 5, "two idle lines and B's three: {gm}");
    // Run 2 (C alone), B's and C's session files, reports and tables: untouched.
    for p in before.keys() {
        if p.starts_with(f.run2())
            || p.to_string_lossy().contains(&sb)
            || p.to_string_lossy().contains(&sc)
            || p.ends_with("report.html")
        {
            assert_eq!(before[p], after[p], "{}", p.display());
        }
    }
    // Listed again: only the model file is left.
    let list = f.run("list", A, &[]);
    assert!(list.status.success(), "{}", text(&list));
    let listed = String::from_utf8_lossy(&list.stdout).to_string();
    assert_eq!(
        listed.matches("\n  /").count(),
        1,
        "only the model file: {listed}"
    );
    assert!(listed.contains("user_models.json"), "{listed}");
    python_reads(&[&f.run1().join("session.mcap")]);
}

#[test]
fn a_bag_holding_only_the_child_is_deleted() {
    let (f, [_, _, sc]) = fixture();
    let out = f.run("erase", C, &["--yes"]);
    // The model file does not name C: nothing of C is left.
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    assert!(!f.run2().join("session.mcap").exists());
    assert!(text(&out).contains(&format!(
        "deleted {}: all its {} messages were this user's",
        f.run2().join("session.mcap").display(),
        open(&sample(SAMPLE_C)).raw_messages().len()
    )));
    let left: Vec<String> = std::fs::read_dir(f.run2())
        .expect("run 2")
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(left, ["logs"], "C's bag, session files and report gone");
    let log = std::fs::read_to_string(f.run2().join("logs/game_manager.log")).expect("log");
    assert!(!log.contains(C) && !log.contains(&sc), "{log}");
    let list = f.run("list", C, &[]);
    assert!(
        String::from_utf8_lossy(&list.stdout).contains("nothing of this user found"),
        "{}",
        text(&list)
    );
}

#[test]
fn erase_refuses_while_a_session_of_the_child_runs_and_takes_a_crashed_one() {
    let (f, [sa, _, _]) = fixture();
    // A's session without its summary: running, or cut off by a crash.
    std::fs::remove_file(f.run1().join(format!("{sa}.summary.json"))).expect("removes");
    let before = f.snapshot();
    // The game manager's instance lock on its sessions directory (a flock per open file, so
    // this process holds it as another would).
    let game_manager =
        instance_lock::InstanceLock::acquire(&f.run1(), "game_manager", "session files")
            .expect("free");
    let out = f.run("erase", A, &["--yes"]);
    assert_eq!(out.status.code(), Some(4), "{}", text(&out));
    let t = text(&out);
    assert!(
        t.contains(&format!("session {sa:?} of this user is running")),
        "{t}"
    );
    assert!(t.contains(&format!("pid {}", std::process::id())), "{t}");
    assert_eq!(f.snapshot(), before, "nothing changed");
    let list = f.run("list", A, &[]);
    assert!(
        text(&list).contains("erase would refuse"),
        "{}",
        text(&list)
    );
    // The game manager died and its launcher is about to respawn it (which takes the
    // session over): no lock, but the launcher's command line names the run. A stand-in
    // with the launcher's arguments (`launch FILE out:=<run>`, packaging/deb/start).
    drop(game_manager);
    let mut launcher = Command::new("sh")
        .args(["-c", "sleep 30; :", "launch", "tablet_session.launch.yaml"])
        .arg(format!("out:={}", f.run1().display()))
        .spawn()
        .expect("sh runs");
    let cmdline = format!("/proc/{}/cmdline", launcher.id());
    for _ in 0..500 {
        if std::fs::read(&cmdline).is_ok_and(|c| c.starts_with(b"sh\0")) {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    let out = f.run("erase", A, &["--yes"]);
    launcher.kill().expect("kill");
    launcher.wait().expect("wait");
    assert_eq!(out.status.code(), Some(4), "{}", text(&out));
    let t = text(&out);
    assert!(
        t.contains(&format!("pid {} (sh) uses it", launcher.id())),
        "{t}"
    );
    assert_eq!(f.snapshot(), before, "nothing changed");
    // Without confirmation (not a terminal, no --yes) nothing happens either.
    let unconfirmed = f.run("erase", A, &[]);
    assert_eq!(unconfirmed.status.code(), Some(4), "{}", text(&unconfirmed));
    assert!(text(&unconfirmed).contains("--yes"));
    assert_eq!(f.snapshot(), before, "nothing changed");
    // The game manager gone and nothing else running the run: the session was cut off.
    let out = f.run("erase", A, &["--yes"]);
    assert_eq!(out.status.code(), Some(3), "{}", text(&out));
    let t = text(&out);
    assert!(t.contains("has no summary and nothing runs it"), "{t}");
    assert!(!f.run1().join(format!("{sa}.journal")).exists());
}

#[test]
fn a_damaged_bag_is_named_and_rewritten_only_when_asked() {
    let (f, [sa, sb, _]) = fixture();
    let bag = f.run1().join("session.mcap");
    let bytes = std::fs::read(&bag).expect("reads");
    // Cut in A's part (the first third): a chunk torn, as a recorder killed mid-write leaves it.
    std::fs::write(&bag, &bytes[..bytes.len() / 3]).expect("truncates");
    let readable = BagReader::open(&bag).expect("reads");
    assert!(readable.damage().is_some());
    let readable_count = readable.raw_messages().len();
    let list = f.run("list", A, &[]);
    let t = text(&list);
    assert!(t.contains("DAMAGED") && t.contains("is truncated"), "{t}");
    let before = f.snapshot();
    let out = f.run("erase", A, &["--yes"]);
    assert_eq!(out.status.code(), Some(4), "{}", text(&out));
    let t = text(&out);
    assert!(t.contains(&format!("{} is damaged", bag.display())), "{t}");
    assert!(t.contains("--rewrite-damaged"), "{t}");
    assert_eq!(f.snapshot(), before, "nothing changed");
    // B's session files say it went on after the readable part: the unreadable rest is
    // named as B's too, so listing B names the damage as well.
    let list_b = text(&f.run("list", B, &[]));
    assert!(
        list_b.contains("DAMAGED") && list_b.contains(&sb),
        "{list_b}"
    );
    // Export takes what reads.
    let out = f.run("export", A, &["--output", "a.tar.gz"]);
    assert!(out.status.success(), "{}", text(&out));
    let entries = archive(&f.root.join("a.tar.gz"));
    let (_, manifest) = &entries[0];
    assert!(
        String::from_utf8_lossy(manifest).contains("the bag is damaged"),
        "{}",
        String::from_utf8_lossy(manifest)
    );
    std::fs::remove_file(f.root.join("a.tar.gz")).expect("removes");
    let out = f.run("erase", A, &["--yes", "--rewrite-damaged"]);
    assert_eq!(out.status.code(), Some(3), "{}", text(&out));
    let t = text(&out);
    // Everything readable was A's (the cut is in A's part): the bag goes.
    assert!(
        t.contains(&format!(
            "deleted {}: all its {readable_count} messages were this user's",
            bag.display()
        )),
        "{t}"
    );
    assert!(!bag.exists());
    assert!(!f.run1().join(format!("{sa}.jsonl")).exists());
}

#[test]
fn a_damaged_bag_holding_two_children_is_rewritten_from_what_reads() {
    let (f, [_, sb, _]) = fixture();
    let bag = f.run1().join("session.mcap");
    let bytes = std::fs::read(&bag).expect("reads");
    // Cut in B's part (the last fifth): A's session and the start of B's read.
    std::fs::write(&bag, &bytes[..bytes.len() * 4 / 5]).expect("truncates");
    let readable = keys(&BagReader::open(&bag).expect("reads"));
    let out = f.run("erase", A, &["--yes", "--rewrite-damaged"]);
    assert_eq!(out.status.code(), Some(3), "{}", text(&out));
    let t = text(&out);
    assert!(
        t.contains("unreadable bytes after the damage are gone"),
        "{t}"
    );
    let after = open(&bag);
    assert!(after.is_complete());
    let kept = keys(&after);
    assert!(!kept.is_empty());
    let readable: BTreeSet<&Key> = readable.iter().collect();
    for k in &kept {
        assert!(readable.contains(k), "only what read before the damage");
        assert!(!carries(&k.0, &k.4, A));
    }
    assert!(
        kept.iter().any(|k| carries(&k.0, &k.4, &sb)),
        "B's part stays"
    );
    python_reads(&[&bag]);
}
