//! A file written over a long time under a working name (a bag's `<bag>.partial`), made
//! durable piece by piece, and renamed to its final name when done.

use std::fs::{File, OpenOptions};
use std::io::{Seek, SeekFrom, Write};
use std::os::unix::fs::FileExt as _;
use std::path::{Path, PathBuf};

/// Bytes held before they are written without being asked to (a writer that never flushes).
const HELD_AT_MOST: usize = 4 << 20;

/// A new file written in whole pieces: what is written is held in memory (seeks within it
/// too: a bag's chunk header is filled in after its data) and reaches the file in one write at
/// [`Write::flush`], which also makes it durable (fdatasync). So a writer that flushes at its
/// own safe points (a bag at each closed chunk) keeps a readable file through a power cut, and
/// the file never holds a piece half filled in.
#[derive(Debug)]
pub struct GrowingFile {
    file: File,
    path: PathBuf,
    /// Bytes in the file.
    written: u64,
    /// Bytes after them, not yet in the file.
    held: Vec<u8>,
    /// The position of the next write.
    pos: u64,
}

impl GrowingFile {
    /// Creates `path`, which must not exist, with its name (and missing directories) durable.
    pub fn create_new(path: &Path) -> std::io::Result<GrowingFile> {
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        crate::create_dir_all(dir)?;
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(path)?;
        file.sync_all()?;
        crate::sync_dir(dir)?;
        Ok(GrowingFile {
            file,
            path: path.to_path_buf(),
            written: 0,
            held: Vec::new(),
            pos: 0,
        })
    }

    /// Where the file is.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Makes the file durable and renames it to `to` (durably).
    pub fn finish(mut self, to: &Path) -> std::io::Result<()> {
        self.flush()?;
        self.file.sync_all()?;
        crate::rename(&self.path, to)
    }

    /// Writes what is held, in one write, without syncing.
    fn write_held(&mut self) -> std::io::Result<()> {
        if !self.held.is_empty() {
            self.file.write_all_at(&self.held, self.written)?;
            self.written += self.held.len() as u64;
            self.held.clear();
        }
        Ok(())
    }
}

impl Write for GrowingFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if self.pos < self.written {
            // Back into what the file already has (not a bag's way): written there at once.
            let n = buf.len().min((self.written - self.pos) as usize);
            self.file.write_all_at(&buf[..n], self.pos)?;
            self.pos += n as u64;
            return Ok(n);
        }
        let at = (self.pos - self.written) as usize;
        let end = at + buf.len();
        if self.held.len() < end {
            self.held.resize(end, 0);
        }
        self.held[at..end].copy_from_slice(buf);
        self.pos += buf.len() as u64;
        if self.held.len() >= HELD_AT_MOST && self.pos == self.written + self.held.len() as u64 {
            self.write_held()?;
        }
        Ok(buf.len())
    }

    /// Durable: what is held is written, then fdatasync.
    fn flush(&mut self) -> std::io::Result<()> {
        self.write_held()?;
        self.file.sync_data()
    }
}

impl Seek for GrowingFile {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        let end = self.written + self.held.len() as u64;
        let to = match pos {
            SeekFrom::Start(p) => Some(p),
            SeekFrom::End(d) => end.checked_add_signed(d),
            SeekFrom::Current(d) => self.pos.checked_add_signed(d),
        };
        match to {
            Some(p) if p <= end => {
                self.pos = p;
                Ok(p)
            }
            _ => Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "a seek outside the file",
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tests::entries;

    #[test]
    fn grows_under_its_working_name_and_is_renamed_when_done() {
        let dir = tempfile::tempdir().expect("a temporary directory");
        let partial = dir.path().join("run/session.mcap.partial");
        let mut f = GrowingFile::create_new(&partial).expect("creates");
        assert!(
            GrowingFile::create_new(&partial).is_err(),
            "never overwrites"
        );
        f.write_all(b"chunk 1").expect("writes");
        assert_eq!(
            std::fs::read(&partial).expect("reads"),
            b"",
            "held until the flush"
        );
        f.flush().expect("syncs");
        assert_eq!(std::fs::read(&partial).expect("reads"), b"chunk 1");
        // A header filled in after its data, as a bag's chunk is.
        f.write_all(b"[....]data").expect("writes");
        let end = f.stream_position().expect("position");
        f.seek(SeekFrom::Start(8)).expect("seeks back");
        f.write_all(b"4").expect("fills in");
        f.seek(SeekFrom::Start(end)).expect("seeks to the end");
        // Back into what the file has already.
        f.seek(SeekFrom::Start(6)).expect("seeks into the file");
        f.write_all(b"!").expect("writes there");
        f.seek(SeekFrom::End(0)).expect("the end");
        f.write_all(b".").expect("writes");
        f.finish(&dir.path().join("run/session.mcap"))
            .expect("finishes");
        assert_eq!(entries(&dir.path().join("run")), ["session.mcap"]);
        assert_eq!(
            std::fs::read(dir.path().join("run/session.mcap")).expect("reads"),
            b"chunk ![4...]data."
        );
    }
}
