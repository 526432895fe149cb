//! The session files, so a crash or a power cut loses nothing: `<session>.jsonl` gets one line
//! per sequence, appended and fsync'd as soon as the sequence is scored; `<session>.journal`
//! gets one line per start, therapist command carried out and tablet task, fsync'd before its
//! effect is published, so a restarted node can take the session over (`crate::recovery`);
//! `<session>.summary.json` is written atomically (temp file + rename) when the session
//! finishes, is stopped or emergency-stopped. Files are only ever appended to, all through
//! `atomic_file`. A full disk keeps what could not be written in memory until there is room.

use atomic_file::AppendFile;
use qt_therapy_msgs::SequenceResult;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::path::{Path, PathBuf};

/// One line of the session file: the published result and what explains it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SequenceRecord {
    pub result: SequenceResult,
    /// The policy did not answer in time (or refused): same level, no feedback was used.
    pub policy_fallback: bool,
    /// Why this action: the policy's decision (greedy / explored, Q), an override, a fallback.
    pub decision_reason: String,
    /// Message time (ns) of the start of the engagement period (end of the previous answer,
    /// or the session start), of the task appearing (its end), and of the answer.
    pub talk_start_ns: i64,
    pub task_sent_ns: i64,
    pub answered_ns: i64,
    /// Answers for this task that were refused (malformed, duplicated, ...).
    pub rejected_answers: u32,
}

/// A therapist command as the journal records it (start, stop and emergency stop have their
/// own records: the start entry and the summary).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JournalCommand {
    Pause,
    Resume,
    OverrideLevel,
    /// Encouraging or challenging feedback for a sequence (its `feedback`).
    OverrideFeedback,
    AcceptProposal,
}

/// One line of `<session>.journal`: what the session file alone cannot tell a restarted node.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "entry", rename_all = "snake_case")]
pub enum JournalEntry {
    /// The session started: whom it is for, and its START command's id.
    Started {
        session_id: String,
        user_id: String,
        user_model_cluster: i32,
        command_id: u64,
        at_ns: i64,
    },
    /// A therapist command was carried out (its id is never carried out again).
    Command {
        session_id: String,
        command_id: u64,
        command: JournalCommand,
        /// An override's level or feedback (1 encouraging, 2 challenging) and the sequence
        /// it is for.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        level: Option<u8>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        feedback: Option<u8>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        sequence_index: Option<u8>,
        at_ns: i64,
    },
    /// A tablet task was sent (tablets ignore a task id they saw, so ids are never reused).
    Task {
        session_id: String,
        task_id: u32,
        sequence_index: u8,
        at_ns: i64,
    },
    /// A restarted game manager took the session over.
    Recovered {
        session_id: String,
        results: u8,
        next_sequence: u8,
        damage: Vec<String>,
        at_ns: i64,
    },
}

impl JournalEntry {
    pub fn session_id(&self) -> &str {
        match self {
            JournalEntry::Started { session_id, .. }
            | JournalEntry::Command { session_id, .. }
            | JournalEntry::Task { session_id, .. }
            | JournalEntry::Recovered { session_id, .. } => session_id,
        }
    }

    pub fn at_ns(&self) -> i64 {
        match self {
            JournalEntry::Started { at_ns, .. }
            | JournalEntry::Command { at_ns, .. }
            | JournalEntry::Task { at_ns, .. }
            | JournalEntry::Recovered { at_ns, .. } => *at_ns,
        }
    }
}

/// How a session ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SessionEnd {
    Finished,
    Stopped,
    EmergencyStopped,
    NodeShutdown,
}

