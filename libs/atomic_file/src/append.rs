//! Append-only records (the game manager's session file and journal): each append is on disk
//! when it returns, and a failed one leaves nothing behind.

use std::fs::{File, OpenOptions};
use std::io::{Read as _, Seek as _, SeekFrom, Write as _};
use std::path::{Path, PathBuf};

/// A file only ever appended to, one whole record per [`AppendFile::append`].
#[derive(Debug)]
pub struct AppendFile {
    file: File,
    path: PathBuf,
    /// Bytes known to be whole records (what a failed append is cut back to).
    len: u64,
}

impl AppendFile {
    /// Opens `path` to append, creating it (and missing directories) durably. A cut or a crash
    /// mid-append can leave a last record without its end (`end`, say a newline): it is ended
    /// first, so the next record is not glued to it (the torn bytes stay, a damaged record that
    /// readers name and skip). Returns the file and whether it was created.
    pub fn open(path: &Path, end: u8) -> std::io::Result<(AppendFile, bool)> {
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        crate::create_dir_all(dir)?;
        let existed = path.exists();
        let mut file = OpenOptions::new()
            .create(true)
            .append(true)
            .read(true)
            .open(path)?;
        let mut len = file.metadata()?.len();
        if existed && len > 0 {
            let mut last = [0u8; 1];
            file.seek(SeekFrom::Start(len - 1))?;
            file.read_exact(&mut last)?;
            if last[0] != end {
                file.write_all(&[end])?;
                file.sync_data()?;
                len += 1;
            }
        }
        if !existed {
            // The new name must survive a cut as well as what is appended under it.
            file.sync_all()?;
            crate::sync_dir(dir)?;
        }
        Ok((
            AppendFile {
                file,
                path: path.to_path_buf(),
                len,
            },
            !existed,
        ))
    }

    /// Appends `record` in one write and fsyncs it (data and size). On error (a full disk) the
    /// file is cut back to its records before this one, so no torn bytes stay to damage the
    /// next append; the record can be appended again later.
    pub fn append(&mut self, record: &[u8]) -> std::io::Result<()> {
        let written = self
            .file
            .write_all(record)
            .and_then(|()| self.file.sync_data());
        match written {
            Ok(()) => {
                self.len += record.len() as u64;
                Ok(())
            }
            Err(e) => {
                // Best effort: truncating frees space, so it works on a full disk too.
                if self.file.set_len(self.len).is_ok() {
                    let _ = self.file.sync_data();
                }
                Err(e)
            }
        }
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Bytes of whole records in the file.
    pub fn len(&self) -> u64 {
        self.len
    }

    /// True when the file holds no record.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn appends_whole_records_and_ends_a_torn_one_first() {
        let dir = tempfile::tempdir().expect("a temporary directory");
        let path = dir.path().join("s.jsonl");
        let (mut f, created) = AppendFile::open(&path, b'\n').expect("opens");
        assert!(created);
        f.append(b"one\n").expect("appends");
        drop(f);
        // A crash tore the next record.
        std::fs::OpenOptions::new()
            .append(true)
            .open(&path)
            .and_then(|mut f| f.write_all(b"tw"))
            .expect("torn bytes");
        let (mut f, created) = AppendFile::open(&path, b'\n').expect("opens again");
        assert!(!created);
        f.append(b"three\n").expect("appends");
        assert_eq!(std::fs::read(&path).expect("reads"), b"one\ntw\nthree\n");
        assert_eq!(f.len(), 13);
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_failed_append_is_cut_back_off() {
        // /dev/full fails every write with ENOSPC, as a full disk does.
        let Ok(file) = OpenOptions::new().append(true).open("/dev/full") else {
            return;
        };
        let mut f = AppendFile {
            file,
            path: PathBuf::from("/dev/full"),
            len: 0,
        };
        let e = f.append(b"record\n").expect_err("the disk is full");
        assert!(crate::is_no_space(&e), "{e}");
        assert_eq!(f.len(), 0);
    }
}
