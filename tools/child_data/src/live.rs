//! Whether a run of the suite is still live in a directory, so erase leaves a running session
//! and a bag being recorded alone:
//! - the game manager holds an exclusive `flock` on its sessions directory (the run
//!   directory) while it runs (`libs/instance_lock`); a probe that cannot take the lock finds
//!   it alive, and names its pid from `/proc/locks` (`instance_lock::holder`);
//! - between a game manager's crash and its respawn nobody holds the lock, but the launcher
//!   (`out:=<run>`, `--log-dir <run>/logs`) and the recorder (`--output <run>/session.mcap`)
//!   still name the directory in their command lines: any process whose arguments name the
//!   directory or a path in it counts as using it (this process and its parents, e.g. the
//!   `sudo` that started it, excepted).
//!
//! Erase holds the lock of every directory it changes until it is done, so no game manager
//! starts there meanwhile.

use std::fs::{File, TryLockError};
use std::path::{Component, Path, PathBuf};

/// Who keeps a directory live.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LiveBy {
    /// Its lock is held (by the game manager), by this pid if `/proc/locks` says.
    Lock(Option<u32>),
    /// A process whose command line names it (its program's name).
    Process { pid: u32, program: String },
}

impl std::fmt::Display for LiveBy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LiveBy::Lock(Some(pid)) => write!(f, "its lock is held by pid {pid} (a game manager)"),
            LiveBy::Lock(None) => write!(f, "its lock is held (by a game manager)"),
            LiveBy::Process { pid, program } => write!(f, "pid {pid} ({program}) uses it"),
        }
    }
}

/// A directory's lock, held by this process until dropped.
#[derive(Debug)]
pub struct DirLock {
    _file: File,
}

/// Takes `dir`'s lock as the game manager does, or says who holds it.
pub fn lock_dir(dir: &Path) -> Result<Result<DirLock, LiveBy>, std::io::Error> {
    let file = File::open(dir)?;
    match file.try_lock() {
        Ok(()) => Ok(Ok(DirLock { _file: file })),
        Err(TryLockError::WouldBlock) => Ok(Err(LiveBy::Lock(instance_lock::holder(dir)))),
        Err(TryLockError::Error(e)) => Err(e),
    }
}

/// Whether `dir`'s lock is held by someone else (taken and let go again if free).
pub fn lock_held(dir: &Path) -> Option<LiveBy> {
    match lock_dir(dir) {
        Ok(Err(by)) => Some(by),
        _ => None,
    }
}

/// The paths each running process names in its arguments.
#[derive(Debug, Default)]
pub struct Processes {
    /// (pid, program, paths its arguments name)
    list: Vec<(u32, String, Vec<PathBuf>)>,
}

impl Processes {
    /// Reads `/proc` once; a process that ends meanwhile or hides its details is skipped.
    pub fn scan() -> Processes {
        let me = std::process::id();
        let skip = ancestors(me);
        let mut list = Vec::new();
        let Ok(entries) = std::fs::read_dir("/proc") else {
            return Processes::default();
        };
        for entry in entries.flatten() {
            let Some(pid) = entry
                .file_name()
                .to_str()
                .and_then(|s| s.parse::<u32>().ok())
            else {
                continue;
            };
            if pid == me || skip.contains(&pid) {
                continue;
            }
            let Ok(raw) = std::fs::read(entry.path().join("cmdline")) else {
                continue;
            };
            let args: Vec<String> = raw
                .split(|b| *b == 0)
                .filter(|a| !a.is_empty())
                .map(|a| String::from_utf8_lossy(a).into_owned())
                .collect();
            if args.is_empty() {
                continue;
            }
            let cwd = std::fs::read_link(entry.path().join("cwd")).ok();
            let paths = args
                .iter()
                .flat_map(|a| path_candidates(a))
                .filter_map(|p| resolve(p, cwd.as_deref()))
                .collect();
            // The program's name is enough to tell the operator what runs there.
            let program = Path::new(&args[0])
                .file_name()
                .map_or_else(|| args[0].clone(), |n| n.to_string_lossy().into_owned());
            list.push((pid, program, paths));
        }
        Processes { list }
    }

    /// The processes naming `dir` or a path in it.
    pub fn using(&self, dir: &Path) -> Vec<LiveBy> {
        self.list
            .iter()
            .filter(|(_, _, paths)| paths.iter().any(|p| p.starts_with(dir)))
            .map(|(pid, program, _)| LiveBy::Process {
                pid: *pid,
                program: program.clone(),
            })
            .collect()
    }
}

