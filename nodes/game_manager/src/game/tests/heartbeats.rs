//! A watched node that stops its heartbeat: lost exactly at the timeout, the robot silenced,
//! the session held (paused, not lost) with the node named in GameState, and resumed when it
//! is back (by itself, or by the therapist); a start refused meanwhile; no sequence played or
//! recorded twice.

use super::harness::*;
use crate::params::{GameManagerParams, ReliabilityParams};
use crate::protocol::{Input, Output};
use crate::session_file::SessionEnd;
use qt_therapy_msgs::{DecideActionRequest, GameState, TherapistCommand as C};

const POLICY: &str = "behaviour_policy";
const CLASSIFIER: &str = "engagement_classifier";

fn params(auto_resume: bool) -> GameManagerParams {
    GameManagerParams {
        reliability: ReliabilityParams {
            watched_nodes: vec![POLICY.into(), CLASSIFIER.into()],
            auto_resume_after_node_loss: auto_resume,
            ..Default::default()
        },
        ..Default::default()
    }
}

/// A session from T0 whose policy process (pid 20) dies at 20 s and is back as pid 21 at
/// 30 s; the classifier beats all along. Sequence 2's words start at 21 s (one every 3 s
/// from 22.5 s), so the loss falls mid-sequence.
fn policy_killed_at_20_s(auto_resume: bool) -> Harness {
    let mut h = Harness::new(params(auto_resume), rule_policy(), scripted_child(vec![]));
    h.heartbeats(CLASSIFIER, 10, T0, T0 + 400 * S);
    h.heartbeats(POLICY, 20, T0, T0 + 20 * S);
    h.heartbeats(POLICY, 21, T0 + 30 * S, T0 + 400 * S);
    h.start("s");
    h
}

fn sequence_indices(h: &Harness) -> Vec<u8> {
    h.results().iter().map(|r| r.sequence_index).collect()
}

#[test]
fn a_lost_node_holds_the_session_silently_until_it_is_back() {
    let mut h = policy_killed_at_20_s(true);
    // Last heartbeat at 19.9 s: lost at 23.9 s, not a nanosecond before.
    h.run_until(T0 + ns(23.9) - 1);
    assert!(h.gm.lost_nodes().is_empty());
    assert_eq!(h.last_state().phase, GameState::SAYING_SEQUENCE);
    let before = h.log.len();
    h.run_until(T0 + ns(23.9));
    assert_eq!(h.gm.lost_nodes(), vec![POLICY]);
    let state = h.last_state();
    assert_eq!(state.phase, GameState::PAUSED);
    assert!(
        state
            .status
            .starts_with("node lost: behaviour_policy; session paused"),
        "{}",
        state.status
    );
    assert_eq!(
        h.robot_outputs_since(before),
        vec![Output::Silence],
        "silenced at once"
    );
    assert!(
        h.warnings()
            .iter()
            .any(|w| w.contains("behaviour_policy (no heartbeat for 4.0 s, last pid 20)"))
    );

    // Held: nothing reaches the robot or the tablet; the node stays named in GameState.
    let lost_at = h.log.len();
    let tasks = h.tasks().len();
    h.run_until(T0 + 30 * S - 1);
    assert_eq!(h.robot_outputs_since(lost_at), vec![]);
    assert_eq!(h.tasks().len(), tasks);
    let state = h.last_state();
    assert_eq!(state.phase, GameState::PAUSED);
    assert!(state.status.starts_with("node lost: behaviour_policy"));

    // Back as a new process: the sequence is said again from its start.
    h.run_until(T0 + 30 * S);
    let state = h.last_state();
    assert_eq!(state.phase, GameState::SAYING_SEQUENCE);
    assert!(h.gm.lost_nodes().is_empty());
    assert!(h.outputs().any(|o| matches!(o, Output::State(s)
        if s.status == "node behaviour_policy is back (pid 21) after 6.1 s lost: resumed")));
    h.run_until(T0 + 400 * S);
    assert_eq!(sequence_indices(&h), (1..=10).collect::<Vec<u8>>());
    assert!(
        h.results().iter().all(|r| r.outcome == 1),
        "every sequence heard whole"
    );
    assert_eq!(h.records().len(), 10);
    let s = &h.summaries()[0];
    assert_eq!((s.end, s.sequences_played), (SessionEnd::Finished, 10));
}

