//! What stops reading a child's stored sessions, each error naming the value or path at fault.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum StoredError {
    #[error("user id {id:?} {reason}")]
    UserId { id: String, reason: String },
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path} does not exist: nothing to search there")]
    Missing { path: PathBuf },
}

impl StoredError {
    pub fn io(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> StoredError {
        let path = path.into();
        move |source| StoredError::Io { path, source }
    }
}
