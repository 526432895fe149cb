//! Interaction data: one [`InteractionRecord`] per solved sequence. Readers fill it from our CSV
//! format (`csv_file`), from the MigrAVE study's own files (`study`) and from our recorded
//! sessions ([`bag`]); all produce the same type, checked with [`InteractionRecord::validate`].
//! The CSV readers are behind the `csv` feature.

pub mod bag;
#[cfg(feature = "csv")]
pub mod csv_file;
#[cfg(feature = "csv")]
pub mod study;

use sequence_game::{Feedback, Level, Outcome};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

#[cfg(feature = "csv")]
pub use csv_file::{CSV_COLUMNS, read_csv, write_csv};
#[cfg(feature = "csv")]
pub use study::read_study;

/// One solved sequence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InteractionRecord {
    /// Pseudonymous user (participant) id.
    pub user_id: String,
    /// The session (one game of 10 sequences) this sequence belongs to.
    pub session_id: String,
    /// Unix time in seconds when the answer was given.
    pub time: f64,
    /// Level L of the sequence (1, 2, 3 for lengths 3, 5, 7).
    pub level: Level,
    /// Feedback F the robot gave before this sequence.
    pub feedback: Feedback,
    /// Score PS of the user's previous sequence (+L on success, -L on failure), 0 for the first.
    pub previous_score: i8,
    /// Outcome O: success or failure.
    pub outcome: Outcome,
    /// This sequence's score, L · O (the next sequence's PS).
    pub score: i8,
    /// Seconds the user took to answer.
    pub response_time: f64,
    /// The sequence's engagement E in [-1, 1]: the mean expected engagement while the robot
    /// talked (`None` when it could not be estimated, e.g. no face seen).
    pub engagement: Option<f64>,
    /// Expected engagement in [-1, 1] of each second the robot talked before this answer.
    pub engagement_per_second: Vec<f64>,
}

/// A record or file that cannot be used, named precisely.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    #[error("reading {path}: {reason}")]
    Io { path: PathBuf, reason: String },
    #[error("{origin}, record {record}, field {field}: {reason}")]
    Record {
        /// The file (or other origin) of the record.
        origin: String,
        /// 1-based record number (CSV: data row, not counting the header).
        record: usize,
        field: &'static str,
        reason: String,
    },
    #[error("{path}: column {column:?} is missing")]
    Column { path: PathBuf, column: String },
    #[error("{path}: no records")]
    Empty { path: PathBuf },
    #[error(transparent)]
    Bag(bag_file::BagError),
    #[error("{bag}: no topic {topic:?} in the bag, which user-model data needs: {why}")]
    MissingTopic {
        bag: String,
        topic: &'static str,
        why: &'static str,
    },
    /// The same sequence twice with different contents (docs/session_log.md).
    #[error(transparent)]
    Conflict(session_log::Conflict),
    #[error("{bag}: no message on {topic:?}, so no solved sequence to learn from")]
    NoSequences { bag: String, topic: &'static str },
    #[error("{path}: neither a study directory (sequences.csv) nor a directory holding .mcap bags")]
    NoData { path: PathBuf },
}

impl DataError {
    pub(crate) fn io(path: &Path, e: impl std::fmt::Display) -> DataError {
        DataError::Io {
            path: path.into(),
            reason: e.to_string(),
        }
    }
}

/// Why one field of a record is unusable.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldError {
    pub field: &'static str,
    pub reason: String,
}

impl FieldError {
    pub fn new(field: &'static str, reason: impl Into<String>) -> Self {
        FieldError {
            field,
            reason: reason.into(),
        }
    }

    /// Names the record this field belongs to.
    pub fn in_record(self, origin: impl Into<String>, record: usize) -> DataError {
        DataError::Record {
            origin: origin.into(),
            record,
            field: self.field,
            reason: self.reason,
        }
    }
}

/// `value` if it is finite and within [low, high].
pub fn in_range(field: &'static str, value: f64, low: f64, high: f64) -> Result<f64, FieldError> {
    if value.is_finite() && value >= low && value <= high {
        Ok(value)
    } else {
        Err(FieldError::new(
            field,
            format!("{value} is not a finite value in [{low}, {high}]"),
        ))
    }
}

impl InteractionRecord {
    /// Checks every field that the types do not already guarantee.
    pub fn validate(&self) -> Result<(), FieldError> {
        if self.user_id.trim().is_empty() {
            return Err(FieldError::new("user_id", "is empty"));
        }
        in_range("time", self.time, 0.0, f64::MAX)?;
        if !(-3..=3).contains(&self.previous_score) {
            return Err(FieldError::new(
                "previous_score",
                format!("{} is outside -3..=3", self.previous_score),
            ));
        }
        if self.score != self.outcome.score(self.level) {
            return Err(FieldError::new(
                "score",
                format!(
                    "{} is not level x outcome = {}",
                    self.score,
                    self.outcome.score(self.level)
                ),
            ));
        }
        in_range("response_time", self.response_time, 0.0, 86_400.0)?;
        if let Some(e) = self.engagement {
            in_range("engagement", e, -1.0, 1.0)?;
        }
        for e in &self.engagement_per_second {
            in_range("engagement_per_second", *e, -1.0, 1.0)?;
        }
        Ok(())
    }
}

/// Checks every record of a data set that did not come from a file (a simulation, a caller),
/// naming the first bad one by its 1-based position.
pub fn validate_all(records: &[InteractionRecord]) -> Result<(), DataError> {
    for (i, r) in records.iter().enumerate() {
        r.validate()
            .map_err(|e| e.in_record(format!("records (user {:?})", r.user_id), i + 1))?;
    }
    Ok(())
}

/// Reads a data set: a study directory (`sequences.csv` + `engagement_per_second.csv`), a
/// CSV file in our format, a bag (`.mcap`) or a directory of bags. Warnings of the bag reader
/// are logged; [`read_sources`] returns them.
#[cfg(feature = "csv")]
pub fn read_any(path: &Path) -> Result<Vec<InteractionRecord>, DataError> {
    read_sources(&[path.to_path_buf()]).map(|d| d.records)
}

/// Reads and joins several data sets (each as [`read_any`]): study directories and CSV files in
/// the order given, then every bag named or found in a directory, read together (a user's
/// sessions may be in several bags; see [`bag::read_bags`]).
#[cfg(feature = "csv")]
pub fn read_sources(paths: &[PathBuf]) -> Result<bag::BagRecords, DataError> {
    let mut out = bag::BagRecords::default();
    let mut bags = Vec::new();
    for path in paths {
        if path.is_dir() {
            if path.join("sequences.csv").exists() {
                out.records.extend(read_study(path)?);
            } else {
                let found = bag::bags_in(path)?;
                if found.is_empty() {
                    return Err(DataError::NoData { path: path.clone() });
                }
                bags.extend(found);
            }
        } else if bag::is_bag(path) {
            bags.push(path.clone());
        } else {
            out.records.extend(read_csv(path)?);
        }
    }
    if !bags.is_empty() {
        let from_bags = bag::read_bags(&bags)?;
        out.records.extend(from_bags.records);
        out.warnings.extend(from_bags.warnings);
    }
    Ok(out)
}
