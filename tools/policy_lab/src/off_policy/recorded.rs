//! Recorded sessions as counterfactual evaluation reads them: the bags' decisions, results and
//! game states paired per session. A session is kept only when the policy chose every one of
//! its sequences; every other is left out with its kind and reason, so the share left out,
//! and why, can be told beside the estimate (leaving sessions out is itself a bias: the
//! therapist stops or steers the sessions that go badly).

use q_learning::mdp::{LoggedSession, LoggedStep};
use q_learning::messages::transition;
use qt_therapy_msgs::{Decision, SequenceResult};
use sequence_game::{ACTION_COUNT, Outcome};
use serde::Serialize;
use session_log::Messages;
use std::collections::{BTreeMap, BTreeSet};

/// Why a recorded session was left out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
pub enum LeftOutKind {
    /// Stopped before its last sequence (or a sequence's result is missing).
    Incomplete,
    /// The therapist chose a sequence (an override, or a proposal replaced under supervised
    /// autonomy).
    TherapistChose,
    /// The game manager's fallback played a sequence (the policy did not answer in time, or
    /// refused).
    Fallback,
    /// A recorded decision is not what was played, or a message cannot be read as one.
    Inconsistent,
}

impl LeftOutKind {
    pub const ALL: [LeftOutKind; 4] = [
        LeftOutKind::Incomplete,
        LeftOutKind::TherapistChose,
        LeftOutKind::Fallback,
        LeftOutKind::Inconsistent,
    ];

    pub fn describe(self) -> &'static str {
        match self {
            LeftOutKind::Incomplete => "stopped before the end",
            LeftOutKind::TherapistChose => "a sequence the therapist chose",
            LeftOutKind::Fallback => "a sequence the fallback played",
            LeftOutKind::Inconsistent => "a decision not what was played",
        }
    }
}

/// A session left out, and why.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LeftOut {
    pub session_id: String,
    pub kind: LeftOutKind,
    pub reason: String,
}

/// Recorded sessions as counterfactual evaluation reads them, and the ones it had to leave out.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LoggedSessions {
    pub sessions: Vec<LoggedSession>,
    /// Per session, per step, the logging policy's whole distribution.
    pub distributions: Vec<Vec<[f64; ACTION_COUNT]>>,
    pub left_out: Vec<LeftOut>,
}

impl LoggedSessions {
    /// Sessions seen: evaluated and left out.
    pub fn seen(&self) -> usize {
        self.sessions.len() + self.left_out.len()
    }

    /// How many were left out for `kind`.
    pub fn left_out_for(&self, kind: LeftOutKind) -> usize {
        self.left_out.iter().filter(|l| l.kind == kind).count()
    }
}

/// Who chose a sequence's action.
#[derive(Debug, Clone, Copy, PartialEq)]
enum ChosenBy<'a> {
    Policy(&'a Decision),
    Therapist,
    /// `flagged`: the game manager said so (GameState's `policy_fallback`); else inferred
    /// from a missing decision.
    Fallback {
        flagged: bool,
    },
}

/// The one place that tells who chose a sequence. The game manager flags a fallback in the
/// GameState it publishes during the sequence (`policy_fallback`), and that flag wins over a
/// recorded decision: a late policy answer that happens to match the fallback was not what
/// played. A bag whose game states were not recorded leaves only the inference (no decision
/// recorded: the fallback played). When SequenceResult carries the flag itself, read it here.
fn chosen_by<'a>(
    result: &SequenceResult,
    decision: Option<&'a Decision>,
    fallback_flagged: bool,
) -> ChosenBy<'a> {
    if result.overridden {
        ChosenBy::Therapist
    } else if fallback_flagged {
        ChosenBy::Fallback { flagged: true }
    } else {
        match decision {
            Some(d) => ChosenBy::Policy(d),
            None => ChosenBy::Fallback { flagged: false },
        }
    }
}

