//! The one home of the suite's durable writes: every file that must survive a power cut (a
//! robot switched off at the plug) is written through this crate, and nothing else in the
//! suite calls fsync or renames a file into place. A power cut loses every write the kernel
//! has not yet put on disk; here a write is made durable before it is reported done:
//!
//! - **A file replaced whole** (Q-tables, user models, session summaries, reports, a child's
//!   belief or per-user table, exports): [`write`] for bytes in memory, [`NewFile`] for a file
//!   written piece by piece or with its own mode. The bytes go to a temporary file beside the
//!   target, are fsync'd, renamed over the target, and the directory is fsync'd: a reader and
//!   a power cut see the old file or the new one, never a mix.
//! - **An append-only record** (the game manager's session file and journal): [`AppendFile`].
//!   Each `append` is fsync'd before it returns; a cut leaves at most the append under way
//!   torn (readers skip a last line without its newline); a failed append (a full disk) is
//!   cut back off, so the next one is not glued to its remains.
//! - **A growing file renamed when done** (a bag, `<bag>.partial` until finished):
//!   [`GrowingFile`]. `flush` makes what was written so far durable; `finish` syncs and
//!   renames it to its final name.
//! - **Directory changes**: [`create_dir_all`], [`rename`] and [`remove_file`] fsync the
//!   directories they change, so a new name (or a name gone) survives a cut too.
//!
//! [`is_no_space`] tells a full disk (or quota) from other write errors, for the callers that
//! carry on without the disk; [`disk_space`] says how much is left. What the suite writes without this crate is not durable on
//! purpose (node logs, scratch files of tests and benchmarks): docs/reliability.md lists it.

mod append;
mod growing;

pub use append::AppendFile;
pub use growing::GrowingFile;

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Replaces `path` with `bytes` atomically and durably, creating missing parent directories
/// (durably too). The file is readable by all (0644 before the umask), as a plain
/// `File::create` would make it. On error the target is unchanged and no temporary file is
/// left behind.
pub fn write(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut new = NewFile::beside(path)?;
    new.file().write_all(bytes)?;
    new.commit()
}

/// A whole file being written beside its target, which it replaces on [`NewFile::commit`]
/// (fsync, rename, fsync of the directory). Dropped without a commit, it is removed and the
/// target is untouched.
pub struct NewFile {
    tmp: tempfile::NamedTempFile,
    target: PathBuf,
}

impl NewFile {
    /// A new file for `target`, mode 0644 (before the umask).
    pub fn beside(target: &Path) -> std::io::Result<NewFile> {
        NewFile::with_mode(target, 0o644)
    }

    /// A new file for `target` created with `mode` (before the umask): 0600 for a key, so it
    /// is never readable by others on the way. Parent directories are created durably.
    pub fn with_mode(target: &Path, mode: u32) -> std::io::Result<NewFile> {
        // A dot name says what the leftover of a killed writer was meant to become.
        let prefix = format!(
            ".{}.",
            target
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default()
        );
        NewFile::with_prefix(target, &prefix, mode)
    }

    /// A new file for `target` whose temporary name starts with `prefix` (a program that
    /// skips its own leftovers by name), created with `mode`.
    pub fn with_prefix(target: &Path, prefix: &str, mode: u32) -> std::io::Result<NewFile> {
        let dir = dir_of(target);
        create_dir_all(dir)?;
        let mut builder = tempfile::Builder::new();
        builder.prefix(prefix).suffix(".tmp");
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            builder.permissions(std::fs::Permissions::from_mode(mode));
        }
        #[cfg(not(unix))]
        let _ = mode;
        Ok(NewFile {
            tmp: builder.tempfile_in(dir)?,
            target: target.to_path_buf(),
        })
    }

    /// The file to write (and to give an owner or a mode, before the commit).
    pub fn file(&mut self) -> &mut File {
        self.tmp.as_file_mut()
    }

    /// Where the file is until the commit.
    pub fn path(&self) -> &Path {
        self.tmp.path()
    }

    /// Makes the file durable and renames it over the target; then the directory's entry is
    /// made durable too.
    pub fn commit(self) -> std::io::Result<()> {
        self.tmp.as_file().sync_all()?;
        let dir = dir_of(&self.target).to_path_buf();
        self.tmp.persist(&self.target).map_err(|e| e.error)?;
        sync_dir(&dir)
    }

    /// As [`NewFile::commit`], but an existing target is never replaced: then the error's kind
    /// is `AlreadyExists` and the new file is removed.
    pub fn commit_new(self) -> std::io::Result<()> {
        self.tmp.as_file().sync_all()?;
        let dir = dir_of(&self.target).to_path_buf();
        self.tmp
            .persist_noclobber(&self.target)
            .map_err(|e| e.error)?;
        sync_dir(&dir)
    }
}

/// The directory `path` is in ("." for a bare name).
fn dir_of(path: &Path) -> &Path {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    }
}

