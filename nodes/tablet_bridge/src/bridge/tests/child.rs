//! Core tests of the child page's answers.

use super::*;

#[test]
fn a_good_answer_is_published_with_the_tasks_session_and_sequence() {
    let (mut b, c) = waiting();
    let out = b.ws_text(c, &answer(7, &["happy", "sad", "angry"]), at(1000));
    let (commands, answers) = published(&out);
    assert!(commands.is_empty());
    assert_eq!(answers.len(), 1);
    assert_eq!(
        (answers[0].session_id.as_str(), answers[0].sequence_id),
        ("s1", 7)
    );
    assert_eq!(answers[0].answer, vec!["happy", "sad", "angry"]);
    assert_eq!(answers[0].response_time, 2.5);
    assert_eq!(answers[0].header.stamp.to_nanos(), at(1000).wall_nanos);
    assert_eq!(
        to(&out, c),
        vec![ServerMessage::Accepted {
            what: "answer".into()
        }]
    );
}

#[test]
fn bad_answers_are_rejected_with_a_reason_and_the_task_stays_open() {
    let cases: [(String, &str); 9] = [
        (
            answer(6, &["happy", "sad", "angry"]),
            "this answer is for sequence 6, but the current task is sequence 7",
        ),
        (
            answer(7, &["happy", "sad"]),
            "answer has 2 emotions, the task asked for 3",
        ),
        (
            answer(7, &["happy", "sad", "angry", "sad"]),
            "answer has 4 emotions",
        ),
        (
            answer(7, &["happy", "joyful", "sad"]),
            r#"answer[1] = "joyful" is not happy, disgusted"#,
        ),
        (
            answer(7, &["Happy", "sad", "sad"]),
            r#"answer[0] = "Happy""#,
        ),
        (
            r#"{"type":"answer","sequence_id":7,"answer":["sad","sad","sad"],"response_time":-1}"#
                .into(),
            "response_time = -1",
        ),
        (
            r#"{"type":"answer","sequence_id":7,"answer":["sad","sad","sad"],"response_time":1e9}"#
                .into(),
            "response_time = 1000000000",
        ),
        (
            r#"{"type":"answer","sequence_id":7,"answer":[1,2,3],"response_time":1}"#.into(),
            "invalid type",
        ),
        (
            r#"{"type":"answer","sequence_id":7,"answer":["sad"],"response_time":1,"x":1}"#.into(),
            "unknown field `x`",
        ),
    ];
    let (mut b, c) = waiting();
    for (i, (text, reason)) in cases.iter().enumerate() {
        let out = b.ws_text(c, text, at(100 * i as u64));
        assert!(published(&out).1.is_empty(), "{text}");
        let got = reasons(&out, c);
        assert!(got.len() == 1 && got[0].contains(reason), "{text}: {got:?}");
    }
    let out = b.ws_text(c, &answer(7, &["sad", "sad", "disgusted"]), at(2000));
    assert_eq!(
        published(&out).1.len(),
        1,
        "the session goes on: a good answer still works"
    );
}

#[test]
fn an_emotion_the_task_does_not_offer_is_refused() {
    let mut b = Bridge::new(params(), at(0));
    let c = child(&mut b);
    let t = TabletTask {
        choices: vec!["happy".into(), "sad".into()],
        ..task("s1", 1, 3)
    };
    b.dds(DdsInput::Task(t), at(0));
    let out = b.ws_text(c, &answer(1, &["happy", "angry", "sad"]), at(10));
    assert_eq!(
        reasons(&out, c),
        vec![r#"answer[1] = "angry" is not offered by this task"#.to_string()]
    );
}

#[test]
fn an_answer_sent_twice_is_published_once() {
    let (mut b, c) = waiting();
    let other = child(&mut b);
    let good = answer(7, &["happy", "happy", "sad"]);
    let out = b.ws_text(c, &good, at(100));
    assert_eq!(published(&out).1.len(), 1);
    assert_eq!(
        to(&out, other),
        vec![ServerMessage::NoTask {
            reason: "answered".into()
        }]
    );
    for id in [c, other] {
        let out = b.ws_text(id, &good, at(200));
        assert!(published(&out).1.is_empty());
        assert_eq!(
            reasons(&out, id),
            vec!["sequence 7 was already answered".to_string()]
        );
    }
}

#[test]
fn answers_need_an_open_task_an_unpaused_game_and_time_left() {
    let mut b = Bridge::new(params(), at(0));
    let c = child(&mut b);
    let out = b.ws_text(c, &answer(1, &["sad", "sad", "sad"]), at(0));
    assert_eq!(
        reasons(&out, c),
        vec!["no task is waiting for an answer".to_string()]
    );

    let (mut b, c) = waiting();
    b.dds(DdsInput::GameState(game(GameState::PAUSED, "s1")), at(100));
    let out = b.ws_text(c, &answer(7, &["sad", "sad", "sad"]), at(200));
    assert_eq!(reasons(&out, c), vec!["the game is paused".to_string()]);
    b.dds(
        DdsInput::GameState(game(GameState::WAITING_FOR_ANSWER, "s1")),
        at(300),
    );
    // 30 s timeout + 2 s grace from the task's arrival at 0.
    let out = b.ws_text(c, &answer(7, &["sad", "sad", "sad"]), at(32_001));
    assert!(reasons(&out, c)[0].starts_with("too late"), "{out:?}");
    let out = b.ws_text(c, &answer(7, &["sad", "sad", "sad"]), at(31_999));
    assert_eq!(published(&out).1.len(), 1);
}

#[test]
fn a_task_without_a_timeout_never_expires() {
    let mut b = Bridge::new(params(), at(0));
    let c = child(&mut b);
    b.dds(
        DdsInput::Task(TabletTask {
            timeout: 0.0,
            ..task("s1", 1, 3)
        }),
        at(0),
    );
    let out = b.ws_text(c, &answer(1, &["sad", "sad", "sad"]), at(10_000_000));
    assert_eq!(published(&out).1.len(), 1, "{out:?}");
}
