//! A power cut at any moment of a session: the main job runs in process (`in_process/suite.rs`)
//! on the recording file system (`tests/power_cut`, FUSE, as root), which logs every write,
//! rename and sync of every node. Then every point of the log is cut in three ways (nothing
//! unsynced kept; every name change kept but no unsynced data; every unsynced write kept but
//! the last torn: `power_cut::cut`), and what is left is read as a restarted suite would
//! read it. Each cut must leave: every Q-table (the cluster's and, per-user tables on, the
//! child's own) and the child's belief file whole, and the session's at most one sequence
//! behind the sequences scored;
//! the session file and journal readable by the game manager's recovery, damaged at most in a
//! torn last line, holding every scored sequence but at most the one in progress; the bag
//! readable up to its last complete chunk, a prefix of the finished bag, holding every result
//! but at most the one in progress, each as the session file has it; a summary, once there,
//! whole. Needs root and /dev/fuse: skipped without them, failed under QT_REQUIRE_ALL_TESTS.

// The in-process suite's helpers; this test uses some of them.
#[allow(dead_code)]
#[path = "in_process/suite.rs"]
mod suite;

use bag_file::BagReader;
use game_manager::recovery::recover_session;
use game_manager::session_file::{SequenceRecord, SessionFiles, read_records};
use power_cut::cut::{Model, ROOT, Replay, Tree};
use qt_therapy_msgs::SequenceResult;
use qt_therapy_msgs::topics::SEQUENCE_RESULT;
use std::collections::{BTreeMap, HashMap, HashSet};
use std::hash::{DefaultHasher, Hash, Hasher};
use std::path::{Path, PathBuf};
use std::time::Instant;
use suite::{Setup, Suite, virtual_time};

/// A message of a bag as a tuple: (topic, log time, sequence number, bytes).
type Message = (String, u64, u32, Vec<u8>);

fn bag_messages(r: &BagReader) -> Vec<Message> {
    let topics: BTreeMap<u16, String> = r.channels().map(|c| (c.id, c.topic.clone())).collect();
    r.raw_messages()
        .iter()
        .map(|m| {
            (
                topics.get(&m.channel_id).cloned().unwrap_or_default(),
                m.log_time,
                m.sequence,
                m.data.clone(),
            )
        })
        .collect()
}

/// Complete lines of a session file's text (what a scored sequence adds).
fn whole_lines(bytes: &[u8]) -> usize {
    bytes.iter().filter(|b| **b == b'\n').count()
}

/// The session's learned count in a Q-table's text (0 when it has none, or none yet).
fn learned(path: &Path, session: &str) -> Result<u8, String> {
    // The child's belief beside the tables (`child_belief`, on in the main job): its highest
    // observed sequence of the session, as a table's `learned` entry.
    let belief = path
        .file_name()
        .and_then(|n| n.to_str())
        .is_some_and(|n| n.starts_with("belief_"));
    if belief {
        use behaviour_policy::child_beliefs::{BELIEF_FILE, BeliefFile};
        let b: BeliefFile = BELIEF_FILE.load(path).map_err(|e| e.to_string())?;
        return Ok(b
            .observations
            .iter()
            .filter(|o| o.session_id == session)
            .map(|o| o.sequence_index)
            .max()
            .unwrap_or(0));
    }
    let t = q_learning::q_table_file::QTableFile::load(path).map_err(|e| e.to_string())?;
    Ok(t.learned.get(session).copied().unwrap_or(0))
}

/// What the finished session left: the reference every cut is held to.
struct Finished {
    session: String,
    stem: String,
    records: Vec<SequenceRecord>,
    bag: Vec<Message>,
    q_tables: Vec<String>,
    /// The Q-tables there before the session (the others are made during it).
    q_tables_before: HashSet<String>,
    /// The Q-tables that learn from the session (the cluster's and the child's own).
    q_tables_learning: HashSet<String>,
}

