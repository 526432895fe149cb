//! The node's messages to and from the policy core: a `SequenceResult` becomes the
//! `Transition` it learns from, and a core `Decision` becomes the `Decision` message. The DDS
//! node, the bag replays and the replay benchmark share them, so a replay checks the node's own
//! conversion.

use crate::learning::Mode;
use crate::off_policy::{LoggedSession, LoggedStep};
use crate::policy_core::{Decision, Transition};
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::{BehaviourState, SequenceResult};
use sequence_game::{ACTION_COUNT, Action, GameError, Outcome, State};
use std::collections::BTreeMap;

/// Why a `SequenceResult` cannot be learned from.
#[derive(Debug, thiserror::Error)]
pub enum ResultError {
    #[error("state: {0}")]
    State(String),
    #[error(transparent)]
    Game(#[from] GameError),
}

/// The live game's transition: the next state's PS is this sequence's own score, a sequence
/// without a face seen counts as neutral engagement (0), so only RE speaks, and the session's
/// last sequence (its `sequences_planned`-th, whatever the session's length) is terminal.
pub fn transition(r: &SequenceResult) -> Result<Transition, ResultError> {
    let state = r
        .state
        .to_state()
        .map_err(|e| ResultError::State(e.reason))?;
    let action = Action::new(r.action.into())?;
    let next_state = State::new(r.level.into(), r.feedback.into(), r.score().into())?;
    let engagement = r.seen_engagement().unwrap_or(0.0);
    Ok(Transition {
        state,
        action,
        activity_result: f64::from(r.activity_result),
        engagement,
        next_state,
        is_last: r.sequence_index >= r.sequences_planned,
    })
}

/// The `Decision` message of a core decision; `model_used` says which Q-table made it.
pub fn decision_message(
    d: &Decision,
    header: Header,
    session_id: &str,
    model_used: String,
) -> qt_therapy_msgs::Decision {
    qt_therapy_msgs::Decision {
        header,
        session_id: session_id.to_string(),
        step: d.step,
        state: BehaviourState::from_state(d.state),
        action: d.action.index() as u8,
        level: d.level.get(),
        feedback: d.feedback as u8,
        q_values: d.q_values.to_vec(),
        probabilities: d.probabilities.to_vec(),
        temperature: d.temperature,
        explored: d.explored,
        exploitation_only: d.mode == Mode::Exploit,
        model_used,
    }
}

/// Recorded sessions as counterfactual evaluation reads them, and the ones it had to leave out.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LoggedSessions {
    pub sessions: Vec<LoggedSession>,
    /// Per session, per step, the logging policy's whole distribution.
    pub distributions: Vec<Vec<[f64; ACTION_COUNT]>>,
    /// (session id, why it was left out).
    pub left_out: Vec<(String, String)>,
}

/// Pairs each session's results with the policy's decisions (same session, `step` equal to
/// `sequence_index`; the last decision recorded for a step counts). Only whole sessions played
/// by the policy are kept: a session with a therapist override, a sequence without a recorded
/// decision (the game manager's fallback), a decision that disagrees with what was played, or
/// a missing sequence is left out with the reason, since its actions' probabilities are not
/// known.
pub fn logged_sessions(
    decisions: &[qt_therapy_msgs::Decision],
    results: &[SequenceResult],
) -> LoggedSessions {
    let mut by_step: BTreeMap<(&str, u8), &qt_therapy_msgs::Decision> = BTreeMap::new();
    for d in decisions {
        by_step.insert((d.session_id.as_str(), d.step), d);
    }
    // Sessions in order of their first result; a result sent again (a respawn) counts once.
    let mut order: Vec<&str> = Vec::new();
    let mut per_session: BTreeMap<&str, BTreeMap<u8, &SequenceResult>> = BTreeMap::new();
    for r in results {
        let steps = per_session.entry(r.session_id.as_str()).or_insert_with(|| {
            order.push(r.session_id.as_str());
            BTreeMap::new()
        });
        steps.entry(r.sequence_index).or_insert(r);
    }
    let mut out = LoggedSessions::default();
    for id in order {
        let steps = &per_session[id];
        match logged_session(id, steps, &by_step) {
            Ok((session, distribution)) => {
                out.sessions.push(session);
                out.distributions.push(distribution);
            }
            Err(reason) => out.left_out.push((id.to_string(), reason)),
        }
    }
    out
}

type OneSession = (LoggedSession, Vec<[f64; ACTION_COUNT]>);

