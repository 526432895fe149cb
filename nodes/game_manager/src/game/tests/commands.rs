//! The therapist in control: override, pause and resume, stop, emergency stop, and every
//! kind of bad command (stale, duplicated, wrong session, out of place), which is rejected
//! with a reason while the session goes on.

use super::harness::*;
use crate::params::GameManagerParams;
use crate::protocol::{Input, Output};
use crate::session_file::SessionEnd;
use qt_therapy_msgs::{GameState, TherapistCommand as C};

fn harness() -> Harness {
    Harness::new(
        GameManagerParams::default(),
        rule_policy(),
        scripted_child(vec![]),
    )
}

#[test]
fn an_override_beats_the_policy() {
    // During sequence 1's answer: sequence 2 is played at level 3 without asking the policy.
    let mut h = harness();
    h.start("s");
    h.run_until(T0 + 15 * S);
    assert_eq!(h.last_state().phase, GameState::WAITING_FOR_ANSWER);
    h.feed(override_to(3, "s", 2));
    h.run(3600.0);
    let r = h.results();
    assert_eq!(
        (r[1].level, r[1].action, r[1].feedback, r[1].overridden),
        (3, 2, 0, true)
    );
    assert!(!r[0].overridden && !r[2].overridden);
    let steps: Vec<u8> = h
        .outputs()
        .filter_map(|o| match o {
            Output::Decide { request, .. } => Some(request.step),
            _ => None,
        })
        .collect();
    assert_eq!(steps, vec![1, 3, 4, 5, 6, 7, 8, 9, 10]);
    assert_eq!(h.records()[1].decision_reason, "therapist override");
    assert_eq!(h.summaries()[0].overrides, 1);

    // While deciding: the override is used at once and the policy's answer is ignored.
    let mut h = Harness::new(
        GameManagerParams::default(),
        Box::new(|req| PolicyReply::Answer {
            after_s: 1.0,
            response: rule_decision(req),
        }),
        scripted_child(vec![]),
    );
    h.start("s");
    h.run_until(T0 + S / 2);
    h.feed(override_to(2, "s", 2));
    h.run(3600.0);
    let r = h.results();
    assert_eq!((r[0].level, r[0].overridden), (2, true));
    assert!(
        h.outputs()
            .any(|o| matches!(o, Output::Log { message, .. } if message.contains("superseded")))
    );
}

#[test]
fn pause_holds_the_robot_and_resume_says_the_sequence_again() {
    let mut h = harness();
    h.start("s");
    h.run_until(T0 + 8 * S); // words at 7.5, 10.5, 13.5 s
    assert_eq!(h.last_state().phase, GameState::SAYING_SEQUENCE);
    assert_eq!(h.heard().len(), 1);
    h.feed(cmd(C::PAUSE, "s", 2));
    assert_eq!(h.last_state().phase, GameState::PAUSED);
    let paused_at = h.log.len();
    h.run_until(T0 + 60 * S);
    assert!(
        h.robot_outputs_since(paused_at).is_empty(),
        "the robot is quiet while paused"
    );
    assert!(h.tasks().is_empty());
    h.feed(cmd(C::RESUME, "s", 3));
    assert_eq!(h.last_state().phase, GameState::SAYING_SEQUENCE);
    h.run(3600.0);
    let r = h.results();
    assert_eq!(r.len(), 10);
    assert_eq!(r[0].outcome, 1, "the child heard the whole sequence again");
    assert_eq!(
        h.tasks()[0].0,
        T0 + 68 * S,
        "the words restart at the resume"
    );
}

