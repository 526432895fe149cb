//! Core tests of supervised autonomy: who sees a proposal, its countdown on the bridge's clock,
//! stale proposals from the topic's history, and the commands that answer one.

use super::*;
use crate::protocol::{CommandKind, ProposalView};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::{ActionProposal, BehaviourState};

/// A proposal of `session` for sequence `step`, stamped `stamp_ms` after WALL0 by the game
/// manager: a2 (level 2) from (L1, none, +1), or a1 from the start state at step 1.
fn proposal(session: &str, step: u8, status: u8, stamp_ms: i64) -> ActionProposal {
    let stamp = Time::from_nanos(WALL0 + stamp_ms * 1_000_000);
    let state = if step == 1 {
        BehaviourState::default()
    } else {
        BehaviourState {
            level: 1,
            feedback: 0,
            previous_score: 1,
        }
    };
    let settled = status != ActionProposal::PROPOSED;
    ActionProposal {
        header: Header::at(stamp.clone()),
        session_id: session.into(),
        proposal_id: u64::from(step),
        step,
        state,
        action: if step == 1 { 0 } else { 1 },
        level: if step == 1 { 1 } else { 2 },
        feedback: 0,
        temperature: 235.0,
        success_std: -1.0,
        reason: "state visited 3 times (T 235 > 0)".into(),
        countdown: 10.0,
        deadline: Time::from_nanos(stamp.to_nanos() + 10_000_000_000),
        status,
        played_action: if settled { 3 } else { 0 },
        played_level: if settled { 1 } else { 0 },
        played_feedback: if settled { 1 } else { 0 },
        command_id: 0,
        response_time: 0.0,
    }
}

/// A game state of `session` in `phase`, stamped `stamp_ms` after WALL0.
fn stamped(phase: u8, session: &str, stamp_ms: i64) -> GameState {
    GameState {
        header: Header::at(Time::from_nanos(WALL0 + stamp_ms * 1_000_000)),
        ..game(phase, session)
    }
}

/// The proposal views page `id` got.
fn proposals(out: &[Output], id: ClientId) -> Vec<ProposalView> {
    to(out, id)
        .into_iter()
        .filter_map(|m| match m {
            ServerMessage::Proposal(p) => Some(p),
            _ => None,
        })
        .collect()
}

/// A bridge with session s1 deciding sequence 4 and that sequence's proposal open since t = 0,
/// a logged-in therapist page and a child page.
fn proposing() -> (Bridge, ClientId, ClientId) {
    let mut b = Bridge::new(params(), at(0));
    let c = child(&mut b);
    let t = therapist(&mut b);
    b.dds(
        DdsInput::GameState(stamped(GameState::DECIDING, "s1", 0)),
        at(0),
    );
    let out = b.dds(
        DdsInput::Proposal(proposal("s1", 4, ActionProposal::PROPOSED, 1)),
        at(0),
    );
    assert_eq!(proposals(&out, t).len(), 1, "{out:?}");
    (b, t, c)
}

fn login_at(b: &mut Bridge, ms: u64) -> Vec<ProposalView> {
    let id = b.connect(Role::Therapist, at(ms)).expect("room").0;
    let out = b.ws_text(id, &login(PIN), at(ms));
    proposals(&out, id)
}

#[test]
fn a_proposal_reaches_logged_in_therapist_pages_only() {
    let mut b = Bridge::new(params(), at(0));
    let c = child(&mut b);
    let waiting_for_pin = b.connect(Role::Therapist, at(0)).expect("room").0;
    let t = therapist(&mut b);
    b.dds(
        DdsInput::GameState(stamped(GameState::DECIDING, "s1", 0)),
        at(0),
    );
    let out = b.dds(
        DdsInput::Proposal(proposal("s1", 1, ActionProposal::PROPOSED, 1)),
        at(0),
    );
    assert!(to(&out, c).is_empty(), "the child page never sees one");
    assert!(to(&out, waiting_for_pin).is_empty());
    let got = proposals(&out, t);
    assert_eq!(got.len(), 1);
    let v = &got[0];
    assert_eq!((v.step, v.status, v.open), (1, "proposed", true));
    assert_eq!(
        (v.action_name, v.level, v.feedback_name),
        ("level_1", 1, "none")
    );
    assert_eq!(v.remaining, 10.0);
    assert_eq!(v.success_std, None, "-1 means no user model");
    assert_eq!(
        v.choices,
        ["level_1", "level_2", "level_3"],
        "no feedback to offer on sequence 1"
    );
    // Settled: the child page still sees nothing.
    let out = b.dds(
        DdsInput::Proposal(proposal("s1", 1, ActionProposal::TIMED_OUT, 10_001)),
        at(10_000),
    );
    assert!(to(&out, c).is_empty());
    let got = proposals(&out, t);
    assert_eq!((got[0].status, got[0].open), ("timed_out", false));
    assert_eq!(got[0].played_action_name, Some("encourage"));
}

