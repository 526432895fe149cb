//! Q-tables on disk: one versioned JSON file per cluster or user, a row per state that names
//! its (L, F, PS). Written through a temporary file and a rename, so a reader never sees half
//! a table; a corrupt or wrong-version file is refused with its path and the field at fault.

use crate::learning::QTable;
use sequence_game::{ACTION_COUNT, STATE_COUNT, State};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;
use versioned_json::{FileError, Kind};

pub const FORMAT: &str = "qt_therapy q_table";
pub const VERSION: u32 = 1;
/// The file's kind, read and written as the suite's other versioned files (`versioned_json`).
pub const KIND: Kind = Kind {
    format: FORMAT,
    version: VERSION,
    name: "Q-table",
};

#[derive(Debug, thiserror::Error)]
pub enum QTableError {
    /// The file, its layout or a field of it (named), as read or written.
    #[error(transparent)]
    File(#[from] FileError),
    #[error("user id {0:?} cannot name a file: use letters, digits, '-' and '_' only")]
    UserId(String),
}

/// Whose table it is: a cluster's (shared by its users) or one user's.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum QTableOwner {
    Cluster(usize),
    User(String),
}

impl QTableOwner {
    /// `cluster_<k>.json` or `user_<id>.json`.
    pub fn file_name(&self) -> Result<String, QTableError> {
        match self {
            QTableOwner::Cluster(k) => Ok(format!("cluster_{k}.json")),
            QTableOwner::User(id) => {
                let ok = !id.is_empty()
                    && id.len() <= 64
                    && id
                        .chars()
                        .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
                if ok {
                    Ok(format!("user_{id}.json"))
                } else {
                    Err(QTableError::UserId(id.chars().take(80).collect()))
                }
            }
        }
    }
}

impl std::fmt::Display for QTableOwner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            QTableOwner::Cluster(k) => write!(f, "cluster {k}"),
            QTableOwner::User(u) => write!(f, "user {u}"),
        }
    }
}

/// One state's row as stored.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StateRow {
    pub level: u8,
    pub feedback: u8,
    pub previous_score: i8,
    pub q: [f64; ACTION_COUNT],
    pub visits: u32,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Stored {
    format: String,
    version: u32,
    owner: QTableOwner,
    provenance: String,
    updates: u64,
    /// Absent in files written before it existed: nothing learned live yet.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    learned: BTreeMap<String, u8>,
    states: Vec<StateRow>,
}

/// A Q-table with whose it is and where it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct QTableFile {
    pub owner: QTableOwner,
    /// How it came about (pretraining, transfer, live sessions).
    pub provenance: String,
    /// Updates applied since it was created.
    pub updates: u64,
    /// Per session, the highest sequence index learned from: a respawned policy is sent the
    /// results again (transient-local) and must learn each only once.
    pub learned: BTreeMap<String, u8>,
    pub table: QTable,
}

impl QTableFile {
    pub fn load(path: &Path) -> Result<QTableFile, QTableError> {
        let stored: Stored = KIND.load(path)?;
        QTableFile::from_stored(stored, path)
    }

    /// As [`QTableFile::load`], from the file's text (`path` only names it in errors).
    pub fn from_json_str(text: &str, path: &Path) -> Result<QTableFile, QTableError> {
        let stored: Stored = KIND.from_json_str(text, path)?;
        QTableFile::from_stored(stored, path)
    }

