//! The `qtrobot` backend in the core: the game waits for the robot to finish each step (the
//! introduction, a feedback line, each word of a sequence, a reaction) instead of estimating
//! the time; a step the robot does not finish pauses the session with the reason, and the
//! therapist's resume says the interrupted sequence again from its start.

use super::harness::*;
use crate::params::{GameManagerParams, RobotParams};
use crate::protocol::{Input, Output};
use qt_therapy_msgs::{GameState, TherapistCommand as C};
use sequence_game::Emotion;

fn qtrobot() -> GameManagerParams {
    GameManagerParams {
        robot: RobotParams {
            robot_backend: "qtrobot".into(),
            ..Default::default()
        },
        ..GameManagerParams::default()
    }
}

/// (time, emotion word said) of every word of the session, from the robot's faces.
fn words(h: &Harness) -> Vec<(i64, Emotion)> {
    let mut saying = false;
    let mut out = Vec::new();
    for (t, o) in &h.log {
        match o {
            Output::State(s) => saying = s.phase == GameState::SAYING_SEQUENCE,
            Output::ShowEmotion(e) if saying => {
                if let Ok(e) = e.trim_start_matches("QT/").parse::<Emotion>() {
                    out.push((*t, e));
                }
            }
            _ => {}
        }
    }
    out
}

#[test]
fn the_game_waits_for_the_robot_to_finish_each_step() {
    let child = scripted_child(vec![]);
    let mut h = Harness::new(qtrobot(), rule_policy(), child);
    // The robot takes 1.7 s for every step, whatever the speaking-time parameters say.
    h.robot = Box::new(|_| RobotReply::Done { after_s: 1.7 });
    h.start("q");
    h.run(3600.0);
    let results = h.results();
    assert_eq!(results.len(), 10);
    assert!(
        results.iter().all(|r| r.outcome == 1),
        "the child hears every word"
    );
    let steps = h
        .outputs()
        .filter(|o| matches!(o, Output::AwaitRobot { .. }))
        .count();
    let said: usize = results.iter().map(|r| r.sequence.len()).sum();
    // The introduction, every word, every feedback line and every reaction is a step.
    let feedback = results.iter().filter(|r| r.feedback != 0).count();
    // The last reaction goes out with the goodbye, and nothing waits for it.
    assert_eq!(steps, 1 + said + feedback + results.len() - 1);
    // Within a sequence the next word comes exactly when the robot finished the last.
    let w = words(&h);
    let gaps: Vec<i64> = w.windows(2).map(|p| p[1].0 - p[0].0).collect();
    assert!(gaps.iter().filter(|g| **g == ns(1.7)).count() >= said - results.len());
}

#[test]
fn a_step_the_robot_does_not_finish_pauses_the_session_and_resume_says_it_again() {
    let child = scripted_child(vec![]);
    let mut h = Harness::new(qtrobot(), rule_policy(), child);
    // Step 3: the second word of the first sequence (step 1 is the introduction; the rule
    // policy starts at level 1, three words).
    h.robot = Box::new(|step| {
        if step == 3 {
            RobotReply::Fail {
                after_s: 0.4,
                reason: "/qt_robot/speech/say answered that it failed".into(),
            }
        } else {
            RobotReply::Done { after_s: 0.6 }
        }
    });
    h.start("q");
    h.run_until_true(120.0, |h| h.last_state().phase == GameState::PAUSED);
    let paused = h.last_state();
    assert!(
        paused.status.contains("the robot did not finish")
            && paused.status.contains("answered that it failed"),
        "{}",
        paused.status
    );
    assert!(
        h.tasks().is_empty(),
        "no task after a word the robot did not say: {:?}",
        h.states()
            .iter()
            .map(|s| (s.phase, s.status.clone()))
            .collect::<Vec<_>>()
    );
    let said_before: Vec<Emotion> = words(&h).into_iter().map(|(_, e)| e).collect();
    // Nothing happens while paused.
    let before = h.log.len();
    h.run_until(h.now + ns(30.0));
    assert!(
        h.log[before..]
            .iter()
            .all(|(_, o)| !matches!(o, Output::Say(_) | Output::Task(_))),
        "the robot stays quiet while paused"
    );
    h.feed(cmd(C::RESUME, "q", 2));
    h.run(3600.0);
    let results = h.results();
    assert_eq!(results.len(), 10);
    // The interrupted sequence was said again from its first word, whole.
    let all: Vec<Emotion> = words(&h).into_iter().map(|(_, e)| e).collect();
    let first = &results[0].sequence;
    let again: Vec<String> = all[said_before.len()..said_before.len() + first.len()]
        .iter()
        .map(|e| e.name().to_string())
        .collect();
    assert_eq!(&again, first);
    assert!(results[0].outcome == 1);
    let _ = Input::RobotDone { step: 0 };
}