#[test]
fn a_page_that_logs_in_gets_the_open_proposal_with_the_seconds_left_but_not_a_settled_one() {
    let (mut b, _, _) = proposing();
    let got = login_at(&mut b, 3_500);
    assert_eq!(got.len(), 1);
    assert!(
        (got[0].remaining - 6.5).abs() < 1e-9,
        "{}",
        got[0].remaining
    );
    assert_eq!(
        got[0].choices,
        ["level_1", "level_2", "level_3", "encourage", "challenge"]
    );
    // Past its countdown and not settled yet: 0 s left, still open.
    let got = login_at(&mut b, 12_000);
    assert_eq!((got[0].remaining, got[0].open), (0.0, true));
    b.dds(
        DdsInput::Proposal(proposal("s1", 4, ActionProposal::ACCEPTED, 12_001)),
        at(12_000),
    );
    assert!(login_at(&mut b, 12_100).is_empty());
}

#[test]
fn a_pause_stops_the_countdown_until_the_game_goes_on() {
    let (mut b, _, _) = proposing();
    b.dds(
        DdsInput::GameState(stamped(GameState::PAUSED, "s1", 3_000)),
        at(3_000),
    );
    let left = |got: Vec<ProposalView>| got[0].remaining;
    assert!((left(login_at(&mut b, 8_000)) - 7.0).abs() < 1e-9);
    b.dds(
        DdsInput::GameState(stamped(GameState::DECIDING, "s1", 10_000)),
        at(10_000),
    );
    assert!((left(login_at(&mut b, 12_000)) - 5.0).abs() < 1e-9);
    // The game manager proposes again on resume, with its own new countdown.
    b.dds(
        DdsInput::Proposal(proposal("s1", 4, ActionProposal::PROPOSED, 12_500)),
        at(12_500),
    );
    assert!((left(login_at(&mut b, 13_000)) - 9.5).abs() < 1e-9);
    // The session ended without a word on the proposal (a game manager that died): no card.
    b.dds(
        DdsInput::GameState(stamped(GameState::STOPPED, "s1", 14_000)),
        at(14_000),
    );
    assert!(login_at(&mut b, 14_000).is_empty());
}

#[test]
fn a_proposal_delivered_again_does_not_start_its_countdown_again() {
    // The durable topic hands the bridge the open proposal once more (a reader matched
    // again): the same message, so the countdown goes on from its first arrival.
    let (mut b, t, _) = proposing();
    let out = b.dds(
        DdsInput::Proposal(proposal("s1", 4, ActionProposal::PROPOSED, 1)),
        at(3_500),
    );
    assert!(proposals(&out, t).is_empty(), "{out:?}");
    let got = login_at(&mut b, 4_000);
    assert!(
        (got[0].remaining - 6.0).abs() < 1e-9,
        "{}",
        got[0].remaining
    );
    // A settlement delivered again is not shown again either.
    let settled = proposal("s1", 4, ActionProposal::ACCEPTED, 5_000);
    assert_eq!(
        proposals(&b.dds(DdsInput::Proposal(settled.clone()), at(5_000)), t).len(),
        1
    );
    assert!(proposals(&b.dds(DdsInput::Proposal(settled.clone()), at(5_100)), t).is_empty());
    // Settled another way under the same id: not what happened; the first stays.
    let out = b.dds(
        DdsInput::Proposal(ActionProposal {
            status: ActionProposal::TIMED_OUT,
            ..settled
        }),
        at(5_200),
    );
    assert!(proposals(&out, t).is_empty());
    assert!(
        format!("{out:?}").contains("arrived twice and differs (status: 1 -> 3"),
        "{out:?}"
    );
}

