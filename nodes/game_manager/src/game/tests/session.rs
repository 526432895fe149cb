//! Whole sessions through the core: ten sequences with scripted answers, determinism,
//! engagement gathering and the policy's safe fallback.

use super::harness::*;
use crate::params::GameManagerParams;
use crate::protocol::Output;
use crate::sequence::longest_run;
use crate::session_file::SessionEnd;
use qt_therapy_msgs::{DecideActionResponse, GameState};
use sequence_game::{Emotion, State};

fn scripted_session(params: GameManagerParams) -> Harness {
    let child = scripted_child(vec![
        (3, ChildReply::Wrong { after_s: 7.0 }),
        (5, ChildReply::Nothing),
        (7, ChildReply::Wrong { after_s: 12.0 }),
    ]);
    let mut h = Harness::new(params, rule_policy(), child);
    h.start("session-a");
    h.run(3600.0);
    h
}

#[test]
fn a_shorter_session_says_its_length_in_every_result_and_state() {
    let mut params = GameManagerParams::default();
    params.session.sequences_per_session = 5;
    let h = scripted_session(params);
    let results = h.results();
    assert_eq!(results.len(), 5);
    assert!(results.iter().all(|r| r.sequences_planned == 5));
    assert_eq!(results[4].sequence_index, results[4].sequences_planned);
    let states = h.states();
    assert!(
        states
            .iter()
            .filter(|g| !g.session_id.is_empty())
            .all(|g| g.sequences_planned == 5)
    );
    assert_eq!(h.last_state().phase, GameState::FINISHED);
}

#[test]
fn a_whole_session_plays_ten_sequences_scores_and_records_them() {
    let h = scripted_session(GameManagerParams::default());
    let results = h.results();
    assert_eq!(results.len(), 10);
    assert_eq!(h.records().len(), 10);
    let mut state = State::START;
    for (k, r) in results.iter().enumerate() {
        assert_eq!(usize::from(r.sequence_index), k + 1);
        assert_eq!(
            r.state.to_state().expect("valid state"),
            state,
            "sequence {}",
            k + 1
        );
        assert_eq!(r.sequence.len(), 2 * usize::from(r.level) + 1);
        let said: Vec<Emotion> = r
            .sequence
            .iter()
            .map(|w| w.parse().expect("emotion"))
            .collect();
        assert!(longest_run(&said) <= 2, "{:?}", r.sequence);
        let right = r.answer == r.sequence;
        assert_eq!(r.outcome, if right { 1 } else { -1 });
        assert_eq!(
            r.activity_result,
            if right { f32::from(r.level) } else { -1.0 }
        );
        state =
            State::new(r.level.into(), r.feedback.into(), r.score().into()).expect("next state");
        assert_eq!(r.sequences_planned, 10);
        assert_eq!(h.records()[k].result, *r, "the file gets what is published");
    }
    let outcomes: Vec<i8> = results.iter().map(|r| r.outcome).collect();
    assert_eq!(outcomes, vec![1, 1, -1, 1, -1, 1, -1, 1, 1, 1]);
    // Each request names the result it follows (the policy learns it first), published
    // before the request went out.
    let mut published = 0;
    for o in h.outputs() {
        match o {
            Output::Result(r) => published = r.sequence_index,
            Output::Decide { request, .. } => {
                assert_eq!(request.after_sequence, published, "step {}", request.step);
                assert_eq!(request.after_sequence, request.step - 1);
            }
            _ => {}
        }
    }
    assert!(results[4].timed_out && results[4].answer.is_empty());
    assert_eq!(results[4].response_time, 60.0);
    // The rule policy encourages after a failure: feedback 1 on sequences 4, 6 and 8.
    let feedback: Vec<u8> = results.iter().map(|r| r.feedback).collect();
    assert_eq!(feedback, vec![0, 0, 0, 1, 0, 1, 0, 1, 0, 0]);
    let levels: Vec<u8> = results.iter().map(|r| r.level).collect();
    assert_eq!(levels, vec![1, 2, 3, 3, 3, 3, 3, 3, 3, 3]);

    // Tasks: increasing ids, the level's length, four choices, the timeout.
    let tasks = h.tasks();
    assert_eq!(tasks.len(), 10);
    for (k, (_, t)) in tasks.iter().enumerate() {
        assert_eq!(t.sequence_id as usize, k + 1);
        assert_eq!(usize::from(t.length), results[k].sequence.len());
        assert_eq!(t.choices, vec!["happy", "disgusted", "sad", "angry"]);
        assert_eq!(t.timeout, 60.0);
    }

    // The robot said each sequence one word at a time with the face QT/<emotion>, and the
    // task appeared 8 / 14 / 20 s after the first word.
    let mut words = Vec::new();
    let mut in_sequence = false;
    let mut first_word_at = Vec::new();
    for (t, o) in &h.log {
        match o {
            Output::State(s) => {
                if s.phase == GameState::SAYING_SEQUENCE && !in_sequence {
                    first_word_at.push(*t);
                }
                in_sequence = s.phase == GameState::SAYING_SEQUENCE;
            }
            Output::ShowEmotion(e) if in_sequence => words.push(e.clone()),
            _ => {}
        }
    }
    let expected: Vec<String> = results
        .iter()
        .flat_map(|r| r.sequence.iter().map(|w| format!("QT/{w}")))
        .collect();
    assert_eq!(words, expected);
    for (k, (t, _)) in tasks.iter().enumerate() {
        let talk = (t - first_word_at[k]) as f64 * 1e-9;
        assert_eq!(talk, [8.0, 14.0, 20.0][usize::from(results[k].level) - 1]);
    }

    // Encouraging feedback: a line from the list, the face and the gesture, before the words.
    let p = GameManagerParams::default();
    let said: Vec<&String> = h
        .outputs()
        .filter_map(|o| match o {
            Output::Say(s) => Some(s),
            _ => None,
        })
        .collect();
    assert_eq!(
        said.iter()
            .filter(|s| p.lines.encouraging_en.contains(s))
            .count(),
        3
    );
    assert_eq!(
        h.outputs()
            .filter(|o| **o == Output::PlayGesture("QT/clapping".into()))
            .count(),
        3
    );
    assert_eq!(said[0], &p.lines.intro_en);
    assert!(
        said.last()
            .is_some_and(|s| s.ends_with(&p.lines.goodbye_en))
    );

    let summary = h.summaries();
    assert_eq!(summary.len(), 1);
    let s = &summary[0];
    assert_eq!(
        (s.end, s.sequences_played, s.correct, s.timeouts),
        (SessionEnd::Finished, 10, 7, 1)
    );
    assert_eq!(
        s.score,
        results
            .iter()
            .map(|r| i32::from(r.level) * i32::from(r.outcome))
            .sum::<i32>()
    );
    assert_eq!(s.max_score, 27);
    assert_eq!(s.interrupted_sequence, None);
    assert_eq!(h.last_state().phase, GameState::FINISHED);
    let lines = h
        .outputs()
        .filter(|o| matches!(o, Output::LiveLine(_)))
        .count();
    assert_eq!(lines, 12, "start, ten sequences, end");
}

