//! What the therapist console shows, sans-IO: one readable line per solved sequence, joined
//! from the game's `SequenceResult` and the policy's `Decision` that set it up.

use qt_therapy_msgs::{Decision, SequenceResult};

const ACTION_NAMES: [&str; 5] = ["level 1", "level 2", "level 3", "encourage", "challenge"];
const FEEDBACK_NAMES: [&str; 3] = ["none", "encouraging", "challenging"];

/// Why the robot did what it did, in a few words.
pub fn decision_reason(result: &SequenceResult, decision: Option<&Decision>) -> String {
    if result.overridden {
        return "therapist override".into();
    }
    let Some(d) = decision else {
        return "safe fallback (no decision from the policy)".into();
    };
    let best = d
        .q_values
        .iter()
        .enumerate()
        .filter(|(i, _)| d.probabilities.get(*i).is_some_and(|p| *p > 0.0))
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map(|(i, q)| format!("{} Q={q:.2}", ACTION_NAMES.get(i).unwrap_or(&"?")));
    let chosen_q = d
        .q_values
        .get(usize::from(d.action))
        .copied()
        .unwrap_or(f64::NAN);
    let p = d
        .probabilities
        .get(usize::from(d.action))
        .copied()
        .unwrap_or(f64::NAN);
    if d.explored {
        format!(
            "explored (p={p:.2}, T={:.1}; Q={chosen_q:.2}, best {})",
            d.temperature,
            best.unwrap_or_default()
        )
    } else {
        format!("greedy (Q={chosen_q:.2}, p={p:.2}, T={:.1})", d.temperature)
    }
}

/// The live line for one sequence.
pub fn sequence_line(result: &SequenceResult, decision: Option<&Decision>) -> String {
    let outcome = if result.timed_out {
        "timeout".to_string()
    } else if result.outcome == 1 {
        "right".to_string()
    } else {
        "wrong".to_string()
    };
    let engagement = if result.engagement_per_second.is_empty() {
        "E   n/a".to_string()
    } else {
        format!("E {:+.2}", result.engagement)
    };
    format!(
        "seq {:>2}  level {} ({} emotions)  feedback {:<11}  answer {:<7} score {:+}  {engagement}  {:>5.1} s  | {}",
        result.sequence_index,
        result.level,
        2 * result.level + 1,
        FEEDBACK_NAMES
            .get(usize::from(result.feedback))
            .unwrap_or(&"?"),
        outcome,
        i32::from(result.level) * i32::from(result.outcome),
        result.response_time,
        decision_reason(result, decision)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_say_level_answer_score_engagement_and_reason() {
        let r = SequenceResult {
            sequence_index: 3,
            level: 2,
            feedback: 1,
            outcome: -1,
            engagement: 0.25,
            engagement_per_second: vec![0.25],
            response_time: 12.0,
            action: 3,
            ..Default::default()
        };
        let d = Decision {
            action: 3,
            q_values: vec![0.1, 0.9, 0.2, 0.5, 0.0],
            probabilities: vec![0.2, 0.3, 0.1, 0.25, 0.15],
            temperature: 12.0,
            explored: true,
            ..Default::default()
        };
        let line = sequence_line(&r, Some(&d));
        assert!(line.contains("level 2 (5 emotions)"), "{line}");
        assert!(line.contains("feedback encouraging"), "{line}");
        assert!(line.contains("answer wrong   score -2"), "{line}");
        assert!(line.contains("E +0.25"), "{line}");
        assert!(
            line.contains("explored (p=0.25, T=12.0; Q=0.50, best level 2 Q=0.90)"),
            "{line}"
        );
        assert!(sequence_line(&r, None).contains("safe fallback"));
        let o = SequenceResult {
            overridden: true,
            ..r
        };
        assert!(sequence_line(&o, Some(&d)).contains("therapist override"));
    }
}
