//! A full disk, on a small ext4 file system of its own (a loop device, as root): the main job
//! in process (`in_process/suite.rs`) writes its bag, session files and Q-tables there.
//! - The disk fills mid-session (a file written until ENOSPC after sequence 3, deleted after
//!   sequence 6): the session goes on to its end, the recorder and the game manager keep
//!   running, the therapist page and GameState name the disk while it is full, and once there
//!   is room again every record is written, in order, and the bag goes on; nothing written
//!   before is damaged.
//! - Below the floor a START is refused, naming the disk and the floor.
//! - Old runs' bags over the budget are deleted, oldest first, so a START can go ahead;
//!   session files, Q-tables and the running session's directory are kept.
//!
//! Needs root (mount): skipped without it, failed under QT_REQUIRE_ALL_TESTS.

// The in-process suite's helpers; this test uses some of them.
#[allow(dead_code)]
#[path = "in_process/suite.rs"]
mod suite;

use bag_file::BagReader;
use game_manager::session_file::read_records;
use qt_therapy_msgs::topics::{GAME_STATE, SEQUENCE_RESULT};
use qt_therapy_msgs::{GameState, SequenceResult};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;
use suite::{Node, Setup, Suite, virtual_time};

/// A small ext4 file system on a loop device, unmounted when dropped.
struct SmallDisk {
    _dir: tempfile::TempDir,
    mnt: PathBuf,
}

impl SmallDisk {
    /// `mb` megabytes, no blocks reserved for root (the test runs as root).
    fn new(mb: u32) -> Result<SmallDisk, String> {
        let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
        let img = dir.path().join("disk.img");
        let mnt = dir.path().join("mnt");
        std::fs::create_dir(&mnt).map_err(|e| e.to_string())?;
        std::fs::File::create(&img)
            .and_then(|f| f.set_len(u64::from(mb) << 20))
            .map_err(|e| e.to_string())?;
        let run = |cmd: &mut Command| -> Result<(), String> {
            let out = cmd.output().map_err(|e| format!("{cmd:?}: {e}"))?;
            if out.status.success() {
                Ok(())
            } else {
                Err(format!(
                    "{cmd:?}: {}",
                    String::from_utf8_lossy(&out.stderr).trim()
                ))
            }
        };
        run(Command::new("mkfs.ext4")
            .args(["-q", "-F", "-m", "0"])
            .arg(&img))?;
        run(Command::new("mount")
            .args(["-o", "loop"])
            .arg(&img)
            .arg(&mnt))?;
        Ok(SmallDisk { _dir: dir, mnt })
    }

    fn free(&self) -> u64 {
        atomic_file::disk_space(&self.mnt).expect("statvfs").free
    }

    /// Writes `path` until the disk is full, less `leave` bytes.
    fn fill(&self, path: &Path, leave: u64) {
        let mut f = std::fs::File::create(path).expect("the filler");
        let mut chunk = 1usize << 16;
        while chunk > 0 {
            let free = self.free();
            if free <= leave {
                break;
            }
            let n = chunk.min((free - leave) as usize);
            match f.write_all(&vec![0u8; n]).and_then(|()| f.sync_data()) {
                Ok(()) => {}
                Err(_) => chunk /= 4,
            }
        }
    }
}

impl Drop for SmallDisk {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.mnt).status();
    }
}

/// Whether this machine can mount a loop device here (root, mkfs.ext4), and if not, why.
fn small_disk(mb: u32) -> Option<SmallDisk> {
    let why = match SmallDisk::new(mb) {
        Ok(d) => return Some(d),
        Err(e) => e,
    };
    if loopback_netns::skip_or_fail(&format!(
        "a small file system on a loop device cannot be made here (root and mkfs.ext4 needed): \
         {why}"
    )) {
        return None;
    }
    None
}

fn game_manager_params(setup: &mut Setup, params: &[&str]) {
    setup.more.insert(
        Node::GameManager,
        params.iter().map(|p| p.to_string()).collect(),
    );
}

