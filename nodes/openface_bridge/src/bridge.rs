//! The bridge's core: OpenFace CSV lines in (with their line number and the node's clock),
//! `OpenFaceFeatures` messages (each with the time it may be published) and log lines out. A
//! header line starts a run (OpenFace started writing a file); each row after it becomes one
//! message, or is skipped and counted: a lost face (`success` 0), a confidence below the
//! parameter, a bad row (wrong field count, a value that is not a number or not finite, a line
//! too long, each kind named once with its line number), a (face, frame) read already in this
//! run, or a backlog row too old to matter.
//!
//! Stamps (`stamp: openface`): OpenFace's timestamp plus the run's offset to the node's clock,
//! estimated as the smallest lag seen between a row's OpenFace time and the time it was read (a
//! row is never read before it was written), taken over a whole read before any row of it is
//! stamped. So a stamp is never ahead of the clock, rows keep OpenFace's spacing, and a backlog
//! read at once (the bridge restarted in the middle of a run) lands in the past where it
//! belongs. Publication is paced: never faster than `max_publish_hz` (a burst after a stall or
//! a backlog would overflow a best-effort reader's queue), and with `replay_rate` a finished
//! recording is published on OpenFace's own clock (times the rate), each stamped when it is due.
//!
//! The core's clock is the node's steady clock, which a step of the wall clock does not move:
//! pacing and the offset above stay right when NTP or someone steps the wall clock. Its stamps
//! are on that clock too; the node adds the wall clock's offset from it as it publishes, so
//! what goes out is stamped by the wall clock.
//!
//! OpenFace rewrites its whole CSV when it ends (post-processed action units): after the file
//! restarts, its first rows are held until they tell a rewrite (the previous run's frames with
//! the same timestamps, read much faster than OpenFace's clock ran: the file is written at once)
//! from a new run (a camera's pace, or other timestamps); a rewrite keeps the run, so its frames
//! already read are not published again.

use crate::columns::{ColumnMap, HeaderError, ROW_COLUMNS, is_header};
use crate::params::{OpenFaceBridgeParams, StampSource};
use openface::features::OPENFACE_FEATURES;
use qt_therapy_msgs::OpenFaceFeatures;
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use std::collections::{BTreeSet, HashMap, VecDeque};
use tracing::Level;

/// A line for the log.
#[derive(Debug, Clone, PartialEq)]
pub struct LogLine(pub Level, pub String);

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
    /// Rows whose (face, frame) had been read already in the run: OpenFace rewrote its file.
    pub already_read: u64,
    /// Rows the file held when the bridge found it, older than `max_backlog_s` before its
    /// newest row.
    pub backlog_skipped: u64,
    pub runs: u64,
}

/// Rows held after a restart before a rewrite is told from a new run.
const ROWS_TO_DECIDE: usize = 5;

/// Frames whose timestamps a run remembers (five hours at 30 fps), to recognise its rewrite.
const MAX_REMEMBERED_FRAMES: usize = 1 << 19;

/// OpenFace's timestamp going back by more than this (s) without a header starts a new clock.
const CLOCK_BACK_S: f64 = 1.0;

/// One row's values and when it was read.
#[derive(Debug, Clone)]
struct Row {
    frame: f64,
    face_id: String,
    timestamp: f64,
    confidence: f64,
    success: bool,
    features: Vec<f32>,
    read_ns: i64,
}

/// What is known of the run OpenFace is writing.
#[derive(Debug, Clone, Default)]
struct Run {
    /// OpenFace's timestamp of each frame read, by frame number, to recognise its rewrite.
    timestamps: Vec<Option<f64>>,
    /// The highest frame number read.
    last_frame: Option<f64>,
    /// The highest frame read of each face: a (face, frame) not above it is a repeat.
    last_frame_by_face: HashMap<String, f64>,
    /// Wall clock minus OpenFace's clock (ns): the smallest lag seen.
    offset_ns: Option<i64>,
    /// The newest OpenFace timestamp stamped, to see OpenFace's clock go back.
    last_timestamp: Option<f64>,
    /// The last stamp given, so stamps never go back within a run.
    last_stamp_ns: i64,
    /// (OpenFace timestamp, ns on the core's clock) a replay is timed from.
    replay_anchor: Option<(f64, i64)>,
}

