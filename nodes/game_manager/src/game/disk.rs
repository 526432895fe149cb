//! The disk of the session files and the bag, as the core sees it: the free space the node
//! measures (`Input::DiskSpace`) and the session-file writes it keeps in memory for want of
//! room (`Input::FilesUnsaved`). Either puts a warning first in GameState.status (the therapist
//! page shows it in its own element: `GameState::disk_warning`); below `disk_floor_free_mb` a
//! START is refused, naming the disk. A full disk never stops a session: it goes on, and what
//! could not be written is written once there is room.

use super::GameManager;
use crate::protocol::LogLevel;

/// What the core knows of the disk.
#[derive(Debug, Clone, Default)]
pub(super) struct DiskWatch {
    /// Free bytes, as last measured (none yet: no warning, no refusal).
    free: Option<u64>,
    /// Session-file writes kept in memory, and why.
    unsaved: usize,
    reason: String,
    /// The warning last shown, to tell the operator once per change.
    shown: Option<String>,
}

fn mb(bytes: u64) -> String {
    format!("{:.1} MB", bytes as f64 / 1e6)
}

fn bytes(mb: f64) -> u64 {
    (mb * 1e6).round() as u64
}

impl GameManager {
    pub(super) fn on_disk_space(&mut self, free: u64, now: i64) {
        self.disk.free = Some(free);
        self.disk_changed(now);
    }

    pub(super) fn on_files_unsaved(&mut self, unsaved: usize, reason: String, now: i64) {
        if unsaved == 0 && self.disk.unsaved > 0 {
            self.log(
                LogLevel::WARN,
                format!(
                    "disk: the {} session-file writes kept in memory are on disk now",
                    self.disk.unsaved
                ),
            );
        }
        self.disk.unsaved = unsaved;
        self.disk.reason = reason;
        self.disk_changed(now);
    }

    /// Shows a new warning (or its end) at once, and tells the operator.
    fn disk_changed(&mut self, now: i64) {
        let warning = self.disk_warning();
        if warning == self.disk.shown {
            return;
        }
        match &warning {
            Some(w) => self
                .out
                .push(crate::protocol::Output::Alarm(format!("disk: {w}"))),
            None => self.log(LogLevel::INFO, "disk: enough free space again".into()),
        }
        self.disk.shown = warning;
        self.publish_state(now);
    }

    /// The warning GameState.status starts with, if the disk is full or low.
    pub(super) fn disk_warning(&self) -> Option<String> {
        let dir = &self.params.files.sessions_dir;
        if self.disk.unsaved > 0 {
            return Some(format!(
                "full in {dir}: {} session-file writes kept in memory until there is room \
                 ({}), the session goes on",
                self.disk.unsaved, self.disk.reason
            ));
        }
        let free = self.disk.free?;
        let warn = self.params.disk.disk_warning_free_mb;
        (free < bytes(warn)).then(|| {
            format!(
                "{} free in {dir}, below {warn} MB: delete old bags or reports",
                mb(free)
            )
        })
    }

    /// Why a session cannot start for want of disk space, if it cannot.
    pub(super) fn disk_refusal(&self) -> Option<String> {
        let dir = &self.params.files.sessions_dir;
        if self.disk.unsaved > 0 {
            return Some(format!(
                "the disk is full: {} session-file writes in {dir} wait for room; free space, \
                 then start",
                self.disk.unsaved
            ));
        }
        let free = self.disk.free?;
        let floor = self.params.disk.disk_floor_free_mb;
        (free < bytes(floor)).then(|| {
            format!(
                "too little disk space to record a session: {} free in {dir}, below the floor \
                 of {floor} MB (disk_floor_free_mb); free space (old bags, reports), then start",
                mb(free)
            )
        })
    }
}