#[test]
fn same_seed_and_inputs_give_the_same_outputs() {
    let a = scripted_session(GameManagerParams::default());
    let b = scripted_session(GameManagerParams::default());
    assert_eq!(a.log, b.log);
    let mut seed_43 = GameManagerParams::default();
    seed_43.session.seed = 43;
    let c = scripted_session(seed_43);
    let seqs = |h: &Harness| {
        h.results()
            .into_iter()
            .map(|r| r.sequence)
            .collect::<Vec<_>>()
    };
    assert_ne!(seqs(&a), seqs(&c));
}

#[test]
fn time_scale_shortens_every_robot_timing_and_the_timeout() {
    let mut fast = GameManagerParams::default();
    fast.timing.time_scale = 0.1;
    let h = scripted_session(fast);
    let results = h.results();
    assert_eq!(results.len(), 10);
    assert!(
        h.tasks()
            .iter()
            .all(|(_, t)| (t.timeout - 6.0).abs() < 1e-6)
    );
    assert!((results[4].response_time - 6.0).abs() < 1e-6);
}

#[test]
fn engagement_is_the_mean_over_the_seconds_the_robot_talked() {
    let value = |sec: i64| {
        if sec % 5 == 0 {
            None
        } else {
            Some((sec % 7) as f32 / 10.0 - 0.3)
        }
    };
    // Answers 0.1 s after the task: the last windows come in after the answer.
    let child = scripted_child(
        (1..=10)
            .map(|i| (i, ChildReply::Right { after_s: 0.1 }))
            .collect(),
    );
    let mut h = Harness::new(GameManagerParams::default(), rule_policy(), child);
    h.engagement(T0 / S, T0 / S + 1000, value);
    h.start("session-e");
    h.run(3600.0);
    let records = h.records();
    assert_eq!(records.len(), 10);
    let mut previous_answer = T0;
    for r in &records {
        assert_eq!(r.talk_start_ns, previous_answer);
        previous_answer = r.answered_ns;
        let expected: Vec<f32> = (r.talk_start_ns / S - 1..=r.task_sent_ns / S)
            .filter(|sec| {
                let mid = sec * S + S / 2;
                mid >= r.talk_start_ns && mid < r.task_sent_ns
            })
            .filter_map(value)
            .collect();
        assert!(
            expected.len() >= 6,
            "at least the talking seconds with a face"
        );
        assert_eq!(r.result.engagement_per_second, expected);
        let mean = expected.iter().map(|v| f64::from(*v)).sum::<f64>() / expected.len() as f64;
        assert!((f64::from(r.result.engagement) - mean).abs() < 1e-6);
    }
    // Without any window the result says so: no seconds, E = 0.
    let bare = scripted_session(GameManagerParams::default());
    assert!(
        bare.results()
            .iter()
            .all(|r| r.engagement_per_second.is_empty() && r.engagement == 0.0)
    );
}