/// The session files of a cut, as a restarted game manager reads them (`SessionFiles::scan`,
/// then the recovery of an unfinished session): the records that survive, and any damage
/// beyond a torn last line.
fn check_session_files(
    dir: &Path,
    scored: usize,
    done: &Finished,
) -> (Vec<SequenceRecord>, Vec<String>) {
    let mut problems = Vec::new();
    let scan = SessionFiles::new(dir).scan();
    problems.extend(scan.problems.iter().map(|p| format!("session files: {p}")));
    let mut durable: Vec<SequenceRecord> = Vec::new();
    if scan.finished_ids.contains(&done.session) {
        match read_records(&dir.join(format!("{}.jsonl", done.stem))) {
            Ok(r) if !r.torn_tail => durable = r.records,
            Ok(_) => problems.push("a finished session's file ends torn".into()),
            Err(e) => problems.push(format!("a finished session's file: {e}")),
        }
    }
    for u in &scan.unfinished {
        match recover_session(&u.stem, &u.records, &u.journal) {
            Ok(r) => {
                for d in &r.damage {
                    if !(d.contains("torn") || d.contains("no newline at its end")) {
                        problems.push(format!("recovery names damage: {d}"));
                    }
                }
                durable = r.records;
            }
            // Cut before the start's journal line reached the disk: nothing scored yet.
            Err(_) if scored == 0 => {}
            Err(why) => problems.push(format!("recovery refuses {}: {why}", u.stem)),
        }
    }
    if durable[..] != done.records[..durable.len().min(done.records.len())] {
        problems.push("session file: its records differ from the session's".into());
    }
    (durable, problems)
}

/// Each Q-table's name and how many sequences of the session it learned.
type Learned = Vec<(String, usize)>;

/// The Q-tables of a cut: each whole, and how many sequences of the session each learned
/// (a table first made during the session and not yet on disk has learned none).
fn check_q_tables(dir: &Path, done: &Finished) -> (Learned, Vec<String>) {
    let mut problems = Vec::new();
    let mut learned_by = Vec::new();
    for name in &done.q_tables {
        let path = dir.join("q_tables").join(name);
        if !path.exists() {
            if done.q_tables_before.contains(name) {
                problems.push(format!("Q-table {name} is gone"));
            } else {
                learned_by.push((name.clone(), 0));
            }
            continue;
        }
        match learned(&path, &done.session) {
            Ok(n) => learned_by.push((name.clone(), n as usize)),
            Err(e) => problems.push(format!("Q-table {name} is damaged: {e}")),
        }
    }
    (learned_by, problems)
}

/// The bag of a cut: readable, a prefix of the finished bag; its results.
fn check_bag(bytes: Option<&[u8]>, done: &Finished) -> Result<Vec<SequenceResult>, String> {
    let bytes = bytes.ok_or("no bag")?;
    let r = BagReader::from_bytes(bytes, "session.mcap", &Default::default())
        .map_err(|e| format!("bag unreadable: {e}"))?;
    let topics: BTreeMap<u16, &str> = r.channels().map(|c| (c.id, c.topic.as_str())).collect();
    let raw = r.raw_messages();
    let same = raw.len() <= done.bag.len()
        && raw.iter().zip(&done.bag).all(|(m, d)| {
            m.log_time == d.1
                && m.sequence == d.2
                && topics.get(&m.channel_id).copied() == Some(d.0.as_str())
                && m.data == d.3
        });
    if !same {
        return Err("bag: its messages are not those of the finished bag".into());
    }
    Ok(r.messages::<SequenceResult>(SEQUENCE_RESULT.name)
        .map(|m| m.into_iter().map(|s| s.message).collect())
        .unwrap_or_default())
}

/// Each part's verdict by its bytes: a part unchanged since a state already checked is not
/// read again.
#[derive(Default)]
struct Verdicts {
    session: HashMap<u64, (Vec<SequenceRecord>, Vec<String>)>,
    q_tables: HashMap<u64, (Learned, Vec<String>)>,
    bag: HashMap<u64, Result<Vec<SequenceResult>, String>>,
}

fn hash_of<T: Hash>(t: &T) -> u64 {
    let mut h = DefaultHasher::new();
    t.hash(&mut h);
    h.finish()
}