    /// The table of a file that has the layout: every state once, every Q-value finite.
    fn from_stored(stored: Stored, path: &Path) -> Result<QTableFile, QTableError> {
        let field = |field: String, reason: String| FileError::field(path, field, reason);
        if stored.states.len() != STATE_COUNT {
            return Err(field(
                "states".into(),
                format!("has {} rows, expected {STATE_COUNT}", stored.states.len()),
            )
            .into());
        }
        let mut table = QTable::default();
        let mut seen = [false; STATE_COUNT];
        for (i, row) in stored.states.iter().enumerate() {
            let at = |reason: String| field(format!("states[{i}]"), reason);
            let state = State::new(
                row.level.into(),
                row.feedback.into(),
                row.previous_score.into(),
            )
            .map_err(|e| at(e.to_string()))?;
            if std::mem::replace(&mut seen[state.index()], true) {
                return Err(at(format!("{state} appears twice")).into());
            }
            if let Some(q) = row.q.iter().find(|q| !q.is_finite()) {
                return Err(at(format!("Q-value {q} of {state} is not finite")).into());
            }
            table.q[state.index()] = row.q;
            table.visits[state.index()] = row.visits;
        }
        Ok(QTableFile {
            owner: stored.owner,
            provenance: stored.provenance,
            updates: stored.updates,
            learned: stored.learned,
            table,
        })
    }

    /// Writes atomically: the old file stays whole until the new one is complete and synced.
    pub fn save(&self, path: &Path) -> Result<(), QTableError> {
        let stored = Stored {
            format: FORMAT.into(),
            version: VERSION,
            owner: self.owner.clone(),
            provenance: self.provenance.clone(),
            updates: self.updates,
            learned: self.learned.clone(),
            states: State::all()
                .map(|s| StateRow {
                    level: s.level,
                    feedback: s.feedback as u8,
                    previous_score: s.previous_score,
                    q: self.table.q[s.index()],
                    visits: self.table.visits[s.index()],
                })
                .collect(),
        };
        Ok(KIND.save(path, &stored)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> QTableFile {
        let mut table = QTable::default();
        table.q[5][2] = 1.25;
        table.q[63][4] = -0.1 / 3.0;
        table.visits[5] = 17;
        QTableFile {
            owner: QTableOwner::Cluster(1),
            provenance: "test".into(),
            updates: 3,
            learned: BTreeMap::from([("session-1".to_string(), 4)]),
            table,
        }
    }

    #[test]
    fn round_trips_exactly() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("cluster_1.json");
        sample().save(&path).expect("saves");
        assert_eq!(QTableFile::load(&path).expect("loads"), sample());
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&path)
                .expect("metadata")
                .permissions()
                .mode();
            assert_eq!(mode & 0o777, 0o644);
        }
    }

    #[test]
    fn broken_files_are_refused_by_name() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("cluster_1.json");
        sample().save(&path).expect("saves");
        let good = std::fs::read_to_string(&path).expect("read");
        let cases = [
            (good[..good.len() / 2].to_string(), "not JSON"),
            (
                good.replace("\"version\": 1", "\"version\": 7"),
                "version 7",
            ),
            (good.replace(FORMAT, "something else"), "field format"),
            (good.replacen("\"level\": 1", "\"level\": 4", 1), "states["),
            (good.replacen("1.25", "\"x\"", 1), "field states[5].q[2]"),
            (
                good.replacen("\"visits\": 17", "\"visits\": 17, \"more\": 1", 1),
                "more",
            ),
        ];
        for (text, words) in cases {
            std::fs::write(&path, &text).expect("write");
            let e = QTableFile::load(&path).expect_err(words);
            let shown = e.to_string();
            assert!(shown.contains("cluster_1.json"), "{shown}");
            assert!(shown.contains(words), "{shown} lacks {words:?}");
            // Loading never writes.
            assert_eq!(std::fs::read_to_string(&path).expect("read"), text);
        }
    }

    #[test]
    fn owners_name_their_files() {
        assert_eq!(
            QTableOwner::Cluster(2).file_name().expect("name"),
            "cluster_2.json"
        );
        assert_eq!(
            QTableOwner::User("P-07_a".into())
                .file_name()
                .expect("name"),
            "user_P-07_a.json"
        );
        for bad in ["", "../etc", "a b", "x/y"] {
            assert!(QTableOwner::User(bad.into()).file_name().is_err(), "{bad}");
        }
    }
}