/// Pairs each session's results with the policy's decisions (same session, `step` equal to
/// `sequence_index`; the last decision recorded for a step counts) and the game manager's
/// fallback flags. Only whole sessions the policy chose throughout are kept. `log` is taken
/// through the suite's rule for what arrives twice (`session_log`): a result delivered again
/// after a respawn is in it once.
pub fn logged_sessions(log: &Messages) -> LoggedSessions {
    let mut by_step: BTreeMap<(&str, u8), &Decision> = BTreeMap::new();
    for d in &log.decisions {
        by_step.insert((d.message.session_id.as_str(), d.message.step), &d.message);
    }
    let fallbacks: BTreeSet<(&str, u8)> = log
        .states
        .iter()
        .map(|g| &g.message)
        .filter(|g| g.policy_fallback && g.sequence_index > 0)
        .map(|g| (g.session_id.as_str(), g.sequence_index))
        .collect();
    // Sessions in order of their first result.
    let mut order: Vec<&str> = Vec::new();
    let mut per_session: BTreeMap<&str, BTreeMap<u8, &SequenceResult>> = BTreeMap::new();
    for r in log.results.iter().map(|r| &r.message) {
        let steps = per_session.entry(r.session_id.as_str()).or_insert_with(|| {
            order.push(r.session_id.as_str());
            BTreeMap::new()
        });
        steps.insert(r.sequence_index, r);
    }
    let mut out = LoggedSessions::default();
    for id in order {
        match logged_session(id, &per_session[id], &by_step, &fallbacks) {
            Ok((session, distribution)) => {
                out.sessions.push(session);
                out.distributions.push(distribution);
            }
            Err((kind, reason)) => out.left_out.push(LeftOut {
                session_id: id.to_string(),
                kind,
                reason,
            }),
        }
    }
    out
}

type OneSession = (LoggedSession, Vec<[f64; ACTION_COUNT]>);