/// The final record of a session.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SessionSummary {
    pub session_id: String,
    pub user_id: String,
    pub user_model_cluster: i32,
    pub end: SessionEnd,
    pub reason: String,
    pub sequences_planned: u8,
    pub sequences_played: u8,
    /// The sequence that was under way when the session was stopped (not scored).
    pub interrupted_sequence: Option<u8>,
    pub correct: u32,
    pub timeouts: u32,
    /// Sum of L * O and of L (the paper's score and maximum score).
    pub score: i32,
    pub max_score: i32,
    /// Mean of the sequences' E over sequences with engagement data.
    pub mean_engagement: Option<f64>,
    pub overrides: u32,
    /// Supervised autonomy: decisions proposed to the therapist, and how many of them were
    /// accepted, replaced by the therapist's choice, or played when the countdown ran out
    /// (0 in files written before proposals existed).
    #[serde(default)]
    pub proposals: u32,
    #[serde(default)]
    pub proposals_accepted: u32,
    #[serde(default)]
    pub proposals_replaced: u32,
    #[serde(default)]
    pub proposals_timed_out: u32,
    pub policy_fallbacks: u32,
    pub rejected_commands: u32,
    pub rejected_answers: u32,
    pub seed: i64,
    pub language: String,
    pub started_ns: i64,
    pub ended_ns: i64,
}

/// A session file that could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum SessionFileError {
    #[error("creating session directory {path}: {source}")]
    CreateDir {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("writing session file {path}: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("encoding a record for {path}: {source}")]
    Encode {
        path: PathBuf,
        source: serde_json::Error,
    },
    #[error("session file {path}, line {line}: {reason}")]
    Parse {
        path: PathBuf,
        line: usize,
        reason: String,
    },
}

/// File-name stem for a session id: ids may hold any printable character, names may not.
pub fn sanitized_stem(session_id: &str) -> String {
    let s = sequence_game::id_file_stem(session_id);
    if s.is_empty() { "session".into() } else { s }
}

fn write_err(path: &Path) -> impl FnOnce(std::io::Error) -> SessionFileError + '_ {
    move |source| SessionFileError::Write {
        path: path.to_path_buf(),
        source,
    }
}

impl SessionFileError {
    /// True when the disk (or the quota) is full.
    pub fn is_no_space(&self) -> bool {
        match self {
            SessionFileError::CreateDir { source, .. } | SessionFileError::Write { source, .. } => {
                atomic_file::is_no_space(source)
            }
            _ => false,
        }
    }
}

/// The session whose files are being written.
#[derive(Debug)]
struct OpenSession {
    id: String,
    stem: String,
}

/// Which of a session's append-only files.
#[derive(Debug, Clone, Copy)]
enum Kind {
    Records,
    Journal,
}

impl Kind {
    fn extension(self) -> &'static str {
        match self {
            Kind::Records => "jsonl",
            Kind::Journal => "journal",
        }
    }
}

/// A write that failed (a full disk) and is kept, in order, until it can be made.
#[derive(Debug)]
enum Unsaved {
    /// A line for an append-only file.
    Line { path: PathBuf, line: String },
    /// A summary, written whole; then its session's files are closed.
    Summary { path: PathBuf, text: String },
}

/// Largest file a start-up scan reads: a session's files are a few kB; anything far larger is
/// not one of ours, and is left alone rather than read into memory.
const MAX_SCANNED_BYTES: u64 = 16 << 20;

/// What a start-up finds in the sessions directory.
#[derive(Debug, Default)]
pub struct DirectoryScan {
    /// Session ids of the finished sessions (their summaries).
    pub finished_ids: Vec<String>,
    /// Sessions with a session file or journal and no summary.
    pub unfinished: Vec<UnfinishedFiles>,
    /// What could not be read, and why (the files are left as they are).
    pub problems: Vec<String>,
}

/// The text of an unfinished session's files (invalid UTF-8 replaced, so damage is named per
/// line rather than failing the file); empty for a file that is not there.
#[derive(Debug, Clone, PartialEq)]
pub struct UnfinishedFiles {
    pub stem: String,
    pub records: String,
    pub journal: String,
}

/// Writes the session files of one node, one session at a time, through `atomic_file` (lines
/// appended and fsync'd, summaries replaced whole). A write the disk has no room for is kept
/// in memory, in order, and made by the next write or [`SessionFiles::retry_unsaved`]: the
/// files stay whole (a failed append is cut back off) and nothing is written out of order.
#[derive(Debug)]
pub struct SessionFiles {
    dir: PathBuf,
    current: Option<OpenSession>,
    /// The open append-only files, by path.
    open: BTreeMap<PathBuf, AppendFile>,
    unsaved: VecDeque<Unsaved>,
}

