//! Supervised autonomy: an unsure decision is proposed to the therapist, who accepts it,
//! replaces it, or lets it run out; a pause stops its countdown, the session's end withdraws
//! it; sure decisions, and sessions without supervision, go straight through.

use super::harness::*;
use crate::params::{GameManagerParams, SupervisionParams};
use crate::protocol::{Input, Output};
use qt_therapy_msgs::{ActionProposal, GameState, TherapistCommand as C};
use sequence_game::{Prediction, UserModelTable};

fn supervised() -> GameManagerParams {
    GameManagerParams {
        supervision: SupervisionParams {
            supervised_autonomy: true,
            propose_above_temperature: 100.0,
            proposal_countdown_s: 5.0,
            ..Default::default()
        },
        ..Default::default()
    }
}

/// The rule policy, its state hot (temperature 250) at the listed steps.
fn unsure_at(
    steps: Vec<u8>,
) -> Box<dyn FnMut(&qt_therapy_msgs::DecideActionRequest) -> PolicyReply> {
    Box::new(move |req| {
        let mut response = rule_decision(req);
        if steps.contains(&req.step) {
            response.decision.temperature = 250.0;
        }
        PolicyReply::Answer {
            after_s: 0.05,
            response,
        }
    })
}

fn proposals(h: &Harness) -> Vec<(i64, ActionProposal)> {
    h.log
        .iter()
        .filter_map(|(t, o)| match o {
            Output::Proposal(p) => Some((*t, p.clone())),
            _ => None,
        })
        .collect()
}

fn open_proposal(h: &Harness, step: u8) -> bool {
    proposals(h)
        .last()
        .is_some_and(|(_, p)| p.step == step && p.status == ActionProposal::PROPOSED)
}

fn accept(session: &str, id: u64) -> Input {
    cmd(C::ACCEPT_PROPOSAL, session, id)
}

#[test]
fn sure_decisions_and_unsupervised_sessions_go_straight_through() {
    // Supervised, every state cooled (temperature 1): nothing is proposed.
    let mut h = Harness::new(supervised(), rule_policy(), scripted_child(vec![]));
    h.start("s");
    h.run(3600.0);
    assert_eq!(h.results().len(), 10);
    assert!(proposals(&h).is_empty());
    // Hot states but supervision off: as before, nothing is proposed.
    let mut h = Harness::new(
        GameManagerParams::default(),
        unsure_at((1..=10).collect()),
        scripted_child(vec![]),
    );
    h.start("s");
    h.run(3600.0);
    assert_eq!(h.results().len(), 10);
    assert!(proposals(&h).is_empty());
    assert_eq!(h.summaries()[0].proposals, 0);
}

#[test]
fn an_accepted_proposal_plays_at_once() {
    let mut h = Harness::new(supervised(), unsure_at(vec![2]), scripted_child(vec![]));
    h.start("s");
    h.run_until_true(120.0, |h| open_proposal(h, 2));
    let (proposed_at, p) = proposals(&h).pop().expect("proposed");
    assert_eq!((p.step, p.temperature, p.success_std), (2, 250.0, -1.0));
    assert!(p.reason.contains("temperature 250.0 > 100"), "{}", p.reason);
    assert_eq!(p.countdown, 5.0);
    assert_eq!(p.deadline.to_nanos(), proposed_at + 5 * S);
    // The reaction to sequence 1 is over: only the therapist holds the game now.
    h.run_until(proposed_at + 4 * S);
    let state = h.last_state();
    assert_eq!(state.phase, GameState::DECIDING);
    assert!(state.status.contains("proposing L2"), "{}", state.status);
    assert_eq!(h.tasks().len(), 1);
    h.feed(accept("s", 2));
    let (_, settled) = proposals(&h).pop().expect("settled");
    assert_eq!(settled.status, ActionProposal::ACCEPTED);
    assert_eq!(settled.command_id, 2);
    assert_eq!(
        (
            settled.played_action,
            settled.played_level,
            settled.played_feedback
        ),
        (p.action, p.level, p.feedback)
    );
    assert!((settled.response_time - 4.0).abs() < 1e-3);
    assert_eq!(
        h.last_state().command_outcome,
        GameState::COMMAND_CARRIED_OUT
    );
    h.run(3600.0);
    let r = h.results();
    assert_eq!(r.len(), 10);
    assert_eq!((r[1].action, r[1].overridden), (p.action, false));
    let reason = &h.records()[1].decision_reason;
    assert!(
        reason.ends_with("proposed to the therapist: L2 (T 250, no user model), as the state is little visited (temperature 250.0 > 100): accepted after 4.0 s"),
        "{reason}"
    );
    let summary = &h.summaries()[0];
    assert_eq!(
        (summary.proposals, summary.proposals_accepted),
        (1, 1),
        "{summary:?}"
    );
    // Accepting again, with nothing open, is refused with the reason.
    let mut h = Harness::new(supervised(), unsure_at(vec![]), scripted_child(vec![]));
    h.start("s");
    h.run_until(T0 + 3 * S);
    h.feed(accept("s", 2));
    let state = h.last_state();
    assert_eq!(state.command_outcome, GameState::COMMAND_REFUSED);
    assert!(state.command_refusal.contains("no proposal is open"));
}

