//! The power-cut test's harness: a file system that records every write and sync of every
//! process under its mount point ([`fs`], over FUSE), and rebuilds what a power cut after any
//! one of them would leave on disk ([`cut`], the weakest POSIX guarantees). A test mounts it,
//! makes what is there durable ([`Mounted::baseline`]), runs a session, and checks every cut
//! point of the log ([`Mounted::log`]) against its promises.
//!
//! Mounting needs root and `/dev/fuse` ([`can_mount`]); fuser mounts with mount(2) itself, so
//! neither libfuse nor fusermount is needed.

pub mod cut;
pub mod fs;

use cut::{Op, Tree};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// Whether this machine can mount the recording file system (root, `/dev/fuse`), and if not,
/// why.
pub fn can_mount() -> Result<(), String> {
    if !Path::new("/dev/fuse").exists() {
        return Err("no /dev/fuse on this machine".into());
    }
    let uid = std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("Uid:"))
                .and_then(|l| l.split_whitespace().next().map(str::to_string))
        });
    if uid.as_deref() != Some("0") {
        return Err("mounting a FUSE file system needs root".into());
    }
    Ok(())
}

/// The recording file system, mounted; unmounted when dropped.
pub struct Mounted {
    state: Arc<Mutex<fs::State>>,
    point: PathBuf,
    session: Option<fuser::BackgroundSession>,
}

impl Mounted {
    /// Mounts an empty recording file system on the directory `point`.
    pub fn mount(point: &Path) -> std::io::Result<Mounted> {
        let (fs, state) = fs::RecordingFs::new();
        let mut config = fuser::Config::default();
        config
            .mount_options
            .push(fuser::MountOption::FSName("power_cut".into()));
        // One thread: the log's order is the order the operations were carried out.
        config.n_threads = Some(1);
        let session = fuser::spawn_mount(fs, point, &config)?;
        Ok(Mounted {
            state,
            point: point.to_path_buf(),
            session: Some(session),
        })
    }

    /// The mount point.
    pub fn point(&self) -> &Path {
        &self.point
    }

    fn state(&self) -> std::sync::MutexGuard<'_, fs::State> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Takes what is there now as durable (as `sync` would) and starts an empty log; returns
    /// that tree.
    pub fn baseline(&self) -> Tree {
        let mut s = self.state();
        s.log.clear();
        s.tree.clone()
    }

    /// The operations logged since the baseline, in order.
    pub fn log(&self) -> Vec<Op> {
        self.state().log.clone()
    }
}

impl Drop for Mounted {
    fn drop(&mut self) {
        if let Some(s) = self.session.take() {
            let _ = s.umount_and_join();
        }
    }
}
