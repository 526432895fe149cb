//! The bridge's core: OpenFace CSV lines in (with their line number and the wall clock),
//! `OpenFaceFeatures` messages and log lines out. A header line starts a run (OpenFace started
//! writing a file); each row after it becomes one message, stamped from OpenFace's timestamp
//! anchored to the wall clock at the run's first row (or the receipt time), or is skipped and
//! counted: a lost face (`success` 0), a confidence below the parameter, or a bad row (wrong
//! field count, a value that is not a number or not finite, a line too long), each kind named
//! once with its line number. OpenFace rewrites its whole CSV when it ends (post-processed
//! action units): after the file restarts, its first rows are held until they tell a rewrite
//! (the previous run's frames with the same timestamps, read much faster than OpenFace's clock
//! ran: the file is written at once) from a new run (a camera's pace, or other timestamps), and
//! a rewrite's rows already read are not published again.

use crate::columns::{ColumnMap, HeaderError, ROW_COLUMNS, is_header};
use crate::params::{OpenFaceBridgeParams, StampSource};
use openface::features::OPENFACE_FEATURES;
use qt_therapy_msgs::OpenFaceFeatures;
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use std::collections::BTreeSet;
use tracing::Level;

/// What the shell must do.
#[derive(Debug, Clone, PartialEq)]
pub enum Output {
    Publish(OpenFaceFeatures),
    Log(Level, String),
}

/// Why a row was not published.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BadRow {
    #[error("a row before any header")]
    NoHeader,
    #[error("{got} fields, the header has {expected}")]
    FieldCount { expected: usize, got: usize },
    #[error("{column} = {value:?} is not a number")]
    NotANumber { column: String, value: String },
    #[error("{column} = {value} is not finite")]
    NotFinite { column: String, value: f64 },
    #[error("success = {0} is not 0 or 1")]
    Success(f64),
    #[error("confidence = {0} is not in [0, 1]")]
    Confidence(f64),
    #[error("face_id is empty")]
    NoFaceId,
    #[error("longer than {0} bytes")]
    TooLong(usize),
}

impl BadRow {
    /// The kind, so each is named once.
    pub fn kind(&self) -> &'static str {
        match self {
            BadRow::NoHeader => "no header",
            BadRow::FieldCount { .. } => "field count",
            BadRow::NotANumber { .. } => "not a number",
            BadRow::NotFinite { .. } => "not finite",
            BadRow::Success(_) => "success",
            BadRow::Confidence(_) => "confidence",
            BadRow::NoFaceId => "face_id",
            BadRow::TooLong(_) => "too long",
        }
    }
}

/// What happened to the lines so far.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Counts {
    pub rows: u64,
    pub published: u64,
    /// `success` 0: OpenFace lost the face.
    pub lost_face: u64,
    pub low_confidence: u64,
    pub bad: u64,
    /// Rows of a file OpenFace rewrote that had been published already.
    pub already_published: u64,
    pub runs: u64,
}

/// Rows held after a restart before a rewrite is told from a new run.
const ROWS_TO_DECIDE: usize = 5;

/// Frames whose timestamps a run remembers (five hours at 30 fps), to recognise its rewrite.
const MAX_REMEMBERED_FRAMES: usize = 1 << 19;

/// One row's values.
#[derive(Debug, Clone)]
struct Row {
    frame: f64,
    face_id: String,
    timestamp: f64,
    confidence: f64,
    success: bool,
    features: Vec<f32>,
}

/// What is known of the run OpenFace is writing.
#[derive(Debug, Clone, Default)]
struct Run {
    /// OpenFace's timestamp of each frame read, by frame number, to recognise its rewrite.
    timestamps: Vec<Option<f64>>,
    /// The highest frame number read.
    last_frame: Option<f64>,
    /// (OpenFace timestamp, wall clock ns) of the row stamps are measured from.
    anchor: Option<(f64, i64)>,
}

impl Run {
    fn remember(&mut self, frame: f64, timestamp: f64) {
        self.last_frame = Some(self.last_frame.map_or(frame, |f| f.max(frame)));
        if frame >= 0.0 && frame < MAX_REMEMBERED_FRAMES as f64 {
            let k = frame as usize;
            if self.timestamps.len() <= k {
                self.timestamps.resize(k + 1, None);
            }
            self.timestamps[k] = Some(timestamp);
        }
    }

    fn timestamp_of(&self, frame: f64) -> Option<f64> {
        (frame >= 0.0)
            .then(|| self.timestamps.get(frame as usize).copied().flatten())
            .flatten()
    }
}

/// After a restart: the run before it and the rows held until a rewrite is told from a new
/// run.
#[derive(Debug, Clone)]
struct Deciding {
    previous: Run,
    held: Vec<(Row, i64)>,
}