#[test]
fn without_auto_resume_the_therapist_resumes_once_the_node_is_back() {
    let mut h = policy_killed_at_20_s(false);
    h.run_until(T0 + 25 * S);
    let lost_at = h.log.len();
    // Too early: the node is still lost.
    h.feed(Input::Command(command(C::RESUME, "s", 2)));
    let status = h.last_state().status;
    assert!(
        status.contains("rejected") && status.contains("held because a node is lost"),
        "{status}"
    );
    h.run_until(T0 + 35 * S);
    let state = h.last_state();
    assert_eq!(state.phase, GameState::PAUSED);
    assert!(
        state.status.ends_with("waiting for the therapist's resume"),
        "{}",
        state.status
    );
    assert_eq!(h.robot_outputs_since(lost_at), vec![]);
    h.feed(Input::Command(command(C::RESUME, "s", 3)));
    assert_eq!(h.last_state().phase, GameState::SAYING_SEQUENCE);
    h.run_until(T0 + 400 * S);
    assert_eq!(sequence_indices(&h), (1..=10).collect::<Vec<u8>>());
    assert_eq!(h.summaries()[0].rejected_commands, 1);
}

#[test]
fn a_therapist_pause_outlasts_the_hold_and_a_quick_restart_is_only_logged() {
    let mut h = Harness::new(params(true), rule_policy(), scripted_child(vec![]));
    // The classifier restarts within the timeout (1 s gap): never lost, but logged.
    h.heartbeats(CLASSIFIER, 10, T0, T0 + 50 * S);
    h.heartbeats(CLASSIFIER, 11, T0 + 51 * S, T0 + 400 * S);
    h.heartbeats(POLICY, 20, T0, T0 + 20 * S);
    h.heartbeats(POLICY, 21, T0 + 30 * S, T0 + 400 * S);
    h.start("s");
    h.run_until(T0 + 22 * S);
    h.feed(Input::Command(command(C::PAUSE, "s", 2)));
    let paused_at = h.log.len();
    h.run_until(T0 + 31 * S);
    assert_eq!(h.robot_outputs_since(paused_at), vec![], "already silent");
    let state = h.last_state();
    assert_eq!(state.phase, GameState::PAUSED);
    assert!(
        state.status.ends_with("still paused by the therapist"),
        "{}",
        state.status
    );
    h.feed(Input::Command(command(C::RESUME, "s", 3)));
    assert_eq!(h.last_state().phase, GameState::SAYING_SEQUENCE);
    h.run_until(T0 + 400 * S);
    assert_eq!(sequence_indices(&h), (1..=10).collect::<Vec<u8>>());
    assert!(h.warnings().iter().any(
        |w| w == "node engagement_classifier restarted (pid 10 -> 11) within the loss timeout"
    ));
    assert_eq!(
        h.warnings()
            .iter()
            .filter(|w| w.starts_with("node lost"))
            .count(),
        1
    );
}

