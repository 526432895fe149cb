//! The game manager's session files, read for whose session they are: `<stem>.jsonl` (one
//! `SequenceRecord` per line, its `result` a `SequenceResult` with `session_id` and
//! `user_id`), `<stem>.journal` (one entry per line; the `started` entry names the user) and
//! `<stem>.summary.json` (`session_id`, `user_id`, `started_ns`, `ended_ns`), as
//! `nodes/game_manager/src/session_file.rs` writes them. Read through small structs of our own
//! (a tool may not depend on a node's crate): only the fields that say whose session it is and
//! when it ran, every other field ignored, so a newer file with more fields still reads. A
//! session with a journal or session file but no summary is unfinished: running, or cut off
//! by a crash.

use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

#[derive(Debug, Default, Deserialize)]
struct SummaryHead {
    #[serde(default)]
    session_id: String,
    #[serde(default)]
    user_id: String,
    #[serde(default)]
    started_ns: i64,
    #[serde(default)]
    ended_ns: i64,
}

#[derive(Debug, Deserialize)]
struct JournalHead {
    entry: String,
    #[serde(default)]
    session_id: String,
    #[serde(default)]
    user_id: String,
    #[serde(default)]
    at_ns: i64,
}

#[derive(Debug, Deserialize)]
struct RecordHead {
    result: ResultHead,
    #[serde(default)]
    answered_ns: i64,
}

#[derive(Debug, Deserialize)]
struct ResultHead {
    #[serde(default)]
    session_id: String,
    #[serde(default)]
    user_id: String,
}

/// One session's files in one directory.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SessionFiles {
    pub dir: PathBuf,
    pub stem: String,
    /// The files that exist, in the order `.jsonl`, `.journal`, `.summary.json`.
    pub files: Vec<PathBuf>,
    pub session_id: Option<String>,
    pub user_id: Option<String>,
    /// Its summary exists: the session ended (finished, stopped, or the node shut down).
    pub finished: bool,
    /// When it started and the latest time any of its files names (ns since the epoch).
    pub started_ns: Option<i64>,
    pub last_ns: Option<i64>,
    /// Lines or files that could not be read (named; the rest was read).
    pub problems: Vec<String>,
}

impl SessionFiles {
    pub fn unfinished(&self) -> bool {
        !self.finished
    }

    fn note_time(&mut self, ns: i64) {
        if ns > 0 {
            self.last_ns = Some(self.last_ns.map_or(ns, |l| l.max(ns)));
        }
    }

    fn whose(&mut self, session_id: &str, user_id: &str) {
        if self.session_id.is_none() && !session_id.is_empty() {
            self.session_id = Some(session_id.to_string());
        }
        if self.user_id.is_none() && !user_id.is_empty() {
            self.user_id = Some(user_id.to_string());
        }
    }
}

const SUFFIXES: [&str; 3] = [".jsonl", ".journal", ".summary.json"];

/// `(stem, which)` of a session file's name: which is 0 for `.jsonl`, 1 for `.journal`, 2 for
/// `.summary.json`.
fn split_name(path: &Path) -> Option<(String, usize)> {
    let name = path.file_name()?.to_str()?;
    SUFFIXES
        .iter()
        .enumerate()
        .find_map(|(i, s)| name.strip_suffix(s).map(|stem| (stem.to_string(), i)))
}

/// Largest session file read: a session's files are a few kB (the game manager's own limit).
const MAX_BYTES: u64 = 16 << 20;

fn read_text(path: &Path) -> Result<String, String> {
    let len = std::fs::metadata(path)
        .map_err(|e| format!("{}: {e}", path.display()))?
        .len();
    if len > MAX_BYTES {
        return Err(format!(
            "{}: {len} bytes is too large for a session file; not read",
            path.display()
        ));
    }
    let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(String::from_utf8_lossy(&bytes).into_owned())
}