#[test]
fn a_silent_policy_gets_the_safe_fallback() {
    let child = scripted_child(vec![(2, ChildReply::Wrong { after_s: 3.0 })]);
    let mut h = Harness::new(
        GameManagerParams::default(),
        Box::new(|_| PolicyReply::Silent),
        child,
    );
    h.start("session-f");
    h.run(3600.0);
    let results = h.results();
    assert_eq!(results.len(), 10);
    assert!(
        results
            .iter()
            .all(|r| r.level == 1 && r.feedback == 0 && !r.overridden)
    );
    assert!(
        h.records()
            .iter()
            .all(|r| r.policy_fallback && r.decision_reason.contains("within 2 s"))
    );
    assert!(h.states().iter().any(|s| s.policy_fallback));
    assert_eq!(h.summaries()[0].policy_fallbacks, 10);
}

#[test]
fn late_refused_failed_or_impossible_decisions_fall_back() {
    let policy = Box::new(|req: &qt_therapy_msgs::DecideActionRequest| {
        let mut good = rule_decision(req);
        match req.step {
            // Too late: after the 2 s deadline.
            1 => PolicyReply::Answer {
                after_s: 3.0,
                response: good,
            },
            2 => PolicyReply::Answer {
                after_s: 0.1,
                response: DecideActionResponse {
                    ok: false,
                    error: "no q-table".into(),
                    ..Default::default()
                },
            },
            3 => PolicyReply::Fail {
                after_s: 0.1,
                reason: "no server".into(),
            },
            4 => {
                good.decision.step = 9;
                PolicyReply::Answer {
                    after_s: 0.1,
                    response: good,
                }
            }
            5 => {
                good.decision.level = 3;
                good.decision.action = 1;
                PolicyReply::Answer {
                    after_s: 0.1,
                    response: good,
                }
            }
            _ => PolicyReply::Answer {
                after_s: 0.1,
                response: good,
            },
        }
    });
    let mut h = Harness::new(GameManagerParams::default(), policy, scripted_child(vec![]));
    h.start("session-g");
    h.run(3600.0);
    let records = h.records();
    assert_eq!(records.len(), 10);
    let reasons: Vec<&str> = records.iter().map(|r| r.decision_reason.as_str()).collect();
    assert!(
        reasons[0].contains("did not answer within 2 s"),
        "{}",
        reasons[0]
    );
    assert!(
        reasons[1].contains("policy refused: no q-table"),
        "{}",
        reasons[1]
    );
    assert!(
        reasons[2].contains("policy call failed: no server"),
        "{}",
        reasons[2]
    );
    assert!(
        reasons[3].contains("for step 9, expected 4"),
        "{}",
        reasons[3]
    );
    assert!(
        reasons[4].contains("decision says level 3"),
        "{}",
        reasons[4]
    );
    assert!(
        records[..5]
            .iter()
            .all(|r| r.policy_fallback && r.result.feedback == 0)
    );
    assert!(records[5..].iter().all(|r| !r.policy_fallback));
    assert_eq!(records[0].result.level, 1, "level 1 on the first sequence");
    assert!(h.outputs().any(
        |o| matches!(o, Output::Log { message, .. } if message.contains("late or superseded"))
    ));
    // A decision in the start state that gives feedback is refused too.
    let mut h = Harness::new(
        GameManagerParams::default(),
        Box::new(|req| {
            let mut r = rule_decision(req);
            if req.step == 1 {
                r.decision.action = 3;
            }
            PolicyReply::Answer {
                after_s: 0.1,
                response: r,
            }
        }),
        scripted_child(vec![]),
    );
    h.start("session-h");
    h.run(3600.0);
    assert!(
        h.records()[0]
            .decision_reason
            .contains("not allowed in state")
    );
}