#[test]
fn a_disk_full_mid_session_is_told_and_the_session_goes_on_and_loses_nothing() {
    let Some(disk) = small_disk(8) else { return };
    let out = disk.mnt.join("sessions/20260302-090000");
    let filler = disk.mnt.join("filler");
    let mut setup = Setup::default();
    game_manager_params(
        &mut setup,
        &[
            "disk_warning_free_mb:=0.5",
            "disk_floor_free_mb:=0.2",
            "disk_check_interval_s:=2.0",
        ],
    );
    let (code, lines, states, page_warnings, results_published) = virtual_time(async {
        let mut suite = Suite::new(&out, setup);
        suite.start_all();
        let (mut probe, _) = suite.join("disk_probe");
        let mut states = node_shell::Bus::subscribe(&mut probe, GAME_STATE, 4096).expect("states");
        let mut results =
            node_shell::Bus::subscribe(&mut probe, SEQUENCE_RESULT, 64).expect("results");
        let mut page = suite.page(tablet_bridge::protocol::Role::Therapist).await;
        page.send(serde_json::json!({"type": "login", "pin": "1234"}))
            .await;
        let therapist = suite.run_session(None, false, 1);
        therapist
            .wait_for_line("seq  3/", Duration::from_secs(600))
            .await;
        disk.fill(&filler, 0);
        therapist
            .wait_for_line("seq  6/", Duration::from_secs(600))
            .await;
        std::fs::remove_file(&filler).expect("room again");
        let (code, lines) = therapist.exit().await;
        // The disk's next look writes what waited (every 2 s).
        tokio::time::sleep(Duration::from_secs(5)).await;
        suite.stop_all().await;
        let mut seen = Vec::new();
        while let Ok(s) = states.try_recv() {
            seen.push(s);
        }
        let mut published = Vec::new();
        while let Ok(r) = results.try_recv() {
            published.push(r);
        }
        page.read();
        let warnings: Vec<String> = page
            .seen
            .iter()
            .filter(|m| m["type"] == "game")
            .filter_map(|m| m["disk_warning"].as_str().map(str::to_string))
            .filter(|w| !w.is_empty())
            .collect();
        (code, lines, seen, warnings, published)
    });
    let context = lines.join("\n");
    assert_eq!(code, 0, "the session finished:\n{context}");
    // GameState named the disk while it was full (not a lost node), and the page showed it.
    let full: Vec<&GameState> = states
        .iter()
        .filter(|s| GameState::disk_warning(&s.status).is_some_and(|w| w.starts_with("full in")))
        .collect();
    assert!(!full.is_empty(), "no GameState said the disk was full");
    assert!(
        states.iter().all(|s| !s.status.contains("node lost")),
        "a node was lost: {:?}",
        states.iter().find(|s| s.status.contains("node lost"))
    );
    assert!(
        page_warnings.iter().any(|w| w.starts_with("full in")),
        "the therapist page showed no disk warning: {page_warnings:?}"
    );
    let last = states.last().expect("states");
    assert_eq!(last.phase, GameState::FINISHED, "{}", last.status);
    assert!(
        GameState::disk_warning(&last.status).is_none(),
        "the warning is gone once there is room: {}",
        last.status
    );
    // Every record is on disk, whole and in order, as published; the summary too.
    let stem = std::fs::read_dir(&out)
        .expect("out")
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .find_map(|n| n.strip_suffix(".summary.json").map(str::to_string))
        .expect("the summary was written once there was room");
    let file = read_records(&out.join(format!("{stem}.jsonl"))).expect("the session file");
    assert!(!file.torn_tail);
    let indices: Vec<u8> = file
        .records
        .iter()
        .map(|r| r.result.sequence_index)
        .collect();
    assert_eq!(indices, (1..=10).collect::<Vec<u8>>());
    let on_disk: Vec<SequenceResult> = file.records.iter().map(|r| r.result.clone()).collect();
    assert_eq!(on_disk, results_published);
    // The Q-table learned every sequence (kept in memory while the disk was full).
    let q = q_learning::q_table_file::QTableFile::load(&out.join("q_tables/cluster_0.json"))
        .expect("the Q-table is whole");
    assert_eq!(q.learned.get(&file.records[0].result.session_id), Some(&10));
    // The bag: finished, undamaged, the results on disk before the disk filled (the second
    // before it, not yet in a closed chunk, may be missing) and those after it had room.
    let bag = BagReader::open(&out.join("session.mcap")).expect("the finished bag");
    assert!(bag.damage().is_none(), "{:?}", bag.damage());
    let in_bag: Vec<SequenceResult> = bag
        .messages::<SequenceResult>(SEQUENCE_RESULT.name)
        .expect("results")
        .into_iter()
        .map(|m| m.message)
        .collect();
    for r in &in_bag {
        assert_eq!(Some(r), on_disk.get(usize::from(r.sequence_index) - 1));
    }
    let bagged: Vec<u8> = in_bag.iter().map(|r| r.sequence_index).collect();
    for i in [1, 2, 9, 10] {
        assert!(
            bagged.contains(&i),
            "result {i} is not in the bag: {bagged:?}"
        );
    }
    println!(
        "disk full: the bag holds results {bagged:?}; {} GameStates named the full disk",
        full.len()
    );
}

