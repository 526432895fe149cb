//! A month on the robot's PC, in one process on the virtual clock (`in_process/suite.rs`): each
//! day the suite starts in the morning (a new run directory, as the robot's service makes one
//! at every start), plays one session for each of several children, one after another (the
//! simulated child restarted as the next child, of its own cluster), and stops in the evening;
//! the clock jumps over the night. The Q-tables live across days, one per child
//! (`per_user_q_tables`) beside the clusters'.
//!
//! Checked: every session whole (its ten results, tasks and decisions in the day's bag, its
//! session file and summary), each child's own table learning exactly its own sessions (ten
//! updates a session, its decisions made from it, the other children's tables untouched), the
//! clusters' tables learning every session of their children, memory flat (live heap bytes,
//! counted by this program's allocator, after each evening's stop) and the bytes on disk
//! growing by the sessions only (each day's run directory about the first's, the Q-tables a
//! few bytes a session). The suite's test runs the month (30 days of three children) at
//! `time_scale` 0.2; `bash bench/month/month.sh` runs it at the robot's pace, for the bytes on
//! disk a real session leaves (docs/reliability.md, "A month of sessions").
//!   cargo test -p suite_tests --test month -- --nocapture
//!   QT_MONTH_DAYS=30 QT_MONTH_TIME_SCALE=1.0 cargo test -p suite_tests --test month -- --ignored --nocapture
// Counting the heap needs a GlobalAlloc, which is an unsafe trait; test-only.
#![allow(unsafe_code)]

// The in-process suite, shared with tests/in_process.rs; the month uses part of it.
#[path = "in_process/suite.rs"]
#[allow(dead_code)]
mod suite;

use qt_therapy_msgs::Decision;
use qt_therapy_msgs::hri_msgs::IdsList;
use qt_therapy_msgs::topics::{DECISION, PERSONS_TRACKED};
use std::alloc::{GlobalAlloc, Layout, System};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering};
use std::time::{Duration, Instant};
use suite::{Node, Setup, Suite, T0_NS, virtual_time};

/// Bytes allocated and not yet freed, and allocations made, by the whole process.
static LIVE_BYTES: AtomicI64 = AtomicI64::new(0);
static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

struct Counting;

// SAFETY: every call is forwarded unchanged to the system allocator; the counters are atomics.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        LIVE_BYTES.fetch_add(layout.size() as i64, Ordering::Relaxed);
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE_BYTES.fetch_sub(layout.size() as i64, Ordering::Relaxed);
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        LIVE_BYTES.fetch_add(new_size as i64 - layout.size() as i64, Ordering::Relaxed);
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// A child of the clinic: a user id and the cluster they behave like.
#[derive(Debug, Clone, Copy)]
struct Child {
    user: &'static str,
    cluster: i64,
}

/// The children of the month, in the order they come each day.
const CHILDREN: [Child; 3] = [
    Child {
        user: "child-a",
        cluster: 0,
    },
    Child {
        user: "child-b",
        cluster: 1,
    },
    Child {
        user: "child-c",
        cluster: 0,
    },
];

const DAY_NS: i64 = 86_400_000_000_000;

/// What one day left behind.
#[derive(Debug, Clone)]
struct DayFigures {
    /// Live heap bytes once every node of the day has stopped.
    live_bytes: i64,
    /// The process's resident memory then (kB).
    rss_kb: u64,
    /// Allocations made during the day.
    allocations: u64,
    /// The day's run directory: its bag, session files (bytes).
    run_bytes: u64,
    /// Every Q-table file (bytes), after the day.
    q_table_bytes: u64,
    /// Every child's belief file (bytes), after the day.
    belief_bytes: u64,
    /// Files under the output directory, after the day.
    files: usize,
    sessions: usize,
    /// ROS4HRI persons the classifier tracked during the day (a face, each time it is found
    /// again after it was lost).
    persons: usize,
}

/// What a session may leave in the process for its life, at most (bytes): the ROS4HRI persons
/// the classifier tracked meanwhile (a new one each time the face is found again after it was
/// lost), each with two topics whose names are made once and kept (`msgs/src/topics.rs`) and an
/// entry on the in-process bus for each. Measured over a month of three children at
/// `time_scale` 0.2: the live heap after an evening's stop grows 2.7 KiB a session (1.9 KiB a
/// person, 1.3 persons a session), and 22 bytes a session with `ros4hri: false`.
const PER_SESSION_BYTES: i64 = 4 * 1024;

/// Bytes and files under `dir`, recursively.
fn disk_use(dir: &Path) -> (u64, usize) {
    let mut bytes = 0;
    let mut files = 0;
    for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let path = e.path();
        if path.is_dir() {
            let (b, f) = disk_use(&path);
            bytes += b;
            files += f;
        } else if let Ok(m) = e.metadata() {
            bytes += m.len();
            files += 1;
        }
    }
    (bytes, files)
}

