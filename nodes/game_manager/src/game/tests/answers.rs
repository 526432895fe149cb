//! Bad tablet answers: for another task, with unknown emotions, of the wrong length, for
//! another session, sent twice, with no task waiting, after the timeout. Each is rejected
//! with a reason and the session goes on.

use super::harness::*;
use crate::params::GameManagerParams;
use crate::protocol::{Input, Output};
use qt_therapy_msgs::TabletAnswer;

fn answer(session: &str, sequence_id: u32, words: &[&str]) -> Input {
    Input::Answer(TabletAnswer {
        session_id: session.into(),
        sequence_id,
        answer: words.iter().map(|w| w.to_string()).collect(),
        response_time: 2.0,
        ..Default::default()
    })
}

fn rejected(h: &mut Harness, input: Input, reason: &str) {
    let out = h.feed(input);
    assert!(
        out.iter()
            .any(|o| matches!(o, Output::Log { message, .. } if message.contains(reason))),
        "no warning with {reason:?}: {out:?}"
    );
    assert!(h.last_state().status.contains(reason));
    assert!(!out.iter().any(|o| matches!(o, Output::Result(_))));
}

#[test]
fn bad_answers_are_rejected_with_a_reason_and_the_session_goes_on() {
    let child = scripted_child(vec![(1, ChildReply::Nothing), (2, ChildReply::Nothing)]);
    let mut h = Harness::new(GameManagerParams::default(), rule_policy(), child);
    rejected(&mut h, answer("s", 1, &["happy"]), "no session is running");
    h.start("s");
    h.run_until(T0 + 15 * S);
    let said = h.heard();
    assert_eq!(said.len(), 3);
    let words: Vec<&str> = said.iter().map(String::as_str).collect();
    rejected(
        &mut h,
        answer("s", 99, &words),
        "for another task: waiting for task 1",
    );
    rejected(
        &mut h,
        answer("s", 1, &["happy", "joyful", "sad"]),
        "answer[1] = \"joyful\" is not",
    );
    rejected(
        &mut h,
        answer("s", 1, &words[..2]),
        "answer has 2 emotions, the task asked for 3",
    );
    rejected(&mut h, answer("other", 1, &words), "wrong session");
    let mut nan = answer("s", 1, &words);
    if let Input::Answer(a) = &mut nan {
        a.response_time = f32::NAN;
    }
    rejected(&mut h, nan, "response_time");
    h.feed(answer("s", 1, &words));
    rejected(
        &mut h,
        answer("s", 1, &words),
        "duplicate: this task was already answered",
    );
    h.run_until(T0 + 16 * S);
    let r = &h.results()[0];
    assert_eq!((r.outcome, r.answer.clone()), (1, said.clone()));
    assert_eq!(h.records()[0].rejected_answers, 5);
    rejected(
        &mut h,
        answer("s", 2, &words),
        "no task is waiting for an answer",
    );

    // Task 2 times out; its answer afterwards is refused.
    h.run_until_true(600.0, |h| h.results().len() == 2);
    assert!(h.results()[1].timed_out);
    rejected(
        &mut h,
        answer("s", 2, &["happy"; 5]),
        "came after the task had timed out",
    );
    h.run(3600.0);
    assert_eq!(h.results().len(), 10);
    assert_eq!(h.summaries()[0].rejected_answers, 8);
}
