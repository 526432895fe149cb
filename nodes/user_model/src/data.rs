//! Interaction data: one record per solved sequence (user, session, time, L, F, PS, O, score,
//! response time, the per-second engagement while the robot talked). Reads our CSV format and
//! the MigrAVE study's own files (`sequences.csv` + `engagement_per_second.csv`), and writes
//! our CSV.

use sequence_game::{Feedback, Level, Outcome};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// One solved sequence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InteractionRecord {
    pub user_id: String,
    pub session_id: String,
    /// Seconds since the epoch when the answer was given.
    pub time: f64,
    pub level: Level,
    /// Feedback given before this sequence.
    pub feedback: Feedback,
    /// Score of the previous sequence (+L on success, -L on failure), 0 for the first.
    pub previous_score: i8,
    pub outcome: Outcome,
    /// L * O.
    pub score: i8,
    /// Seconds the user took to answer.
    pub response_time: f64,
    /// The sequence's engagement E: mean expected engagement while the robot talked (`None`
    /// when no face was seen).
    pub engagement: Option<f64>,
    /// Expected engagement of each second the robot talked before this answer.
    pub engagement_per_second: Vec<f64>,
}

/// A record or file that cannot be used, named precisely.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    #[error("reading {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}, record {record}: {reason}")]
    Record {
        path: PathBuf,
        record: usize,
        reason: String,
    },
    #[error("{path}: column {column:?} is missing")]
    Column { path: PathBuf, column: String },
    #[error("{path}: no records")]
    Empty { path: PathBuf },
}

/// The columns of our CSV format, in order.
pub const CSV_COLUMNS: [&str; 11] = [
    "user_id",
    "session_id",
    "time",
    "level",
    "feedback",
    "previous_score",
    "outcome",
    "score",
    "response_time",
    "engagement_mean",
    "engagement_per_second",
];

fn reader(path: &Path) -> Result<(csv::Reader<std::fs::File>, Vec<String>), DataError> {
    let mut r = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|e| DataError::Io {
            path: path.into(),
            source: std::io::Error::other(e.to_string()),
        })?;
    let headers = r
        .headers()
        .map_err(|e| DataError::Record {
            path: path.into(),
            record: 0,
            reason: e.to_string(),
        })?
        .iter()
        .map(str::to_string)
        .collect();
    Ok((r, headers))
}

fn column(path: &Path, headers: &[String], name: &str) -> Result<usize, DataError> {
    headers
        .iter()
        .position(|h| h == name)
        .ok_or_else(|| DataError::Column {
            path: path.into(),
            column: name.into(),
        })
}

fn field<T: std::str::FromStr>(
    path: &Path,
    record: usize,
    row: &csv::StringRecord,
    i: usize,
    name: &str,
) -> Result<T, DataError> {
    let raw = row.get(i).unwrap_or("");
    raw.parse::<T>().map_err(|_| DataError::Record {
        path: path.into(),
        record,
        reason: format!("{name} = {raw:?} is not a valid value"),
    })
}

fn finite(
    path: &Path,
    record: usize,
    name: &str,
    v: f64,
    low: f64,
    high: f64,
) -> Result<f64, DataError> {
    if v.is_finite() && v >= low && v <= high {
        Ok(v)
    } else {
        Err(DataError::Record {
            path: path.into(),
            record,
            reason: format!("{name} = {v} is outside [{low}, {high}]"),
        })
    }
}

