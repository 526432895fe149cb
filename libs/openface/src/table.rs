//! Labelled feature tables (CSV: participant, frame time, the 32 OpenFace columns, label) and
//! unlabelled feature CSVs for `predict`. Columns are found by name in any order; extra
//! columns are ignored. The loader survives the known dirt of the MigrAVE frames (numbers that
//! lost their decimal point) and reports what it did (see [`crate::repair`]).

use crate::features::{FEATURE_COUNT, canonical_index, model_feature_name};
use crate::repair::{CleaningReport, DecimalRepair, repair_dotless};
use std::path::{Path, PathBuf};

/// What a frame labelled 0 ("neutral" in the authors' three-level scheme) becomes for the
/// binary classifier.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NeutralLabel {
    /// +1: the head and gaze of neutral frames face the robot, and the paper's -1 means "not
    /// focused on the robot". Our default.
    Engaged,
    /// -1: only "actively involved" counts as engaged.
    Disengaged,
    /// Leave neutral frames out.
    Drop,
}

impl std::str::FromStr for NeutralLabel {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "engaged" => Ok(NeutralLabel::Engaged),
            "disengaged" => Ok(NeutralLabel::Disengaged),
            "drop" => Ok(NeutralLabel::Drop),
            other => Err(format!(
                "neutral_label {other:?} is not engaged, disengaged or drop"
            )),
        }
    }
}

/// How to read a labelled table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LoadOptions {
    pub neutral_label: NeutralLabel,
    pub decimal_repair: DecimalRepair,
}

/// Frames with a binary label, features in canonical order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FeatureTable {
    pub participants: Vec<String>,
    /// Frame time in seconds (0 when the source has none).
    pub timestamps: Vec<f64>,
    /// +1 engaged, -1 disengaged.
    pub labels: Vec<i8>,
    pub rows: Vec<[f64; FEATURE_COUNT]>,
}

impl FeatureTable {
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Distinct participants, sorted (the order of the cross-validation folds).
    pub fn participant_ids(&self) -> Vec<String> {
        let mut ids = self.participants.clone();
        ids.sort();
        ids.dedup();
        ids
    }

    /// The rows at `indices`, in that order.
    pub fn select(&self, indices: &[usize]) -> FeatureTable {
        FeatureTable {
            participants: indices
                .iter()
                .map(|&i| self.participants[i].clone())
                .collect(),
            timestamps: indices.iter().map(|&i| self.timestamps[i]).collect(),
            labels: indices.iter().map(|&i| self.labels[i]).collect(),
            rows: indices.iter().map(|&i| self.rows[i]).collect(),
        }
    }
}

/// Why a table cannot be read. Every variant names the file; row errors name the line.
#[derive(Debug, thiserror::Error)]
pub enum TableError {
    #[error("reading {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("reading {path}: {source}")]
    Csv { path: PathBuf, source: csv::Error },
    #[error("{path} has no column {column:?}")]
    MissingColumn { path: PathBuf, column: String },
    #[error("{path} line {line}: column {column} value {value:?} is not a number")]
    BadNumber {
        path: PathBuf,
        line: u64,
        column: String,
        value: String,
    },
    #[error("{path} line {line}: label {value:?} is not 1, 0 or -1")]
    BadLabel {
        path: PathBuf,
        line: u64,
        value: String,
    },
    #[error("{path} has no rows")]
    Empty { path: PathBuf },
}

/// Column positions of the 32 features in a header, by name.
fn feature_columns(headers: &csv::StringRecord, path: &Path) -> Result<[usize; 32], TableError> {
    let mut at = [usize::MAX; FEATURE_COUNT];
    for (i, h) in headers.iter().enumerate() {
        if let Some(c) = canonical_index(h) {
            at[c] = i;
        }
    }
    match at.iter().position(|&i| i == usize::MAX) {
        Some(c) => Err(TableError::MissingColumn {
            path: path.to_path_buf(),
            column: model_feature_name(c),
        }),
        None => Ok(at),
    }
}

fn find_column(headers: &csv::StringRecord, names: &[&str]) -> Option<usize> {
    headers.iter().position(|h| names.contains(&h.trim()))
}

fn open(path: &Path) -> Result<csv::Reader<std::fs::File>, TableError> {
    let file = std::fs::File::open(path).map_err(|source| TableError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_reader(file))
}

/// Parses a feature cell: empty, `nan` or `NaN` are missing values.
fn parse_value(text: &str) -> Option<f64> {
    if text.is_empty() || text.eq_ignore_ascii_case("nan") {
        return Some(f64::NAN);
    }
    text.parse::<f64>().ok()
}

/// A continuous value written as a bare non-zero integer: its decimal point may be lost.
fn looks_dotless(text: &str) -> bool {
    let digits = text.strip_prefix('-').unwrap_or(text);
    !digits.is_empty()
        && digits.bytes().all(|b| b.is_ascii_digit())
        && !digits.trim_start_matches('0').is_empty()
}