/// Checks what a cut left (`tree`, the suite's output under `out`), with `scored` sequences
/// in the live session file when the power went; the problems found. `scratch` receives the
/// files the game manager's and the policy's own readers read from disk.
fn check(
    tree: &Tree,
    scored: usize,
    done: &Finished,
    scratch: &Path,
    verdicts: &mut Verdicts,
) -> Vec<String> {
    let out = Path::new("out");
    let file = |rel: &str| tree.file(&out.join(rel));
    let allowed_loss = scored.saturating_sub(1);
    let mut problems = Vec::new();

    let session_names = [
        format!("{}.jsonl", done.stem),
        format!("{}.journal", done.stem),
        format!("{}.summary.json", done.stem),
    ];
    let texts: Vec<Option<&[u8]>> = session_names.iter().map(|n| file(n)).collect();
    let (durable, session_problems) = verdicts
        .session
        .entry(hash_of(&(&texts, scored)))
        .or_insert_with(|| {
            let dir = scratch.join("session");
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(&dir).expect("scratch");
            for (name, text) in session_names.iter().zip(&texts) {
                if let Some(t) = text {
                    std::fs::write(dir.join(name), t).expect("scratch");
                }
            }
            check_session_files(&dir, scored, done)
        })
        .clone();
    problems.extend(session_problems);
    if durable.len() < allowed_loss {
        problems.push(format!(
            "session file: {} of {scored} scored sequences survive",
            durable.len()
        ));
    }

    let q_texts: Vec<Option<&[u8]>> = done
        .q_tables
        .iter()
        .map(|n| file(&format!("q_tables/{n}")))
        .collect();
    let (learned_by, q_problems) = verdicts
        .q_tables
        .entry(hash_of(&q_texts))
        .or_insert_with(|| {
            let dir = scratch.join("q");
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(dir.join("q_tables")).expect("scratch");
            for (name, text) in done.q_tables.iter().zip(&q_texts) {
                if let Some(t) = text {
                    std::fs::write(dir.join("q_tables").join(name), t).expect("scratch");
                }
            }
            check_q_tables(&dir, done)
        })
        .clone();
    problems.extend(q_problems);
    for (name, n) in &learned_by {
        let behind = done.q_tables_learning.contains(name) && *n < allowed_loss;
        if behind || *n > durable.len().max(scored) {
            problems.push(format!(
                "Q-table {name} learned {n} sequences; the session scored {scored}, its file \
                 holds {}",
                durable.len()
            ));
        }
    }

    let bag = file("session.mcap").or_else(|| file("session.mcap.partial"));
    let results = verdicts
        .bag
        .entry(hash_of(&bag))
        .or_insert_with(|| check_bag(bag, done))
        .clone();
    match results {
        // Before the first sequence is scored the recorder may not have its first chunk on
        // disk: nothing is lost then (a restarted recorder sets an unreadable file aside).
        Err(_) if scored == 0 => {}
        Err(e) => problems.push(e),
        Ok(results) => {
            if results.len() < allowed_loss {
                problems.push(format!(
                    "bag: {} of {scored} results survive",
                    results.len()
                ));
            }
            for res in &results {
                let i = usize::from(res.sequence_index);
                if done.records.get(i.wrapping_sub(1)).map(|d| &d.result) != Some(res) {
                    problems.push(format!("bag: result {i} differs from the session file's"));
                }
            }
        }
    }
    problems
}

/// Hashes the files under `ino` (names and bytes), to check each distinct state once.
fn hash_tree(tree: &Tree, ino: u64, h: &mut DefaultHasher) {
    if let Some(entries) = tree.entries(ino) {
        for (name, child) in entries {
            name.hash(h);
            match tree.nodes.get(child) {
                Some(power_cut::cut::Node::File(d)) => d.hash(h),
                Some(power_cut::cut::Node::Dir(_)) => hash_tree(tree, *child, h),
                None => {}
            }
        }
    }
}