impl Run {
    fn remember(&mut self, row: &Row) {
        let frame = row.frame;
        self.last_frame = Some(self.last_frame.map_or(frame, |f| f.max(frame)));
        if frame >= 0.0 && frame < MAX_REMEMBERED_FRAMES as f64 {
            let k = frame as usize;
            if self.timestamps.len() <= k {
                self.timestamps.resize(k + 1, None);
            }
            self.timestamps[k] = Some(row.timestamp);
        }
        match self.last_frame_by_face.get_mut(&row.face_id) {
            Some(f) => *f = f.max(frame),
            None => {
                self.last_frame_by_face.insert(row.face_id.clone(), frame);
            }
        }
    }

    fn timestamp_of(&self, frame: f64) -> Option<f64> {
        (frame >= 0.0)
            .then(|| self.timestamps.get(frame as usize).copied().flatten())
            .flatten()
    }

    /// Whether this (face, frame) was read already in the run.
    fn seen(&self, row: &Row) -> bool {
        self.last_frame_by_face
            .get(&row.face_id)
            .is_some_and(|&f| row.frame <= f)
    }
}

/// After a restart: the run before it and the rows held until a rewrite is told from a new
/// run.
#[derive(Debug, Clone)]
struct Deciding {
    previous: Run,
    held: Vec<Row>,
}

/// How the bridge publishes, from its parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Pace {
    /// Least time between two publications (ns).
    min_gap_ns: i64,
    /// A finished recording replayed at this multiple of OpenFace's clock.
    replay_rate: Option<f64>,
}

/// The bridge core.
#[derive(Debug, Clone)]
pub struct Bridge {
    frame_id: String,
    stamp: StampSource,
    min_confidence: f64,
    max_line_bytes: usize,
    pace: Pace,
    /// Rows of the file's first read kept until it is caught up: the newest `max_backlog_s`
    /// of them are published, the older are skipped. `None` once caught up (or on a pipe, or
    /// in a replay, where every row counts).
    backlog: Option<VecDeque<Row>>,
    max_backlog_s: f64,
    map: Option<ColumnMap>,
    run: Run,
    deciding: Option<Deciding>,
    /// Rows taken since the last `end_of_read`, to be stamped together.
    pending: Vec<Row>,
    /// Messages stamped and waiting for their time (ns on the core's clock).
    queue: VecDeque<(i64, OpenFaceFeatures)>,
    last_due_ns: Option<i64>,
    /// When `due` last handed a message out.
    last_sent_ns: Option<i64>,
    told: BTreeSet<&'static str>,
    counts: Counts,
}

impl Bridge {
    /// A bridge for validated parameters.
    pub fn new(params: &OpenFaceBridgeParams, stamp: StampSource) -> Bridge {
        let replay_rate = (params.replay_rate > 0.0).then_some(params.replay_rate);
        let follows_a_file = params.csv_path != "-";
        Bridge {
            frame_id: params.frame_id.clone(),
            stamp,
            min_confidence: params.min_confidence,
            max_line_bytes: params.max_line_bytes,
            pace: Pace {
                min_gap_ns: (1e9 / params.max_publish_hz).round() as i64,
                replay_rate,
            },
            backlog: (follows_a_file && replay_rate.is_none()).then(VecDeque::new),
            max_backlog_s: params.max_backlog_s,
            map: None,
            run: Run::default(),
            deciding: None,
            pending: Vec::new(),
            queue: VecDeque::new(),
            last_due_ns: None,
            last_sent_ns: None,
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
             read before OpenFace rewrote its file, {} older backlog skipped; {} run(s)",
            c.rows,
            c.published,
            c.lost_face,
            c.low_confidence,
            c.bad,
            c.already_read,
            c.backlog_skipped,
            c.runs
        )
    }

    /// The file was truncated, replaced or rewritten (OpenFace restarted, or rewrote it at its
    /// end).
    pub fn restarted(&mut self, why: &str) -> Vec<LogLine> {
        let mut out = Vec::new();
        // Rows still held from an earlier restart belong to the run they were read in.
        self.decide(false, &mut out);
        self.deciding = Some(Deciding {
            previous: std::mem::take(&mut self.run),
            held: Vec::new(),
        });
        self.map = None;
        out.push(LogLine(
            Level::INFO,
            format!("the OpenFace CSV was {why}: reading it again from its header"),
        ));
        out
    }

    /// Everything the file held when it was found has been read: the newest `max_backlog_s`
    /// of it goes out with the next `end_of_read`.
    pub fn caught_up(&mut self) -> Vec<LogLine> {
        let Some(backlog) = self.backlog.take() else {
            return Vec::new();
        };
        let mut out = Vec::new();
        if self.counts.backlog_skipped > 0 {
            out.push(LogLine(
                Level::INFO,
                format!(
                    "the OpenFace CSV held a run already: its last {} s ({} rows) published, \
                     {} older rows skipped (max_backlog_s)",
                    self.max_backlog_s,
                    backlog.len(),
                    self.counts.backlog_skipped
                ),
            ));
        }
        self.pending.extend(backlog);
        out
    }

