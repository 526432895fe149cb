//! The wall clock stepped mid-session (NTP's first sync, a clock set by hand): the session goes
//! on by the steady clock exactly as without the step. No timer fires early or late, no
//! watched node is taken for lost, every sequence's engagement comes from its own seconds
//! (the classifier's windows are stamped by the stepped clock), and only the stamps move.

use super::harness::*;
use crate::params::{GameManagerParams, ReliabilityParams};

const POLICY: &str = "behaviour_policy";
const CLASSIFIER: &str = "engagement_classifier";

/// A session from T0, its watched nodes beating all along, windows of engagement every
/// second; the wall clock stepped by `by` at 40 s (mid-sequence).
fn session(step_by: Option<i64>) -> Harness {
    let params = GameManagerParams {
        reliability: ReliabilityParams {
            watched_nodes: vec![POLICY.into(), CLASSIFIER.into()],
            ..Default::default()
        },
        ..Default::default()
    };
    let child = scripted_child(vec![(4, ChildReply::Wrong { after_s: 6.0 })]);
    let mut h = Harness::new(params, rule_policy(), child);
    h.wall_step = step_by.map(|by| (T0 + 40 * S, by));
    h.heartbeats(POLICY, 20, T0, T0 + 600 * S);
    h.heartbeats(CLASSIFIER, 21, T0, T0 + 600 * S);
    h.engagement(T0 / S, T0 / S + 600, |sec| {
        Some((sec % 9) as f32 / 10.0 - 0.4)
    });
    h.start("s");
    h.run(600.0);
    h
}

#[test]
fn a_step_of_the_wall_clock_moves_no_timer_no_period_and_only_the_stamps() {
    let plain = session(None);
    assert_eq!(plain.results().len(), 10);
    for by in [-3600 * S, 7200 * S, -5 * S] {
        let stepped = session(Some(by));
        let at = T0 + 40 * S;
        assert_eq!(stepped.records().len(), 10, "step {by}");
        for (a, b) in plain.records().iter().zip(stepped.records()) {
            // The session's own times are steady: the same as without the step.
            assert_eq!(
                (a.talk_start_ns, a.task_sent_ns, a.answered_ns),
                (b.talk_start_ns, b.task_sent_ns, b.answered_ns),
                "step {by}"
            );
            let (x, y) = (&a.result, &b.result);
            assert_eq!(
                (&x.answer, x.timed_out, x.level, x.response_time),
                (&y.answer, y.timed_out, y.level, y.response_time)
            );
            assert_eq!(
                x.engagement_per_second, y.engagement_per_second,
                "sequence {}, step {by}",
                x.sequence_index
            );
            assert!(!y.engagement_per_second.is_empty());
            // Stamps follow the wall clock; a period's ends are stamped on one clock.
            let moved = if b.answered_ns >= at { by } else { 0 };
            assert_eq!(
                y.header.stamp.to_nanos() - x.header.stamp.to_nanos(),
                moved,
                "sequence {}",
                x.sequence_index
            );
            let length = |r: &qt_therapy_msgs::SequenceResult| {
                r.engagement_period_end.to_nanos() - r.engagement_period_start.to_nanos()
            };
            assert_eq!(length(x), length(y));
        }
        let warnings = stepped.warnings();
        assert!(
            !warnings.iter().any(|w| w.contains("node lost")),
            "{warnings:?}"
        );
        let told: Vec<&String> = warnings
            .iter()
            .filter(|w| w.contains("the wall clock stepped"))
            .collect();
        assert_eq!(told.len(), 1, "{warnings:?}");
        assert!(
            told[0].contains(&format!("{:+.3} s", by as f64 * 1e-9)),
            "{}",
            told[0]
        );
    }
}