/// Reads records in our CSV format.
pub fn read_csv(path: &Path) -> Result<Vec<InteractionRecord>, DataError> {
    let (mut r, headers) = reader(path)?;
    let idx: Vec<usize> = CSV_COLUMNS
        .iter()
        .map(|c| column(path, &headers, c))
        .collect::<Result<_, _>>()?;
    let mut out = Vec::new();
    for (n, row) in r.records().enumerate() {
        let record = n + 1;
        let row = row.map_err(|e| DataError::Record {
            path: path.into(),
            record,
            reason: e.to_string(),
        })?;
        let bad = |reason: String| DataError::Record {
            path: path.into(),
            record,
            reason,
        };
        let level = Level::new(field::<i64>(path, record, &row, idx[3], "level")?)
            .map_err(|e| bad(e.to_string()))?;
        let feedback = Feedback::new(field::<i64>(path, record, &row, idx[4], "feedback")?)
            .map_err(|e| bad(e.to_string()))?;
        let previous_score = field::<i8>(path, record, &row, idx[5], "previous_score")?;
        if !(-3..=3).contains(&previous_score) {
            return Err(bad(format!(
                "previous_score = {previous_score} is outside -3..=3"
            )));
        }
        let outcome = Outcome::new(field::<i64>(path, record, &row, idx[6], "outcome")?)
            .map_err(|e| bad(e.to_string()))?;
        let score = field::<i8>(path, record, &row, idx[7], "score")?;
        if score != outcome.score(level) {
            return Err(bad(format!(
                "score = {score} is not level x outcome = {}",
                outcome.score(level)
            )));
        }
        let mean = row.get(idx[9]).unwrap_or("");
        let engagement = if mean.is_empty() {
            None
        } else {
            Some(finite(
                path,
                record,
                "engagement_mean",
                field(path, record, &row, idx[9], "engagement_mean")?,
                -1.0,
                1.0,
            )?)
        };
        let per_second = row.get(idx[10]).unwrap_or("");
        let engagement_per_second = per_second
            .split(';')
            .filter(|s| !s.trim().is_empty())
            .map(|s| {
                let v = s
                    .trim()
                    .parse::<f64>()
                    .map_err(|_| bad(format!("engagement value {s:?} is not a number")))?;
                finite(path, record, "engagement", v, -1.0, 1.0)
            })
            .collect::<Result<Vec<f64>, _>>()?;
        out.push(InteractionRecord {
            user_id: row.get(idx[0]).unwrap_or("").to_string(),
            session_id: row.get(idx[1]).unwrap_or("").to_string(),
            time: finite(
                path,
                record,
                "time",
                field(path, record, &row, idx[2], "time")?,
                0.0,
                f64::MAX,
            )?,
            level,
            feedback,
            previous_score,
            outcome,
            score,
            response_time: finite(
                path,
                record,
                "response_time",
                field(path, record, &row, idx[8], "response_time")?,
                0.0,
                86_400.0,
            )?,
            engagement,
            engagement_per_second,
        });
        if out.last().is_some_and(|r| r.user_id.is_empty()) {
            return Err(DataError::Record {
                path: path.into(),
                record,
                reason: "user_id is empty".into(),
            });
        }
    }
    if out.is_empty() {
        return Err(DataError::Empty { path: path.into() });
    }
    Ok(out)
}

/// Writes records in our CSV format (temporary file, then rename).
pub fn write_csv(path: &Path, records: &[InteractionRecord]) -> Result<(), DataError> {
    let io = |source: std::io::Error| DataError::Io {
        path: path.into(),
        source,
    };
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(io)?;
    let tmp = tempfile::NamedTempFile::new_in(dir).map_err(io)?;
    {
        let mut w = csv::Writer::from_writer(tmp.as_file());
        let csv_err = |e: csv::Error| DataError::Io {
            path: path.into(),
            source: std::io::Error::other(e.to_string()),
        };
        w.write_record(CSV_COLUMNS).map_err(csv_err)?;
        for r in records {
            let per_second: Vec<String> = r
                .engagement_per_second
                .iter()
                .map(|e| format!("{e:.4}"))
                .collect();
            w.write_record([
                r.user_id.clone(),
                r.session_id.clone(),
                format!("{:.3}", r.time),
                r.level.get().to_string(),
                (r.feedback as u8).to_string(),
                r.previous_score.to_string(),
                r.outcome.sign().to_string(),
                r.score.to_string(),
                format!("{:.3}", r.response_time),
                r.engagement.map(|e| format!("{e}")).unwrap_or_default(),
                per_second.join(";"),
            ])
            .map_err(csv_err)?;
        }
        w.flush().map_err(io)?;
    }
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(tmp.path(), std::fs::Permissions::from_mode(0o644)).map_err(io)?;
    tmp.persist(path).map_err(|e| io(e.error))?;
    Ok(())
}

