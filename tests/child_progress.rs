//! The child list and a child's progress read from a robot's stored sessions as the suite
//! writes them (`stored_sessions`: the game manager's session files and the recorder's bags):
//! 200 children with a session each, one child with 50 sessions (one of its runs' bags cut
//! short, another run without a bag; its decisions planned on a belief about the child) and
//! one with a single session. The list names every
//! child with its sessions and last date; the progress holds every session with the numbers
//! its session files and bags hold, each result once; the damaged and the missing bag are
//! named and the rest still shown; what the robot believes about the child is read from the
//! last session's decisions (and said to be missing where they carry none); erasing a child (`child_data`) takes it off the list and
//! deletes its progress report; the report (`session_report --user`, English and German) is
//! one self-contained page.

use child_sessions::{Belief, Language, Progress, UserId, children, progress_document};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The fifty-session child's runs: ten sessions each, run-001 .. run-005; run-002's bag is cut
/// short and run-004 has none.
const FIFTY: &str = "child-fifty";
const ONE: &str = "child-one";

fn stored(root: &Path) {
    let out = Command::new(env!("CARGO_BIN_EXE_stored_sessions"))
        .arg("--root")
        .arg(root)
        .args(["--children", "200", "--child", "child-fifty:50", "--child"])
        .arg(format!("{ONE}:1"))
        .args(["--planned-on-belief", FIFTY])
        .args(["--damaged-bag", "2", "--missing-bag", "4"])
        .output()
        .expect("stored_sessions runs");
    assert!(out.status.success(), "{out:?}");
}

/// The summary files of `user`'s sessions under `root`, as the game manager wrote them.
fn summaries(root: &Path, user: &str) -> Vec<serde_json::Value> {
    let mut found = Vec::new();
    for run in std::fs::read_dir(root).expect("root") {
        for f in std::fs::read_dir(run.expect("run").path()).expect("run dir") {
            let path = f.expect("file").path();
            if path.to_string_lossy().ends_with(".summary.json") {
                let v: serde_json::Value =
                    serde_json::from_str(&std::fs::read_to_string(&path).expect("read"))
                        .expect("JSON");
                if v["user_id"] == user {
                    found.push(v);
                }
            }
        }
    }
    found.sort_by_key(|v| v["started_ns"].as_i64());
    found
}

/// The suite's binaries' directory (`cargo build --workspace --bins`; tests/run.sh builds it).
fn bin(name: &str) -> PathBuf {
    let path = Path::new(env!("CARGO_BIN_EXE_stored_sessions")).with_file_name(name);
    assert!(
        path.exists(),
        "{} is not built: run `cargo build --workspace --bins` first (tests/run.sh does)",
        path.display()
    );
    path
}

/// A directory for the stored sessions: in memory where the machine has /dev/shm, since the
/// game manager's writer fsyncs every line (3,500 here: 20 s on this machine's disk, 0.7 s in
/// memory).
pub fn fast_temp_dir() -> tempfile::TempDir {
    let shm = Path::new("/dev/shm");
    let in_memory = shm
        .is_dir()
        .then(|| tempfile::tempdir_in(shm).ok())
        .flatten();
    in_memory.unwrap_or_else(|| tempfile::tempdir().expect("temp dir"))
}