impl SessionFiles {
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        SessionFiles {
            dir: dir.into(),
            current: None,
            open: BTreeMap::new(),
            unsaved: VecDeque::new(),
        }
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Goes on writing a recovered session's existing files `<stem>.*` (appending).
    pub fn adopt(&mut self, session_id: &str, stem: &str) {
        self.current = Some(OpenSession {
            id: session_id.to_string(),
            stem: stem.to_string(),
        });
    }

    /// The stem of `session_id`'s files: a fresh one per session, never reusing an existing
    /// file (a session id whose files exist gets `<id>-2.*`).
    fn stem(&mut self, session_id: &str) -> Result<String, SessionFileError> {
        if let Some(open) = &self.current
            && open.id == session_id
        {
            return Ok(open.stem.clone());
        }
        atomic_file::create_dir_all(&self.dir).map_err(|source| SessionFileError::CreateDir {
            path: self.dir.clone(),
            source,
        })?;
        let base = sanitized_stem(session_id);
        let unsaved: BTreeSet<&Path> = self
            .unsaved
            .iter()
            .map(|u| match u {
                Unsaved::Line { path, .. } | Unsaved::Summary { path, .. } => path.as_path(),
            })
            .collect();
        let taken = |stem: &str| {
            ["jsonl", "journal", "summary.json"].iter().any(|ext| {
                let p = self.dir.join(format!("{stem}.{ext}"));
                p.exists() || unsaved.contains(p.as_path())
            })
        };
        let mut stem = base.clone();
        let mut n = 2;
        while taken(&stem) {
            stem = format!("{base}-{n}");
            n += 1;
        }
        self.current = Some(OpenSession {
            id: session_id.to_string(),
            stem: stem.clone(),
        });
        Ok(stem)
    }

    /// Appends one record as one line and fsyncs it; returns the file's path.
    pub fn append(&mut self, record: &SequenceRecord) -> Result<PathBuf, SessionFileError> {
        self.append_line(&record.result.session_id, Kind::Records, record)
    }

    /// Appends one journal entry as one line and fsyncs it; returns the file's path.
    pub fn append_journal(&mut self, entry: &JournalEntry) -> Result<PathBuf, SessionFileError> {
        self.append_line(entry.session_id(), Kind::Journal, entry)
    }

    fn append_line(
        &mut self,
        session_id: &str,
        kind: Kind,
        value: &impl Serialize,
    ) -> Result<PathBuf, SessionFileError> {
        let stem = self.stem(session_id)?;
        let path = self.dir.join(format!("{stem}.{}", kind.extension()));
        let mut line = serde_json::to_string(value).map_err(|source| SessionFileError::Encode {
            path: path.clone(),
            source,
        })?;
        line.push('\n');
        self.unsaved.push_back(Unsaved::Line {
            path: path.clone(),
            line,
        });
        self.retry_unsaved()?;
        Ok(path)
    }

    /// Writes the session summary atomically and closes the session; returns its path. When
    /// the disk has no room, the summary is kept to be written later, and the session is closed
    /// all the same (a new session gets files of its own).
    pub fn write_summary(&mut self, summary: &SessionSummary) -> Result<PathBuf, SessionFileError> {
        let stem = self.stem(&summary.session_id)?;
        let path = self.dir.join(format!("{stem}.summary.json"));
        let mut text =
            serde_json::to_string_pretty(summary).map_err(|source| SessionFileError::Encode {
                path: path.clone(),
                source,
            })?;
        text.push('\n');
        self.unsaved.push_back(Unsaved::Summary {
            path: path.clone(),
            text,
        });
        self.current = None;
        self.retry_unsaved()?;
        Ok(path)
    }

