//! Watches the two threads of the node's RustDDS participant (its event loop and its
//! discovery) and ends the process when one of them has ended, so that the launcher (`respawn`)
//! or systemd starts the node again. A node whose DDS threads are gone is alive but deaf and
//! mute: it keeps its process, its heartbeat task and its state, and sends and receives nothing.
//! RustDDS 0.15.1 ended both threads on a stop and continue (SIGSTOP/SIGCONT) until our patch
//! (third_party/README.md); this catches that and whatever else may end them.
//!
//! RustDDS gives no handle to its threads, so they are found by name in `/proc/self/task`:
//! `RustDDS Participant <id> event loop` and `RustDDS discovery thread`, which Linux cuts to
//! 15 bytes. The participant's threads are the ones that appear while it is built.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::Duration;

/// The threads of the process, as Linux lists them.
pub const TASK_DIR: &str = "/proc/self/task";

/// The thread names RustDDS 0.15 gives its participant's threads, as `/proc` shows them
/// (cut to 15 bytes), and what each does.
const RUSTDDS_THREADS: [(&str, &str); 2] = [
    ("RustDDS Partici", "event loop"),
    ("RustDDS discove", "discovery"),
];

/// How often the watch looks.
pub const WATCH_PERIOD: Duration = Duration::from_millis(500);

/// The exit code of a node whose DDS threads ended (EX_SOFTWARE): non-zero, so that systemd's
/// `Restart=on-failure` restarts it too.
pub const EXIT_CODE: i32 = 70;

/// One thread of a RustDDS participant.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct DdsThread {
    pub tid: u32,
    /// Its name as `/proc/<pid>/task/<tid>/comm` gives it.
    pub comm: String,
}

impl DdsThread {
    /// What the thread does in RustDDS.
    pub fn role(&self) -> &'static str {
        RUSTDDS_THREADS
            .iter()
            .find(|(comm, _)| *comm == self.comm)
            .map_or("unknown", |(_, role)| role)
    }
}

impl std::fmt::Display for DdsThread {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "RustDDS's {} thread ({:?}, tid {})",
            self.role(),
            self.comm,
            self.tid
        )
    }
}

/// A thread's name from its `comm` file.
fn read_comm(task_dir: &Path, tid: u32) -> Option<String> {
    std::fs::read_to_string(task_dir.join(tid.to_string()).join("comm"))
        .ok()
        .map(|c| c.trim_end_matches('\n').to_string())
}

/// RustDDS's threads now in the process whose threads `task_dir` lists, by thread id.
pub fn rustdds_threads(task_dir: &Path) -> std::io::Result<BTreeSet<DdsThread>> {
    let mut found = BTreeSet::new();
    for entry in std::fs::read_dir(task_dir)? {
        let Some(tid) = entry?.file_name().to_str().and_then(|t| t.parse().ok()) else {
            continue;
        };
        // A thread can end between the listing and the read.
        if let Some(comm) = read_comm(task_dir, tid)
            && RUSTDDS_THREADS.iter().any(|(name, _)| *name == comm)
        {
            found.insert(DdsThread { tid, comm });
        }
    }
    Ok(found)
}

/// The threads a participant started: those of `after` not in `before`, if they are one of
/// each kind RustDDS starts; otherwise what was found, as an error.
pub fn participant_threads(
    before: &BTreeSet<DdsThread>,
    after: &BTreeSet<DdsThread>,
) -> Result<Vec<DdsThread>, Vec<DdsThread>> {
    let new: Vec<DdsThread> = after.difference(before).cloned().collect();
    let one_of_each = RUSTDDS_THREADS
        .iter()
        .all(|(name, _)| new.iter().filter(|t| t.comm == *name).count() == 1);
    if one_of_each && new.len() == RUSTDDS_THREADS.len() {
        Ok(new)
    } else {
        Err(new)
    }
}

/// Of `watched`, the threads that have ended: gone from `task_dir`, or their id now names
/// another thread.
pub fn ended(task_dir: &Path, watched: &[DdsThread]) -> Vec<DdsThread> {
    watched
        .iter()
        .filter(|t| read_comm(task_dir, t.tid).as_deref() != Some(t.comm.as_str()))
        .cloned()
        .collect()
}

