//! The operator's view of a session: why the robot chose an action (the policy's decision,
//! greedy or explored, with its Q-values; a therapist override; the safe fallback), one line
//! per scored sequence, and a proposal to the therapist (supervised autonomy) with what
//! became of it, in the same words for the game manager, the console and the report.

use qt_therapy_msgs::{ActionProposal, Decision, ProposalStatus, SequenceResult};
use sequence_game::{Action, Feedback, Level};
use std::time::Duration;

/// How long a listener waits for results after the FINISHED state: results travel on their
/// own topic, so the last one may arrive just after the state that ends the session.
pub const LAST_RESULT_GRACE: Duration = Duration::from_secs(2);

/// An action index of a message in words, `?` if it is none of a1..a5.
fn action_label(index: usize) -> String {
    Action::new(index as i64).map_or_else(|_| "?".into(), Action::label)
}

/// Why the policy chose `d.action`, from its Q-values, probabilities and temperature.
pub fn decision_reason(d: &Decision) -> String {
    let q = |i: usize| d.q_values.get(i).copied().unwrap_or(f64::NAN);
    let p = |i: usize| d.probabilities.get(i).copied().unwrap_or(f64::NAN);
    let a = usize::from(d.action);
    let name = action_label(a);
    if d.planned_on_belief {
        // The plan on the child's belief: what the table would have done, where it differs.
        let from_table = if d.baseline_action == d.action {
            "as the table".to_string()
        } else {
            format!("table: {}", action_label(usize::from(d.baseline_action)))
        };
        let levels = d
            .belief_success
            .iter()
            .map(|p| format!("{:.0}%", 100.0 * p))
            .collect::<Vec<_>>()
            .join("/");
        return format!(
            "policy planned on the child's belief: {name} ({from_table}; P(right) by level {levels} \
             after {} sequences) [{}]",
            d.belief_observations, d.model_used
        );
    }
    if d.explored {
        // The best allowed action (probability > 0), to show what exploring gave up.
        let best = (0..d.q_values.len())
            .filter(|i| p(*i) > 0.0)
            .max_by(|x, y| q(*x).total_cmp(&q(*y)))
            .map(|i| format!("{} Q={:.2}", action_label(i), q(i)))
            .unwrap_or_else(|| "?".into());
        format!(
            "policy explored: {name} (Q={:.2}, p={:.2}, T={:.1}; best {best}) [{}]",
            q(a),
            p(a),
            d.temperature,
            d.model_used
        )
    } else {
        format!(
            "policy greedy: {name} (Q={:.2}, p={:.2}, T={:.1}) [{}]",
            q(a),
            p(a),
            d.temperature,
            d.model_used
        )
    }
}

/// The reason as a listener who saw the result and (maybe) the decision before it tells it:
/// the therapist's override, the policy's choice, or else the game's safe fallback (same
/// level, no feedback), which is what a sequence without a decision was played with.
pub fn reason_from_messages(r: &SequenceResult, decision: Option<&Decision>) -> String {
    if r.overridden {
        "therapist override".into()
    } else if let Some(d) = decision {
        decision_reason(d)
    } else {
        "safe fallback (no decision from the policy)".into()
    }
}

/// One line per scored sequence: its place in the session, level, feedback, answer, score,
/// engagement, reason.
pub fn sequence_line(r: &SequenceResult, reason: &str) -> String {
    let answer = if r.timed_out {
        "timeout"
    } else if r.is_right() {
        "right"
    } else {
        "wrong"
    };
    let engagement = if r.engagement_per_second.is_empty() {
        "E  n/a      ".to_string()
    } else {
        format!(
            "E {:+.2} ({:>2} s)",
            r.engagement,
            r.engagement_per_second.len()
        )
    };
    let planned = if r.sequences_planned > 0 {
        format!("/{}", r.sequences_planned)
    } else {
        String::new()
    };
    format!(
        "seq {:>2}{planned}  level {} ({} emotions)  feedback {:<11}  answer {:<7}  score {:+}  {engagement}  | {reason}",
        r.sequence_index,
        r.level,
        Level::new(r.level.into()).map_or(0, Level::sequence_length),
        Feedback::new(r.feedback.into()).map_or("?", Feedback::name),
        answer,
        r.score(),
    )
}

/// An action's effect in words: `L2`, `L2 + encouraging`.
pub fn level_and_feedback(level: u8, feedback: u8) -> String {
    match feedback {
        0 => format!("L{level}"),
        f => format!(
            "L{level} + {}",
            Feedback::new(f.into()).map_or("feedback ?", Feedback::name)
        ),
    }
}

/// A softmax temperature: whole numbers while it is large (it starts in the hundreds), two
/// significant digits once it is small.
fn temperature(t: f64) -> String {
    if t.abs() >= 10.0 {
        format!("{t:.0}")
    } else if t.abs() >= 1.0 {
        format!("{t:.1}")
    } else {
        format!("{t:.2}")
    }
}