    /// Writes, in order, what could not be written before (a full disk); stops at the first
    /// write that fails again and returns its error. Ok once nothing is left unsaved.
    pub fn retry_unsaved(&mut self) -> Result<(), SessionFileError> {
        while let Some(next) = self.unsaved.front() {
            match next {
                Unsaved::Line { path, line } => {
                    let file = match self.open.get_mut(path) {
                        Some(f) => f,
                        None => {
                            let (f, _) = AppendFile::open(path, b'\n').map_err(write_err(path))?;
                            self.open.entry(path.clone()).or_insert(f)
                        }
                    };
                    file.append(line.as_bytes()).map_err(write_err(path))?;
                }
                Unsaved::Summary { path, text } => {
                    atomic_file::write(path, text.as_bytes()).map_err(write_err(path))?;
                    // The session is over: its append-only files are closed.
                    let stem = path.to_string_lossy();
                    let stem = stem.trim_end_matches(".summary.json").to_string();
                    self.open
                        .retain(|p, _| !p.to_string_lossy().starts_with(&format!("{stem}.")));
                }
            }
            self.unsaved.pop_front();
        }
        Ok(())
    }

    /// How many lines and summaries wait for room on the disk.
    pub fn unsaved(&self) -> usize {
        self.unsaved.len()
    }

    /// Reads what a restarted node needs from the directory: the finished sessions' ids and
    /// the files of every session without a summary. Never fails: a directory that is not
    /// there yet holds nothing, and what cannot be read is named in `problems`.
    pub fn scan(&self) -> DirectoryScan {
        let mut scan = DirectoryScan::default();
        let entries = match std::fs::read_dir(&self.dir) {
            Ok(e) => e,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return scan,
            Err(e) => {
                scan.problems
                    .push(format!("reading {}: {e}", self.dir.display()));
                return scan;
            }
        };
        let mut stems = std::collections::BTreeSet::new();
        for entry in entries.filter_map(Result::ok) {
            let name = entry.file_name().to_string_lossy().to_string();
            if name.ends_with(".summary.json") {
                let path = entry.path();
                match read_capped(&path).map(|t| serde_json::from_str::<SessionSummary>(&t)) {
                    Ok(Ok(summary)) => scan.finished_ids.push(summary.session_id),
                    Ok(Err(e)) => scan.problems.push(format!("{}: {e}", path.display())),
                    Err(e) => scan.problems.push(e),
                }
                continue;
            }
            let stem = name
                .strip_suffix(".jsonl")
                .or_else(|| name.strip_suffix(".journal"));
            if let Some(stem) = stem
                && !self.dir.join(format!("{stem}.summary.json")).exists()
            {
                stems.insert(stem.to_string());
            }
        }
        for stem in stems {
            let mut texts = [String::new(), String::new()];
            for (text, kind) in texts.iter_mut().zip([Kind::Records, Kind::Journal]) {
                let path = self.dir.join(format!("{stem}.{}", kind.extension()));
                if path.exists() {
                    match read_capped(&path) {
                        Ok(t) => *text = t,
                        Err(e) => scan.problems.push(e),
                    }
                }
            }
            let [records, journal] = texts;
            scan.unfinished.push(UnfinishedFiles {
                stem,
                records,
                journal,
            });
        }
        scan
    }
}

/// A file's text, invalid UTF-8 replaced; refused when larger than a session file can be.
fn read_capped(path: &Path) -> Result<String, String> {
    let name = path.display();
    let len = std::fs::metadata(path)
        .map_err(|e| format!("{name}: {e}"))?
        .len();
    if len > MAX_SCANNED_BYTES {
        return Err(format!(
            "{name}: {len} bytes is too large for a session file; left as it is"
        ));
    }
    let bytes = std::fs::read(path).map_err(|e| format!("{name}: {e}"))?;
    Ok(String::from_utf8_lossy(&bytes).into_owned())
}

/// The records of a session file. A torn last line (a crash mid-write) is reported in
/// `torn_tail`, not as an error; a bad line anywhere else is an error naming the line.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionRecords {
    pub records: Vec<SequenceRecord>,
    pub torn_tail: bool,
}

