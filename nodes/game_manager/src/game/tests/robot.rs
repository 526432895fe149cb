//! The `qtrobot` backend in the core: the game waits for the robot to finish each step (the
//! introduction, a feedback line, each word of a sequence, a reaction) instead of estimating
//! the time; a step the robot does not finish pauses the session with the reason, and the
//! therapist's resume says the interrupted sequence again from its start.

use super::harness::*;
use crate::params::GameManagerParams;
use crate::protocol::{Input, Output};
use qt_therapy_msgs::{GameState, TherapistCommand as C};
use sequence_game::Emotion;

fn qtrobot() -> GameManagerParams {
    GameManagerParams {
        robot_backend: "qtrobot".into(),
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