#[test]
fn proposals_from_the_topics_history_do_not_come_back() {
    // A bridge started during session s2 gets s1's proposals from the durable topic.
    let mut b = Bridge::new(params(), at(0));
    let t = therapist(&mut b);
    b.dds(
        DdsInput::GameState(stamped(GameState::DECIDING, "s2", 50_000)),
        at(0),
    );
    let out = b.dds(
        DdsInput::Proposal(proposal("s1", 9, ActionProposal::PROPOSED, 20_000)),
        at(0),
    );
    assert!(proposals(&out, t).is_empty(), "{out:?}");
    let out = b.dds(
        DdsInput::Proposal(proposal("s2", 3, ActionProposal::PROPOSED, 49_000)),
        at(0),
    );
    assert_eq!(proposals(&out, t).len(), 1);
    // An older message of the same session (re-delivered) does not replace the newer one.
    let out = b.dds(
        DdsInput::Proposal(proposal("s2", 2, ActionProposal::ACCEPTED, 40_000)),
        at(0),
    );
    assert!(proposals(&out, t).is_empty());
    assert_eq!(login_at(&mut b, 10)[0].step, 3);
    // The next session's first proposal may come before its first state: it is kept, and
    // that state does not drop it.
    let out = b.dds(
        DdsInput::Proposal(proposal("s3", 1, ActionProposal::PROPOSED, 60_000)),
        at(100),
    );
    assert_eq!(proposals(&out, t).len(), 1);
    b.dds(
        DdsInput::GameState(stamped(GameState::FINISHED, "s2", 59_000)),
        at(100),
    );
    b.dds(
        DdsInput::GameState(stamped(GameState::DECIDING, "s3", 59_500)),
        at(100),
    );
    assert_eq!(login_at(&mut b, 200)[0].session_id, "s3");
    // A later state of another session drops it.
    b.dds(
        DdsInput::GameState(stamped(GameState::DECIDING, "s4", 70_000)),
        at(300),
    );
    assert!(login_at(&mut b, 300).is_empty());
}