pub fn read_records(path: &Path) -> Result<SessionRecords, SessionFileError> {
    let text = std::fs::read_to_string(path).map_err(write_err(path))?;
    let complete = text.ends_with('\n') || text.is_empty();
    let lines: Vec<&str> = text.lines().collect();
    let mut records = Vec::with_capacity(lines.len());
    let mut torn_tail = false;
    for (i, line) in lines.iter().enumerate() {
        match serde_json::from_str::<SequenceRecord>(line) {
            Ok(r) => records.push(r),
            Err(_) if i + 1 == lines.len() && !complete => torn_tail = true,
            Err(e) => {
                return Err(SessionFileError::Parse {
                    path: path.to_path_buf(),
                    line: i + 1,
                    reason: e.to_string(),
                });
            }
        }
    }
    Ok(SessionRecords { records, torn_tail })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(session: &str, index: u8) -> SequenceRecord {
        SequenceRecord {
            result: SequenceResult {
                session_id: session.into(),
                sequence_index: index,
                level: 1,
                sequence: vec!["happy".into(), "sad".into(), "angry".into()],
                outcome: 1,
                ..Default::default()
            },
            policy_fallback: false,
            decision_reason: "greedy".into(),
            talk_start_ns: 1,
            task_sent_ns: 2,
            answered_ns: 3,
            rejected_answers: 0,
        }
    }

    fn summary(session: &str) -> SessionSummary {
        SessionSummary {
            session_id: session.into(),
            user_id: "u".into(),
            user_model_cluster: 0,
            end: SessionEnd::Stopped,
            reason: "therapist".into(),
            sequences_planned: 10,
            sequences_played: 2,
            interrupted_sequence: Some(3),
            correct: 2,
            timeouts: 0,
            score: 2,
            max_score: 2,
            mean_engagement: None,
            overrides: 0,
            proposals: 0,
            proposals_accepted: 0,
            proposals_replaced: 0,
            proposals_timed_out: 0,
            policy_fallbacks: 0,
            rejected_commands: 0,
            rejected_answers: 0,
            seed: 1,
            language: "en".into(),
            started_ns: 0,
            ended_ns: 5,
        }
    }

    #[test]
    fn records_are_appended_and_read_back_and_a_rerun_gets_a_new_file() {
        let dir = tempfile::tempdir().expect("temp dir");
        let mut files = SessionFiles::new(dir.path().join("sessions"));
        let path = files.append(&record("a/../b", 1)).expect("append");
        assert_eq!(
            path.file_name().and_then(|n| n.to_str()),
            Some("a_.._b.jsonl")
        );
        files.append(&record("a/../b", 2)).expect("append");
        let read = read_records(&path).expect("read");
        assert_eq!(read.records, vec![record("a/../b", 1), record("a/../b", 2)]);
        assert!(!read.torn_tail);
        let s = files.write_summary(&summary("a/../b")).expect("summary");
        let back: SessionSummary =
            serde_json::from_str(&std::fs::read_to_string(&s).expect("read")).expect("json");
        assert_eq!(back, summary("a/../b"));
        // The same id again (a restarted node): new files, the old ones untouched.
        let again = files.append(&record("a/../b", 1)).expect("append");
        assert_eq!(
            again.file_name().and_then(|n| n.to_str()),
            Some("a_.._b-2.jsonl")
        );
        assert_eq!(read_records(&path).expect("read").records.len(), 2);
        let leftovers: Vec<_> = std::fs::read_dir(dir.path().join("sessions"))
            .expect("dir")
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
            .collect();
        assert!(leftovers.is_empty());
    }

    #[test]
    fn a_torn_last_line_is_reported_and_a_bad_middle_line_names_its_number() {
        let dir = tempfile::tempdir().expect("temp dir");
        let mut files = SessionFiles::new(dir.path());
        let path = files.append(&record("s", 1)).expect("append");
        let mut text = std::fs::read_to_string(&path).expect("read");
        text.push_str("{\"result\": {\"sess");
        std::fs::write(&path, &text).expect("write");
        let read = read_records(&path).expect("torn tail is not an error");
        assert_eq!((read.records.len(), read.torn_tail), (1, true));
        text.push('\n');
        std::fs::write(
            &path,
            format!(
                "{text}{}\n",
                serde_json::to_string(&record("s", 2)).expect("json")
            ),
        )
        .expect("write");
        match read_records(&path) {
            Err(SessionFileError::Parse { line, .. }) => assert_eq!(line, 2),
            other => panic!("expected a parse error on line 2, got {other:?}"),
        }
    }
}
