//! Q-tables on disk: one versioned JSON file per cluster (or user), written through a temporary
//! file and a rename after every update, so a crash loses nothing already learned and a reader
//! never sees half a table.

use crate::learning::QTable;
use sequence_game::{ACTION_COUNT, STATE_COUNT};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

pub const FORMAT: &str = "qt_therapy q_table";
pub const VERSION: u32 = 1;

#[derive(Debug, thiserror::Error)]
pub enum QTableError {
    #[error("{path}: {reason}")]
    File { path: PathBuf, reason: String },
    #[error("{path} is q_table format version {found}; this program reads version {VERSION}")]
    Version { path: PathBuf, found: u64 },
}

/// The file's content.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct QTableFile {
    pub format: String,
    pub version: u32,
    /// The cluster (or user) this table is for.
    pub owner: String,
    /// How it came about (pretraining, sessions learned from).
    pub provenance: String,
    pub updates: u64,
    pub table: QTable,
}

impl QTableFile {
    pub fn new(owner: &str, provenance: &str, table: QTable) -> Self {
        QTableFile {
            format: FORMAT.into(),
            version: VERSION,
            owner: owner.into(),
            provenance: provenance.into(),
            updates: 0,
            table,
        }
    }

    pub fn load(path: &Path) -> Result<QTableFile, QTableError> {
        let bad = |reason: String| QTableError::File {
            path: path.into(),
            reason,
        };
        let text = std::fs::read_to_string(path).map_err(|e| bad(e.to_string()))?;
        let value: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| bad(format!("not JSON (truncated?): {e}")))?;
        if value.get("format").and_then(|f| f.as_str()) != Some(FORMAT) {
            return Err(bad(format!(
                "not a Q-table file (its \"format\" is not {FORMAT:?})"
            )));
        }
        let found = value.get("version").and_then(|v| v.as_u64()).unwrap_or(0);
        if found != u64::from(VERSION) {
            return Err(QTableError::Version {
                path: path.into(),
                found,
            });
        }
        let file: QTableFile = serde_json::from_value(value).map_err(|e| bad(e.to_string()))?;
        if file.table.q.len() != STATE_COUNT || file.table.visits.len() != STATE_COUNT {
            return Err(bad(format!(
                "the table has {} states, expected {STATE_COUNT}",
                file.table.q.len()
            )));
        }
        if let Some((s, _)) = file
            .table
            .q
            .iter()
            .enumerate()
            .find(|(_, row)| row.iter().any(|q| !q.is_finite()))
        {
            return Err(bad(format!("Q-values of state {s} are not finite")));
        }
        let _ = ACTION_COUNT;
        Ok(file)
    }

    /// Writes atomically; the old file stays whole until the new one is complete.
    pub fn save(&self, path: &Path) -> Result<(), QTableError> {
        let bad = |reason: String| QTableError::File {
            path: path.into(),
            reason,
        };
        let text = serde_json::to_string(self).map_err(|e| bad(e.to_string()))?;
        let dir = path
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        std::fs::create_dir_all(dir).map_err(|e| bad(e.to_string()))?;
        let tmp = tempfile::NamedTempFile::new_in(dir).map_err(|e| bad(e.to_string()))?;
        std::fs::write(tmp.path(), text).map_err(|e| bad(e.to_string()))?;
        tmp.as_file().sync_all().map_err(|e| bad(e.to_string()))?;
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(tmp.path(), std::fs::Permissions::from_mode(0o644))
            .map_err(|e| bad(e.to_string()))?;
        tmp.persist(path).map_err(|e| bad(e.error.to_string()))?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_and_refuses_broken_files_without_touching_them() {
        let dir = std::env::temp_dir().join(format!("qtable_{}", std::process::id()));
        let path = dir.join("cluster_0.json");
        let mut f = QTableFile::new("cluster 0", "test", QTable::default());
        f.table.q[5][2] = 1.25;
        f.save(&path).expect("saves");
        assert_eq!(QTableFile::load(&path).expect("loads"), f);
        let good = std::fs::read_to_string(&path).expect("read");
        std::fs::write(&path, &good[..good.len() / 2]).expect("truncate");
        let e = QTableFile::load(&path).expect_err("truncated");
        assert!(e.to_string().contains("cluster_0.json"), "{e}");
        std::fs::write(&path, good.replace("\"version\":1", "\"version\":7")).expect("write");
        assert!(matches!(
            QTableFile::load(&path),
            Err(QTableError::Version { found: 7, .. })
        ));
        let _ = std::fs::remove_dir_all(dir);
    }
}