/// What the therapist is asked: `L2 + encouraging (T 235, σ 0.31)`.
pub fn proposal_asked(p: &ActionProposal) -> String {
    let sigma = if p.success_std < 0.0 {
        "no user model".to_string()
    } else {
        format!("σ {:.2}", p.success_std)
    };
    format!(
        "{} (T {}, {sigma})",
        level_and_feedback(p.level, p.feedback),
        temperature(p.temperature)
    )
}

/// The status of an `ActionProposal` by name (`proposed`, `accepted`, `replaced`,
/// `timed_out`, `withdrawn`), which the page translates; `unknown` otherwise.
pub fn proposal_status_name(status: u8) -> &'static str {
    ProposalStatus::try_from(status).map_or("unknown", ProposalStatus::name)
}

/// What became of a proposal, from the message that settled it: `accepted after 2.1 s`,
/// `replaced by L3 after 1.2 s`, `ran out after 5.0 s: played`, `withdrawn (the session
/// ended first)`.
pub fn proposal_answer(s: &ActionProposal) -> String {
    match ProposalStatus::try_from(s.status) {
        Ok(ProposalStatus::Proposed) => "waiting for the therapist".into(),
        Ok(ProposalStatus::Accepted) => format!("accepted after {:.1} s", s.response_time),
        Ok(ProposalStatus::Replaced) => format!(
            "replaced by {} after {:.1} s",
            level_and_feedback(s.played_level, s.played_feedback),
            s.response_time
        ),
        Ok(ProposalStatus::TimedOut) => {
            format!("ran out after {:.1} s: played", s.response_time)
        }
        Ok(ProposalStatus::Withdrawn) => "withdrawn (the session ended first)".into(),
        Err(_) => format!("status {}?", s.status),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_and_reason_say_what_happened_and_why() {
        let d = Decision {
            action: 3,
            q_values: vec![0.1, 0.9, 0.2, 0.5, 0.0],
            probabilities: vec![0.2, 0.3, 0.1, 0.25, 0.15],
            temperature: 12.0,
            explored: true,
            model_used: "cluster 0".into(),
            ..Default::default()
        };
        let reason = decision_reason(&d);
        assert_eq!(
            reason,
            "policy explored: encourage (Q=0.50, p=0.25, T=12.0; best level 2 Q=0.90) [cluster 0]"
        );
        let greedy = decision_reason(&Decision {
            explored: false,
            action: 1,
            ..d.clone()
        });
        assert!(
            greedy.starts_with("policy greedy: level 2 (Q=0.90"),
            "{greedy}"
        );
        let planned = decision_reason(&Decision {
            planned_on_belief: true,
            belief_observations: 14,
            belief_success: vec![0.9, 0.55, 0.2],
            baseline_action: 2,
            action: 1,
            ..d.clone()
        });
        assert_eq!(
            planned,
            "policy planned on the child's belief: level 2 (table: level 3; P(right) by level \
             90%/55%/20% after 14 sequences) [cluster 0]"
        );
        let r = SequenceResult {
            sequence_index: 3,
            sequences_planned: 10,
            level: 2,
            feedback: 1,
            outcome: -1,
            engagement: 0.25,
            engagement_per_second: vec![0.25; 14],
            ..Default::default()
        };
        let line = sequence_line(&r, &reason);
        assert!(
            line.starts_with("seq  3/10  level 2 (5 emotions)  feedback encouraging"),
            "{line}"
        );
        assert!(
            line.contains("answer wrong    score -2  E +0.25 (14 s)"),
            "{line}"
        );
        let t = SequenceResult {
            timed_out: true,
            engagement_per_second: vec![],
            ..r
        };
        assert!(sequence_line(&t, "x").contains("answer timeout  score -2  E  n/a"));
        let unknown = SequenceResult {
            sequences_planned: 0,
            ..t.clone()
        };
        assert!(sequence_line(&unknown, "x").starts_with("seq  3  level 2"));
        assert!(reason_from_messages(&t, None).starts_with("safe fallback"));
        let o = SequenceResult {
            overridden: true,
            ..t
        };
        assert_eq!(reason_from_messages(&o, Some(&d)), "therapist override");
    }

    #[test]
    fn a_proposal_and_its_answer_in_words() {
        let p = ActionProposal {
            level: 2,
            feedback: 1,
            temperature: 235.0,
            success_std: 0.31,
            ..Default::default()
        };
        assert_eq!(proposal_asked(&p), "L2 + encouraging (T 235, σ 0.31)");
        let cool = ActionProposal {
            temperature: 0.42,
            success_std: -1.0,
            feedback: 0,
            ..p.clone()
        };
        assert_eq!(proposal_asked(&cool), "L2 (T 0.42, no user model)");
        let replaced = ActionProposal {
            status: ActionProposal::REPLACED,
            played_level: 3,
            played_feedback: 2,
            response_time: 1.25,
            ..p.clone()
        };
        assert_eq!(
            proposal_answer(&replaced),
            "replaced by L3 + challenging after 1.2 s"
        );
        let ran_out = ActionProposal {
            status: ActionProposal::TIMED_OUT,
            response_time: 5.0,
            ..p
        };
        assert_eq!(proposal_answer(&ran_out), "ran out after 5.0 s: played");
    }
}