/// Reads a labelled table, maps label 0 by `options.neutral_label` and treats dotless
/// continuous values by `options.decimal_repair`.
pub fn load_labelled_csv(
    path: &Path,
    options: &LoadOptions,
) -> Result<(FeatureTable, CleaningReport), TableError> {
    let mut reader = open(path)?;
    let csv_err = |source| TableError::Csv {
        path: path.to_path_buf(),
        source,
    };
    let headers = reader.headers().map_err(csv_err)?.clone();
    let columns = feature_columns(&headers, path)?;
    let missing = |column: &str| TableError::MissingColumn {
        path: path.to_path_buf(),
        column: column.to_string(),
    };
    let participant_at = find_column(&headers, &["participant", "participant_id"])
        .ok_or_else(|| missing("participant"))?;
    let label_at =
        find_column(&headers, &["engagement", "label"]).ok_or_else(|| missing("engagement"))?;
    let time_at = find_column(&headers, &["timestamp", "frame_time", "time"]);

    let mut table = FeatureTable::default();
    let mut dotless: Vec<u32> = Vec::new();
    let mut report = CleaningReport::default();
    for record in reader.records() {
        let record = record.map_err(csv_err)?;
        let line = record.position().map_or(0, |p| p.line());
        report.rows_read += 1;
        let field = |i: usize| record.get(i).unwrap_or("");
        let label = match field(label_at).parse::<f64>() {
            Ok(1.0) => 1,
            Ok(-1.0) => -1,
            Ok(0.0) => {
                report.neutral_rows += 1;
                match options.neutral_label {
                    NeutralLabel::Engaged => 1,
                    NeutralLabel::Disengaged => -1,
                    NeutralLabel::Drop => continue,
                }
            }
            _ => {
                return Err(TableError::BadLabel {
                    path: path.to_path_buf(),
                    line,
                    value: field(label_at).to_string(),
                });
            }
        };
        let mut row = [0f64; FEATURE_COUNT];
        let mut flags = 0u32;
        for (c, &at) in columns.iter().enumerate() {
            let text = field(at);
            row[c] = parse_value(text).ok_or_else(|| TableError::BadNumber {
                path: path.to_path_buf(),
                line,
                column: model_feature_name(c),
                value: text.to_string(),
            })?;
            if crate::features::is_continuous(c) && looks_dotless(text) {
                flags |= 1 << c;
            }
        }
        let time = time_at.and_then(|i| field(i).parse::<f64>().ok());
        table.participants.push(field(participant_at).to_string());
        table.timestamps.push(time.unwrap_or(0.0));
        table.labels.push(label);
        table.rows.push(row);
        dotless.push(flags);
    }
    if table.is_empty() {
        return Err(TableError::Empty {
            path: path.to_path_buf(),
        });
    }
    repair_dotless(&mut table, &dotless, options.decimal_repair, &mut report);
    Ok((table, report))
}

/// Reads the 32 feature columns of any CSV whose header names them (`of_AU01_c` or
/// `AU01_c` ...); returns the rows in canonical order.
pub fn read_feature_csv(path: &Path) -> Result<Vec<[f64; FEATURE_COUNT]>, TableError> {
    let mut reader = open(path)?;
    let csv_err = |source| TableError::Csv {
        path: path.to_path_buf(),
        source,
    };
    let headers = reader.headers().map_err(csv_err)?.clone();
    let columns = feature_columns(&headers, path)?;
    let mut rows = Vec::new();
    for record in reader.records() {
        let record = record.map_err(csv_err)?;
        let line = record.position().map_or(0, |p| p.line());
        let mut row = [0f64; FEATURE_COUNT];
        for (c, &at) in columns.iter().enumerate() {
            let text = record.get(at).unwrap_or("");
            row[c] = parse_value(text).ok_or_else(|| TableError::BadNumber {
                path: path.to_path_buf(),
                line,
                column: model_feature_name(c),
                value: text.to_string(),
            })?;
        }
        rows.push(row);
    }
    Ok(rows)
}

/// Writes a labelled table in the authors' column layout (participant, timestamp,
/// engagement, `of_AU01_c` ... `of_pose_Rz`), atomically.
pub fn write_labelled_csv(path: &Path, table: &FeatureTable) -> std::io::Result<()> {
    use crate::features::AUTHORS_FEATURE_ORDER;
    let mut out = String::with_capacity(table.len() * 300);
    out.push_str("participant,timestamp,engagement");
    for &c in &AUTHORS_FEATURE_ORDER {
        out.push(',');
        out.push_str(&model_feature_name(c));
    }
    out.push('\n');
    for i in 0..table.len() {
        let (p, t, l) = (&table.participants[i], table.timestamps[i], table.labels[i]);
        out.push_str(&format!("{p},{t:.3},{l}"));
        for &c in &AUTHORS_FEATURE_ORDER {
            out.push_str(&format!(",{}", table.rows[i][c]));
        }
        out.push('\n');
    }
    atomic_file::write(path, out.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dotless_detection() {
        assert!(looks_dotless("-49981"));
        assert!(looks_dotless("18"));
        assert!(!looks_dotless("0"));
        assert!(!looks_dotless("-0"));
        assert!(!looks_dotless("-49.98"));
        assert!(!looks_dotless("1e-5"));
        assert!(!looks_dotless(""));
    }
}
