//! Interaction records from our MCAP session bags (`bag record`), so user models can be fitted
//! straight from recorded sessions: one record per `SequenceResult`, with the per-second
//! engagement recomputed from the `ExpectedEngagement` windows of the period the robot talked
//! for that sequence, the game manager's own period and rule (`session_tally::engagement`):
//! from the end of the previous sequence of the session (its answer or timeout; the session's
//! start for the first) to the moment the task was sent to the tablet; a window
//! counts when its midpoint lies in that period and it saw a face; each second is the mean of
//! its sources' smoothed values. The period is the result's own (`engagement_period_start`,
//! `_end`, as the game manager timed it); for results recorded before it carried one, it is
//! inferred from the bag: the session's start is its first `GameState` stamp, the task's
//! sending its `TabletTask` stamp, and the answer that task's stamp plus the result's response
//! time (a few milliseconds off the game manager's, so a window at the edge may differ). A
//! damaged bag yields the sequences before the damage and a warning naming the bad record.

use super::{DataError, FieldError, InteractionRecord};
use bag_file::{BagReader, Stamped};
use qt_therapy_msgs::topics::{EXPECTED_ENGAGEMENT, GAME_STATE, SEQUENCE_RESULT, TABLET_TASK};
use qt_therapy_msgs::{ExpectedEngagement, SequenceResult};
use sequence_game::{Feedback, Level, Outcome};
use session_tally::EngagementLog;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Records read from bags, and what the reader had to work around (damage, unclosed files,
/// messages delivered again).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BagRecords {
    pub records: Vec<InteractionRecord>,
    pub warnings: Vec<String>,
}

/// The messages of one bag the records are made from (the sans-IO input of [`records_from`]),
/// each taken once by the suite's rule for what arrives twice (`session_log`).
pub type SessionMessages = session_log::Messages;

/// Whether `path` names a bag file (by its `.mcap` extension).
pub fn is_bag(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mcap"))
}

/// The bags (`*.mcap`) under `dir`, at any depth, in path order. Unfinished recordings
/// (`*.mcap.partial`) are not taken.
pub fn bags_in(dir: &Path) -> Result<Vec<PathBuf>, DataError> {
    let mut out = Vec::new();
    let mut pending = vec![dir.to_path_buf()];
    while let Some(d) = pending.pop() {
        for entry in std::fs::read_dir(&d).map_err(|e| DataError::io(&d, e))? {
            let path = entry.map_err(|e| DataError::io(&d, e))?.path();
            if path.is_dir() {
                pending.push(path);
            } else if is_bag(&path) {
                out.push(path);
            }
        }
    }
    out.sort();
    Ok(out)
}

/// Why user-model data needs each topic it reads.
const NEEDED: [(&str, &str); 4] = [
    (
        SEQUENCE_RESULT.name,
        "it holds one SequenceResult per solved sequence",
    ),
    (
        TABLET_TASK.name,
        "its task times end the period the robot talked",
    ),
    (
        GAME_STATE.name,
        "its first stamp of a session starts that session's first period",
    ),
    (
        EXPECTED_ENGAGEMENT.name,
        "it holds the per-second engagement",
    ),
];

/// Reads the records of one bag.
pub fn read_bag(path: &Path) -> Result<BagRecords, DataError> {
    read_bags(&[path.to_path_buf()])
}