// QTrobot V3 (`qtrobot_ros2`): its gateway serves one call at a time, so the core asks for
// one at a time.

fn qtrobot_v3() -> GameManagerParams {
    GameManagerParams {
        robot: RobotParams {
            robot_backend: "qtrobot_ros2".into(),
            ..Default::default()
        },
        ..GameManagerParams::default()
    }
}

/// Every robot call put out, with its time, checking that each `AwaitRobot` follows exactly
/// one act (the silence is not a call anyone waits for).
fn calls(h: &Harness) -> Vec<(i64, Output)> {
    let mut act: Option<Output> = None;
    let mut out = Vec::new();
    for (t, o) in &h.log {
        match o {
            Output::Silence => {}
            Output::Say(_) | Output::ShowEmotion(_) | Output::PlayGesture(_) => {
                assert!(act.is_none(), "two acts in one call: {act:?}, {o:?}");
                act = Some(o.clone());
            }
            Output::AwaitRobot { .. } => {
                out.push((*t, act.take().expect("a call without an act")));
            }
            _ => {}
        }
    }
    assert!(act.is_none(), "an act put out with no call: {act:?}");
    out
}

fn is_act(o: &Output) -> bool {
    matches!(
        o,
        Output::Say(_) | Output::ShowEmotion(_) | Output::PlayGesture(_)
    )
}

/// Runs until the first word's face is the call under way; returns when it went out.
fn until_the_first_words_face(h: &mut Harness) -> i64 {
    h.run_until_true(120.0, |h| {
        h.last_state().phase == GameState::SAYING_SEQUENCE
            && calls(h)
                .last()
                .is_some_and(|(_, o)| matches!(o, Output::ShowEmotion(_)))
    });
    calls(h).last().expect("the face went out").0
}

#[test]
fn a_v3_is_asked_for_one_call_at_a_time_each_face_before_its_word() {
    let mut h = Harness::new(qtrobot_v3(), rule_policy(), scripted_child(vec![]));
    // Every call takes the robot 0.5 s.
    h.start("v");
    h.run(3600.0);
    let results = h.results();
    assert_eq!(results.len(), 10);
    assert!(
        results.iter().all(|r| r.outcome == 1),
        "the child saw every face"
    );
    let calls = calls(&h);
    // Never a call while another is under way: the next goes out once the last returned.
    assert!(calls.windows(2).all(|w| w[1].0 - w[0].0 >= ns(0.5)));
    // The introduction: its face, its gesture, then its words.
    let intro: Vec<&Output> = calls[..3].iter().map(|(_, o)| o).collect();
    assert!(
        matches!(
            intro[..],
            [
                Output::ShowEmotion(_),
                Output::PlayGesture(_),
                Output::Say(_)
            ]
        ),
        "{intro:?}"
    );
    // Each sequence: each word's face, then the word; the task once the last word returned.
    for (task_at, task) in h.tasks() {
        let r = results
            .iter()
            .find(|r| r.sequence_index == task.sequence_index)
            .expect("a result for each task");
        let before: Vec<&(i64, Output)> = calls.iter().filter(|(t, _)| *t < task_at).collect();
        let words = &before[before.len() - 2 * r.sequence.len()..];
        let expected: Vec<Output> = r
            .sequence
            .iter()
            .flat_map(|e| {
                [
                    Output::ShowEmotion(format!("QT/{e}")),
                    Output::Say(e.clone()),
                ]
            })
            .collect();
        let played: Vec<Output> = words.iter().map(|(_, o)| o.clone()).collect();
        assert_eq!(played, expected);
        assert_eq!(task_at, words[words.len() - 1].0 + ns(0.5));
    }
}