#[test]
fn the_therapists_level_or_feedback_replaces_a_proposal() {
    let mut h = Harness::new(supervised(), unsure_at(vec![2, 4]), scripted_child(vec![]));
    h.start("s");
    h.run_until_true(120.0, |h| open_proposal(h, 2));
    h.feed(override_to(3, "s", 2));
    let (_, settled) = proposals(&h).pop().expect("settled");
    assert_eq!(settled.status, ActionProposal::REPLACED);
    assert_eq!(
        (
            settled.played_action,
            settled.played_level,
            settled.command_id
        ),
        (2, 3, 2)
    );
    h.run_until_true(120.0, |h| open_proposal(h, 4));
    h.feed(cmd(C::OVERRIDE_CHALLENGING, "s", 3));
    let (_, settled) = proposals(&h).pop().expect("settled");
    assert_eq!(settled.status, ActionProposal::REPLACED);
    h.run(3600.0);
    let r = h.results();
    assert_eq!((r[1].level, r[1].overridden), (3, true));
    // a5: challenging feedback, the level of sequence 3 repeated.
    assert_eq!(
        (r[3].action, r[3].level, r[3].feedback, r[3].overridden),
        (4, r[2].level, 2, true)
    );
    assert_eq!(
        (
            settled.played_action,
            settled.played_level,
            settled.played_feedback
        ),
        (4, r[2].level, 2)
    );
    let summary = &h.summaries()[0];
    assert_eq!(
        (
            summary.proposals,
            summary.proposals_replaced,
            summary.overrides
        ),
        (2, 2, 2)
    );
}

#[test]
fn feedback_overrides_without_a_proposal_and_their_refusals() {
    let mut h = Harness::new(supervised(), rule_policy(), scripted_child(vec![]));
    h.start("s");
    // Sequence 1 is being decided: feedback before it makes no sense.
    h.feed(cmd(C::OVERRIDE_ENCOURAGING, "s", 2));
    let state = h.last_state();
    assert_eq!(state.command_outcome, GameState::COMMAND_REFUSED);
    assert!(
        state.command_refusal.contains("not on the first"),
        "{state:?}"
    );
    // While sequence 1 waits for its answer, encouragement is set for sequence 2.
    h.run_until(T0 + 15 * S);
    h.feed(cmd(C::OVERRIDE_ENCOURAGING, "s", 3));
    h.run(3600.0);
    let r = h.results();
    assert_eq!(
        (r[1].action, r[1].level, r[1].feedback, r[1].overridden),
        (3, r[0].level, 1, true)
    );
    assert!(proposals(&h).is_empty());
    let journal = serde_json::to_string(&h.journal()).expect("json");
    assert!(journal.contains("\"override_feedback\""), "{journal}");
}