#[test]
fn a_start_waits_for_every_watched_node_and_unwatched_ones_do_not_count() {
    let mut h = Harness::new(params(true), rule_policy(), scripted_child(vec![]));
    // Heartbeats of a node nobody watches start no watch.
    h.heartbeats("simulated_child", 5, T0, T0 + 60 * S);
    h.run_until(T0 + 10 * S);
    assert!(h.gm.lost_nodes().is_empty());
    assert!(h.warnings().is_empty());
    // From the classifier's first heartbeat on, the policy (never heard) has 4 s.
    h.heartbeats(CLASSIFIER, 10, T0 + 10 * S, T0 + 400 * S);
    h.heartbeats(POLICY, 20, T0 + 20 * S, T0 + 400 * S);
    h.run_until(T0 + 14 * S - 1);
    assert!(h.gm.lost_nodes().is_empty());
    h.run_until(T0 + 14 * S);
    assert_eq!(h.gm.lost_nodes(), vec![POLICY]);
    assert!(h.warnings().iter().any(|w| w.contains("never heard")));
    let state = h.last_state();
    assert_eq!(state.phase, GameState::IDLE);
    assert!(
        state
            .status
            .starts_with("node lost: behaviour_policy; a session cannot start"),
        "{}",
        state.status
    );
    h.run_until(T0 + 15 * S);
    h.feed(Input::Command(command(C::START, "s", 1)));
    let status = h.last_state().status;
    assert!(
        status.starts_with("node lost: behaviour_policy; rejected command 1 (start)"),
        "{status}"
    );
    assert!(h.robot_outputs_since(0).is_empty());
    h.run_until(T0 + 20 * S);
    assert!(h.gm.lost_nodes().is_empty());
    h.feed(Input::Command(command(C::START, "s", 2)));
    assert_eq!(h.last_state().phase, GameState::DECIDING);
    h.run_until(T0 + 400 * S);
    assert_eq!(sequence_indices(&h), (1..=10).collect::<Vec<u8>>());
}

#[test]
fn a_hold_while_the_task_waits_keeps_the_task_and_suspends_its_timeout() {
    // Task 1 goes out at 14 s (timeout 60 s); the child never answers it. The policy's last
    // heartbeat is at 15.9 s: held from 19.9 s to its return at 40 s (20.1 s).
    let child = scripted_child(vec![(1, ChildReply::Nothing)]);
    let mut h = Harness::new(params(true), rule_policy(), child);
    h.heartbeats(CLASSIFIER, 10, T0, T0 + 400 * S);
    h.heartbeats(POLICY, 20, T0, T0 + 16 * S);
    h.heartbeats(POLICY, 21, T0 + 40 * S, T0 + 400 * S);
    h.start("s");
    h.run_until(T0 + 20 * S);
    assert_eq!(h.last_state().phase, GameState::PAUSED);
    let held_at = h.log.len();
    h.run_until(T0 + 40 * S);
    assert_eq!(h.last_state().phase, GameState::WAITING_FOR_ANSWER);
    assert!(
        h.last_state()
            .status
            .ends_with("resumed: waiting for the answer"),
        "{}",
        h.last_state().status
    );
    assert_eq!(h.robot_outputs_since(held_at), vec![]);
    h.run_until(T0 + 200 * S);
    let timed_out_at = h
        .log
        .iter()
        .find(|(_, o)| matches!(o, Output::Result(_)))
        .map(|(t, _)| *t);
    assert_eq!(timed_out_at, Some(T0 + 14 * S + 60 * S + ns(20.1)));
    assert!(h.results()[0].timed_out);
    let task_ids: Vec<u32> = h.tasks().iter().map(|(_, t)| t.sequence_id).collect();
    assert_eq!(task_ids, (1..=task_ids.len() as u32).collect::<Vec<u32>>());
    assert_eq!(h.tasks()[0].1.sequence_index, 1);
    assert_eq!(
        h.tasks()[1].1.sequence_index,
        2,
        "task 1 was not sent again"
    );
}

#[test]
fn a_therapist_resume_during_a_hold_leaves_the_hold_to_the_node() {
    let mut h = policy_killed_at_20_s(true);
    h.run_until(T0 + 22 * S);
    h.feed(Input::Command(command(C::PAUSE, "s", 2)));
    h.run_until(T0 + 25 * S);
    h.feed(Input::Command(command(C::RESUME, "s", 3)));
    let state = h.last_state();
    assert_eq!(state.phase, GameState::PAUSED);
    assert_eq!(
        state.status,
        "node lost: behaviour_policy; resumed by the therapist (command 3); still held until the node is back"
    );
    let resumed_at = h.log.len();
    h.run_until(T0 + 30 * S - 1);
    assert_eq!(h.robot_outputs_since(resumed_at), vec![]);
    h.run_until(T0 + 30 * S);
    assert_eq!(h.last_state().phase, GameState::SAYING_SEQUENCE);
    h.run_until(T0 + 400 * S);
    assert_eq!(sequence_indices(&h), (1..=10).collect::<Vec<u8>>());
}