/// Reads the records of several bags (a user may have played several sessions, each in its
/// own bag), sorted by user, then time. What arrives twice follows the suite's one rule
/// (`session_log`, docs/session_log.md), across the bags too: a result delivered again, or a
/// session in two bags (a bag and its copy), is taken once and named in a warning; the same
/// sequence with another content is an error naming both.
pub fn read_bags(paths: &[PathBuf]) -> Result<BagRecords, DataError> {
    let mut out = BagRecords::default();
    let mut rule = session_log::SessionReader::new();
    for path in paths {
        let reader = BagReader::open(path).map_err(DataError::Bag)?;
        let name = reader.name().to_string();
        let log = rule.read_bag(&reader).map_err(|e| match e {
            session_log::SessionLogError::Bag(e) => DataError::Bag(e),
            session_log::SessionLogError::Conflict(c) => DataError::Conflict(c),
        })?;
        if let Some((topic, why)) = NEEDED.iter().find(|(t, _)| log.missing_topics.contains(t)) {
            return Err(DataError::MissingTopic {
                bag: name,
                topic,
                why,
            });
        }
        let messages = &log.messages;
        let origin = format!("{name}, topic {}", SEQUENCE_RESULT.name);
        if let Some(damage) = &log.damage {
            let warning = format!(
                "{name} is damaged; using the {} sequence results before the damage: {damage}",
                messages.results.len()
            );
            tracing::warn!("{warning}");
            out.warnings.push(warning);
        } else if !log.complete {
            let warning = format!(
                "{name} was not closed cleanly (no footer); using its {} sequence results",
                messages.results.len()
            );
            tracing::warn!("{warning}");
            out.warnings.push(warning);
        }
        if let Some(warning) = log.repeats_warning() {
            tracing::warn!("{warning}");
            out.warnings.push(warning);
        }
        if messages.results.is_empty() && log.repeats_on(SEQUENCE_RESULT) == 0 {
            return Err(DataError::NoSequences {
                bag: name,
                topic: SEQUENCE_RESULT.name,
            });
        }
        out.records.extend(records_from(messages, &origin)?);
    }
    out.records.sort_by(|a, b| {
        a.user_id
            .cmp(&b.user_id)
            .then(a.time.total_cmp(&b.time))
            .then(a.session_id.cmp(&b.session_id))
    });
    Ok(out)
}

/// Nanoseconds since the epoch of a header stamp.
fn stamp_ns(t: &qt_therapy_msgs::builtin_interfaces::Time) -> i64 {
    t.to_nanos()
}

/// The per-second engagement of `[start_ns, end_ns)`, gathered by the game manager's own
/// `EngagementLog` (midpoint rule, faceless windows left out, sources averaged per second).
pub fn engagement_per_second(
    windows: &[Stamped<ExpectedEngagement>],
    start_ns: i64,
    end_ns: i64,
) -> Vec<f64> {
    let mut log = EngagementLog::default();
    // Only windows overlapping the period: the log keeps at most an hour of windows, and a
    // bag may hold many sessions.
    for w in windows {
        let e = &w.message;
        if e.window_end.to_nanos() > start_ns && e.window_start.to_nanos() < end_ns {
            log.push(e);
        }
    }
    log.gather(start_ns, end_ns)
        .per_second
        .into_iter()
        .map(f64::from)
        .collect()
}

/// Makes the records of one bag's messages; `origin` names the results in errors (record n is
/// the n-th SequenceResult in log-time order).
pub fn records_from(
    m: &SessionMessages,
    origin: &str,
) -> Result<Vec<InteractionRecord>, DataError> {
    let mut session_start: HashMap<&str, i64> = HashMap::new();
    for s in &m.states {
        if s.message.session_id.is_empty() {
            continue;
        }
        let t = stamp_ns(&s.message.header.stamp);
        session_start
            .entry(s.message.session_id.as_str())
            .and_modify(|v| *v = (*v).min(t))
            .or_insert(t);
    }
    // The previous answer (ns) of each session.
    let mut last_answer: HashMap<&str, i64> = HashMap::new();
    let mut out = Vec::with_capacity(m.results.len());
    for (n, stamped) in m.results.iter().enumerate() {
        let r = &stamped.message;
        let (record, answered) = (|| -> Result<(InteractionRecord, i64), FieldError> {
            let game = |field: &'static str| {
                move |e: sequence_game::GameError| FieldError::new(field, e.to_string())
            };
            let level = Level::new(r.level.into()).map_err(game("level"))?;
            let feedback = Feedback::new(r.feedback.into()).map_err(game("feedback"))?;
            let outcome = Outcome::new(r.outcome.into()).map_err(game("outcome"))?;
            let response_time = f64::from(r.response_time);
            let rt_ok = super::in_range("response_time", response_time, 0.0, 86_400.0)?;
            let (talk_start, task) = match explicit_period(r)? {
                Some(period) => period,
                None => inferred_period(m, r, &session_start, &last_answer)?,
            };
            let answered = task + (rt_ok * 1e9).round() as i64;
            let per_second = engagement_per_second(&m.engagement, talk_start, task);
            let engagement = (!per_second.is_empty())
                .then(|| per_second.iter().sum::<f64>() / per_second.len() as f64);
            let record = InteractionRecord {
                user_id: r.user_id.clone(),
                session_id: r.session_id.clone(),
                time: answered as f64 / 1e9,
                level,
                feedback,
                previous_score: r.state.previous_score,
                outcome,
                score: outcome.score(level),
                response_time,
                engagement,
                engagement_per_second: per_second,
            };
            record.validate()?;
            Ok((record, answered))
        })()
        .map_err(|e| e.in_record(origin, n + 1))?;
        last_answer.insert(r.session_id.as_str(), answered);
        out.push(record);
    }
    Ok(out)
}