/// What an argument may name: itself, and what follows `:=` or `=` (`out:=DIR`, `--output=F`).
fn path_candidates(arg: &str) -> Vec<&str> {
    let mut out = vec![arg];
    if let Some((_, v)) = arg.split_once(":=") {
        out.push(v);
    }
    if let Some((_, v)) = arg.split_once('=') {
        out.push(v);
    }
    out
}

/// An argument as an absolute, normalised path (relative ones from the process's working
/// directory); None for what cannot be a path.
fn resolve(arg: &str, cwd: Option<&Path>) -> Option<PathBuf> {
    if arg.is_empty() || arg.starts_with('-') && !arg.contains('/') {
        return None;
    }
    let p = Path::new(arg);
    let joined = if p.is_absolute() {
        p.to_path_buf()
    } else {
        cwd?.join(p)
    };
    if let Ok(c) = std::fs::canonicalize(&joined) {
        return Some(c);
    }
    let mut out = PathBuf::new();
    for part in joined.components() {
        match part {
            Component::ParentDir => {
                out.pop();
            }
            Component::CurDir => {}
            other => out.push(other),
        }
    }
    Some(out)
}

/// `pid`'s parents up to init, from `/proc/<pid>/stat` (the field after the command's `)`).
fn ancestors(pid: u32) -> Vec<u32> {
    let mut out = Vec::new();
    let mut at = pid;
    while let Some(parent) = std::fs::read_to_string(format!("/proc/{at}/stat"))
        .ok()
        .and_then(|s| {
            let rest = &s[s.rfind(')')? + 1..];
            rest.split_whitespace().nth(1)?.parse::<u32>().ok()
        })
    {
        if parent == 0 || out.contains(&parent) {
            break;
        }
        out.push(parent);
        at = parent;
    }
    out
}

/// What keeps the run directory `run` live: its lock and the processes naming it or a path
/// in it; empty when nothing does.
pub fn live_by(run: &Path, processes: &Processes) -> Vec<LiveBy> {
    let mut out = Vec::new();
    out.extend(lock_held(run));
    out.extend(processes.using(run));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    /// A child forked by one test holds a copy of every open file of this process until it
    /// execs (a flock belongs to the open file, so the copy keeps a lock the other test let
    /// go of: seen once under load). The tests that lock and the test that forks take turns.
    static FORK_OR_LOCK: Mutex<()> = Mutex::new(());

    #[test]
    fn a_held_lock_names_its_holder_and_a_free_one_is_taken() {
        let _turn = FORK_OR_LOCK.lock().unwrap_or_else(|e| e.into_inner());
        let dir = tempfile::tempdir().expect("temp dir");
        // The game manager's lock (a flock per open file, so in-process works).
        let held =
            instance_lock::InstanceLock::acquire(dir.path(), "game_manager", "session files")
                .expect("free");
        let by = lock_held(dir.path()).expect("held");
        assert_eq!(by, LiveBy::Lock(Some(std::process::id())));
        drop(held);
        assert!(lock_held(dir.path()).is_none());
        let mine = lock_dir(dir.path()).expect("opens").expect("free");
        assert!(lock_held(dir.path()).is_some());
        drop(mine);
    }

    #[test]
    fn a_process_naming_a_directory_uses_it() {
        let _turn = FORK_OR_LOCK.lock().unwrap_or_else(|e| e.into_inner());
        let dir = tempfile::tempdir().expect("temp dir");
        let run = dir.path().join("run-1");
        std::fs::create_dir_all(&run).expect("dir");
        let run = std::fs::canonicalize(&run).expect("canonical");
        // A stand-in for the launcher's command line (`launch FILE out:=<run>`).
        let mut child = std::process::Command::new("sh")
            .args(["-c", "sleep 30; :", "launch"])
            .arg(format!("out:={}", run.display()))
            .spawn()
            .expect("sh runs");
        // Until it has exec'd, the child's command line is still this test's.
        let cmdline = format!("/proc/{}/cmdline", child.id());
        for _ in 0..500 {
            if std::fs::read(&cmdline).is_ok_and(|c| c.starts_with(b"sh\0")) {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        let by = Processes::scan().using(&run);
        let other = Processes::scan().using(dir.path().join("run-2").as_path());
        child.kill().expect("kill");
        child.wait().expect("wait");
        assert!(
            by.iter()
                .any(|b| matches!(b, LiveBy::Process { pid, .. } if *pid == child.id())),
            "{by:?}"
        );
        assert!(other.is_empty(), "{other:?}");
        assert_eq!(path_candidates("out:=/a"), ["out:=/a", "/a", "/a"]);
    }
}
