//! Whole-file writes for everything the suite saves (models, Q-tables, session summaries, CSV,
//! figures, reports): a reader sees the old file or the new one, never half of one, and once
//! `write` returns the new file survives a power cut.
//!
//! The bytes go to a temporary file beside the target (a rename is atomic only within one file
//! system), are fsync'd, renamed over the target, and the directory is fsync'd so the rename
//! itself is on disk. The file is created readable by all (0644 before the umask), as a plain
//! `File::create` would make it: tempfile's private 0600 would hide models and Q-tables from
//! the other nodes' users.

use std::io::Write;
use std::path::Path;

/// Replaces `path` with `bytes` atomically and durably, creating missing parent directories.
/// On error the target is unchanged and no temporary file is left behind.
pub fn write(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    std::fs::create_dir_all(dir)?;
    let mut builder = tempfile::Builder::new();
    // A dot name says what the leftover of a killed writer was meant to become.
    let prefix = format!(
        ".{}.",
        path.file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    );
    builder.prefix(&prefix).suffix(".tmp");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o644));
    }
    let mut tmp = builder.tempfile_in(dir)?;
    tmp.write_all(bytes)?;
    tmp.as_file().sync_all()?;
    tmp.persist(path).map_err(|e| e.error)?;
    sync_dir(dir)
}

#[cfg(unix)]
fn sync_dir(dir: &Path) -> std::io::Result<()> {
    std::fs::File::open(dir)?.sync_all()
}

#[cfg(not(unix))]
fn sync_dir(_dir: &Path) -> std::io::Result<()> {
    // Directories cannot be opened as files there; the rename is as durable as it gets.
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entries(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .expect("lists the directory")
            .map(|e| {
                e.expect("an entry")
                    .file_name()
                    .to_string_lossy()
                    .into_owned()
            })
            .collect();
        names.sort();
        names
    }

    #[test]
    fn replaces_the_whole_file_and_leaves_no_temporary_file() {
        let dir = tempfile::tempdir().expect("a temporary directory");
        let path = dir.path().join("q_table.json");
        write(&path, b"a longer first version").expect("first write");
        write(&path, b"second").expect("second write");
        assert_eq!(std::fs::read(&path).expect("reads back"), b"second");
        assert_eq!(entries(dir.path()), ["q_table.json"]);
    }

    #[test]
    fn creates_missing_directories() {
        let dir = tempfile::tempdir().expect("a temporary directory");
        let path = dir.path().join("out/figures/curve.svg");
        write(&path, b"<svg/>").expect("writes");
        assert_eq!(std::fs::read(&path).expect("reads back"), b"<svg/>");
    }

    #[cfg(unix)]
    #[test]
    fn the_file_is_readable_by_others() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().expect("a temporary directory");
        let path = dir.path().join("model.json");
        write(&path, b"{}").expect("writes");
        let mode = std::fs::metadata(&path)
            .expect("metadata")
            .permissions()
            .mode();
        // 0644 less whatever the umask takes away from group and others.
        assert_eq!(mode & 0o700, 0o600, "owner reads and writes: {mode:o}");
        assert_eq!(mode & 0o111, 0, "nothing executable: {mode:o}");
        let others_may_read = umask_lets_others_read(dir.path());
        assert_eq!(mode & 0o004 != 0, others_may_read, "mode {mode:o}");
    }

    /// Whether this process's umask lets others read a new file, found by making one.
    #[cfg(unix)]
    fn umask_lets_others_read(dir: &Path) -> bool {
        use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
        let probe = dir.join("umask-probe");
        std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(0o644)
            .open(&probe)
            .expect("creates the probe");
        let mode = std::fs::metadata(&probe)
            .expect("metadata")
            .permissions()
            .mode();
        std::fs::remove_file(&probe).expect("removes the probe");
        mode & 0o004 != 0
    }

    #[test]
    fn a_failed_write_leaves_the_target_and_no_temporary_file() {
        let dir = tempfile::tempdir().expect("a temporary directory");
        // The target is a non-empty directory: the rename must fail.
        let path = dir.path().join("summary.json");
        std::fs::create_dir(&path).expect("a directory in the way");
        std::fs::write(path.join("inside"), b"kept").expect("a file inside it");
        let err = write(&path, b"new").expect_err("cannot replace a directory");
        assert!(!err.to_string().is_empty());
        assert_eq!(entries(dir.path()), ["summary.json"]);
        assert_eq!(std::fs::read(path.join("inside")).expect("kept"), b"kept");
    }

    #[test]
    fn a_parent_that_is_a_file_is_an_error() {
        let dir = tempfile::tempdir().expect("a temporary directory");
        let file = dir.path().join("plain");
        std::fs::write(&file, b"x").expect("a plain file");
        assert!(write(&file.join("below.json"), b"{}").is_err());
    }
}
