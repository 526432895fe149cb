//! Follows a file as another program appends to it, as `tail -F` does: complete lines only (a
//! line written halfway waits for its newline), and the file truncated or replaced (OpenFace
//! restarted, or rewrote it when it ended) is read again from its start. Polled: the caller
//! decides how often. A file that does not exist yet is waited for.

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

/// What a poll found.
#[derive(Debug, Clone, PartialEq)]
pub enum FollowEvent {
    /// A complete line (newline removed), its number in the file from 1.
    Line { text: String, line_no: u64 },
    /// A line longer than the limit: dropped up to its newline.
    TooLong { line_no: u64 },
    /// The file was truncated or replaced: what follows is read from its start.
    Restarted { why: &'static str },
}

/// A followed file.
#[derive(Debug)]
pub struct Follower {
    path: PathBuf,
    file: Option<File>,
    /// (device, inode) of the open file, to see it replaced.
    identity: (u64, u64),
    offset: u64,
    /// Bytes after the last newline read.
    partial: Vec<u8>,
    /// The partial line went over the limit: the rest of it is dropped.
    overlong: bool,
    line_no: u64,
    max_line_bytes: usize,
    /// Skip what the file holds when it is first opened.
    start_at_end: bool,
}

impl Follower {
    pub fn new(path: &Path, max_line_bytes: usize, start_at_end: bool) -> Follower {
        Follower {
            path: path.to_path_buf(),
            file: None,
            identity: (0, 0),
            offset: 0,
            partial: Vec::new(),
            overlong: false,
            line_no: 0,
            max_line_bytes,
            start_at_end,
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Whether the file has been found.
    pub fn is_open(&self) -> bool {
        self.file.is_some()
    }

    /// Reads what was appended since the last poll.
    pub fn poll(&mut self) -> std::io::Result<Vec<FollowEvent>> {
        let mut events = Vec::new();
        let meta = match std::fs::metadata(&self.path) {
            Ok(m) => m,
            // Not written yet, or between OpenFace's delete and create: wait.
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(events),
            Err(e) => return Err(e),
        };
        let identity = (meta.dev(), meta.ino());
        if self.file.is_none() || identity != self.identity {
            let first = self.file.is_none() && self.line_no == 0 && self.offset == 0;
            let mut file = File::open(&self.path)?;
            self.offset = 0;
            if first && self.start_at_end {
                self.offset = file.seek(SeekFrom::End(0))?;
            }
            if !first {
                events.push(FollowEvent::Restarted { why: "replaced" });
            }
            self.file = Some(file);
            self.identity = identity;
            self.reset();
        } else if meta.len() < self.offset {
            events.push(FollowEvent::Restarted { why: "truncated" });
            self.offset = 0;
            self.reset();
        }
        let Some(file) = self.file.as_mut() else {
            return Ok(events);
        };
        file.seek(SeekFrom::Start(self.offset))?;
        let mut chunk = Vec::new();
        let read = file.take(4 << 20).read_to_end(&mut chunk)?;
        self.offset += read as u64;
        self.split(&chunk, &mut events);
        Ok(events)
    }

    fn reset(&mut self) {
        self.partial.clear();
        self.overlong = false;
        self.line_no = 0;
    }

    /// Cuts `chunk` into complete lines after what was left over.
    fn split(&mut self, chunk: &[u8], events: &mut Vec<FollowEvent>) {
        let mut rest = chunk;
        while let Some(end) = rest.iter().position(|b| *b == b'\n') {
            let (piece, after) = rest.split_at(end);
            rest = &after[1..];
            self.line_no += 1;
            if self.overlong || self.partial.len() + piece.len() > self.max_line_bytes {
                events.push(FollowEvent::TooLong {
                    line_no: self.line_no,
                });
            } else {
                self.partial.extend_from_slice(piece);
                events.push(FollowEvent::Line {
                    text: String::from_utf8_lossy(&self.partial).into_owned(),
                    line_no: self.line_no,
                });
            }
            self.partial.clear();
            self.overlong = false;
        }
        if self.overlong || self.partial.len() + rest.len() > self.max_line_bytes {
            // Bounded memory: the rest of an overlong line is not kept.
            self.overlong = true;
            self.partial.clear();
        } else {
            self.partial.extend_from_slice(rest);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn lines(events: &[FollowEvent]) -> Vec<String> {
        events
            .iter()
            .filter_map(|e| match e {
                FollowEvent::Line { text, .. } => Some(text.clone()),
                _ => None,
            })
            .collect()
    }

    fn append(path: &Path, text: &str) {
        let mut f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
            .expect("opens");
        f.write_all(text.as_bytes()).expect("writes");
    }

    #[test]
    fn a_half_written_line_waits_for_its_newline() {
        let dir = tempfile::tempdir().expect("dir");
        let path = dir.path().join("webcam.csv");
        let mut f = Follower::new(&path, 1024, false);
        assert!(f.poll().expect("waits").is_empty(), "no file yet");
        append(&path, "frame, face_id\n1, 0\n2, ");
        assert_eq!(lines(&f.poll().expect("reads")), ["frame, face_id", "1, 0"]);
        assert!(f.poll().expect("reads").is_empty());
        append(&path, "0\n3, 0\n");
        let events = f.poll().expect("reads");
        assert_eq!(lines(&events), ["2, 0", "3, 0"]);
        assert_eq!(
            events.last(),
            Some(&FollowEvent::Line {
                text: "3, 0".into(),
                line_no: 4
            })
        );
    }

    #[test]
    fn a_truncated_or_replaced_file_is_read_again_from_its_start() {
        let dir = tempfile::tempdir().expect("dir");
        let path = dir.path().join("webcam.csv");
        append(&path, "frame\n1\n2\n");
        let mut f = Follower::new(&path, 1024, false);
        assert_eq!(lines(&f.poll().expect("reads")).len(), 3);
        // Truncated in place and written again (shorter than before).
        std::fs::OpenOptions::new()
            .write(true)
            .truncate(true)
            .open(&path)
            .expect("truncates");
        append(&path, "frame\n");
        let events = f.poll().expect("reads");
        assert_eq!(events[0], FollowEvent::Restarted { why: "truncated" });
        assert_eq!(lines(&events), ["frame"]);
        // Replaced by a new file (rename over it), as OpenFace's rewrite may do.
        let new = dir.path().join("new.csv");
        append(&new, "frame\n9\n");
        std::fs::rename(&new, &path).expect("renames");
        let events = f.poll().expect("reads");
        assert_eq!(events[0], FollowEvent::Restarted { why: "replaced" });
        assert_eq!(
            events[2],
            FollowEvent::Line {
                text: "9".into(),
                line_no: 2
            }
        );
    }

    #[test]
    fn an_overlong_line_is_dropped_without_holding_it() {
        let dir = tempfile::tempdir().expect("dir");
        let path = dir.path().join("webcam.csv");
        let mut f = Follower::new(&path, 16, false);
        append(&path, "ok\n");
        append(&path, &"x".repeat(40));
        assert_eq!(lines(&f.poll().expect("reads")), ["ok"]);
        assert!(f.partial.is_empty(), "not kept");
        append(&path, &format!("{}\nfine\n", "y".repeat(40)));
        let events = f.poll().expect("reads");
        assert_eq!(
            events,
            [
                FollowEvent::TooLong { line_no: 2 },
                FollowEvent::Line {
                    text: "fine".into(),
                    line_no: 3
                }
            ]
        );
    }

    #[test]
    fn start_at_end_skips_what_was_there() {
        let dir = tempfile::tempdir().expect("dir");
        let path = dir.path().join("webcam.csv");
        append(&path, "frame\n1\n");
        let mut f = Follower::new(&path, 1024, true);
        assert!(lines(&f.poll().expect("reads")).is_empty());
        append(&path, "2\n");
        assert_eq!(lines(&f.poll().expect("reads")), ["2"]);
    }
}