    /// A line longer than `max_line_bytes` (its text dropped by the follower).
    pub fn too_long(&mut self, line_no: u64) -> Vec<LogLine> {
        let mut out = Vec::new();
        self.bad(BadRow::TooLong(self.max_line_bytes), line_no, &mut out);
        out
    }

    /// One line of the CSV (without its newline), read at `now_ns`. A header that
    /// lacks a needed column is an error: OpenFace runs with the wrong outputs. Rows taken
    /// wait for `end_of_read`.
    pub fn line(
        &mut self,
        text: &str,
        line_no: u64,
        now_ns: i64,
    ) -> Result<Vec<LogLine>, HeaderError> {
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
            let map = ColumnMap::from_header(text)?;
            if self.map.is_some() && self.deciding.is_none() {
                // A header in the middle of a stream (OpenFace started again on a pipe): what
                // was read goes out on the old run's clock; a new run begins.
                out.extend(self.end_of_read(now_ns));
                self.run = Run::default();
            }
            self.map = Some(map);
            self.counts.runs += 1;
            out.push(LogLine(
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
        let row = match parse_row(map, text, now_ns) {
            Ok(row) => row,
            Err(e) => {
                self.bad(e, line_no, &mut out);
                return Ok(out);
            }
        };
        if let Some(d) = self.deciding.as_mut() {
            let same_frame = d.previous.timestamp_of(row.frame) == Some(row.timestamp);
            let whole = d.previous.last_frame.is_some_and(|f| row.frame >= f);
            d.held.push(row);
            if !same_frame {
                self.decide(false, &mut out);
            } else if whole || d.held.len() >= ROWS_TO_DECIDE {
                let rewritten = written_at_once(&d.held);
                self.decide(rewritten, &mut out);
            }
            return Ok(out);
        }
        self.take_row(row);
        Ok(out)
    }

    /// The end of one read of the file or the pipe, at `now_ns`: the rows taken
    /// since the last one are stamped together and queued for publication.
    pub fn end_of_read(&mut self, now_ns: i64) -> Vec<LogLine> {
        let mut out = Vec::new();
        if self.pending.is_empty() {
            return out;
        }
        let rows = std::mem::take(&mut self.pending);
        if self.stamp == StampSource::OpenFace && self.pace.replay_rate.is_none() {
            self.update_offset(&rows, &mut out);
        }
        for row in rows {
            let (stamp_ns, due_ns) = self.times(&row, now_ns);
            self.counts.published += 1;
            self.queue.push_back((
                due_ns,
                OpenFaceFeatures {
                    header: Header {
                        stamp: Time::from_nanos(stamp_ns),
                        frame_id: self.frame_id.clone(),
                    },
                    face_id: row.face_id,
                    confidence: row.confidence as f32,
                    success: true,
                    features: row.features,
                },
            ));
        }
        out
    }

    /// The messages whose time has come at `now_ns`, in order, never closer together than
    /// `max_publish_hz` allows: a queue held back (no reader yet) does not go out as a burst.
    pub fn due(&mut self, now_ns: i64) -> Vec<OpenFaceFeatures> {
        let mut out = Vec::new();
        while self.next_due_ns().is_some_and(|due| due <= now_ns) {
            if let Some((_, m)) = self.queue.pop_front() {
                out.push(m);
                self.last_sent_ns = Some(now_ns);
            }
        }
        out
    }

    /// When the next queued message may go out (ns on the core's clock).
    pub fn next_due_ns(&self) -> Option<i64> {
        let (due, _) = self.queue.front()?;
        Some(match self.last_sent_ns {
            Some(sent) => (*due).max(sent + self.pace.min_gap_ns),
            None => *due,
        })
    }

    /// Messages waiting for their time.
    pub fn queued(&self) -> usize {
        self.queue.len()
    }

    /// Lowers the run's offset to the smallest lag among `rows` (all read by now), and starts
    /// a new clock where OpenFace's went back without a header.
    fn update_offset(&mut self, rows: &[Row], out: &mut Vec<LogLine>) {
        let Some(first) = rows.first() else {
            return;
        };
        if let Some(last) = self.run.last_timestamp
            && first.timestamp < last - CLOCK_BACK_S
        {
            out.push(LogLine(
                Level::WARN,
                format!(
                    "OpenFace's timestamp went back from {last} s to {} s without a new \
                     header: stamps measured on a new clock from this row",
                    first.timestamp
                ),
            ));
            self.run.offset_ns = None;
            self.run.last_stamp_ns = i64::MIN;
        }
        let smallest_lag = rows
            .iter()
            .map(|r| r.read_ns - (r.timestamp * 1e9).round() as i64)
            .min();
        if let Some(lag) = smallest_lag {
            self.run.offset_ns = Some(self.run.offset_ns.map_or(lag, |o| o.min(lag)));
        }
        self.run.last_timestamp = rows.iter().map(|r| r.timestamp).reduce(f64::max);
    }

    /// A row's stamp and the time it may be published.
    fn times(&mut self, row: &Row, now_ns: i64) -> (i64, i64) {
        let paced =
            |last: Option<i64>, at: i64| last.map_or(at, |l| at.max(l + self.pace.min_gap_ns));
        if let Some(rate) = self.pace.replay_rate {
            let (t0, wall0) = match self.run.replay_anchor {
                Some((t0, wall0)) if row.timestamp >= t0 => (t0, wall0),
                // The first row, or a recording whose clock went back: timed from now.
                _ => {
                    let anchor = (
                        row.timestamp,
                        now_ns.max(self.last_due_ns.unwrap_or(now_ns)),
                    );
                    self.run.replay_anchor = Some(anchor);
                    anchor
                }
            };
            let due = paced(
                self.last_due_ns,
                wall0 + ((row.timestamp - t0) / rate * 1e9).round() as i64,
            );
            self.last_due_ns = Some(due);
            // Published when due, so stamped then: on the recording's clock, never ahead.
            return (due, due);
        }
        let stamp = match (self.stamp, self.run.offset_ns) {
            (StampSource::OpenFace, Some(offset)) => {
                let on_openface_clock = (row.timestamp * 1e9).round() as i64 + offset;
                on_openface_clock
                    .max(self.run.last_stamp_ns)
                    .min(row.read_ns)
            }
            _ => row.read_ns,
        };
        self.run.last_stamp_ns = stamp;
        let due = paced(self.last_due_ns, now_ns);
        self.last_due_ns = Some(due);
        (stamp, due)
    }

    /// Ends the wait after a restart: the file is the previous run `rewritten`, or a new run;
    /// then the held rows go through.
    fn decide(&mut self, rewritten: bool, out: &mut Vec<LogLine>) {
        let Some(d) = self.deciding.take() else {
            return;
        };
        if rewritten {
            out.push(LogLine(
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
        for row in d.held {
            self.take_row(row);
        }
    }

    /// Takes a parsed row for publication, or skips and counts it.
    fn take_row(&mut self, row: Row) {
        if self.run.seen(&row) {
            self.counts.already_read += 1;
            return;
        }
        self.run.remember(&row);
        if !row.success {
            self.counts.lost_face += 1;
            return;
        }
        if row.confidence < self.min_confidence {
            self.counts.low_confidence += 1;
            return;
        }
        match self.backlog.as_mut() {
            Some(backlog) => {
                // Only the newest max_backlog_s of what the file held is worth publishing.
                if backlog.back().is_some_and(|b| row.timestamp < b.timestamp) {
                    // A new run inside the backlog: the older one is over.
                    self.counts.backlog_skipped += backlog.len() as u64;
                    backlog.clear();
                }
                let oldest = row.timestamp - self.max_backlog_s;
                backlog.push_back(row);
                while backlog.front().is_some_and(|b| b.timestamp < oldest) {
                    backlog.pop_front();
                    self.counts.backlog_skipped += 1;
                }
            }
            None => self.pending.push(row),
        }
    }

    /// Counts a bad row and names its kind the first time it happens.
    fn bad(&mut self, e: BadRow, line_no: u64, out: &mut Vec<LogLine>) {
        self.counts.bad += 1;
        if self.told.insert(e.kind()) {
            out.push(LogLine(
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
fn written_at_once(held: &[Row]) -> bool {
    let (Some(first), Some(last)) = (held.first(), held.last()) else {
        return false;
    };
    let openface_ns = (last.timestamp - first.timestamp) * 1e9;
    ((last.read_ns - first.read_ns) as f64) * 4.0 <= openface_ns.max(0.0)
}

/// The values of one row, by the header's map.
fn parse_row(map: &ColumnMap, text: &str, read_ns: i64) -> Result<Row, BadRow> {
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
        read_ns,
    })
}

#[cfg(test)]
mod tests;