/// This process's resident memory (kB), from /proc.
fn rss_kb() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .unwrap_or_default()
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.split_whitespace().next()?.parse().ok())
        .unwrap_or(0)
}

/// A Q-table file's JSON, or Null when it is not there.
fn q_table(out: &Path, name: &str) -> serde_json::Value {
    std::fs::read_to_string(out.join("q_tables").join(name))
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or(serde_json::Value::Null)
}

/// Every Q-table file's bytes, by name.
fn q_table_files(out: &Path) -> BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(out.join("q_tables"))
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().to_string();
            Some((name, std::fs::read(e.path()).ok()?))
        })
        .collect()
}

/// The session a console started, from its line `session <id> started for user ...`.
fn started_session(lines: &[String]) -> Option<String> {
    lines.iter().find_map(|l| {
        let rest = l.strip_prefix("session ")?;
        let (id, tail) = rest.split_once(' ')?;
        tail.starts_with("started").then(|| id.to_string())
    })
}

/// `days` days of one session for each of `children`, into `out`, the classifier's ROS4HRI
/// persons on or off; the figures of each day.
async fn month(
    out: &Path,
    days: u32,
    children: &[Child],
    time_scale: f64,
    ros4hri: bool,
) -> Vec<DayFigures> {
    let setup = Setup {
        time_scale,
        more: BTreeMap::from([
            (Node::Policy, vec!["per_user_q_tables:=true".to_string()]),
            (Node::Classifier, vec![format!("ros4hri:={ros4hri}")]),
        ]),
        ..Setup::default()
    };
    let mut suite = Suite::new(out, setup);
    let mut figures = Vec::new();
    let mut sessions_of: BTreeMap<&str, u64> = BTreeMap::new();
    let cluster_updates = |k: i64| q_table(out, &format!("cluster_{k}.json"))["updates"].as_u64();
    let mut cluster_base: BTreeMap<i64, u64> = BTreeMap::new();
    for k in [0, 1] {
        cluster_base.insert(k, cluster_updates(k).unwrap_or(0));
    }
    let mut cluster_sessions: BTreeMap<i64, u64> = BTreeMap::new();
    for day in 0..days {
        // The morning: nothing runs over the night, so the clock jumps to 09:00.
        let morning = T0_NS + i64::from(day) * DAY_NS;
        let now = suite.bus.clock().steady_nanos();
        if morning > now {
            tokio::time::advance(Duration::from_nanos((morning - now) as u64)).await;
        }
        let allocations_before = ALLOCATIONS.load(Ordering::Relaxed);
        let run = out.join("runs").join(format!("day-{:02}", day + 1));
        suite.set_run(&run);
        suite.setup.cluster = children[0].cluster;
        suite.start_all();
        let mut ids = Vec::new();
        for (i, child) in children.iter().enumerate() {
            if i > 0 && child.cluster != suite.setup.cluster {
                // The next child in front of the camera and the tablet.
                suite.stop(Node::Child).await;
                suite.setup.cluster = child.cluster;
                suite.start(Node::Child);
            }
            suite.setup.user = child.user.to_string();
            let before = q_table_files(out);
            let (code, lines) = suite.run_session(None, false, 1).exit().await;
            let context = format!("day {}, {}:\n{}", day + 1, child.user, lines.join("\n"));
            assert_eq!(code, 0, "{context}");
            let id = started_session(&lines).unwrap_or_else(|| panic!("no session: {context}"));

            // The child's own table learned this session, ten updates; the others' did not
            // move; the cluster's learned it too.
            let n = sessions_of.entry(child.user).or_insert(0);
            *n += 1;
            let own = format!("user_{}.json", child.user);
            let table = q_table(out, &own);
            assert_eq!(table["updates"].as_u64(), Some(10 * *n), "{own}: {context}");
            assert_eq!(table["learned"][&id].as_u64(), Some(10), "{own}: {context}");
            // The child's belief learned the session's ten sequences too.
            let belief = format!("belief_{}.json", child.user);
            let observed = q_table(out, &belief)["observations"]
                .as_array()
                .map(Vec::len);
            assert_eq!(observed, Some(10 * *n as usize), "{belief}: {context}");
            let after = q_table_files(out);
            for (name, bytes) in &before {
                if name != &own && name != &belief && !name.starts_with("cluster_") {
                    assert_eq!(after.get(name), Some(bytes), "{name} changed: {context}");
                }
            }
            *cluster_sessions.entry(child.cluster).or_insert(0) += 1;
            assert_eq!(
                cluster_updates(child.cluster),
                Some(cluster_base[&child.cluster] + 10 * cluster_sessions[&child.cluster]),
                "cluster {}: {context}",
                child.cluster
            );
            ids.push((id, child.user, context));
        }
        suite.stop_all().await;

        // Every session of the day whole in the day's bag, decided from its child's table,
        // and in its session files.
        let bag = run.join("session.mcap");
        let decisions: Vec<Decision> = bag_file::BagReader::open(&bag)
            .expect("the day's bag")
            .messages::<Decision>(DECISION.name)
            .expect("decisions")
            .into_iter()
            .map(|d| d.message)
            .collect();
        for (id, user, context) in &ids {
            let s = suite_tests::whole_session_in_bag(&bag, Some(id), context);
            assert_eq!(s.decisions.len(), 10, "{context}");
            let own = format!("user_{user}.json");
            assert!(
                decisions
                    .iter()
                    .filter(|d| &d.session_id == id)
                    .all(|d| d.model_used.contains(&own)),
                "decisions of {id} not from {own}"
            );
            let records = std::fs::read_to_string(run.join(format!("{id}.jsonl")))
                .unwrap_or_else(|e| panic!("{id}.jsonl: {e}\n{context}"));
            assert_eq!(records.lines().count(), 10, "{context}");
            assert!(run.join(format!("{id}.summary.json")).exists(), "{context}");
        }
        let persons: std::collections::BTreeSet<String> = bag_file::BagReader::open(&bag)
            .expect("the day's bag")
            .messages::<IdsList>(PERSONS_TRACKED.name)
            .expect("tracked persons")
            .into_iter()
            .flat_map(|m| m.message.ids)
            .collect();
        let (run_bytes, _) = disk_use(&run);
        let (q_tables, _) = disk_use(&out.join("q_tables"));
        let belief_bytes: u64 = q_table_files(out)
            .iter()
            .filter(|(name, _)| name.starts_with("belief_"))
            .map(|(_, bytes)| bytes.len() as u64)
            .sum();
        let q_table_bytes = q_tables - belief_bytes;
        let (_, files) = disk_use(out);
        figures.push(DayFigures {
            live_bytes: LIVE_BYTES.load(Ordering::Relaxed),
            rss_kb: rss_kb(),
            allocations: ALLOCATIONS.load(Ordering::Relaxed) - allocations_before,
            run_bytes,
            q_table_bytes,
            belief_bytes,
            files,
            sessions: ids.len(),
            persons: persons.len(),
        });
    }
    figures
}