fn logged_session(
    id: &str,
    results: &BTreeMap<u8, &SequenceResult>,
    decisions: &BTreeMap<(&str, u8), &qt_therapy_msgs::Decision>,
) -> Result<OneSession, String> {
    let planned = results
        .values()
        .map(|r| r.sequences_planned)
        .max()
        .unwrap_or(0);
    let indices: Vec<u8> = results.keys().copied().collect();
    if planned == 0 || indices != (1..=planned).collect::<Vec<u8>>() {
        return Err(format!(
            "incomplete: sequences {indices:?} of {planned} recorded"
        ));
    }
    let mut steps = Vec::with_capacity(results.len());
    let mut distribution = Vec::with_capacity(results.len());
    for (&k, r) in results {
        if r.overridden {
            return Err(format!(
                "the therapist chose sequence {k}: its action was not the policy's draw"
            ));
        }
        let d = decisions.get(&(id, k)).ok_or_else(|| {
            format!("no decision recorded for sequence {k} (the game manager's fallback played it)")
        })?;
        let t = transition(r).map_err(|e| format!("sequence {k}: {e}"))?;
        let state = d
            .state
            .to_state()
            .map_err(|e| format!("decision for sequence {k}: {}", e.reason))?;
        if state != t.state || usize::from(d.action) != t.action.index() {
            return Err(format!(
                "sequence {k}: the decision ({} in {state}) is not what was played ({} in {})",
                d.action, t.action, t.state
            ));
        }
        let probabilities: [f64; ACTION_COUNT] =
            d.probabilities.as_slice().try_into().map_err(|_| {
                format!(
                    "decision for sequence {k} has {} probabilities, not {ACTION_COUNT}",
                    d.probabilities.len()
                )
            })?;
        let outcome = Outcome::new(r.outcome.into()).map_err(|e| format!("sequence {k}: {e}"))?;
        steps.push(LoggedStep {
            state,
            step: k,
            action: t.action,
            logged_probability: probabilities[t.action.index()],
            outcome,
            engagement: t.engagement,
        });
        distribution.push(probabilities);
    }
    Ok((
        LoggedSession {
            session_id: id.to_string(),
            steps,
        },
        distribution,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_result_becomes_the_transition_the_game_played() {
        let r = SequenceResult {
            sequence_index: 10,
            sequences_planned: 10,
            state: BehaviourState::from_state(State::START),
            action: 1,
            level: 2,
            feedback: 0,
            outcome: -1,
            activity_result: -1.0,
            engagement: 0.5,
            ..Default::default()
        };
        let t = transition(&r).expect("valid");
        assert_eq!(t.next_state, State::new(2, 0, -2).expect("state"));
        assert_eq!(t.engagement, 0.0, "no seconds with a face: neutral");
        assert!(t.is_last);
        let seen = SequenceResult {
            engagement_per_second: vec![0.5],
            sequence_index: 3,
            ..r.clone()
        };
        let t = transition(&seen).expect("valid");
        assert_eq!((t.engagement, t.is_last), (0.5, false));
        let bad = SequenceResult { action: 9, ..r };
        assert!(transition(&bad).is_err());
    }

    fn played(session: &str, k: u8, planned: u8) -> (qt_therapy_msgs::Decision, SequenceResult) {
        let state = if k == 1 {
            State::START
        } else {
            State::new(2, 0, 2).expect("state")
        };
        let d = qt_therapy_msgs::Decision {
            session_id: session.into(),
            step: k,
            state: BehaviourState::from_state(state),
            action: 1,
            level: 2,
            probabilities: vec![0.25, 0.5, 0.25, 0.0, 0.0],
            ..Default::default()
        };
        let r = SequenceResult {
            session_id: session.into(),
            sequence_index: k,
            sequences_planned: planned,
            state: BehaviourState::from_state(state),
            action: 1,
            level: 2,
            outcome: 1,
            activity_result: 2.0,
            engagement_per_second: vec![0.25],
            engagement: 0.25,
            ..Default::default()
        };
        (d, r)
    }

    #[test]
    fn recorded_sessions_pair_decisions_with_results_and_leave_out_what_the_policy_did_not_play() {
        let mut decisions = Vec::new();
        let mut results = Vec::new();
        for (session, planned, played_count) in [("whole", 3, 3), ("stopped", 3, 2)] {
            for k in 1..=played_count {
                let (d, r) = played(session, k, planned);
                decisions.push(d);
                results.push(r);
            }
        }
        // A result sent again after a respawn counts once.
        results.push(results[0].clone());
        let (d, mut r) = played("override", 1, 1);
        r.overridden = true;
        decisions.push(d);
        results.push(r);
        let (_, r) = played("fallback", 1, 1);
        results.push(r);
        let (mut d, r) = played("disagree", 1, 1);
        d.action = 0;
        decisions.push(d);
        results.push(r);
        let log = logged_sessions(&decisions, &results);
        assert_eq!(log.sessions.len(), 1);
        let s = &log.sessions[0];
        assert_eq!((s.session_id.as_str(), s.steps.len()), ("whole", 3));
        assert_eq!(s.steps[1].logged_probability, 0.5);
        assert_eq!(s.steps[1].engagement, 0.25);
        assert_eq!(s.steps[2].outcome, Outcome::Success);
        assert_eq!(log.distributions[0][0], [0.25, 0.5, 0.25, 0.0, 0.0]);
        let reasons: Vec<(&str, &str)> = log
            .left_out
            .iter()
            .map(|(id, why)| (id.as_str(), why.as_str()))
            .collect();
        assert_eq!(reasons.len(), 4, "{reasons:?}");
        assert!(reasons[0].0 == "stopped" && reasons[0].1.contains("incomplete"));
        assert!(reasons[1].0 == "override" && reasons[1].1.contains("therapist"));
        assert!(reasons[2].0 == "fallback" && reasons[2].1.contains("no decision"));
        assert!(reasons[3].0 == "disagree" && reasons[3].1.contains("not what was played"));
    }

    #[test]
    fn the_last_sequence_of_a_shorter_session_is_terminal() {
        let r = |sequence_index| SequenceResult {
            sequence_index,
            sequences_planned: 5,
            state: BehaviourState::from_state(State::START),
            action: 1,
            level: 2,
            outcome: 1,
            activity_result: 2.0,
            ..Default::default()
        };
        let last: Vec<bool> = (1..=5)
            .map(|i| transition(&r(i)).expect("valid").is_last)
            .collect();
        assert_eq!(last, [false, false, false, false, true]);
    }
}