/// When the game manager asks the policy for `step` in an undisturbed session.
fn decide_time(step: u8) -> i64 {
    let mut h = Harness::new(params(true), rule_policy(), scripted_child(vec![]));
    h.heartbeats(CLASSIFIER, 10, T0, T0 + 400 * S);
    h.heartbeats(POLICY, 20, T0, T0 + 400 * S);
    h.start("s");
    h.run_until(T0 + 400 * S);
    h.log
        .iter()
        .find_map(|(t, o)| match o {
            Output::Decide { request, .. } if request.step == step => Some(*t),
            _ => None,
        })
        .expect("a request for the step")
}

/// The policy's heartbeats around sequence 2, in seconds from its first request for that
/// sequence: pid 20 from the start until `beats[0].0`, then each `(from, to)` of `beats[1..]`
/// as pid 21 (the last running to the end). Its first `silent` requests for sequence 2 get no
/// answer, as a dead process gives none. Runs the session; returns it with the times of the
/// requests for sequence 2 from the first.
fn policy_around_step_2(silent: usize, beats: &[(f64, f64)]) -> (Harness, Vec<i64>) {
    let t2 = decide_time(2);
    let mut asked = 0;
    let policy: Box<dyn FnMut(&DecideActionRequest) -> PolicyReply> = Box::new(move |req| {
        if req.step == 2 {
            asked += 1;
            if asked <= silent {
                return PolicyReply::Silent;
            }
        }
        PolicyReply::Answer {
            after_s: 0.05,
            response: rule_decision(req),
        }
    });
    let mut h = Harness::new(params(true), policy, scripted_child(vec![]));
    h.heartbeats(CLASSIFIER, 10, T0, T0 + 400 * S);
    h.heartbeats(POLICY, 20, T0, t2 + ns(beats[0].0));
    for (i, &(from, to)) in beats.iter().enumerate().skip(1) {
        let to = if i + 1 == beats.len() {
            T0 + 400 * S
        } else {
            t2 + ns(to)
        };
        h.heartbeats(POLICY, 21, t2 + ns(from), to);
    }
    h.start("s");
    h.run_until(T0 + 400 * S);
    let requests = h
        .log
        .iter()
        .filter_map(|(t, o)| match o {
            Output::Decide { request, .. } if request.step == 2 => Some(*t - t2),
            _ => None,
        })
        .collect();
    (h, requests)
}

/// The policy process dies `dies_before_s` before the first request for sequence 2 (which
/// it never answers) and is back `back_after_s` after it.
fn policy_dies_around_step_2(dies_before_s: f64, back_after_s: f64) -> (Harness, Vec<i64>) {
    policy_around_step_2(1, &[(-dies_before_s, 0.0), (back_after_s, f64::INFINITY)])
}

/// Sequence 2's record, with how many fallbacks the session summary counts.
fn step_2_fallback(h: &Harness) -> (bool, u32) {
    let records = h.records();
    assert_eq!(records.len(), 10, "every sequence recorded once");
    let fallback = records
        .iter()
        .find(|r| r.result.sequence_index == 2)
        .map(|r| r.policy_fallback);
    (fallback == Some(true), h.summaries()[0].policy_fallbacks)
}

#[test]
fn a_request_that_runs_out_while_held_asks_the_policy_again_instead_of_falling_back() {
    // Dead 3 s before the request: lost 1 s after it (the heartbeat timeout, 4 s), held when
    // the policy deadline (2 s) runs out; back at +10 s and asked again then.
    let (h, requests) = policy_dies_around_step_2(3.0, 10.0);
    assert_eq!(
        requests,
        vec![0, 10 * S],
        "asked again when the policy is back"
    );
    assert!(
        h.warnings().iter().all(|w| !w.contains("fallback")),
        "no fallback while held: {:?}",
        h.warnings()
    );
    let records = h.records();
    assert_eq!(records.len(), 10);
    assert!(records.iter().all(|r| !r.policy_fallback));
    assert_eq!(h.summaries()[0].policy_fallbacks, 0);
}