fn logged_session(
    id: &str,
    results: &BTreeMap<u8, &SequenceResult>,
    decisions: &BTreeMap<(&str, u8), &Decision>,
    fallbacks: &BTreeSet<(&str, u8)>,
) -> Result<OneSession, (LeftOutKind, String)> {
    let inconsistent = |why: String| (LeftOutKind::Inconsistent, why);
    let planned = results
        .values()
        .map(|r| r.sequences_planned)
        .max()
        .unwrap_or(0);
    let indices: Vec<u8> = results.keys().copied().collect();
    if planned == 0 || indices != (1..=planned).collect::<Vec<u8>>() {
        return Err((
            LeftOutKind::Incomplete,
            format!("incomplete: sequences {indices:?} of {planned} recorded"),
        ));
    }
    let mut steps = Vec::with_capacity(results.len());
    let mut distribution = Vec::with_capacity(results.len());
    for (&k, r) in results {
        let d = match chosen_by(
            r,
            decisions.get(&(id, k)).copied(),
            fallbacks.contains(&(id, k)),
        ) {
            ChosenBy::Policy(d) => d,
            ChosenBy::Therapist => {
                return Err((
                    LeftOutKind::TherapistChose,
                    format!(
                        "the therapist chose sequence {k}: its action was not the policy's draw"
                    ),
                ));
            }
            ChosenBy::Fallback { flagged: true } => {
                return Err((
                    LeftOutKind::Fallback,
                    format!(
                        "the game manager played its fallback for sequence {k} (GameState \
                         policy_fallback){}",
                        if decisions.contains_key(&(id, k)) {
                            "; the decision recorded for it came too late to play"
                        } else {
                            ""
                        }
                    ),
                ));
            }
            ChosenBy::Fallback { flagged: false } => {
                return Err((
                    LeftOutKind::Fallback,
                    format!(
                        "no decision recorded for sequence {k} (the game manager's fallback \
                         played it)"
                    ),
                ));
            }
        };
        let t = transition(r).map_err(|e| inconsistent(format!("sequence {k}: {e}")))?;
        let state = d
            .state
            .to_state()
            .map_err(|e| inconsistent(format!("decision for sequence {k}: {}", e.reason)))?;
        if state != t.state || usize::from(d.action) != t.action.index() {
            return Err(inconsistent(format!(
                "sequence {k}: the decision ({} in {state}) is not what was played ({} in {})",
                d.action, t.action, t.state
            )));
        }
        let probabilities: [f64; ACTION_COUNT] =
            d.probabilities.as_slice().try_into().map_err(|_| {
                inconsistent(format!(
                    "decision for sequence {k} has {} probabilities, not {ACTION_COUNT}",
                    d.probabilities.len()
                ))
            })?;
        let outcome = Outcome::new(r.outcome.into())
            .map_err(|e| inconsistent(format!("sequence {k}: {e}")))?;
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
    use bag_file::Stamped;
    use qt_therapy_msgs::{BehaviourState, GameState};
    use sequence_game::State;

    fn played(session: &str, k: u8, planned: u8) -> (Decision, SequenceResult) {
        let state = if k == 1 {
            State::START
        } else {
            State::new(2, 0, 2).expect("state")
        };
        let d = Decision {
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
        // A result sent again after a respawn counts once (the reader drops it).
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
        // The policy answered after the game manager gave up and played its fallback, which
        // happens to be the same action: flagged in the game state, so not the policy's.
        let (d, r) = played("late", 1, 1);
        decisions.push(d);
        results.push(r);
        let states = [
            GameState {
                session_id: "late".into(),
                sequence_index: 1,
                policy_fallback: true,
                ..Default::default()
            },
            // Another session's flag, and a flag before the first sequence, touch nothing.
            GameState {
                session_id: "elsewhere".into(),
                sequence_index: 1,
                policy_fallback: true,
                ..Default::default()
            },
            GameState {
                session_id: "whole".into(),
                sequence_index: 0,
                policy_fallback: true,
                ..Default::default()
            },
        ];
        fn stamped<M: Clone>(list: &[M]) -> Vec<Stamped<M>> {
            list.iter()
                .enumerate()
                .map(|(n, m)| Stamped {
                    log_time: n as u64,
                    publish_time: 0,
                    sequence: 0,
                    message: m.clone(),
                })
                .collect()
        }
        let messages = |states: &[GameState]| Messages {
            decisions: stamped(&decisions),
            results: stamped(&results),
            states: stamped(states),
            ..Default::default()
        };
        let taken = session_log::SessionReader::new()
            .take("test", messages(&states))
            .expect("no conflict");
        assert_eq!(taken.repeats.len(), 1);
        let log = logged_sessions(&taken.messages);
        assert_eq!(log.sessions.len(), 1);
        assert_eq!(log.seen(), 6);
        let s = &log.sessions[0];
        assert_eq!((s.session_id.as_str(), s.steps.len()), ("whole", 3));
        assert_eq!(s.steps[1].logged_probability, 0.5);
        assert_eq!(s.steps[1].engagement, 0.25);
        assert_eq!(s.steps[2].outcome, Outcome::Success);
        assert_eq!(log.distributions[0][0], [0.25, 0.5, 0.25, 0.0, 0.0]);
        let reasons: Vec<(&str, LeftOutKind, &str)> = log
            .left_out
            .iter()
            .map(|l| (l.session_id.as_str(), l.kind, l.reason.as_str()))
            .collect();
        assert_eq!(reasons.len(), 5, "{reasons:?}");
        use LeftOutKind::*;
        let kinds: Vec<(&str, LeftOutKind)> = reasons.iter().map(|r| (r.0, r.1)).collect();
        assert_eq!(
            kinds,
            [
                ("stopped", Incomplete),
                ("override", TherapistChose),
                ("fallback", Fallback),
                ("disagree", Inconsistent),
                ("late", Fallback),
            ]
        );
        assert!(reasons[0].2.contains("incomplete"));
        assert!(reasons[2].2.contains("no decision"));
        assert!(reasons[3].2.contains("not what was played"));
        assert!(reasons[4].2.contains("came too late"), "{}", reasons[4].2);
        assert_eq!(log.left_out_for(Fallback), 2);
        // Without the game states the late answer would pass for the policy's.
        let blind = session_log::SessionReader::new()
            .take("test", messages(&[]))
            .expect("no conflict");
        let blind = logged_sessions(&blind.messages);
        assert_eq!(blind.sessions.len(), 2);
    }
}