/// Creates `dir` and its missing parents, each new one's entry made durable (its parent
/// fsync'd): a directory made just before a cut does not vanish with what was put in it.
pub fn create_dir_all(dir: &Path) -> std::io::Result<()> {
    if dir.as_os_str().is_empty() || dir.is_dir() {
        return Ok(());
    }
    if let Some(parent) = dir.parent() {
        create_dir_all(parent)?;
    }
    match std::fs::create_dir(dir) {
        Ok(()) => sync_dir(dir_of(dir)),
        // Made meanwhile by another process: its maker syncs it.
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && dir.is_dir() => Ok(()),
        Err(e) => Err(e),
    }
}

/// Renames `from` to `to` (replacing it) and makes the change durable: both directories are
/// fsync'd. The file's own data must be durable already (a [`GrowingFile`]'s is).
pub fn rename(from: &Path, to: &Path) -> std::io::Result<()> {
    std::fs::rename(from, to)?;
    let (a, b) = (dir_of(from), dir_of(to));
    sync_dir(b)?;
    if a != b { sync_dir(a) } else { Ok(()) }
}

/// Removes the file `path` and makes its removal durable (its directory fsync'd).
pub fn remove_file(path: &Path) -> std::io::Result<()> {
    std::fs::remove_file(path)?;
    sync_dir(dir_of(path))
}

/// Makes the entries of `dir` (names created, renamed or removed in it) durable.
#[cfg(unix)]
pub fn sync_dir(dir: &Path) -> std::io::Result<()> {
    File::open(dir)?.sync_all()
}

/// Makes the entries of `dir` durable: a no-op where directories cannot be opened as files.
#[cfg(not(unix))]
pub fn sync_dir(_dir: &Path) -> std::io::Result<()> {
    Ok(())
}

/// Space on the file system that holds `path`, in bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DiskSpace {
    /// What an unprivileged writer may still use (statvfs's available blocks).
    pub free: u64,
    pub total: u64,
}

/// How much space the file system of `path` has left (`statvfs`).
#[cfg(unix)]
pub fn disk_space(path: &Path) -> std::io::Result<DiskSpace> {
    let s = nix::sys::statvfs::statvfs(path).map_err(std::io::Error::from)?;
    let unit = s.fragment_size() as u64;
    Ok(DiskSpace {
        free: (s.blocks_available() as u64).saturating_mul(unit),
        total: (s.blocks() as u64).saturating_mul(unit),
    })
}

/// Whether `e` says the disk (or the user's quota) is full: ENOSPC or EDQUOT.
pub fn is_no_space(e: &std::io::Error) -> bool {
    matches!(
        e.kind(),
        std::io::ErrorKind::StorageFull | std::io::ErrorKind::QuotaExceeded
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn entries(dir: &Path) -> Vec<String> {
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

    #[cfg(unix)]
    #[test]
    fn a_new_file_with_mode_0600_is_never_readable_by_others() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().expect("a temporary directory");
        let path = dir.path().join("server.key");
        let mut new = NewFile::with_mode(&path, 0o600).expect("a new file");
        let mode = new
            .file()
            .metadata()
            .expect("metadata")
            .permissions()
            .mode();
        assert_eq!(mode & 0o077, 0, "private on the way: {mode:o}");
        new.file().write_all(b"key").expect("writes");
        new.commit().expect("commits");
        let mode = std::fs::metadata(&path)
            .expect("metadata")
            .permissions()
            .mode();
        assert_eq!(mode & 0o077, 0, "private: {mode:o}");
    }

    #[test]
    fn commit_new_never_replaces_a_file() {
        let dir = tempfile::tempdir().expect("a temporary directory");
        let path = dir.path().join("export.tar.gz");
        std::fs::write(&path, b"old").expect("a file there");
        let mut new = NewFile::beside(&path).expect("a new file");
        new.file().write_all(b"new").expect("writes");
        let err = new.commit_new().expect_err("the target exists");
        assert_eq!(err.kind(), std::io::ErrorKind::AlreadyExists);
        assert_eq!(std::fs::read(&path).expect("kept"), b"old");
        assert_eq!(entries(dir.path()), ["export.tar.gz"]);
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

    #[test]
    fn rename_and_remove_change_the_directory() {
        let dir = tempfile::tempdir().expect("a temporary directory");
        let a = dir.path().join("a");
        std::fs::write(&a, b"x").expect("a file");
        rename(&a, &dir.path().join("b")).expect("renames");
        assert_eq!(entries(dir.path()), ["b"]);
        remove_file(&dir.path().join("b")).expect("removes");
        assert!(entries(dir.path()).is_empty());
    }

    #[test]
    fn a_full_disk_is_told_from_other_errors() {
        assert!(is_no_space(&std::io::Error::from_raw_os_error(28))); // ENOSPC
        assert!(is_no_space(&std::io::Error::from_raw_os_error(122))); // EDQUOT
        assert!(!is_no_space(&std::io::Error::from_raw_os_error(5))); // EIO
    }
}