/// The bridge core.
#[derive(Debug, Clone)]
pub struct Bridge {
    frame_id: String,
    stamp: StampSource,
    min_confidence: f64,
    max_line_bytes: usize,
    map: Option<ColumnMap>,
    run: Run,
    deciding: Option<Deciding>,
    /// Rows up to this frame were published before OpenFace rewrote the file.
    skip_through_frame: Option<f64>,
    told: BTreeSet<&'static str>,
    counts: Counts,
}

impl Bridge {
    /// A bridge for validated parameters.
    pub fn new(params: &OpenFaceBridgeParams, stamp: StampSource) -> Bridge {
        Bridge {
            frame_id: params.frame_id.clone(),
            stamp,
            min_confidence: params.min_confidence,
            max_line_bytes: params.max_line_bytes,
            map: None,
            run: Run::default(),
            deciding: None,
            skip_through_frame: None,
            told: BTreeSet::new(),
            counts: Counts::default(),
        }
    }

    pub fn counts(&self) -> &Counts {
        &self.counts
    }

    /// The counts as a log line.
    pub fn report(&self) -> String {
        let c = &self.counts;
        format!(
            "{} rows: {} published, {} without a face, {} below min_confidence, {} bad, {} \
             published before OpenFace rewrote its file; {} run(s)",
            c.rows, c.published, c.lost_face, c.low_confidence, c.bad, c.already_published, c.runs
        )
    }

    /// The file was truncated or replaced (OpenFace restarted, or rewrote it at its end).
    pub fn restarted(&mut self, why: &str) -> Vec<Output> {
        let mut out = Vec::new();
        // Rows still held from an earlier restart belong to the run they were read in.
        self.decide(false, &mut out);
        self.deciding = Some(Deciding {
            previous: std::mem::take(&mut self.run),
            held: Vec::new(),
        });
        self.map = None;
        self.skip_through_frame = None;
        out.push(Output::Log(
            Level::INFO,
            format!("the OpenFace CSV was {why}: reading it again from its header"),
        ));
        out
    }

    /// A line longer than `max_line_bytes` (its text dropped by the follower).
    pub fn too_long(&mut self, line_no: u64) -> Vec<Output> {
        let mut out = Vec::new();
        self.bad(BadRow::TooLong(self.max_line_bytes), line_no, &mut out);
        out
    }

    /// One line of the CSV (without its newline), read at wall clock `now_ns`. A header that
    /// lacks a needed column is an error: OpenFace runs with the wrong outputs.
    pub fn line(
        &mut self,
        text: &str,
        line_no: u64,
        now_ns: i64,
    ) -> Result<Vec<Output>, HeaderError> {
        let text = text.trim_end_matches('\r');
        let mut out = Vec::new();
        if text.trim().is_empty() {
            return Ok(out);
        }
        if text.len() > self.max_line_bytes {
            self.bad(BadRow::TooLong(self.max_line_bytes), line_no, &mut out);
            return Ok(out);
        }
        if is_header(text) {
            self.map = Some(ColumnMap::from_header(text)?);
            self.counts.runs += 1;
            out.push(Output::Log(
                Level::INFO,
                format!("OpenFace CSV header at line {line_no}: following its rows"),
            ));
            return Ok(out);
        }
        self.counts.rows += 1;
        let Some(map) = &self.map else {
            self.bad(BadRow::NoHeader, line_no, &mut out);
            return Ok(out);
        };
        let row = match parse_row(map, text) {
            Ok(row) => row,
            Err(e) => {
                self.bad(e, line_no, &mut out);
                return Ok(out);
            }
        };
        if let Some(d) = self.deciding.as_mut() {
            let same_frame = d.previous.timestamp_of(row.frame) == Some(row.timestamp);
            let whole = d.previous.last_frame.is_some_and(|f| row.frame >= f);
            d.held.push((row, now_ns));
            if !same_frame {
                self.decide(false, &mut out);
            } else if whole || d.held.len() >= ROWS_TO_DECIDE {
                let rewritten = written_at_once(&d.held);
                self.decide(rewritten, &mut out);
            }
            return Ok(out);
        }
        self.take_row(row, now_ns, &mut out);
        Ok(out)
    }

    /// Ends the wait after a restart: the file is the previous run `rewritten`, or a new run;
    /// then the held rows go through.
    fn decide(&mut self, rewritten: bool, out: &mut Vec<Output>) {
        let Some(d) = self.deciding.take() else {
            return;
        };
        if rewritten {
            self.skip_through_frame = d.previous.last_frame;
            out.push(Output::Log(
                Level::INFO,
                format!(
                    "OpenFace rewrote its run (same frames, same timestamps): frames up to {} \
                     were read already and are not published again",
                    d.previous.last_frame.unwrap_or(0.0)
                ),
            ));
            // The rewrite keeps the run's clock and memory.
            self.run = d.previous;
        }
        for (row, now_ns) in d.held {
            self.take_row(row, now_ns, out);
        }
    }