/// How much a day's run directory (its bag and session files) may exceed the first day's: the
/// same sessions leave about the same bytes (measured: within 10 % of the first day's over a
/// month), so more is something accumulating.
const RUN_GROWTH: f64 = 1.25;

/// What a session may add to the Q-tables, at most (bytes): the child's and the cluster's
/// `learned` entry (the session id and its highest sequence learned); the tables themselves
/// keep their size. Measured: 61 bytes a session over a month.
const Q_TABLE_BYTES_PER_SESSION: u64 = 256;

/// What a session adds to its child's belief file, at most (bytes): its ten observed
/// sequences (the file keeps every sequence of the child's, so the belief can be rebuilt).
/// Measured: 2,086 bytes a session over a month of three children.
const BELIEF_BYTES_PER_SESSION: u64 = 4096;

/// Prints the month's figures, a line a day, then the bytes on disk (a session's, the month's)
/// and checks that memory stays flat and the disk grows by the sessions only: from the second
/// evening on (the first warms the process up), the live heap after an evening's stop grows by
/// no more than the ROS4HRI persons of its sessions cost; no day's run directory is more than
/// [`RUN_GROWTH`] times the first's; the Q-tables grow by at most
/// [`Q_TABLE_BYTES_PER_SESSION`] a session.
fn report(figures: &[DayFigures], took: Duration) {
    for (d, f) in figures.iter().enumerate() {
        eprintln!(
            "day {:2}: {} sessions, {} persons; live heap after the evening's stop {:.1} KiB, \
             RSS {} kB, {} allocations; run directory {:.1} KiB; Q-tables {:.1} KiB; {} files \
             in all",
            d + 1,
            f.sessions,
            f.persons,
            f.live_bytes as f64 / 1024.0,
            f.rss_kb,
            f.allocations,
            f.run_bytes as f64 / 1024.0,
            f.q_table_bytes as f64 / 1024.0,
            f.files
        );
    }
    let sessions: usize = figures.iter().map(|f| f.sessions).sum();
    eprintln!(
        "{} days, {sessions} sessions in {:.1} s of wall time",
        figures.len(),
        took.as_secs_f64()
    );
    let (Some(first), Some(last)) = (figures.first(), figures.last()) else {
        return;
    };
    let runs: u64 = figures.iter().map(|f| f.run_bytes).sum();
    let (least, most) = figures
        .iter()
        .map(|f| f.run_bytes / f.sessions.max(1) as u64)
        .fold((u64::MAX, 0), |(a, b), x| (a.min(x), b.max(x)));
    eprintln!(
        "on disk: {:.2} MB in all ({:.2} MB of run directories, {:.1} KB of Q-tables, {} files); \
         a session's run directory {:.0} KB ({:.0} to {:.0} KB a session by day)",
        (runs + last.q_table_bytes) as f64 / 1e6,
        runs as f64 / 1e6,
        last.q_table_bytes as f64 / 1e3,
        last.files,
        runs as f64 / sessions.max(1) as f64 / 1e3,
        least as f64 / 1e3,
        most as f64 / 1e3
    );
    for (d, f) in figures.iter().enumerate() {
        assert!(
            f.run_bytes as f64 <= first.run_bytes as f64 * RUN_GROWTH,
            "day {}: the run directory holds {} bytes, the first day's {}",
            d + 1,
            f.run_bytes,
            first.run_bytes
        );
    }
    let later: u64 = figures[1..].iter().map(|f| f.sessions as u64).sum();
    assert!(
        last.q_table_bytes <= first.q_table_bytes + later * Q_TABLE_BYTES_PER_SESSION,
        "the Q-tables grew from {} to {} bytes over {later} sessions",
        first.q_table_bytes,
        last.q_table_bytes
    );
    eprintln!(
        "children's belief files: {:.1} KB after the month, {:.0} bytes a session",
        last.belief_bytes as f64 / 1e3,
        last.belief_bytes as f64 / sessions.max(1) as f64
    );
    assert!(
        last.belief_bytes <= sessions as u64 * BELIEF_BYTES_PER_SESSION,
        "the belief files hold {} bytes after {sessions} sessions",
        last.belief_bytes
    );
    if let Some(second) = figures.get(1) {
        let days = (figures.len() - 2) as i64;
        let sessions: usize = figures[2..].iter().map(|f| f.sessions).sum();
        let persons: usize = figures[2..].iter().map(|f| f.persons).sum();
        let grew = last.live_bytes - second.live_bytes;
        eprintln!(
            "live heap from the second evening to the last: {:+.1} KiB over {days} days, \
             {:.0} bytes a session, {:.0} bytes a ROS4HRI person ({persons}); RSS {:+} kB",
            grew as f64 / 1024.0,
            grew as f64 / sessions.max(1) as f64,
            grew as f64 / persons.max(1) as f64,
            last.rss_kb as i64 - second.rss_kb as i64
        );
        assert!(
            grew <= sessions as i64 * PER_SESSION_BYTES,
            "the live heap grew {grew} bytes over {sessions} sessions"
        );
    }
}

