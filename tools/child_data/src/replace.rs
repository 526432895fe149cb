//! Changing the suite's files in place of the service: a file is replaced whole through
//! `atomic_file` (a new file beside it, synced, renamed over it, the directory synced), so a
//! reader sees the old or the new one and a power cut leaves one of them; the new file gets the
//! old one's owner, group and mode, so the service (`qt-therapy`, files 0640) reads and writes
//! it as before and nobody else gains access. Deletions sync the directory too.

use crate::error::ChildDataError;
use crate::find::STAGING_PREFIX;
use std::fs::File;
use std::io::Write;
use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::Path;

/// Gives `file` the owner, group and mode `like` has; a warning when the owner cannot be
/// given (not running as root), the file then belonging to this process's user.
fn take_over(file: &File, like: &std::fs::Metadata, path: &Path) -> Option<String> {
    let _ = file.set_permissions(std::fs::Permissions::from_mode(like.mode() & 0o7777));
    let meta = file.metadata().ok()?;
    if meta.uid() == like.uid() && meta.gid() == like.gid() {
        return None;
    }
    match std::os::unix::fs::fchown(file, Some(like.uid()), Some(like.gid())) {
        Ok(()) => None,
        Err(e) => Some(format!(
            "{} could not be given back to uid {} gid {} ({e}): it now belongs to uid {}",
            path.display(),
            like.uid(),
            like.gid(),
            meta.uid()
        )),
    }
}

/// Replaces `path` by `bytes`, keeping its owner, group and mode; returns a warning if the
/// owner could not be kept.
pub fn replace_with_bytes(path: &Path, bytes: &[u8]) -> Result<Option<String>, ChildDataError> {
    let meta = std::fs::metadata(path).map_err(ChildDataError::io(path))?;
    let mut new = atomic_file::NewFile::with_prefix(path, STAGING_PREFIX, 0o600)
        .map_err(ChildDataError::io(path))?;
    new.file()
        .write_all(bytes)
        .map_err(ChildDataError::io(path))?;
    let warning = take_over(new.file(), &meta, path);
    new.commit().map_err(ChildDataError::io(path))?;
    Ok(warning)
}

/// Moves `new` (a finished file in the same file system) over `path`, keeping `path`'s owner,
/// group and mode; returns a warning if the owner could not be kept.
pub fn replace_with_file(path: &Path, new: &Path) -> Result<Option<String>, ChildDataError> {
    let meta = std::fs::metadata(path).map_err(ChildDataError::io(path))?;
    let file = File::options()
        .read(true)
        .write(true)
        .open(new)
        .map_err(ChildDataError::io(new))?;
    let warning = take_over(&file, &meta, path);
    file.sync_all().map_err(ChildDataError::io(new))?;
    drop(file);
    atomic_file::rename(new, path).map_err(ChildDataError::io(path))?;
    Ok(warning)
}

/// Deletes `path` and syncs its directory.
pub fn delete(path: &Path) -> Result<(), ChildDataError> {
    atomic_file::remove_file(path).map_err(ChildDataError::io(path))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_replaced_file_keeps_its_mode_and_leaves_nothing_beside_it() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("game_manager.log");
        std::fs::write(&path, b"a\nb\n").expect("write");
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o640)).expect("mode");
        let warning = replace_with_bytes(&path, b"b\n").expect("replaced");
        assert_eq!(warning, None);
        assert_eq!(std::fs::read(&path).expect("read"), b"b\n");
        let mode = std::fs::metadata(&path).expect("meta").mode() & 0o777;
        assert_eq!(mode, 0o640);
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .expect("list")
            .flatten()
            .map(|e| e.file_name())
            .collect();
        assert_eq!(names, ["game_manager.log"]);
        delete(&path).expect("deleted");
        assert!(!path.exists());
    }
}