#[test]
fn a_request_still_pending_when_the_policy_is_back_is_asked_again() {
    // Dead 3.5 s before the request: lost 0.4 s after it, back at +1.5 s, before the deadline
    // (+2 s): the request went to the dead process, so the new one is asked at once.
    let (h, requests) = policy_dies_around_step_2(3.5, 1.5);
    assert_eq!(requests, vec![0, ns(1.5)]);
    assert!(h.records().iter().all(|r| !r.policy_fallback));
    assert_eq!(h.results().len(), 10);
}

#[test]
fn a_policy_silent_at_its_deadline_is_waited_for_until_it_is_lost_and_back() {
    // Dead 1 s before the request (last heartbeat 1.1 s before): at the deadline (+2 s) its
    // heartbeat has been silent 3.1 s, short of the loss timeout (4 s). Waiting, lost at
    // +2.9 s, held, back at +10 s and asked again then: no fallback.
    let (h, requests) = policy_dies_around_step_2(1.0, 10.0);
    assert_eq!(requests, vec![0, 10 * S]);
    assert!(
        h.warnings()
            .iter()
            .any(|w| w.contains("no heartbeat for 3.1 s: waiting")),
        "{:?}",
        h.warnings()
    );
    assert_eq!(step_2_fallback(&h), (false, 0));
}

#[test]
fn a_policy_dying_just_after_the_request_is_waited_for_too() {
    // Dies 1 s after the request: silent 1 s at the deadline; back (a new pid, never lost)
    // at +2.5 s and asked again at once.
    let (h, requests) = policy_around_step_2(1, &[(1.0, 0.0), (2.5, f64::INFINITY)]);
    assert_eq!(requests, vec![0, ns(2.5)]);
    assert_eq!(step_2_fallback(&h), (false, 0));
}

#[test]
fn a_policy_dying_just_before_its_deadline_is_waited_for_too() {
    // Dies 0.2 s before the deadline: heard 0.2-0.3 s before it, too recently to count as
    // silent then, so the deadline looks again 0.5 s after that heartbeat and waits. Back (a
    // new pid, never lost) at +5 s and asked again then.
    let (h, requests) = policy_around_step_2(1, &[(1.8, 0.0), (5.0, f64::INFINITY)]);
    assert_eq!(requests, vec![0, 5 * S]);
    assert_eq!(step_2_fallback(&h), (false, 0));
    assert!(
        h.warnings()
            .iter()
            .any(|w| w.contains("no heartbeat for 0.5 s: waiting")),
        "{:?}",
        h.warnings()
    );
}

#[test]
fn a_slow_policy_gets_the_fallback_at_most_half_a_second_after_its_deadline() {
    // Alive (a restart within the timeout, heartbeats throughout) but silent: slow, not dead.
    let (h, requests) = policy_around_step_2(1, &[(3.0, 0.0), (3.0, f64::INFINITY)]);
    assert_eq!(requests, vec![0]);
    assert_eq!(step_2_fallback(&h), (true, 1));
    assert!(
        h.warnings().iter().all(|w| !w.contains("waiting")),
        "{:?}",
        h.warnings()
    );
    // The deadline (+2 s) heard it within 0.1 s, and looked again 0.5 s after that beat.
    let t2 = decide_time(2);
    let fell_back_at = h
        .log
        .iter()
        .find_map(|(t, o)| match o {
            Output::Log { message, .. } if message.starts_with("sequence 2: safe fallback") => {
                Some(*t - t2)
            }
            _ => None,
        })
        .expect("a fallback for sequence 2");
    assert!(
        (ns(2.4)..=ns(2.5)).contains(&fell_back_at),
        "fallback {fell_back_at} ns after the request"
    );
}

#[test]
fn an_answer_in_the_second_look_at_the_heartbeat_still_counts() {
    // The policy beats throughout and answers sequence 2 at +2.3 s: after its deadline,
    // before the look that would have played the fallback.
    let policy: Box<dyn FnMut(&DecideActionRequest) -> PolicyReply> =
        Box::new(|req| PolicyReply::Answer {
            after_s: if req.step == 2 { 2.3 } else { 0.05 },
            response: rule_decision(req),
        });
    let mut h = Harness::new(params(true), policy, scripted_child(vec![]));
    h.heartbeats(CLASSIFIER, 10, T0, T0 + 400 * S);
    h.heartbeats(POLICY, 20, T0, T0 + 400 * S);
    h.start("s");
    h.run_until(T0 + 400 * S);
    assert_eq!(step_2_fallback(&h), (false, 0));
    assert!(h.warnings().iter().all(|w| !w.contains("fallback")));
}