/// The month in the suite's tests: 30 days of three children, at `time_scale` 0.2 (the
/// robot's and child's timings five times faster, so the bags are smaller than the robot's;
/// bench/month/month.sh runs the real pace).
#[test]
fn a_month_of_daily_sessions_keeps_each_childs_state_memory_flat_and_the_disk_bounded() {
    let out = std::env::temp_dir().join(format!("qt_month_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let started = Instant::now();
    let figures = virtual_time(month(&out, 30, &CHILDREN, 0.2, true));
    report(&figures, started.elapsed());
    if std::env::var_os("QT_KEEP_TEST_OUTPUT").is_none() {
        let _ = std::fs::remove_dir_all(&out);
    }
}

/// The month as `bench/month/month.sh` asks for it: `QT_MONTH_DAYS` days (30), at
/// `QT_MONTH_TIME_SCALE` (1.0: the robot's and child's real pace, so the bags are as large as
/// the robot's), the ROS4HRI persons on unless `QT_MONTH_ROS4HRI=false`, into `QT_MONTH_OUT`.
#[test]
#[ignore = "minutes: bench/month/month.sh"]
fn a_month_of_daily_sessions_at_the_robots_pace() {
    let days = std::env::var("QT_MONTH_DAYS")
        .ok()
        .and_then(|d| d.parse().ok())
        .unwrap_or(30);
    let ros4hri = std::env::var("QT_MONTH_ROS4HRI").map_or(true, |v| v != "false");
    let time_scale = std::env::var("QT_MONTH_TIME_SCALE")
        .ok()
        .and_then(|d| d.parse().ok())
        .unwrap_or(1.0);
    let out = std::env::var_os("QT_MONTH_OUT")
        .map(PathBuf::from)
        .unwrap_or_else(|| std::env::temp_dir().join(format!("qt_month_{}", std::process::id())));
    let started = Instant::now();
    let figures = virtual_time(month(&out, days, &CHILDREN, time_scale, ros4hri));
    report(&figures, started.elapsed());
}
