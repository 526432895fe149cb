//! Session bags written in-process from interaction records, laid out as the game manager
//! publishes a session: a GameState at the session's start, then per sequence the robot's
//! talking seconds (one ExpectedEngagement window each, plus a faceless one), the TabletTask,
//! a window with a face while the user answers (which must not count), and the SequenceResult.
//! The records are first brought to what a bag can hold (f32 engagement and response time, ns
//! times laid end to end); those are what the reader must return.
#![allow(dead_code)]

use bag_file::{BagWriter, WriterOptions};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::topics::{EXPECTED_ENGAGEMENT, GAME_STATE, SEQUENCE_RESULT, TABLET_TASK};
use qt_therapy_msgs::{BehaviourState, ExpectedEngagement, GameState, SequenceResult, TabletTask};
use std::path::Path;
use user_models::InteractionRecord;

const S: i64 = 1_000_000_000;

/// One sequence as it will be written: the record and its period ends (ns).
struct Laid {
    record: InteractionRecord,
    talk_start: i64,
    task: i64,
    answered: i64,
}

/// Lays one session's records end to end from their first talking second.
fn lay_out(session: &[InteractionRecord]) -> Vec<Laid> {
    let first = &session[0];
    let seconds = first.engagement_per_second.len().max(1) as f64;
    // Rounded, so laying out records already laid out changes nothing.
    let mut talk_start =
        ((first.time - f64::from(first.response_time as f32) - seconds).round() as i64) * S;
    let mut out = Vec::new();
    for r in session {
        let per_second: Vec<f64> = r
            .engagement_per_second
            .iter()
            .map(|v| f64::from(*v as f32))
            .collect();
        let task = talk_start + per_second.len().max(1) as i64 * S;
        let response_time = f64::from(r.response_time as f32);
        let answered = task + (response_time * 1e9).round() as i64;
        let engagement = (!per_second.is_empty())
            .then(|| per_second.iter().sum::<f64>() / per_second.len() as f64);
        out.push(Laid {
            record: InteractionRecord {
                time: answered as f64 / 1e9,
                response_time,
                engagement,
                engagement_per_second: per_second,
                ..r.clone()
            },
            talk_start,
            task,
            answered,
        });
        talk_start = answered;
    }
    out
}

/// The sessions of `records` (in record order, grouped by session id, first appearance first).
fn sessions(records: &[InteractionRecord]) -> Vec<Vec<InteractionRecord>> {
    let mut order: Vec<String> = Vec::new();
    for r in records {
        if !order.contains(&r.session_id) {
            order.push(r.session_id.clone());
        }
    }
    order
        .iter()
        .map(|s| {
            records
                .iter()
                .filter(|r| &r.session_id == s)
                .cloned()
                .collect()
        })
        .collect()
}

/// The records as a bag holds them (what [`write_bag`] writes and the reader must return).
pub fn at_bag_precision(records: &[InteractionRecord]) -> Vec<InteractionRecord> {
    sessions(records)
        .iter()
        .flat_map(|s| lay_out(s).into_iter().map(|l| l.record))
        .collect()
}

fn window(start: i64, value: f32, has_faces: bool) -> ExpectedEngagement {
    ExpectedEngagement {
        header: Header::at(Time::from_nanos(start + S)),
        source: "qt_camera/0".into(),
        window_start: Time::from_nanos(start),
        window_end: Time::from_nanos(start + S),
        has_faces,
        mean: value,
        smoothed: value,
        frame_count: if has_faces { 30 } else { 0 },
        missing_count: if has_faces { 0 } else { 30 },
    }
}

/// Writes the sessions of `records` into the bag at `path` (finished).
pub fn write_bag(path: &Path, records: &[InteractionRecord]) {
    write_bag_with(path, records, &WriterOptions::default());
}

/// As [`write_bag`], with the writer's options (e.g. small chunks).
pub fn write_bag_with(path: &Path, records: &[InteractionRecord], options: &WriterOptions) {
    let mut w = BagWriter::create(path, options).expect("creates the bag");
    let states = w.add_topic(GAME_STATE).expect("topic");
    let tasks = w.add_topic(TABLET_TASK).expect("topic");
    let windows = w.add_topic(EXPECTED_ENGAGEMENT).expect("topic");
    let results = w.add_topic(SEQUENCE_RESULT).expect("topic");
    let at = |ns: i64| ns as u64;
    for session in sessions(records) {
        let laid = lay_out(&session);
        let first = &laid[0];
        w.write(
            states,
            at(first.talk_start),
            &GameState {
                header: Header::at(Time::from_nanos(first.talk_start)),
                phase: GameState::DECIDING,
                session_id: first.record.session_id.clone(),
                user_id: first.record.user_id.clone(),
                sequence_index: 1,
                status: "session started".into(),
                ..Default::default()
            },
        )
        .expect("writes");
        let mut state = BehaviourState::default();
        for (k, l) in laid.iter().enumerate() {
            let r = &l.record;
            let index = k as u8 + 1;
            // A window without a face just before the talking starts, then the talking seconds.
            w.write(
                windows,
                at(l.talk_start),
                &window(l.talk_start - S, 0.9, false),
            )
            .expect("writes");
            for (i, v) in r.engagement_per_second.iter().enumerate() {
                let start = l.talk_start + i as i64 * S;
                w.write(
                    windows,
                    at(start + S + 20_000_000),
                    &window(start, *v as f32, true),
                )
                .expect("writes");
            }
            w.write(
                tasks,
                at(l.task),
                &TabletTask {
                    header: Header::at(Time::from_nanos(l.task)),
                    session_id: r.session_id.clone(),
                    sequence_id: u32::from(index),
                    sequence_index: index,
                    length: r.level.sequence_length() as u8,
                    choices: vec![
                        "happy".into(),
                        "disgusted".into(),
                        "sad".into(),
                        "angry".into(),
                    ],
                    timeout: 60.0,
                },
            )
            .expect("writes");
            // Seen while the user answers: not the robot's talking, so it must not count.
            if l.answered - l.task > S {
                w.write(
                    windows,
                    at(l.task + S + 20_000_000),
                    &window(l.task, 0.99, true),
                )
                .expect("writes");
            }
            state.previous_score = r.previous_score;
            let stamp = l.answered + 100_000_000;
            w.write(
                results,
                at(stamp),
                &SequenceResult {
                    header: Header::at(Time::from_nanos(stamp)),
                    session_id: r.session_id.clone(),
                    user_id: r.user_id.clone(),
                    user_model_cluster: -1,
                    sequence_index: index,
                    state: state.clone(),
                    action: 0,
                    level: r.level.get(),
                    feedback: u8::from(r.feedback),
                    overridden: false,
                    sequence: vec![],
                    answer: vec![],
                    outcome: r.outcome.sign(),
                    timed_out: false,
                    activity_result: r.outcome.activity_result(r.level) as f32,
                    engagement: r.engagement.unwrap_or(0.0) as f32,
                    engagement_per_second: r
                        .engagement_per_second
                        .iter()
                        .map(|v| *v as f32)
                        .collect(),
                    engagement_period_start: Time::from_nanos(l.talk_start),
                    engagement_period_end: Time::from_nanos(l.task),
                    response_time: r.response_time as f32,
                    sequences_planned: laid.len() as u8,
                },
            )
            .expect("writes");
            state.level = r.level.get();
            state.feedback = u8::from(r.feedback);
        }
    }
    w.finish().expect("finishes the bag");
}