#[test]
fn the_list_and_the_progress_are_read_from_what_is_stored() {
    let dir = fast_temp_dir();
    let root = dir.path().join("sessions");
    stored(&root);
    let places = [root.clone()];

    let list = children(&places).expect("the list");
    assert_eq!(list.children.len(), 202, "200 + the two");
    assert!(list.problems.is_empty(), "{:?}", list.problems);
    let of = |id: &str| list.children.iter().find(|c| c.user_id == id).expect(id);
    assert_eq!(of(FIFTY).sessions, 50);
    assert_eq!((of(ONE).sessions, of("child-200").sessions), (1, 1));
    // Dates: the fifty-session child played last (its 50th day).
    assert_eq!(list.children[0].user_id, FIFTY);

    let user = UserId::new(FIFTY).expect("id");
    let p = Progress::build(&user, &places).expect("progress");
    assert_eq!(p.sessions.len(), 50);
    let files = summaries(&root, FIFTY);
    for (s, summary) in p.sessions.iter().zip(&files) {
        // Every session whole from its files, even where the bag is cut short or missing,
        // each result once though the bag holds it too.
        assert_eq!(
            s.tally.sequences as u64,
            summary["sequences_played"].as_u64().expect("n")
        );
        assert_eq!(
            i64::from(s.tally.score),
            summary["score"].as_i64().expect("score")
        );
        assert_eq!(
            i64::from(s.tally.max_score),
            summary["max_score"].as_i64().expect("max")
        );
        assert_eq!(s.started_ns, summary["started_ns"].as_i64());
        let overrides = summary["overrides"].as_u64().expect("overrides") as usize;
        assert_eq!(s.overrides, overrides, "{}", s.session_id);
        let proposed = summary["proposals"].as_u64().expect("proposals") as u32;
        assert_eq!(s.proposals.map(|c| c.proposed), Some(proposed));
    }
    // Sessions 11..20 (run-002, bag cut short) and 31..40 (run-004, no bag).
    let decided = |k: usize| p.sessions[k - 1].decisions;
    assert!(decided(1).is_some_and(|d| d > 0));
    assert_eq!(decided(35), None, "run-004 has no bag");
    assert!(
        decided(12).is_some(),
        "what reads before the damage is used"
    );
    let pauses: usize = p.sessions.iter().map(|s| s.pauses).sum();
    assert_eq!(
        pauses, 13,
        "every fourth session paused once (sessions 2, 6, ..., 50)"
    );
    let named = |what: &str| p.problems.iter().any(|x| x.contains(what));
    assert!(
        named("run-002/session.mcap is damaged"),
        "{:#?}",
        p.problems
    );
    assert!(named("no bag in") && named("run-004"), "{:#?}", p.problems);
    assert!(p.problems.len() <= 3, "nothing else: {:#?}", p.problems);
    // The belief: from the fiftieth session (run-005 has its bag), its first and last
    // decisions, after the child's 49 sessions before it.
    let Belief::Carried(b) = &p.belief else {
        panic!("{:?}", p.belief);
    };
    assert_eq!(
        (b.session_number, b.session_id.as_str()),
        (50, p.sessions[49].session_id.as_str())
    );
    assert_eq!(Some(b.planned), p.sessions[49].decisions);
    assert!(b.left_table <= b.planned);
    assert_eq!(b.session_start.observations, 490);
    assert!(b.now.observations > b.session_start.observations);
    for (start, now) in b.session_start.levels.iter().zip(&b.now.levels) {
        assert!(now.success >= start.success && now.success_sd <= start.success_sd);
    }

    let en = progress_document(&p, Language::En, 0);
    let de = progress_document(&p, Language::De, 0);
    for (html, words) in [
        (
            &en,
            [
                "Progress of child-fifty",
                "What the robot believes now",
                "Level 1 (3 emotions): right about",
            ],
        ),
        (
            &de,
            [
                "Verlauf von child-fifty",
                "Was der Roboter jetzt annimmt",
                "Level 1 (3 Emotionen): etwa",
            ],
        ),
    ] {
        for w in words {
            assert!(html.contains(w), "{w}");
        }
        assert_eq!(html.matches("<tr data-session=").count(), 50);
        // Two figures across sessions, and the belief's.
        assert_eq!(html.matches("<svg role=\"img\"").count(), 3);
        assert!(
            html.contains("@page { size: A4"),
            "the print stylesheet is inlined"
        );
        assert!(
            !html.contains("<script") && !html.contains("src="),
            "nothing fetched"
        );
    }

    // One session, and none.
    let p = Progress::build(&UserId::new(ONE).expect("id"), &places).expect("progress");
    assert_eq!(p.sessions.len(), 1);
    assert_eq!(p.belief, Belief::NotCarried);
    let html = progress_document(&p, Language::En, 0);
    assert_eq!(html.matches("<tr data-session=").count(), 1);
    assert!(html.contains("Not available: the robot did not learn about this child"));
    let none = Progress::build(&UserId::new("child-new").expect("id"), &places).expect("none");
    assert!(none.sessions.is_empty() && none.problems.is_empty());
    assert!(progress_document(&none, Language::En, 0).contains("No session of this child"));

    // The installed command writes the same report.
    let out_file = dir.path().join("progress.html");
    let out = Command::new(bin("session_report"))
        .args(["--user", FIFTY, "--language", "de", "--sessions-root"])
        .arg(&root)
        .arg("--output")
        .arg(&out_file)
        .output()
        .expect("session_report runs");
    assert!(out.status.success(), "{out:?}");
    let written = std::fs::read_to_string(&out_file).expect("the report");
    assert!(
        written.contains("Verlauf von child-fifty")
            && written.contains("anders als die Tabelle der Gruppe")
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("is damaged"), "{stderr}");

    // Erased, the child is off the list, and its progress report kept with the runs is gone.
    let kept = root.join(format!("progress-{ONE}.html"));
    let out = Command::new(bin("session_report"))
        .args(["--user", ONE, "--sessions-root"])
        .arg(&root)
        .arg("--output")
        .arg(&kept)
        .output()
        .expect("session_report runs");
    assert!(out.status.success() && kept.is_file(), "{out:?}");
    let erased = Command::new(bin("child_data"))
        .args([
            "erase",
            "--user",
            ONE,
            "--yes",
            "--rewrite-damaged",
            "--data",
        ])
        .arg(&root)
        .output()
        .expect("child_data runs");
    assert_eq!(erased.status.code(), Some(0), "{erased:?}");
    assert!(
        !kept.exists(),
        "{}",
        String::from_utf8_lossy(&erased.stdout)
    );
    let list = children(&places).expect("the list");
    assert_eq!(list.children.len(), 201);
    assert!(list.children.iter().all(|c| c.user_id != ONE));
}
