//! Follows a file as another program appends to it, as `tail -F` does: complete lines only (a
//! line written halfway waits for its newline), and the file truncated, replaced or rewritten in
//! place (OpenFace restarted, or rewrote it when it ended) is read again from its start. Polled:
//! the caller decides how often. A file that does not exist yet is waited for.
//!
//! A rewrite is told by the file's identity (device, inode) and its content, never by its
//! length alone: OpenFace's end-of-run rewrite (`FaceAnalyser::PostprocessOutputFile`) truncates
//! the same inode and writes every row again, a little longer than before (each field after
//! `", "`), so a poll usually finds the file longer than what was read. The bytes just before
//! the read offset are kept and compared at every poll: an append leaves them as they were, a
//! rewrite does not.

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
    /// The file was truncated, replaced or rewritten in place: what follows is read from its
    /// start.
    Restarted { why: &'static str },
    /// Everything the file held at the first poll has been read: what comes after was written
    /// since (the lines before are a backlog: the bridge was restarted in a run). Told at the
    /// first poll when the file is not there yet.
    CaughtUp,
}

/// Bytes before the read offset kept to see the file rewritten in place.
const TAIL_BYTES: usize = 64;

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
    /// The last bytes read (up to `TAIL_BYTES`), which sit just before `offset` in the file.
    tail: Vec<u8>,
    /// The file's length when it was first opened, until the reading passes it.
    backlog_end: Option<u64>,
    /// Whether the file was ever opened (so the first open is told from a replacement).
    opened_once: bool,
    /// Whether the file was polled before: only a file there at the first poll holds a
    /// backlog (one that appears later is OpenFace starting while the bridge waited).
    polled_once: bool,
}

impl Follower {
    pub fn new(path: &Path, max_line_bytes: usize) -> Follower {
        Follower {
            path: path.to_path_buf(),
            file: None,
            identity: (0, 0),
            offset: 0,
            partial: Vec::new(),
            overlong: false,
            line_no: 0,
            max_line_bytes,
            tail: Vec::new(),
            backlog_end: None,
            opened_once: false,
            polled_once: false,
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
        let first_poll = !self.polled_once;
        self.polled_once = true;
        let meta = match std::fs::metadata(&self.path) {
            Ok(m) => m,
            // Not written yet, or between OpenFace's delete and create: wait. Not there at
            // first: there is no backlog; all it will hold is new.
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                if first_poll {
                    events.push(FollowEvent::CaughtUp);
                }
                return Ok(events);
            }
            Err(e) => return Err(e),
        };
        let identity = (meta.dev(), meta.ino());
        if self.file.is_none() || identity != self.identity {
            let first = !self.opened_once;
            let file = File::open(&self.path)?;
            self.offset = 0;
            if first {
                if first_poll {
                    self.backlog_end = Some(meta.len());
                }
            } else {
                events.push(FollowEvent::Restarted { why: "replaced" });
            }
            self.file = Some(file);
            self.opened_once = true;
            self.identity = identity;
            self.reset();
        } else if meta.len() < self.offset {
            events.push(FollowEvent::Restarted { why: "truncated" });
            self.restart_in_place();
        } else if !self.tail_unchanged()? {
            events.push(FollowEvent::Restarted {
                why: "rewritten in place",
            });
            self.restart_in_place();
        }
        let Some(file) = self.file.as_mut() else {
            return Ok(events);
        };
        file.seek(SeekFrom::Start(self.offset))?;
        let mut chunk = Vec::new();
        let read = file.take(4 << 20).read_to_end(&mut chunk)?;
        self.offset += read as u64;
        self.keep_tail(&chunk);
        self.split(&chunk, &mut events);
        if self.backlog_end.is_some_and(|end| self.offset >= end) {
            self.backlog_end = None;
            events.push(FollowEvent::CaughtUp);
        }
        Ok(events)
    }

    /// A partial last line left when the file is finished (a recording without its final
    /// newline), as a line; `None` when there is none.
    pub fn finish(&mut self) -> Option<FollowEvent> {
        if self.partial.is_empty() || self.overlong {
            return None;
        }
        self.line_no += 1;
        let text = String::from_utf8_lossy(&self.partial).into_owned();
        self.partial.clear();
        Some(FollowEvent::Line {
            text,
            line_no: self.line_no,
        })
    }

    /// Whether the bytes before the read offset are still those read.
    fn tail_unchanged(&mut self) -> std::io::Result<bool> {
        let Some(file) = self.file.as_mut() else {
            return Ok(true);
        };
        if self.tail.is_empty() {
            return Ok(true);
        }
        let mut now = vec![0; self.tail.len()];
        file.seek(SeekFrom::Start(self.offset - self.tail.len() as u64))?;
        match file.read_exact(&mut now) {
            Ok(()) => Ok(now == self.tail),
            // Shorter than a moment ago: truncated between the length and the read.
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => Ok(false),
            Err(e) => Err(e),
        }
    }