#[test]
fn an_unanswered_proposal_plays_when_its_countdown_runs_out() {
    let mut h = Harness::new(supervised(), unsure_at(vec![1, 3]), scripted_child(vec![]));
    h.start("s");
    h.run(3600.0);
    let r = h.results();
    assert_eq!(r.len(), 10);
    let all = proposals(&h);
    let statuses: Vec<(u8, u8)> = all.iter().map(|(_, p)| (p.step, p.status)).collect();
    assert_eq!(
        statuses,
        vec![
            (1, ActionProposal::PROPOSED),
            (1, ActionProposal::TIMED_OUT),
            (3, ActionProposal::PROPOSED),
            (3, ActionProposal::TIMED_OUT),
        ]
    );
    // Played exactly at the deadline: the intro (6 s) was shorter than the countdown.
    let (proposed_at, _) = all[0];
    let (timed_out_at, p) = &all[1];
    assert_eq!(*timed_out_at, proposed_at + 5 * S);
    assert_eq!((p.command_id, p.played_action), (0, p.action));
    // Each proposal has its id, its time of proposing, in all its messages; two proposals
    // have two (docs/session_log.md).
    let ids: Vec<u64> = all.iter().map(|(_, p)| p.proposal_id).collect();
    assert_eq!(ids[0], u64::try_from(proposed_at).expect("after the epoch"));
    assert_eq!((ids[1], ids[3]), (ids[0], ids[2]));
    assert!(ids[2] > ids[0]);
    assert!(!r[0].overridden && !r[2].overridden);
    assert!(
        h.records()[2]
            .decision_reason
            .ends_with("ran out after 5.0 s: played")
    );
    assert_eq!(h.summaries()[0].proposals_timed_out, 2);
}

#[test]
fn a_pause_stops_the_countdown_and_a_stop_withdraws_the_proposal() {
    let mut h = Harness::new(supervised(), unsure_at(vec![2]), scripted_child(vec![]));
    h.start("s");
    h.run_until_true(120.0, |h| open_proposal(h, 2));
    let (proposed_at, _) = proposals(&h).pop().expect("proposed");
    h.run_until(proposed_at + 2 * S);
    h.feed(cmd(C::PAUSE, "s", 2));
    h.run_until(proposed_at + 60 * S);
    assert_eq!(proposals(&h).len(), 1, "no time runs out while paused");
    assert_eq!(h.tasks().len(), 1);
    h.feed(cmd(C::RESUME, "s", 3));
    let (again_at, again) = proposals(&h).pop().expect("shown again");
    assert_eq!(again.status, ActionProposal::PROPOSED);
    assert_eq!(again.deadline.to_nanos(), again_at + 5 * S);
    // Shown again: the same proposal (its id), a new showing (its deadline).
    let first = &proposals(&h)[0].1;
    assert_eq!(again.proposal_id, first.proposal_id);
    assert_ne!(again.deadline, first.deadline);
    h.run_until(again_at + 4 * S);
    assert_eq!(proposals(&h).len(), 2);
    h.feed(cmd(C::STOP, "s", 4));
    let (_, last) = proposals(&h).pop().expect("withdrawn");
    assert_eq!(
        (last.status, last.proposal_id),
        (ActionProposal::WITHDRAWN, first.proposal_id)
    );
    assert_eq!(h.results().len(), 1);
    assert_eq!(h.summaries()[0].proposals, 1);
}

#[test]
fn the_sigma_rule_reads_the_sessions_cluster_or_the_most_cautious() {
    let table = |cluster: usize, std: f64| {
        UserModelTable::tabulate(
            cluster,
            |_| Prediction { mean: 0.5, std },
            |_, _| Prediction {
                mean: 0.0,
                std: 0.1,
            },
        )
    };
    let run = |cluster: i32| {
        let mut params = supervised();
        params.session.sequences_per_session = 2;
        params.supervision.propose_above_success_std = 0.3;
        let mut h = Harness::new(params, rule_policy(), scripted_child(vec![]));
        h.gm = std::mem::replace(
            &mut h.gm,
            crate::GameManager::new(GameManagerParams::default()).expect("valid"),
        )
        .with_user_models(vec![table(0, 0.1), table(1, 0.45)]);
        let mut start = command(C::START, "s", 1);
        start.user_model_cluster = cluster;
        h.feed(Input::Command(start));
        h.run(3600.0);
        proposals(&h)
    };
    assert!(run(0).is_empty(), "cluster 0 is sure (σ 0.1)");
    let p = run(1);
    assert_eq!(p.len(), 4, "both decisions proposed for cluster 1");
    assert_eq!(p[0].1.success_std, 0.45);
    assert!(p[0].1.reason.contains("σ 0.45 > 0.3"), "{}", p[0].1.reason);
    // Unknown cluster: the most cautious σ of the file.
    assert_eq!(run(-1).len(), 4);
}
