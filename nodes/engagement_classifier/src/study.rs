//! Reads one participant's session from the MigrAVE study records (`engagement_per_second.csv`
//! and `sequences.csv`) into the plain series the engagement plot takes: seconds since the
//! session start, expected engagement per second, answer times and stage ends.

use crate::smoothing::smooth_series;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// Why the study records cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    #[error("reading {path}: {source}")]
    Csv { path: PathBuf, source: csv::Error },
    #[error("{path}: participant {participant:?} spans {seconds} s; a session lasts minutes")]
    Span {
        path: PathBuf,
        participant: String,
        seconds: i64,
    },
    #[error("{path}: no rows for participant {participant:?} (known: {known})")]
    UnknownParticipant {
        path: PathBuf,
        participant: String,
        known: String,
    },
}

/// Longest session we draw (a day).
const MAX_SESSION_SECONDS: i64 = 86_400;

#[derive(Deserialize)]
struct SecondRow {
    participant_id: String,
    secs: i64,
    eng_qt: f64,
}

#[derive(Deserialize)]
struct SequenceRow {
    participant_id: String,
    secs: f64,
    length: u8,
}

/// One session, as plain data for [`crate::plot::EngagementPlot`].
#[derive(Debug, Clone, PartialEq)]
pub struct StudySession {
    pub participant: String,
    /// Unix time of the first second with an engagement value.
    pub start_secs: i64,
    /// Seconds since `start_secs`, one per second from the first to the last value.
    pub seconds: Vec<f64>,
    /// Expected engagement per second as recorded (NaN where the record has no value).
    pub engagement: Vec<f64>,
    /// The same, smoothed as the authors did (ewm, alpha 0.75).
    pub smoothed: Vec<f64>,
    /// Seconds since start at which an answer was given (`secs` of each sequence).
    pub answers: Vec<f64>,
    /// Seconds since start of the last answer of each stage (a run of one length), with L.
    pub stage_ends: Vec<(f64, u8)>,
}

fn read_rows<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<Vec<T>, StudyError> {
    let csv_err = |source| StudyError::Csv {
        path: path.to_path_buf(),
        source,
    };
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(csv_err)?;
    reader.deserialize().map(|r| r.map_err(csv_err)).collect()
}

/// Loads `participant`'s session from the study directory `dir`.
pub fn load_study_session(
    dir: &Path,
    participant: &str,
    smoothing_alpha: f64,
) -> Result<StudySession, StudyError> {
    let seconds_path = dir.join("engagement_per_second.csv");
    let mut rows: Vec<SecondRow> = read_rows(&seconds_path)?;
    let unknown = |path: &Path, ids: Vec<String>| {
        let mut ids = ids;
        ids.sort();
        ids.dedup();
        StudyError::UnknownParticipant {
            path: path.to_path_buf(),
            participant: participant.to_string(),
            known: ids.join(", "),
        }
    };
    let ids: Vec<String> = rows.iter().map(|r| r.participant_id.clone()).collect();
    rows.retain(|r| r.participant_id == participant);
    rows.sort_by_key(|r| r.secs);
    let (Some(first), Some(last)) = (rows.first(), rows.last()) else {
        return Err(unknown(&seconds_path, ids));
    };
    let start_secs = first.secs;
    let seconds = last.secs.saturating_sub(start_secs).saturating_add(1);
    // One value per second is allocated; a broken timestamp must not ask for years of them.
    if seconds > MAX_SESSION_SECONDS {
        return Err(StudyError::Span {
            path: seconds_path,
            participant: participant.to_string(),
            seconds,
        });
    }
    let span = seconds as usize;
    let mut engagement = vec![f64::NAN; span];
    for r in &rows {
        engagement[(r.secs - start_secs) as usize] = r.eng_qt;
    }
    let sequences_path = dir.join("sequences.csv");
    let mut sequences: Vec<SequenceRow> = read_rows(&sequences_path)?;
    let ids: Vec<String> = sequences.iter().map(|r| r.participant_id.clone()).collect();
    sequences.retain(|r| r.participant_id == participant);
    if sequences.is_empty() {
        return Err(unknown(&sequences_path, ids));
    }
    sequences.sort_by(|a, b| a.secs.total_cmp(&b.secs));
    let at = |secs: f64| secs - start_secs as f64;
    let answers = sequences.iter().map(|s| at(s.secs)).collect();
    let stage_ends = sequences
        .iter()
        .enumerate()
        .filter(|(i, s)| {
            sequences
                .get(i + 1)
                .is_none_or(|next| next.length != s.length)
        })
        .map(|(_, s)| (at(s.secs), s.length))
        .collect();
    Ok(StudySession {
        participant: participant.to_string(),
        start_secs,
        seconds: (0..span).map(|s| s as f64).collect(),
        smoothed: smooth_series(&engagement, smoothing_alpha, true),
        engagement,
        answers,
        stage_ends,
    })
}