#[test]
fn a_pause_drops_the_rest_of_the_word_and_the_resume_waits_for_the_call_under_way() {
    let mut h = Harness::new(qtrobot_v3(), rule_policy(), scripted_child(vec![]));
    // Every call takes the robot 3 s.
    h.robot = Box::new(|_| RobotReply::Done { after_s: 3.0 });
    h.start("v");
    let face_at = until_the_first_words_face(&mut h);
    let face = calls(&h).len() - 1;
    h.run_until(face_at + ns(0.2));
    h.feed(cmd(C::PAUSE, "v", 2));
    h.run_until(face_at + ns(0.4));
    h.feed(cmd(C::RESUME, "v", 3));
    h.run(3600.0);
    let all = calls(&h);
    // The word after the face never went out: the sequence began again with the same face,
    // asked for only once the robot had shown the first (3 s), not while it did.
    assert_eq!(all[face + 1].1, all[face].1);
    assert!(all[face + 1].0 >= face_at + ns(3.0));
    assert!(all.windows(2).all(|w| w[1].0 - w[0].0 >= ns(3.0)));
    let results = h.results();
    assert_eq!(results.len(), 10);
    assert!(results.iter().all(|r| r.outcome == 1));
}

#[test]
fn the_emergency_stop_silences_a_v3_first_and_asks_it_for_nothing_more() {
    let mut h = Harness::new(qtrobot_v3(), rule_policy(), scripted_child(vec![]));
    h.robot = Box::new(|_| RobotReply::Done { after_s: 1.0 });
    h.start("v");
    let face_at = until_the_first_words_face(&mut h);
    h.run_until(face_at + ns(0.2));
    let out = h.feed(cmd(C::EMERGENCY_STOP, "v", 2));
    assert_eq!(out.first(), Some(&Output::Silence));
    let stopped = h.log.len();
    h.run(600.0);
    assert!(
        h.log[stopped..].iter().all(|(_, o)| !is_act(o)),
        "nothing after the stop"
    );
    assert_eq!(h.last_state().phase, GameState::EMERGENCY_STOPPED);
}

#[test]
fn a_stop_says_goodbye_to_a_v3_once_the_call_under_way_returned_one_call_at_a_time() {
    let mut h = Harness::new(qtrobot_v3(), rule_policy(), scripted_child(vec![]));
    h.robot = Box::new(|_| RobotReply::Done { after_s: 1.0 });
    h.start("v");
    let face_at = until_the_first_words_face(&mut h);
    let n = calls(&h).len();
    h.run_until(face_at + ns(0.2));
    h.feed(cmd(C::STOP, "v", 2));
    h.run(600.0);
    let after: Vec<(i64, Output)> = calls(&h)[n..].to_vec();
    let goodbye = h.gm.params().lines.goodbye_en.clone();
    assert_eq!(
        after,
        vec![
            (face_at + ns(1.0), Output::PlayGesture("QT/bye".into())),
            (face_at + ns(2.0), Output::Say(goodbye)),
        ],
        "the word is dropped; the goodbye follows the face, one call at a time"
    );
    assert_eq!(h.last_state().phase, GameState::STOPPED);
}

#[test]
fn a_v3_cut_short_by_a_hold_is_no_failure_and_the_session_goes_on() {
    const POLICY: &str = "behaviour_policy";
    let mut params = qtrobot_v3();
    params.reliability.watched_nodes = vec![POLICY.into()];
    let mut h = Harness::new(params, rule_policy(), scripted_child(vec![]));
    // The policy's process dies at 5 s (lost at 8.9 s) and is back at 12 s.
    h.heartbeats(POLICY, 20, T0, T0 + 5 * S);
    h.heartbeats(POLICY, 21, T0 + 12 * S, T0 + 600 * S);
    // The introduction's words (the third call) would take 10 s; the hold's silence cuts
    // them short, and the gateway then answers `result: false`.
    let mut n = 0;
    h.robot = Box::new(move |_| {
        n += 1;
        if n == 3 {
            RobotReply::Fail {
                after_s: 10.0,
                reason: "/qtrobot/tts/engine/say/text answered that it failed".into(),
            }
        } else {
            RobotReply::Done { after_s: 0.5 }
        }
    });
    h.start("v");
    h.run_until(T0 + ns(8.9));
    assert_eq!(h.gm.lost_nodes(), vec![POLICY]);
    assert!(
        h.outputs().any(|o| *o == Output::Silence),
        "silenced at the loss"
    );
    h.run(3600.0);
    assert!(
        h.states()
            .iter()
            .all(|s| !s.status.contains("the robot did not finish")),
        "the cut is the game's own silence, not a failure"
    );
    let results = h.results();
    assert_eq!(
        results.len(),
        10,
        "the session went on when the node was back"
    );
}