    /// Remembers the last bytes read.
    fn keep_tail(&mut self, chunk: &[u8]) {
        if chunk.len() >= TAIL_BYTES {
            self.tail.clear();
            self.tail
                .extend_from_slice(&chunk[chunk.len() - TAIL_BYTES..]);
        } else {
            self.tail.extend_from_slice(chunk);
            let over = self.tail.len().saturating_sub(TAIL_BYTES);
            self.tail.drain(..over);
        }
    }

    /// Same file, new content: read it again from its start.
    fn restart_in_place(&mut self) {
        self.offset = 0;
        self.reset();
    }

    fn reset(&mut self) {
        self.tail.clear();
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
        let mut f = Follower::new(&path, 1024);
        assert_eq!(
            f.poll().expect("waits"),
            [FollowEvent::CaughtUp],
            "no file yet"
        );
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
        let mut f = Follower::new(&path, 1024);
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
        let mut f = Follower::new(&path, 16);
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
    fn what_the_file_held_at_first_is_a_backlog_told_once() {
        let dir = tempfile::tempdir().expect("dir");
        let path = dir.path().join("webcam.csv");
        append(&path, "frame\n1\n");
        let mut f = Follower::new(&path, 1024);
        let events = f.poll().expect("reads");
        assert_eq!(lines(&events), ["frame", "1"]);
        assert_eq!(events.last(), Some(&FollowEvent::CaughtUp));
        append(&path, "2\n");
        assert_eq!(f.poll().expect("reads"), [line("2", 3)]);
        // A file that appears later holds no backlog: all of it is new.
        let later = dir.path().join("later.csv");
        let mut g = Follower::new(&later, 1024);
        assert_eq!(g.poll().expect("waits"), [FollowEvent::CaughtUp]);
        append(&later, "frame\n1\n");
        assert_eq!(g.poll().expect("reads"), [line("frame", 1), line("1", 2)]);
    }

    fn line(text: &str, line_no: u64) -> FollowEvent {
        FollowEvent::Line {
            text: text.into(),
            line_no,
        }
    }

    /// OpenFace's end-of-run rewrite (lib/local/FaceAnalyser/src/FaceAnalyser.cpp,
    /// `FaceAnalyser::PostprocessOutputFile`): the whole file read in, the same inode opened
    /// again with `std::ofstream(path, std::ios_base::out)` (truncated), the header written as
    /// it was and every row again with each field after `", "` (so longer than before), one
    /// `std::endl` (a flush) per line.
    fn rewrite_as_openface_does(path: &Path) {
        let before = std::fs::read_to_string(path).expect("reads");
        let mut lines = before.lines();
        let mut out = std::fs::OpenOptions::new()
            .write(true)
            .truncate(true)
            .open(path)
            .expect("same inode, truncated");
        writeln!(out, "{}", lines.next().expect("a header")).expect("writes");
        for row in lines {
            let tokens: Vec<&str> = row.split(',').map(str::trim_end).collect();
            writeln!(out, "{}", tokens.join(", ")).expect("writes");
        }
    }

    #[test]
    fn a_rewrite_in_place_longer_than_what_was_read_is_seen() {
        let dir = tempfile::tempdir().expect("dir");
        let path = dir.path().join("webcam.csv");
        append(&path, "frame,face_id,timestamp\n1,0,0.000\n2,0,0.033\n");
        let mut f = Follower::new(&path, 1024);
        assert_eq!(lines(&f.poll().expect("reads")).len(), 3);
        let inode = std::fs::metadata(&path).expect("meta").ino();
        // Two more rows, then OpenFace ends and rewrites the file between two polls: it is
        // longer than what was read, on the same inode.
        append(&path, "3,0,0.067\n4,0,0.100\n");
        rewrite_as_openface_does(&path);
        assert_eq!(std::fs::metadata(&path).expect("meta").ino(), inode);
        let events = f.poll().expect("reads");
        assert_eq!(
            events[0],
            FollowEvent::Restarted {
                why: "rewritten in place"
            }
        );
        assert_eq!(
            lines(&events),
            [
                "frame,face_id,timestamp",
                "1, 0, 0.000",
                "2, 0, 0.033",
                "3, 0, 0.067",
                "4, 0, 0.100"
            ]
        );
        // Appends after it are appends.
        append(&path, "5, 0, 0.133\n");
        assert_eq!(f.poll().expect("reads"), [line("5, 0, 0.133", 6)]);
    }

    #[test]
    fn a_file_still_finished_without_its_newline_gives_its_last_line() {
        let dir = tempfile::tempdir().expect("dir");
        let path = dir.path().join("webcam.csv");
        append(&path, "frame\n1\n2");
        let mut f = Follower::new(&path, 1024);
        assert_eq!(lines(&f.poll().expect("reads")), ["frame", "1"]);
        assert_eq!(f.finish(), Some(line("2", 3)));
        assert_eq!(f.finish(), None);
    }
}