#[test]
fn a_power_cut_at_any_write_of_a_session_loses_at_most_the_sequence_in_progress() {
    if let Err(why) = power_cut::can_mount()
        && loopback_netns::skip_or_fail(&why)
    {
        return;
    }
    let scratch = tempfile::tempdir().expect("a temporary directory");
    let point = scratch.path().join("mnt");
    std::fs::create_dir_all(&point).expect("the mount point");
    let mounted = power_cut::Mounted::mount(&point).expect("mounts the recording file system");
    let out = point.join("out");
    let started = Instant::now();
    let (baseline, code) = virtual_time(async {
        // Per-user Q-tables on: the child's own table is written beside its cluster's.
        let mut setup = Setup::default();
        setup.more.insert(
            suite::Node::Policy,
            vec!["per_user_q_tables:=true".to_string()],
        );
        let mut suite = Suite::new(&out, setup);
        let baseline = mounted.baseline();
        suite.start_all();
        let (code, _) = suite.run_session(None, false, 1).exit().await;
        suite.stop_all().await;
        (baseline, code)
    });
    let session_s = started.elapsed().as_secs_f64();
    assert_eq!(code, 0, "the session ran to its end");
    let log = mounted.log();
    drop(mounted);

    // The finished session, from the live tree at the end.
    let mut end = Replay::new(baseline.clone());
    for op in &log {
        end.step(op);
    }
    let out_ino = *baseline
        .entries(ROOT)
        .and_then(|e| e.get(std::ffi::OsStr::new("out")))
        .expect("out is in the baseline");
    let finished_dir = scratch.path().join("finished");
    end.live
        .materialize(out_ino, &finished_dir)
        .expect("writes the finished tree");
    let summary = std::fs::read_dir(&finished_dir)
        .expect("lists")
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .find_map(|n| n.strip_suffix(".summary.json").map(str::to_string))
        .expect("the session's summary");
    let records = read_records(&finished_dir.join(format!("{summary}.jsonl")))
        .expect("the finished session file")
        .records;
    let mut done = Finished {
        session: records[0].result.session_id.clone(),
        stem: summary.clone(),
        bag: bag_messages(&BagReader::open(&finished_dir.join("session.mcap")).expect("bag")),
        q_tables: std::fs::read_dir(finished_dir.join("q_tables"))
            .expect("q_tables")
            .filter_map(Result::ok)
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".json") && !n.starts_with('.'))
            .collect(),
        q_tables_before: baseline
            .entries(out_ino)
            .and_then(|e| e.get(std::ffi::OsStr::new("q_tables")))
            .and_then(|q| baseline.entries(*q))
            .map(|e| e.keys().map(|n| n.to_string_lossy().into_owned()).collect())
            .unwrap_or_default(),
        q_tables_learning: HashSet::new(),
        records,
    };
    let finished_tables = check_q_tables(&finished_dir, &done);
    assert!(finished_tables.1.is_empty(), "{:?}", finished_tables.1);
    done.q_tables_learning = finished_tables
        .0
        .into_iter()
        .filter(|(_, n)| *n == done.records.len())
        .map(|(name, _)| name)
        .collect();
    assert_eq!(done.records.len(), 10, "the whole session");
    assert_eq!(
        done.q_tables_learning.len(),
        3,
        "a cluster's and the child's own Q-table, and the child's belief, learn the whole \
         session: {:?}",
        done.q_tables
    );
    let jsonl = PathBuf::from("out").join(format!("{summary}.jsonl"));

    // Every cut point, three ways.
    let checking = Instant::now();
    let mut replay = Replay::new(baseline);
    let mut seen = HashSet::new();
    let (mut states, mut cuts, mut losses) = (0usize, 0usize, Vec::new());
    let writes = log
        .iter()
        .filter(|o| matches!(o, power_cut::cut::Op::Write { .. }))
        .count();
    let syncs = log
        .iter()
        .filter(|o| matches!(o, power_cut::cut::Op::Sync { .. }))
        .count();
    let cut_dir = scratch.path().join("cut");
    let mut verdicts = Verdicts::default();
    for k in 0..=log.len() {
        if k > 0 {
            replay.step(&log[k - 1]);
        }
        let scored = replay.live.file(&jsonl).map_or(0, whole_lines);
        for model in Model::ALL {
            cuts += 1;
            let tree = replay.after_cut(model);
            let mut h = DefaultHasher::new();
            hash_tree(&tree, out_ino, &mut h);
            scored.hash(&mut h);
            if !seen.insert(h.finish()) {
                continue;
            }
            states += 1;
            for p in check(&tree, scored, &done, &cut_dir, &mut verdicts) {
                losses.push(format!("after op {k} of {} ({model:?}): {p}", log.len()));
            }
        }
    }
    println!(
        "power cut: a session of {} operations ({writes} writes, {syncs} syncs) in {session_s:.1} \
         s; {cuts} cuts tried ({} points x 3 models), {states} distinct states checked in {:.1} \
         s (session files read {} times, Q-tables {}, bags {}); losses found: {}",
        log.len(),
        log.len() + 1,
        checking.elapsed().as_secs_f64(),
        verdicts.session.len(),
        verdicts.q_tables.len(),
        verdicts.bag.len(),
        losses.len()
    );
    assert!(
        losses.is_empty(),
        "{} losses, the first:\n{}",
        losses.len(),
        losses
            .iter()
            .take(20)
            .cloned()
            .collect::<Vec<_>>()
            .join("\n")
    );
}