/// A running watch; dropping it stops it (before the participant goes, so that its threads
/// ending at a clean stop are not taken for a failure).
pub struct ThreadWatch {
    stop: Option<mpsc::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl ThreadWatch {
    /// Looks at `watched` in `task_dir` every `period` on a thread of its own (not a task of
    /// the node's runtime, which may be what hangs) and calls `on_end` once with the threads
    /// that ended, the first time any has.
    pub fn start(
        task_dir: PathBuf,
        watched: Vec<DdsThread>,
        period: Duration,
        on_end: impl FnOnce(Vec<DdsThread>) + Send + 'static,
    ) -> std::io::Result<ThreadWatch> {
        let (stop, stopped) = mpsc::channel::<()>();
        let thread = std::thread::Builder::new()
            .name("dds watch".into())
            .spawn(move || {
                while let Err(mpsc::RecvTimeoutError::Timeout) = stopped.recv_timeout(period) {
                    let gone = ended(&task_dir, &watched);
                    if !gone.is_empty() {
                        on_end(gone);
                        return;
                    }
                }
            })?;
        Ok(ThreadWatch {
            stop: Some(stop),
            thread: Some(thread),
        })
    }
}

impl Drop for ThreadWatch {
    fn drop(&mut self) {
        drop(self.stop.take());
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// What a node does when its DDS threads ended: says which, and exits with [`EXIT_CODE`].
/// No clean stop: removing DDS entities needs the event loop that is gone, and every node's
/// state on disk is written as it goes, so this is a crash the suite is built to survive
/// (the kill test), not a loss.
pub fn exit_node(node: &str, ended: &[DdsThread]) -> ! {
    let what: Vec<String> = ended.iter().map(ToString::to_string).collect();
    tracing::error!(
        node,
        "{} ended: this node can no longer send or receive over DDS; exiting with code \
         {EXIT_CODE} so that the launcher (respawn) or systemd starts it again",
        what.join(" and ")
    );
    std::process::exit(EXIT_CODE);
}

/// Starts the watch of the participant built between `before` (RustDDS's threads then) and
/// now; the node exits when one of its threads ends. None, after a warning, when its threads
/// cannot be told (a RustDDS that names them otherwise, or no `/proc`).
pub fn watch_participant(node: &str, before: &BTreeSet<DdsThread>) -> Option<ThreadWatch> {
    let task_dir = PathBuf::from(TASK_DIR);
    let after = match rustdds_threads(&task_dir) {
        Ok(after) => after,
        Err(e) => {
            tracing::warn!("cannot watch RustDDS's threads: reading {TASK_DIR}: {e}");
            return None;
        }
    };
    let threads = match participant_threads(before, &after) {
        Ok(threads) => threads,
        Err(found) => {
            tracing::warn!(
                "cannot watch RustDDS's threads: expected one event loop and one discovery \
                 thread of the new participant, found {found:?}"
            );
            return None;
        }
    };
    let name = node.to_string();
    match ThreadWatch::start(task_dir, threads, WATCH_PERIOD, move |gone| {
        exit_node(&name, &gone)
    }) {
        Ok(watch) => Some(watch),
        Err(e) => {
            tracing::warn!("cannot watch RustDDS's threads: starting the watch: {e}");
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::process::Command;
    use std::time::Instant;

    /// A stand-in for `/proc/self/task`: a directory per thread id with its `comm` file
    /// (name and newline, as Linux writes it).
    fn fake_task_dir(threads: &[(u32, &str)]) -> tempfile::TempDir {
        let dir = tempfile::tempdir().expect("temp dir");
        for (tid, comm) in threads {
            set_thread(dir.path(), *tid, comm);
        }
        dir
    }

    fn set_thread(dir: &Path, tid: u32, comm: &str) {
        let task = dir.join(tid.to_string());
        std::fs::create_dir_all(&task).expect("task dir");
        std::fs::write(task.join("comm"), format!("{comm}\n")).expect("comm");
    }

    fn thread(tid: u32, comm: &str) -> DdsThread {
        DdsThread {
            tid,
            comm: comm.into(),
        }
    }

    /// The threads of a node as `/proc` showed them (user_model, before and after
    /// SIGSTOP/SIGCONT with RustDDS 0.15.1 unpatched).
    const NODE: [(u32, &str); 5] = [
        (100, "user_model"),
        (101, "tokio-rt-worker"),
        (102, "tokio-rt-worker"),
        (103, "RustDDS Partici"),
        (104, "RustDDS discove"),
    ];

    #[test]
    fn a_participants_threads_are_found_by_their_names() {
        let dir = fake_task_dir(&NODE[..3]);
        let before = rustdds_threads(dir.path()).expect("reads");
        assert!(before.is_empty());
        set_thread(dir.path(), 103, "RustDDS Partici");
        set_thread(dir.path(), 104, "RustDDS discove");
        let after = rustdds_threads(dir.path()).expect("reads");
        let threads = participant_threads(&before, &after).expect("one of each");
        assert_eq!(
            threads,
            vec![
                thread(103, "RustDDS Partici"),
                thread(104, "RustDDS discove")
            ]
        );
        assert_eq!(
            threads[0].to_string(),
            "RustDDS's event loop thread (\"RustDDS Partici\", tid 103)"
        );
        assert_eq!(threads[1].role(), "discovery");
    }

    #[test]
    fn threads_of_another_participant_or_a_missing_one_are_not_watched() {
        // A participant already there is not the new one's.
        let before = BTreeSet::from([thread(50, "RustDDS Partici"), thread(51, "RustDDS discove")]);
        let mut after = before.clone();
        after.insert(thread(60, "RustDDS Partici"));
        assert_eq!(
            participant_threads(&before, &after),
            Err(vec![thread(60, "RustDDS Partici")])
        );
        // Renamed threads (another RustDDS): nothing found, so the caller warns.
        let dir = fake_task_dir(&[(1, "node"), (2, "dds-event-loop")]);
        let found = rustdds_threads(dir.path()).expect("reads");
        assert_eq!(participant_threads(&BTreeSet::new(), &found), Err(vec![]));
    }

    #[test]
    fn a_thread_that_ended_or_whose_id_was_reused_is_found_ended() {
        let dir = fake_task_dir(&NODE);
        let watched = vec![
            thread(103, "RustDDS Partici"),
            thread(104, "RustDDS discove"),
        ];
        assert!(ended(dir.path(), &watched).is_empty());
        // The event loop ended (as after a stop and continue): its directory is gone.
        std::fs::remove_dir_all(dir.path().join("103")).expect("remove");
        assert_eq!(
            ended(dir.path(), &watched),
            vec![thread(103, "RustDDS Partici")]
        );
        // The discovery thread's id now names another thread.
        set_thread(dir.path(), 104, "tokio-rt-worker");
        assert_eq!(ended(dir.path(), &watched).len(), 2);
    }

    #[test]
    fn the_watch_reports_once_when_a_thread_ends_and_stops_when_dropped() {
        let dir = fake_task_dir(&NODE);
        let watched = vec![
            thread(103, "RustDDS Partici"),
            thread(104, "RustDDS discove"),
        ];
        let (tx, rx) = mpsc::channel();
        let watch = ThreadWatch::start(
            dir.path().to_path_buf(),
            watched.clone(),
            Duration::from_millis(10),
            move |gone| tx.send(gone).expect("the test listens"),
        )
        .expect("starts");
        assert!(rx.recv_timeout(Duration::from_millis(200)).is_err());
        std::fs::remove_dir_all(dir.path().join("104")).expect("remove");
        let gone = rx.recv_timeout(Duration::from_secs(10)).expect("reported");
        assert_eq!(gone, vec![thread(104, "RustDDS discove")]);
        drop(watch);
        // A watch dropped before its threads end reports nothing.
        let (tx, rx) = mpsc::channel();
        let watch = ThreadWatch::start(
            dir.path().to_path_buf(),
            watched[..1].to_vec(),
            Duration::from_millis(10),
            move |gone| tx.send(gone).expect("the test listens"),
        )
        .expect("starts");
        drop(watch);
        std::fs::remove_dir_all(dir.path().join("103")).expect("remove");
        assert!(rx.recv_timeout(Duration::from_millis(200)).is_err());
    }

    const EXIT_ROLE: &str = "QT_DDS_WATCH_TEST_EXIT_IN";

    /// The node's own reaction, in a process of its own (this test binary again): a watched
    /// thread ends, the process says which and exits with [`EXIT_CODE`].
    #[test]
    fn a_node_whose_dds_thread_ended_says_which_and_exits_non_zero() {
        if let Some(dir) = std::env::var_os(EXIT_ROLE) {
            let dir = PathBuf::from(dir);
            crate::logging::init_logging("dds_watch_test");
            let _watch = ThreadWatch::start(
                dir.clone(),
                vec![thread(103, "RustDDS Partici")],
                Duration::from_millis(10),
                |gone| exit_node("dds_watch_test", &gone),
            )
            .expect("starts");
            std::fs::remove_dir_all(dir.join("103")).expect("remove");
            std::thread::sleep(Duration::from_secs(10));
            panic!("the watch did not end the process");
        }
        let dir = fake_task_dir(&NODE);
        let started = Instant::now();
        let out = Command::new(std::env::current_exe().expect("test binary"))
            .args([
                "--exact",
                "dds_watch::tests::a_node_whose_dds_thread_ended_says_which_and_exits_non_zero",
                "--nocapture",
            ])
            .env(EXIT_ROLE, dir.path())
            .output()
            .expect("runs");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(EXIT_CODE), "{stderr}");
        assert!(
            stderr.contains(
                "RustDDS's event loop thread (\"RustDDS Partici\", tid 103) ended: this node \
                 can no longer send or receive over DDS; exiting with code 70"
            ),
            "{stderr}"
        );
        assert!(started.elapsed() < Duration::from_secs(10));
    }

    const IN_NAMESPACE: &str = "QT_DDS_WATCH_TEST_IN_NAMESPACE";

    /// Real threads: a RustDDS participant's two threads are found by their names in
    /// `/proc/self/task`, live while it lives, and are found ended once it is gone (its
    /// threads then end cleanly: the only way to end them without the bug). Inside a
    /// loopback-only namespace, as every DDS participant of the tests.
    #[test]
    fn a_real_participants_threads_are_found_and_their_end_is_seen() {
        loopback_netns::test_inside_namespace(
            "dds_watch::tests::a_real_participants_threads_are_found_and_their_end_is_seen",
            IN_NAMESPACE,
            Duration::from_secs(60),
            || {
                let task_dir = Path::new(TASK_DIR);
                let before = rustdds_threads(task_dir).expect("reads /proc");
                let participant = rustdds::DomainParticipantBuilder::new(0)
                    .with_only_networks([std::net::IpAddr::V4(std::net::Ipv4Addr::LOCALHOST)])
                    .build()
                    .expect("a participant");
                let after = rustdds_threads(task_dir).expect("reads /proc");
                let threads = participant_threads(&before, &after)
                    .unwrap_or_else(|found| panic!("RustDDS's threads not told: {found:?}"));
                println!("watched: {threads:?}");
                let (tx, rx) = mpsc::channel();
                let _watch = ThreadWatch::start(
                    task_dir.to_path_buf(),
                    threads.clone(),
                    Duration::from_millis(50),
                    move |gone| tx.send(gone).expect("the test listens"),
                )
                .expect("starts");
                assert!(
                    rx.recv_timeout(Duration::from_secs(1)).is_err(),
                    "a live participant's threads taken for ended"
                );
                drop(participant);
                let gone = rx
                    .recv_timeout(Duration::from_secs(20))
                    .expect("the end of the participant's threads seen");
                assert_eq!(gone, threads);
            },
        );
    }
}