#[test]
fn below_the_floor_a_start_is_refused_and_old_bags_make_room() {
    let Some(disk) = small_disk(8) else { return };
    let sessions = disk.mnt.join("sessions");
    // Two old runs, each a bag of 1.5 MB and its session file.
    for run in ["20260301-090000", "20260301-140000"] {
        let dir = sessions.join(run);
        std::fs::create_dir_all(&dir).expect("an old run");
        std::fs::write(dir.join("session.mcap"), vec![7u8; 1_500_000]).expect("an old bag");
        std::fs::write(dir.join("s-1.jsonl"), b"{}\n").expect("an old session file");
    }
    let out = sessions.join("20260302-090000");
    let base = [
        "disk_warning_free_mb:=1.2",
        "disk_floor_free_mb:=1.0",
        "disk_check_interval_s:=2.0",
    ];
    // Without retention, a disk with less than the floor free refuses the START.
    let mut setup = Setup::default();
    game_manager_params(&mut setup, &base);
    let filler = disk.mnt.join("filler");
    let (code, lines) = virtual_time(async {
        let mut suite = Suite::new(&out, setup);
        disk.fill(&filler, 500_000);
        suite.start_all();
        let r = suite.run_session(None, false, 1).exit().await;
        suite.stop_all().await;
        r
    });
    let context = lines.join("\n");
    assert_eq!(code, 4, "refused:\n{context}");
    assert!(
        context.contains("too little disk space to record a session")
            && context.contains("below the floor of 1 MB"),
        "{context}"
    );
    // With retention over the sessions directory: the oldest bag goes, the start goes ahead.
    let mut setup = Setup::default();
    let retention = format!("retention_dir:={}", sessions.display());
    let mut params = base.to_vec();
    params.push(&retention);
    params.push("retention_budget_mb:=100.0");
    game_manager_params(&mut setup, &params);
    let (code, lines) = virtual_time(async {
        let mut suite = Suite::new(&out, setup);
        disk.fill(&filler, 500_000);
        suite.start_all();
        let r = suite.run_session(None, false, 1).exit().await;
        suite.stop_all().await;
        r
    });
    assert_eq!(code, 0, "the session ran:\n{}", lines.join("\n"));
    let old = sessions.join("20260301-090000");
    assert!(!old.join("session.mcap").exists(), "the oldest bag went");
    assert!(old.join("s-1.jsonl").exists(), "its session file stays");
    assert!(
        sessions.join("20260301-140000/session.mcap").exists(),
        "the newer bag stays: one was enough"
    );
    assert!(out.join("session.mcap").exists() && out.join("q_tables/cluster_0.json").exists());
}