/// Reads the MigrAVE study's own files from `dir`: `sequences.csv` gives one record per
/// sequence (PS from the previous sequence of the same participant); its engagement E is the
/// sequence's `eng_qt` (the authors' mean while the robot talked), and its per-second values
/// are the seconds of `engagement_per_second.csv` in [start, start + talking_time).
pub fn read_study(dir: &Path) -> Result<Vec<InteractionRecord>, DataError> {
    let seq_path = dir.join("sequences.csv");
    let eng_path = dir.join("engagement_per_second.csv");
    let mut per_second: BTreeMap<String, BTreeMap<i64, f64>> = BTreeMap::new();
    {
        let (mut r, headers) = reader(&eng_path)?;
        let (p, s, e) = (
            column(&eng_path, &headers, "participant_id")?,
            column(&eng_path, &headers, "secs")?,
            column(&eng_path, &headers, "eng_qt")?,
        );
        for (n, row) in r.records().enumerate() {
            let row = row.map_err(|e| DataError::Record {
                path: eng_path.clone(),
                record: n + 1,
                reason: e.to_string(),
            })?;
            let secs: f64 = field(&eng_path, n + 1, &row, s, "secs")?;
            let value = finite(
                &eng_path,
                n + 1,
                "eng_qt",
                field(&eng_path, n + 1, &row, e, "eng_qt")?,
                -1.0,
                1.0,
            )?;
            per_second
                .entry(row.get(p).unwrap_or("").to_string())
                .or_default()
                .insert(secs as i64, value);
        }
    }
    let (mut r, headers) = reader(&seq_path)?;
    let cols: Vec<usize> = [
        "participant_id",
        "secs",
        "id",
        "length",
        "correct",
        "feedback",
        "duration",
        "eng_qt",
        "start",
        "talking_time",
    ]
    .iter()
    .map(|c| column(&seq_path, &headers, c))
    .collect::<Result<_, _>>()?;
    let mut rows: Vec<(String, i64, InteractionRecord)> = Vec::new();
    for (n, row) in r.records().enumerate() {
        let record = n + 1;
        let row = row.map_err(|e| DataError::Record {
            path: seq_path.clone(),
            record,
            reason: e.to_string(),
        })?;
        let bad = |reason: String| DataError::Record {
            path: seq_path.clone(),
            record,
            reason,
        };
        let user = row.get(cols[0]).unwrap_or("").to_string();
        let level = Level::from_sequence_length(field(&seq_path, record, &row, cols[3], "length")?)
            .map_err(|e| bad(e.to_string()))?;
        let correct: i64 = field(&seq_path, record, &row, cols[4], "correct")?;
        if correct != 0 && correct != 1 {
            return Err(bad(format!("correct = {correct} is not 0 or 1")));
        }
        let outcome = Outcome::from_correct(correct == 1);
        let feedback = Feedback::new(field(&seq_path, record, &row, cols[5], "feedback")?)
            .map_err(|e| bad(e.to_string()))?;
        let start: f64 = field(&seq_path, record, &row, cols[8], "start")?;
        let talking: f64 = field(&seq_path, record, &row, cols[9], "talking_time")?;
        let eng_qt = finite(
            &seq_path,
            record,
            "eng_qt",
            field(&seq_path, record, &row, cols[7], "eng_qt")?,
            -1.0,
            1.0,
        )?;
        rows.push((
            user.clone(),
            field(&seq_path, record, &row, cols[2], "id")?,
            InteractionRecord {
                user_id: user.clone(),
                session_id: format!("{user}-study"),
                time: field(&seq_path, record, &row, cols[1], "secs")?,
                level,
                feedback,
                previous_score: 0,
                outcome,
                score: outcome.score(level),
                response_time: finite(
                    &seq_path,
                    record,
                    "duration",
                    field(&seq_path, record, &row, cols[6], "duration")?,
                    0.0,
                    86_400.0,
                )?,
                engagement: Some(eng_qt),
                engagement_per_second: per_second
                    .get(&user)
                    .map(|m| {
                        m.range(start as i64..(start + talking) as i64)
                            .map(|(_, v)| *v)
                            .collect()
                    })
                    .unwrap_or_default(),
            },
        ));
    }
    if rows.is_empty() {
        return Err(DataError::Empty { path: seq_path });
    }
    rows.sort_by(|a, b| (a.0.as_str(), a.1).cmp(&(b.0.as_str(), b.1)));
    let mut out: Vec<InteractionRecord> = Vec::with_capacity(rows.len());
    for (user, _, mut rec) in rows {
        rec.previous_score = match out.last() {
            Some(prev) if prev.user_id == user => prev.score,
            _ => 0,
        };
        out.push(rec);
    }
    Ok(out)
}

/// Reads a data set: a study directory, or a CSV file in our format.
pub fn read_any(path: &Path) -> Result<Vec<InteractionRecord>, DataError> {
    if path.is_dir() {
        read_study(path)
    } else {
        read_csv(path)
    }
}