    /// Publishes a parsed row, or skips and counts it.
    fn take_row(&mut self, row: Row, now_ns: i64, out: &mut Vec<Output>) {
        if self.skip_through_frame.is_some_and(|f| row.frame <= f) {
            self.counts.already_published += 1;
            return;
        }
        self.run.remember(row.frame, row.timestamp);
        if !row.success {
            self.counts.lost_face += 1;
            return;
        }
        if row.confidence < self.min_confidence {
            self.counts.low_confidence += 1;
            return;
        }
        let stamp_ns = self.stamp_ns(row.timestamp, now_ns, out);
        self.counts.published += 1;
        out.push(Output::Publish(OpenFaceFeatures {
            header: Header {
                stamp: Time::from_nanos(stamp_ns),
                frame_id: self.frame_id.clone(),
            },
            face_id: row.face_id,
            confidence: row.confidence as f32,
            success: true,
            features: row.features,
        }));
    }

    /// The stamp of a row with OpenFace timestamp `timestamp`, read at `now_ns`.
    fn stamp_ns(&mut self, timestamp: f64, now_ns: i64, out: &mut Vec<Output>) -> i64 {
        if self.stamp == StampSource::Receipt {
            return now_ns;
        }
        match self.run.anchor {
            Some((t0, _)) if timestamp < t0 => {
                out.push(Output::Log(
                    Level::WARN,
                    format!(
                        "OpenFace's timestamp went back from {t0} s to {timestamp} s without a \
                         new header: stamps measured from this row"
                    ),
                ));
                self.run.anchor = Some((timestamp, now_ns));
                now_ns
            }
            Some((t0, wall0)) => wall0 + ((timestamp - t0) * 1e9).round() as i64,
            None => {
                self.run.anchor = Some((timestamp, now_ns));
                now_ns
            }
        }
    }

    /// Counts a bad row and names its kind the first time it happens.
    fn bad(&mut self, e: BadRow, line_no: u64, out: &mut Vec<Output>) {
        self.counts.bad += 1;
        if self.told.insert(e.kind()) {
            out.push(Output::Log(
                Level::WARN,
                format!(
                    "skipped a bad OpenFace CSV row at line {line_no}: {e} (rows like it are \
                     skipped and counted without another word)"
                ),
            ));
        }
    }
}

/// Whether held rows were read much faster than OpenFace's clock ran between them (at least
/// four times), as a file written at once is: a new run comes at its camera's pace.
fn written_at_once(held: &[(Row, i64)]) -> bool {
    let (Some((first, first_ns)), Some((last, last_ns))) = (held.first(), held.last()) else {
        return false;
    };
    let openface_ns = (last.timestamp - first.timestamp) * 1e9;
    ((last_ns - first_ns) as f64) * 4.0 <= openface_ns.max(0.0)
}

/// The values of one row, by the header's map.
fn parse_row(map: &ColumnMap, text: &str) -> Result<Row, BadRow> {
    let fields: Vec<&str> = text.split(',').map(str::trim).collect();
    if fields.len() != map.width {
        return Err(BadRow::FieldCount {
            expected: map.width,
            got: fields.len(),
        });
    }
    let number = |index: usize, column: &str| -> Result<f64, BadRow> {
        let value = fields[index];
        let v: f64 = value.parse().map_err(|_| BadRow::NotANumber {
            column: column.to_string(),
            value: value.chars().take(20).collect(),
        })?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(BadRow::NotFinite {
                column: column.to_string(),
                value: v,
            })
        }
    };
    let [frame, face_id, timestamp, confidence, success] = map.row;
    let frame = number(frame, ROW_COLUMNS[0])?;
    let face_id = fields[face_id].to_string();
    if face_id.is_empty() {
        return Err(BadRow::NoFaceId);
    }
    let timestamp = number(timestamp, ROW_COLUMNS[2])?;
    let confidence = number(confidence, ROW_COLUMNS[3])?;
    if !(0.0..=1.0).contains(&confidence) {
        return Err(BadRow::Confidence(confidence));
    }
    let success = number(success, ROW_COLUMNS[4])?;
    if success != 0.0 && success != 1.0 {
        return Err(BadRow::Success(success));
    }
    let success = success == 1.0;
    let mut features = Vec::with_capacity(map.features.len());
    for (k, &index) in map.features.iter().enumerate() {
        features.push(number(index, OPENFACE_FEATURES[k])? as f32);
    }
    Ok(Row {
        frame,
        face_id,
        timestamp,
        confidence,
        success,
        features,
    })
}

#[cfg(test)]
mod tests;