#[test]
fn pause_suspends_the_answer_timeout_and_keeps_an_answer_given_meanwhile() {
    let mut h = Harness::new(
        GameManagerParams::default(),
        rule_policy(),
        scripted_child(vec![(1, ChildReply::Nothing)]),
    );
    h.start("s");
    h.run_until(T0 + 24 * S); // task 1 went out at 14 s: 50 s left
    h.feed(cmd(C::PAUSE, "s", 2));
    h.run_until(T0 + 124 * S);
    assert!(h.results().is_empty(), "no timeout while paused");
    h.feed(cmd(C::RESUME, "s", 3));
    h.run_until(T0 + 200 * S);
    let at = h
        .log
        .iter()
        .find(|(_, o)| matches!(o, Output::Result(_)))
        .map(|(t, _)| *t);
    assert_eq!(at, Some(T0 + 174 * S));
    assert!(h.results()[0].timed_out);

    // An answer that arrives while paused is scored; the game waits for the resume.
    let mut h = harness();
    h.start("s");
    h.run_until(T0 + 15 * S);
    h.feed(cmd(C::PAUSE, "s", 2));
    let paused_at = h.log.len();
    h.run_until(T0 + 40 * S);
    assert_eq!(h.results().len(), 1);
    assert_eq!(h.results()[0].outcome, 1);
    assert!(h.robot_outputs_since(paused_at).is_empty());
    assert_eq!(h.last_state().phase, GameState::PAUSED);
    h.feed(cmd(C::RESUME, "s", 3));
    assert_eq!(h.last_state().phase, GameState::SAYING_SEQUENCE);
    h.run(3600.0);
    assert_eq!(h.results().len(), 10);
}

#[test]
fn stop_says_goodbye_saves_the_session_and_ends_it() {
    let mut h = harness();
    h.start("s");
    h.run_until(T0 + 45 * S);
    assert_eq!(h.results().len(), 2);
    let out = h.feed(cmd(C::STOP, "s", 2));
    let goodbye = GameManagerParams::default().lines.goodbye_en;
    assert!(out.contains(&Output::Say(goodbye)));
    let s = &h.summaries()[0];
    assert_eq!(
        (s.end, s.sequences_played, s.interrupted_sequence),
        (SessionEnd::Stopped, 2, Some(3))
    );
    assert_eq!(h.last_state().phase, GameState::STOPPED);
    let stopped_at = h.log.len();
    h.run(3600.0);
    assert!(h.robot_outputs_since(stopped_at).is_empty());
    assert_eq!(h.results().len(), 2);
    h.feed(cmd(C::PAUSE, "s", 3));
    assert!(
        h.last_state().status.contains("already ended (stopped)"),
        "{}",
        h.last_state().status
    );
    // A new session may start.
    h.feed(cmd(C::START, "s2", 1));
    assert_eq!(
        (h.last_state().phase, h.last_state().session_id.as_str()),
        (GameState::DECIDING, "s2")
    );
}

#[test]
fn an_emergency_stop_silences_the_robot_at_once_and_saves_the_session() {
    let mut h = harness();
    h.start("s");
    h.run_until(T0 + 10 * S);
    let before = h.log.len();
    // Same id as the start: out of order, honoured anyway.
    let out = h.feed(cmd(C::EMERGENCY_STOP, "s", 1));
    assert_eq!(out.first(), Some(&Output::Silence));
    assert!(
        h.warnings()
            .iter()
            .any(|w| w.contains("honoured for an emergency stop"))
    );
    h.run(3600.0);
    assert_eq!(h.robot_outputs_since(before), vec![Output::Silence]);
    assert!(h.tasks().is_empty() && h.results().is_empty());
    let s = &h.summaries()[0];
    assert_eq!(
        (s.end, s.interrupted_sequence),
        (SessionEnd::EmergencyStopped, Some(1))
    );
    assert_eq!(h.last_state().phase, GameState::EMERGENCY_STOPPED);

    // While the answer's engagement is still being gathered: the answer is recorded first.
    let child = scripted_child(vec![(1, ChildReply::Right { after_s: 0.1 })]);
    let mut h = Harness::new(GameManagerParams::default(), rule_policy(), child);
    h.start("s");
    h.run_until(T0 + 14 * S + S / 2);
    h.feed(cmd(C::EMERGENCY_STOP, "s", 2));
    assert_eq!(h.records().len(), 1);
    let s = &h.summaries()[0];
    assert_eq!((s.sequences_played, s.interrupted_sequence), (1, None));
}

