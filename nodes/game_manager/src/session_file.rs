//! The session files, so a crash loses nothing: `<session>.jsonl` gets one line per sequence,
//! appended and fsync'd as soon as the sequence is scored; `<session>.summary.json` is written
//! atomically (temp file + rename) when the session finishes, is stopped or emergency-stopped.

use qt_therapy_msgs::SequenceResult;
use serde::{Deserialize, Serialize};
use std::fs::{File, OpenOptions};
use std::io::Write as _;
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
    let s: String = session_id
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '_'
            }
        })
        .collect();
    let s = s.trim_start_matches('.').to_string();
    if s.is_empty() { "session".into() } else { s }
}

fn write_err(path: &Path) -> impl FnOnce(std::io::Error) -> SessionFileError + '_ {
    move |source| SessionFileError::Write {
        path: path.to_path_buf(),
        source,
    }
}

fn sync_dir(dir: &Path) -> Result<(), SessionFileError> {
    File::open(dir)
        .and_then(|d| d.sync_all())
        .map_err(write_err(dir))
}

/// Writes the session files of one node, one session at a time.
#[derive(Debug)]
pub struct SessionFiles {
    dir: PathBuf,
    /// The session being written, its file stem and its open JSON-lines file.
    current: Option<(String, String, Option<File>)>,
}

impl SessionFiles {
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        SessionFiles {
            dir: dir.into(),
            current: None,
        }
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The stem of `session_id`'s files: a fresh one per session, never reusing an existing
    /// file (a restarted node that sees a session id again writes `<id>-2.jsonl`).
    fn stem(&mut self, session_id: &str) -> Result<String, SessionFileError> {
        if let Some((id, stem, _)) = &self.current
            && id == session_id
        {
            return Ok(stem.clone());
        }
        std::fs::create_dir_all(&self.dir).map_err(|source| SessionFileError::CreateDir {
            path: self.dir.clone(),
            source,
        })?;
        let base = sanitized_stem(session_id);
        let taken = |stem: &str| {
            self.dir.join(format!("{stem}.jsonl")).exists()
                || self.dir.join(format!("{stem}.summary.json")).exists()
        };
        let mut stem = base.clone();
        let mut n = 2;
        while taken(&stem) {
            stem = format!("{base}-{n}");
            n += 1;
        }
        self.current = Some((session_id.to_string(), stem.clone(), None));
        Ok(stem)
    }

    /// Appends one record as one line and fsyncs it; returns the file's path.
    pub fn append(&mut self, record: &SequenceRecord) -> Result<PathBuf, SessionFileError> {
        let stem = self.stem(&record.result.session_id)?;
        let path = self.dir.join(format!("{stem}.jsonl"));
        let mut line =
            serde_json::to_string(record).map_err(|source| SessionFileError::Encode {
                path: path.clone(),
                source,
            })?;
        line.push('\n');
        let created = !path.exists();
        let Some((_, _, slot)) = self.current.as_mut() else {
            return Err(SessionFileError::Write {
                path,
                source: std::io::Error::other("no session is open"),
            });
        };
        let file = match slot.take() {
            Some(f) => f,
            None => OpenOptions::new()
                .create(true)
                .append(true)
                .open(&path)
                .map_err(write_err(&path))?,
        };
        let file = slot.insert(file);
        // One write of the whole line, then fsync: a crash leaves at most a torn last line.
        file.write_all(line.as_bytes()).map_err(write_err(&path))?;
        file.sync_data().map_err(write_err(&path))?;
        if created {
            sync_dir(&self.dir)?;
        }
        Ok(path)
    }

    /// Writes the session summary atomically and closes the session; returns its path.
    pub fn write_summary(&mut self, summary: &SessionSummary) -> Result<PathBuf, SessionFileError> {
        let stem = self.stem(&summary.session_id)?;
        let path = self.dir.join(format!("{stem}.summary.json"));
        let mut text =
            serde_json::to_string_pretty(summary).map_err(|source| SessionFileError::Encode {
                path: path.clone(),
                source,
            })?;
        text.push('\n');
        atomic_file::write(&path, text.as_bytes()).map_err(write_err(&path))?;
        self.current = None;
        Ok(path)
    }
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