/// Groups session files by directory and stem and reads whose session each group is. Groups
/// in which no file reads as a session file are left out (a `.jsonl` of something else).
pub fn read_sessions(paths: &[&Path]) -> Vec<SessionFiles> {
    let mut groups: BTreeMap<(PathBuf, String), [Option<PathBuf>; 3]> = BTreeMap::new();
    for path in paths {
        let (Some((stem, which)), Some(dir)) = (split_name(path), path.parent()) else {
            continue;
        };
        groups.entry((dir.to_path_buf(), stem)).or_default()[which] = Some(path.to_path_buf());
    }
    let mut out = Vec::new();
    for ((dir, stem), files) in groups {
        let mut s = SessionFiles {
            dir,
            stem,
            files: files.iter().flatten().cloned().collect(),
            finished: files[2].is_some(),
            ..Default::default()
        };
        let mut recognised = false;
        if let Some(path) = &files[2] {
            match read_text(path).map(|t| serde_json::from_str::<SummaryHead>(&t)) {
                Ok(Ok(h)) if !h.session_id.is_empty() => {
                    recognised = true;
                    s.whose(&h.session_id, &h.user_id);
                    if h.started_ns > 0 {
                        s.started_ns = Some(h.started_ns);
                    }
                    s.note_time(h.ended_ns);
                }
                Ok(Ok(_)) => s
                    .problems
                    .push(format!("{}: no session_id", path.display())),
                Ok(Err(e)) => s.problems.push(format!("{}: {e}", path.display())),
                Err(e) => s.problems.push(e),
            }
        }
        for (which, path) in files[..2].iter().enumerate() {
            let Some(path) = path else { continue };
            let text = match read_text(path) {
                Ok(t) => t,
                Err(e) => {
                    s.problems.push(e);
                    continue;
                }
            };
            for (n, line) in text.lines().enumerate() {
                if line.trim().is_empty() {
                    continue;
                }
                let read = if which == 0 {
                    serde_json::from_str::<RecordHead>(line).map(|r| {
                        s.whose(&r.result.session_id, &r.result.user_id);
                        s.note_time(r.answered_ns);
                    })
                } else {
                    serde_json::from_str::<JournalHead>(line).map(|j| {
                        if j.entry == "started" {
                            s.whose(&j.session_id, &j.user_id);
                            if j.at_ns > 0 && s.started_ns.is_none() {
                                s.started_ns = Some(j.at_ns);
                            }
                        } else {
                            s.whose(&j.session_id, "");
                        }
                        s.note_time(j.at_ns);
                    })
                };
                match read {
                    Ok(()) => recognised = true,
                    // A torn line (a crash mid-write) or damage: named, the rest still read.
                    Err(e) => s
                        .problems
                        .push(format!("{}, line {}: {e}", path.display(), n + 1)),
                }
            }
        }
        if recognised {
            if let Some(start) = s.started_ns {
                s.note_time(start);
            }
            out.push(s);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_session_is_known_by_any_of_its_files_and_unfinished_without_a_summary() {
        let dir = tempfile::tempdir().expect("temp dir");
        let d = dir.path();
        let journal = d.join("tablet-1.journal");
        std::fs::write(
            &journal,
            "{\"entry\":\"started\",\"session_id\":\"tablet-1\",\"user_id\":\"child-7\",\
             \"user_model_cluster\":0,\"command_id\":1,\"at_ns\":100}\n\
             {\"entry\":\"task\",\"session_id\":\"tablet-1\",\"task_id\":1,\"sequence_index\":1,\"at_ns\":200}\n\
             {\"entry\":\"ta",
        )
        .expect("write");
        let records = d.join("tablet-2.jsonl");
        std::fs::write(
            &records,
            "{\"result\":{\"session_id\":\"tablet-2\",\"user_id\":\"child-8\"},\"answered_ns\":50}\n",
        )
        .expect("write");
        let summary = d.join("tablet-2.summary.json");
        std::fs::write(
            &summary,
            "{\"session_id\":\"tablet-2\",\"user_id\":\"child-8\",\"started_ns\":10,\"ended_ns\":90}",
        )
        .expect("write");
        let other = d.join("notes.jsonl");
        std::fs::write(&other, "{\"a\":1}\n").expect("write");
        let paths = [
            journal.as_path(),
            records.as_path(),
            summary.as_path(),
            other.as_path(),
        ];
        let sessions = read_sessions(&paths);
        assert_eq!(sessions.len(), 2, "{sessions:#?}");
        let one = &sessions[0];
        assert_eq!(
            (one.session_id.as_deref(), one.user_id.as_deref()),
            (Some("tablet-1"), Some("child-7"))
        );
        assert!(one.unfinished());
        assert_eq!((one.started_ns, one.last_ns), (Some(100), Some(200)));
        assert_eq!(one.problems.len(), 1, "the torn line is named");
        assert!(one.problems[0].contains("line 3"), "{:?}", one.problems);
        let two = &sessions[1];
        assert!(two.finished);
        assert_eq!(two.files, [records.clone(), summary.clone()]);
        assert_eq!(two.user_id.as_deref(), Some("child-8"));
        assert_eq!((two.started_ns, two.last_ns), (Some(10), Some(90)));
    }
}