#[test]
fn bad_commands_are_rejected_with_a_reason_and_the_session_goes_on() {
    let mut h = harness();
    let expect_rejected = |h: &mut Harness, input: Input, reason: &str| {
        let out = h.feed(input);
        let warned = out
            .iter()
            .any(|o| matches!(o, Output::Log { message, .. } if message.contains(reason)));
        assert!(warned, "no warning with {reason:?}: {out:?}");
        let status = h.last_state().status;
        assert!(
            status.starts_with("rejected") && status.contains(reason),
            "{status}"
        );
    };
    expect_rejected(&mut h, cmd(C::PAUSE, "s", 1), "no session is running");
    h.feed(cmd(C::START, "s", 10));
    h.run_until(T0 + 15 * S);
    expect_rejected(
        &mut h,
        cmd(C::PAUSE, "s", 5),
        "stale command id 5 (last accepted 10)",
    );
    expect_rejected(&mut h, cmd(C::PAUSE, "s", 10), "duplicate command id 10");
    expect_rejected(&mut h, cmd(C::PAUSE, "other", 11), "wrong session");
    expect_rejected(&mut h, cmd(C::START, "s2", 1), "busy with session \"s\"");
    expect_rejected(&mut h, cmd(C::START, "s", 11), "already running");
    expect_rejected(&mut h, cmd(C::RESUME, "s", 12), "not paused");
    h.feed(cmd(C::PAUSE, "s", 13));
    expect_rejected(&mut h, cmd(C::PAUSE, "s", 14), "already paused");
    h.feed(cmd(C::RESUME, "s", 15));
    expect_rejected(&mut h, override_to(4, "s", 16), "level 4 is not 1, 2 or 3");
    expect_rejected(&mut h, cmd(9, "s", 17), "unknown command code 9");
    expect_rejected(&mut h, cmd(C::STOP, "", 18), "session_id is empty");
    h.run_until_true(3600.0, |h| h.tasks().len() == 10);
    expect_rejected(
        &mut h,
        override_to(2, "s", 19),
        "no sequence is left to override",
    );
    h.run(3600.0);
    assert_eq!(h.results().len(), 10);
    let s = &h.summaries()[0];
    assert_eq!((s.end, s.rejected_commands), (SessionEnd::Finished, 11));
    expect_rejected(&mut h, cmd(C::START, "s", 100), "already used");
    expect_rejected(&mut h, cmd(C::STOP, "s", 101), "already ended (finished)");
}

#[test]
fn every_command_is_answered_by_a_state_with_its_outcome() {
    // The console waits for such a state before it exits (and sends the command again if it
    // sees none), so each accepted or refused command must publish one, in every phase, with
    // the typed answer it reads (never the status text).
    let answer = |out: &[Output], id: u64| -> Option<(u8, String)> {
        out.iter().rev().find_map(|o| match o {
            Output::State(s) if s.command_session_id == "s" && s.command_id == id => {
                Some((s.command_outcome, s.command_refusal.clone()))
            }
            _ => None,
        })
    };
    let done = Some((GameState::COMMAND_CARRIED_OUT, String::new()));
    let mut h = harness();
    let out = h.feed(cmd(C::START, "s", 1));
    assert_eq!(answer(&out, 1), done, "start: {out:?}");
    h.run_until(T0 + 15 * S);
    assert_eq!(h.last_state().phase, GameState::WAITING_FOR_ANSWER);
    let out = h.feed(cmd(C::PAUSE, "s", 2));
    assert_eq!(answer(&out, 2), done, "pause: {out:?}");
    let out = h.feed(override_to(3, "s", 3));
    assert_eq!(answer(&out, 3), done, "override while paused: {out:?}");
    let out = h.feed(cmd(C::RESUME, "s", 4));
    assert_eq!(answer(&out, 4), done, "resume: {out:?}");
    let out = h.feed(cmd(C::RESUME, "s", 4));
    assert_eq!(
        answer(&out, 4),
        Some((
            GameState::COMMAND_ALREADY_CARRIED_OUT,
            "duplicate command id 4".into()
        )),
        "a repeat is answered as one: {out:?}"
    );
    // While deciding sequence 2 (the override applies at once).
    h.run_until_true(60.0, |h| h.last_state().phase == GameState::DECIDING);
    let out = h.feed(override_to(1, "s", 5));
    assert_eq!(answer(&out, 5), done, "override while deciding: {out:?}");
    let out = h.feed(cmd(C::STOP, "s", 6));
    assert_eq!(answer(&out, 6), done, "stop: {out:?}");
    let out = h.feed(cmd(C::EMERGENCY_STOP, "s", 7));
    assert_eq!(
        answer(&out, 7),
        Some((
            GameState::COMMAND_REFUSED,
            "session has already ended (stopped)".into()
        )),
        "emergency stop after the end: {out:?}"
    );
    // The answer stays in later states until another command is answered.
    assert_eq!(h.last_state().command_id, 7);
}
