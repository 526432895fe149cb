//! What can stop a listing, an export or an erase, each error naming the file or value at fault.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum ChildDataError {
    /// A user id that cannot be a child's, or a place that is not there.
    #[error(transparent)]
    Stored(#[from] child_sessions::StoredError),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(transparent)]
    Bag(#[from] bag_file::BagError),
    #[error("{path}: {reason}")]
    Csv { path: PathBuf, reason: String },
    #[error("{path} changed since it was listed ({what}): run the command again")]
    Changed { path: PathBuf, what: String },
    #[error("{path} already exists: give another --output, or move that file away first")]
    OutputExists { path: PathBuf },
    #[error("writing the archive {path}: {reason}")]
    Archive { path: PathBuf, reason: String },
}

impl ChildDataError {
    pub(crate) fn io(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> ChildDataError {
        let path = path.into();
        move |source| ChildDataError::Io { path, source }
    }
}