#[test]
fn a_policy_is_waited_for_once_a_sequence() {
    // Silent at the first deadline (+2 s) and back at +2.5 s; asked again, silent again, and
    // its heartbeat is silent again at the second deadline (+4.5 s): the fallback, not a
    // second wait.
    let (h, requests) = policy_around_step_2(2, &[(1.0, 0.0), (2.5, 3.5), (5.0, f64::INFINITY)]);
    assert_eq!(requests, vec![0, ns(2.5)]);
    assert_eq!(step_2_fallback(&h), (true, 1));
}

#[test]
fn a_node_started_twice_is_told_once_and_the_session_goes_on() {
    // Two policy processes beat side by side from the start (heartbeats 50 ms apart).
    let mut h = Harness::new(params(true), rule_policy(), scripted_child(vec![]));
    h.heartbeats(CLASSIFIER, 10, T0, T0 + 400 * S);
    h.heartbeats(POLICY, 20, T0, T0 + 400 * S);
    h.heartbeats(POLICY, 21, T0 + ns(0.05), T0 + 400 * S);
    h.start("s");
    h.run_until(T0 + 400 * S);
    let told: Vec<String> = h
        .warnings()
        .into_iter()
        .filter(|w| w.contains("two processes beat"))
        .collect();
    assert_eq!(
        told,
        vec![
            "two processes beat as node behaviour_policy (pids 21 and 20): it was started twice; \
             stop one, as each answers, publishes and writes on its own"
        ]
    );
    assert!(h.gm.lost_nodes().is_empty());
    assert_eq!(h.results().len(), 10, "the session went on");
}

#[test]
fn a_node_started_twice_stays_in_the_status_until_one_process_stops() {
    // The second policy process beats for the first 30 s only.
    let mut h = Harness::new(params(true), rule_policy(), scripted_child(vec![]));
    h.heartbeats(CLASSIFIER, 10, T0, T0 + 400 * S);
    h.heartbeats(POLICY, 20, T0, T0 + 400 * S);
    h.heartbeats(POLICY, 21, T0 + ns(0.05), T0 + 30 * S);
    h.start("s");
    h.run_until(T0 + 400 * S);
    let twice = "two processes beat as node behaviour_policy (pids 20 and 21): stop one";
    let timed: Vec<(i64, String)> = h
        .log
        .iter()
        .filter_map(|(t, o)| match o {
            Output::State(s) => Some((*t, s.status.clone())),
            _ => None,
        })
        .collect();
    let shown: Vec<i64> = timed
        .iter()
        .filter(|(_, s)| s.starts_with(twice))
        .map(|(t, _)| *t)
        .collect();
    assert!(!shown.is_empty(), "GameState.status tells it");
    // Every state while both beat tells it, and none after the second stopped (its last beat
    // at 29.95 s, silent for the 4 s timeout at 33.95 s).
    let ended = T0 + ns(33.95);
    for (t, status) in &timed {
        if (*shown.first().unwrap_or(&0)..ended).contains(t) {
            assert!(status.starts_with(twice), "at {t}: {status}");
        } else if *t > ended {
            assert!(!status.contains("two processes"), "at {t}: {status}");
        }
    }
    let lines: Vec<&Output> = h
        .outputs()
        .filter(|o| matches!(o, Output::LiveLine(l) | Output::Alarm(l) if l.contains("process")))
        .collect();
    assert_eq!(
        lines,
        vec![
            &Output::Alarm(twice.to_string()),
            &Output::LiveLine("only one process beats as node behaviour_policy again".into())
        ]
    );
    assert!(h.gm.lost_nodes().is_empty());
    assert_eq!(h.results().len(), 10, "the session went on");
}