#[test]
fn answers_to_a_proposal_go_out_with_their_codes_while_it_is_open() {
    let (mut b, t, c) = proposing();
    let send = |b: &mut Bridge, kind: &str, extra: serde_json::Value, ms: u64| {
        let out = b.ws_text(t, &cmd(PIN, kind, extra), at(ms));
        (published(&out).0, reasons(&out, t))
    };
    let cases = [
        (
            "accept_proposal",
            json!({}),
            TherapistCommand::ACCEPT_PROPOSAL,
            0,
        ),
        (
            "accept_proposal",
            json!({"proposal": 4}),
            TherapistCommand::ACCEPT_PROPOSAL,
            0,
        ),
        (
            "override_encouraging",
            json!({"proposal": 4}),
            TherapistCommand::OVERRIDE_ENCOURAGING,
            0,
        ),
        (
            "override_challenging",
            json!({"proposal": 4}),
            TherapistCommand::OVERRIDE_CHALLENGING,
            0,
        ),
        (
            "override_level",
            json!({"proposal": 4, "level": 3}),
            TherapistCommand::OVERRIDE_LEVEL,
            3,
        ),
    ];
    for (i, (kind, extra, code, level)) in cases.into_iter().enumerate() {
        let (commands, refused) = send(&mut b, kind, extra.clone(), 1_000 + i as u64 * 300);
        assert!(refused.is_empty(), "{kind} {extra}: {refused:?}");
        assert_eq!(commands.len(), 1);
        assert_eq!(
            (commands[0].command, commands[0].level),
            (code, level),
            "{kind}"
        );
        assert_eq!(commands[0].session_id, "s1");
    }
    // Every therapist page hears that it went out; the child page hears nothing.
    let out = b.ws_text(t, &cmd(PIN, "accept_proposal", json!({})), at(3_000));
    assert!(matches!(
        &to(&out, t)[..],
        [ServerMessage::CommandSent {
            command: CommandKind::AcceptProposal,
            ..
        }]
    ));
    assert!(to(&out, c).is_empty());

    // Answers to another sequence's proposal, or to a settled one, are refused.
    let (commands, refused) = send(&mut b, "accept_proposal", json!({"proposal": 3}), 3_500);
    assert!(commands.is_empty());
    assert_eq!(
        refused,
        ["the proposal for sequence 3 is not open (the newest is for sequence 4, proposed)"]
    );
    b.dds(
        DdsInput::Proposal(proposal("s1", 4, ActionProposal::TIMED_OUT, 10_001)),
        at(10_000),
    );
    for (kind, extra) in [
        ("accept_proposal", json!({})),
        ("accept_proposal", json!({"proposal": 4})),
        ("override_level", json!({"proposal": 4, "level": 1})),
        ("override_encouraging", json!({"proposal": 4})),
    ] {
        let (commands, refused) = send(&mut b, kind, extra.clone(), 10_500);
        assert!(commands.is_empty(), "{kind} {extra}");
        assert_eq!(
            refused,
            ["the proposal for sequence 4 is already settled (timed_out)"],
            "{kind} {extra}"
        );
    }
    // Without a proposal named, an override is the plain one: the game manager decides.
    for (kind, extra, code) in [
        (
            "override_encouraging",
            json!({}),
            TherapistCommand::OVERRIDE_ENCOURAGING,
        ),
        (
            "override_challenging",
            json!({}),
            TherapistCommand::OVERRIDE_CHALLENGING,
        ),
        (
            "override_level",
            json!({"level": 2}),
            TherapistCommand::OVERRIDE_LEVEL,
        ),
    ] {
        let (commands, refused) = send(&mut b, kind, extra, 11_000);
        assert!(refused.is_empty(), "{kind}: {refused:?}");
        assert_eq!(commands[0].command, code);
    }
}

#[test]
fn answers_that_cannot_fit_the_proposal_or_the_command_are_refused() {
    let mut b = Bridge::new(params(), at(0));
    let t = therapist(&mut b);
    b.dds(
        DdsInput::GameState(stamped(GameState::DECIDING, "s1", 0)),
        at(0),
    );
    let out = b.ws_text(t, &cmd(PIN, "accept_proposal", json!({})), at(0));
    assert_eq!(reasons(&out, t), ["no proposal is open in session s1"]);
    assert!(published(&out).0.is_empty());
    b.dds(
        DdsInput::Proposal(proposal("s1", 1, ActionProposal::PROPOSED, 1)),
        at(0),
    );
    let cases = [
        (
            "override_encouraging",
            json!({"proposal": 1}),
            "sequence 1 has no level to repeat: encourage is not offered",
        ),
        (
            "override_challenging",
            json!({"proposal": 1}),
            "sequence 1 has no level to repeat: challenge is not offered",
        ),
        (
            "override_encouraging",
            json!({"level": 2}),
            "override_encouraging takes no user_id, cluster or level",
        ),
        (
            "accept_proposal",
            json!({"level": 2}),
            "accept_proposal takes no user_id, cluster or level",
        ),
        ("stop", json!({"proposal": 1}), "stop answers no proposal"),
        ("pause", json!({"proposal": 1}), "pause answers no proposal"),
        (
            "override_level",
            json!({"proposal": 1}),
            "override_level needs a level 1..=3",
        ),
        ("accept_proposal", json!({"proposal": -1}), "invalid value"),
    ];
    for (kind, extra, reason) in cases {
        let out = b.ws_text(t, &cmd(PIN, kind, extra.clone()), at(0));
        let got = reasons(&out, t);
        assert!(
            got.len() == 1 && got[0].contains(reason),
            "{kind} {extra}: {got:?}"
        );
        assert!(published(&out).0.is_empty(), "{kind} {extra}");
    }
    // Sequence 1's proposal can be replaced by a level.
    let out = b.ws_text(
        t,
        &cmd(PIN, "override_level", json!({"proposal": 1, "level": 2})),
        at(0),
    );
    assert_eq!(published(&out).0.len(), 1, "{out:?}");
}
