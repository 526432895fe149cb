//! One process per state directory. A node that keeps its state in a directory (the behaviour
//! policy's Q-tables, the game manager's session files) holds an exclusive lock on that
//! directory while it runs, so a second copy started by mistake (a launch file run twice)
//! refuses to start rather than overwrite the first one's files or recover its session. The
//! lock is `flock` on the directory itself: no file is added to it, and the kernel drops the
//! lock when the process dies, even by SIGKILL, so a respawned node takes it at once.
//! [`holder`] names the process that holds it, for the node refused here and for the offline
//! tools (`child_data`) that must leave a live run alone. No DDS: a tool links it without the
//! node shell.

use std::fs::{File, TryLockError};
use std::path::{Path, PathBuf};

/// Why a node could not take its directory.
#[derive(Debug, thiserror::Error)]
pub enum InstanceLockError {
    #[error("no directory given (an empty path)")]
    Empty,
    #[error("cannot create {dir}: {source}")]
    Create {
        dir: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot open {dir} to lock it: {source}")]
    Open {
        dir: PathBuf,
        source: std::io::Error,
    },
    #[error(
        "{dir} is in use by another {node} ({holder}): two would overwrite each other's \
         {what}. Stop that one, or give this one another directory"
    )]
    Held {
        dir: PathBuf,
        node: String,
        holder: String,
        what: String,
    },
    #[error("cannot lock {dir}: {source}")]
    Lock {
        dir: PathBuf,
        source: std::io::Error,
    },
}

/// The lock on a node's state directory, held until this value is dropped (or the process
/// ends).
#[derive(Debug)]
pub struct InstanceLock {
    dir: PathBuf,
    _file: File,
}

impl InstanceLock {
    /// Creates `dir` if needed and locks it for `node`, whose state there is `what` (for the
    /// error a second copy gets, e.g. "Q-tables").
    pub fn acquire(dir: &Path, node: &str, what: &str) -> Result<Self, InstanceLockError> {
        if dir.as_os_str().is_empty() {
            return Err(InstanceLockError::Empty);
        }
        let dir_buf = dir.to_path_buf();
        std::fs::create_dir_all(dir).map_err(|source| InstanceLockError::Create {
            dir: dir_buf.clone(),
            source,
        })?;
        let file = File::open(dir).map_err(|source| InstanceLockError::Open {
            dir: dir_buf.clone(),
            source,
        })?;
        match file.try_lock() {
            Ok(()) => Ok(InstanceLock {
                dir: dir_buf,
                _file: file,
            }),
            Err(TryLockError::WouldBlock) => Err(InstanceLockError::Held {
                holder: holder(dir).map_or("another process".into(), |pid| format!("pid {pid}")),
                dir: dir_buf,
                node: node.into(),
                what: what.into(),
            }),
            Err(TryLockError::Error(source)) => Err(InstanceLockError::Lock {
                dir: dir_buf,
                source,
            }),
        }
    }

    /// The directory held.
    pub fn dir(&self) -> &Path {
        &self.dir
    }
}

/// The process holding a `flock` on `dir`, from `/proc/locks` (Linux), to name it in a
/// message. Lines read `1: FLOCK  ADVISORY  WRITE 1234 fd:01:5678 0 EOF`: the pid, then the
/// device (major:minor, hex) and the inode.
pub fn holder(dir: &Path) -> Option<u32> {
    use std::os::unix::fs::MetadataExt;
    let meta = std::fs::metadata(dir).ok()?;
    // glibc's major()/minor() of a dev_t.
    let dev = meta.dev();
    let major = ((dev >> 8) & 0xfff) | ((dev >> 32) & !0xfff);
    let minor = (dev & 0xff) | ((dev >> 12) & !0xff);
    let file = format!("{major:02x}:{minor:02x}:{}", meta.ino());
    let locks = std::fs::read_to_string("/proc/locks").ok()?;
    locks.lines().find_map(|line| {
        let fields: Vec<&str> = line.split_whitespace().collect();
        let (kind, pid, locked) = (fields.get(1)?, fields.get(4)?, fields.get(5)?);
        (*kind == "FLOCK" && *locked == file)
            .then(|| pid.parse().ok())
            .flatten()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_holder_is_refused_with_the_first_ones_pid_until_it_lets_go() {
        let root = tempfile::tempdir().expect("temp dir");
        let dir = root.path().join("q_tables");
        let first = InstanceLock::acquire(&dir, "behaviour_policy", "Q-tables").expect("free");
        assert!(dir.is_dir(), "made");
        assert_eq!(first.dir(), dir);

        // flock locks belong to the open file, so a second open in this process is refused
        // as another process's would be.
        let err =
            InstanceLock::acquire(&dir, "behaviour_policy", "Q-tables").expect_err("already held");
        let text = err.to_string();
        assert!(
            text.contains(&format!("pid {}", std::process::id())),
            "the holder named: {text}"
        );
        assert!(
            text.contains("in use by another behaviour_policy") && text.contains("Q-tables"),
            "{text}"
        );
        assert_eq!(
            std::fs::read_dir(&dir).expect("lists").count(),
            0,
            "no file added"
        );

        drop(first);
        InstanceLock::acquire(&dir, "behaviour_policy", "Q-tables").expect("free again");
    }

    #[test]
    fn a_file_or_an_empty_path_is_refused_with_why() {
        let root = tempfile::tempdir().expect("temp dir");
        let file = root.path().join("sessions");
        std::fs::write(&file, b"x").expect("writes");
        let err = InstanceLock::acquire(&file, "game_manager", "session files")
            .expect_err("not a directory");
        assert!(err.to_string().contains("sessions"), "{err}");
        let err = InstanceLock::acquire(Path::new(""), "game_manager", "session files")
            .expect_err("empty");
        assert_eq!(err.to_string(), "no directory given (an empty path)");
    }
}
