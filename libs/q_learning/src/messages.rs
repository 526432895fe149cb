//! The node's messages to and from the policy core: a `SequenceResult` becomes the
//! `Transition` it learns from, and a core `Decision` becomes the `Decision` message. The DDS
//! node, the bag replays, the replay benchmark and counterfactual evaluation (`policy_lab`) share
//! them, so a replay checks the node's own conversion.

use crate::learning::Mode;
use crate::policy_core::{Decision, Transition};
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::{BehaviourState, SequenceResult};
use sequence_game::{Action, GameError, State};

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
        planned_on_belief: false,
        belief_observations: 0,
        belief_success: Vec::new(),
        belief_success_sd: Vec::new(),
        belief_engagement: Vec::new(),
        belief_engagement_sd: Vec::new(),
        baseline_action: d.action.index() as u8,
    }
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

    #[test]
    fn an_exploring_decision_is_published_with_its_probabilities_and_not_as_exploitation() {
        use crate::{Learning, PolicyCore, QTable};
        let mut table = QTable::default();
        let s = State::new(2, 0, 2).expect("state");
        table.q[s.index()] = [0.0, 1.0, 0.0, 0.5, 0.0];
        for (mode, exploitation_only) in [(Mode::Exploit, true), (Mode::EpsilonGreedy(0.2), false)]
        {
            let mut core = PolicyCore::new(table.clone(), Learning::default(), mode, 3, 0);
            let d = core.decide(s, 3).expect("decides");
            let m = decision_message(&d, Header::default(), "s-1", "cluster 0".into());
            assert_eq!(m.exploitation_only, exploitation_only);
            assert_eq!(m.probabilities, d.probabilities.to_vec());
            assert_eq!(m.explored, d.explored);
        }
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