/// The period a result says its engagement was gathered over (results recorded since the
/// game manager wrote it); None for a result without one.
fn explicit_period(r: &SequenceResult) -> Result<Option<(i64, i64)>, FieldError> {
    let (start, end) = (
        r.engagement_period_start.to_nanos(),
        r.engagement_period_end.to_nanos(),
    );
    if end == 0 {
        return Ok(None);
    }
    if start > end {
        return Err(FieldError::new(
            "engagement_period_start",
            format!("{start} ns is after engagement_period_end {end} ns"),
        ));
    }
    Ok(Some((start, end)))
}

/// The period of a result recorded without one, from the bag as the game manager timed it:
/// from the previous answer of the session (its task's stamp plus its response time; the
/// session's first GameState for sequence 1) to this sequence's TabletTask stamp.
fn inferred_period(
    m: &SessionMessages,
    r: &SequenceResult,
    session_start: &HashMap<&str, i64>,
    last_answer: &HashMap<&str, i64>,
) -> Result<(i64, i64), FieldError> {
    let result_ns = stamp_ns(&r.header.stamp);
    let task = m
        .tasks
        .iter()
        .filter(|t| {
            t.message.session_id == r.session_id
                && t.message.sequence_index == r.sequence_index
                && stamp_ns(&t.message.header.stamp) <= result_ns
        })
        .map(|t| stamp_ns(&t.message.header.stamp))
        .max()
        .ok_or_else(|| {
            FieldError::new(
                "sequence_index",
                format!(
                    "no TabletTask of session {:?} sequence {} on {} before it, so when the robot stopped talking is unknown",
                    r.session_id, r.sequence_index, TABLET_TASK.name
                ),
            )
        })?;
    let talk_start = match last_answer.get(r.session_id.as_str()) {
        Some(t) => *t,
        None => *session_start.get(r.session_id.as_str()).ok_or_else(|| {
            FieldError::new(
                "session_id",
                format!(
                    "no GameState of session {:?} on {}, so when it started is unknown",
                    r.session_id, GAME_STATE.name
                ),
            )
        })?,
    };
    Ok((talk_start, task))
}

#[cfg(test)]
mod tests {
    use super::*;
    use qt_therapy_msgs::builtin_interfaces::Time;

    const S: i64 = 1_000_000_000;

    fn window(
        start_s: i64,
        smoothed: f32,
        has_faces: bool,
        source: &str,
    ) -> Stamped<ExpectedEngagement> {
        Stamped {
            log_time: ((start_s + 1) * S) as u64,
            publish_time: 0,
            sequence: 0,
            message: ExpectedEngagement {
                source: source.into(),
                window_start: Time::from_nanos(start_s * S),
                window_end: Time::from_nanos((start_s + 1) * S),
                has_faces,
                smoothed,
                ..Default::default()
            },
        }
    }

    #[test]
    fn seconds_are_gathered_as_the_game_manager_does() {
        // The game manager's own test case (scoring.rs), same expected values.
        let mut w: Vec<_> = [(9, 0.9), (10, 0.5), (11, -0.1), (12, 0.2), (20, -1.0)]
            .into_iter()
            .map(|(t, v)| window(t, v, true, "cam/0"))
            .collect();
        w.push(window(13, 0.0, false, "cam/0"));
        w.push(window(11, 0.3, true, "cam2/0"));
        let e = engagement_per_second(&w, 10 * S, 14 * S);
        let expected = [0.5, 0.1, 0.2];
        assert_eq!(e.len(), 3);
        assert!(
            e.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-6),
            "{e:?}"
        );
        assert!(engagement_per_second(&w, 14 * S, 19 * S).is_empty());
    }
}
