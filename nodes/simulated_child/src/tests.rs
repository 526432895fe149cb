//! The child answers as its user model says, once per task, and looks away while answering
//! (its face through the real classifier: tests/simulated_child_faces.rs). Its answers and its
//! frames do not depend on how many frames it put out before them.

use super::*;
use sequence_game::Prediction;

fn table(p: f64, e_success: f64, e_failure: f64) -> UserModelTable {
    UserModelTable::tabulate(
        0,
        |_| Prediction { mean: p, std: 0.0 },
        |_, o| Prediction {
            mean: if o == Outcome::Success {
                e_success
            } else {
                e_failure
            },
            std: 0.0,
        },
    )
}

fn state(phase: u8, index: u8, level: u8) -> GameState {
    state_in("s", phase, index, level)
}

fn state_in(session: &str, phase: u8, index: u8, level: u8) -> GameState {
    GameState {
        phase,
        session_id: session.into(),
        sequence_index: index,
        level,
        feedback: 0,
        last_score: 1,
        ..Default::default()
    }
}

fn task(id: u32, length: u8) -> TabletTask {
    task_in("s", id, length)
}

fn task_in(session: &str, id: u32, length: u8) -> TabletTask {
    TabletTask {
        session_id: session.into(),
        sequence_id: id,
        sequence_index: id as u8,
        length,
        timeout: 60.0,
        ..Default::default()
    }
}

/// Presents one sequence and collects the child's answer.
fn play(child: &mut SimulatedChild, index: u8, words: &[&str], now: &mut i64) -> TabletAnswer {
    child.on_game_state(&state(
        GameState::SAYING_SEQUENCE,
        index,
        ((words.len() - 1) / 2) as u8,
    ));
    for w in words {
        child.on_robot_emotion(&format!("QT/{w}"));
    }
    child.on_game_state(&state(
        GameState::WAITING_FOR_ANSWER,
        index,
        ((words.len() - 1) / 2) as u8,
    ));
    child.on_task(&task(u32::from(index), words.len() as u8), *now);
    loop {
        *now += 100_000_000;
        for out in child.poll(*now) {
            if let ChildOutput::Answer(a) = out {
                return a;
            }
        }
        assert!(*now < 1_000_000_000_000, "no answer");
    }
}

#[test]
fn answers_right_as_often_as_the_user_model_predicts() {
    let mut child = SimulatedChild::new(
        ChildParams {
            time_scale: 0.01,
            ..Default::default()
        },
        table(0.8, 0.5, -0.5),
    )
    .expect("child");
    let words = ["happy", "sad", "angry", "sad", "disgusted"];
    let mut now = 0;
    let n = 250u32;
    let right = (1..=n)
        .filter(|&i| {
            let a = play(&mut child, i as u8, &words, &mut now);
            assert_eq!(a.answer.len(), 5);
            a.answer == words
        })
        .count();
    let rate = right as f64 / f64::from(n);
    // Binomial(250, 0.8): std 0.025; 4 std either side.
    assert!((rate - 0.8).abs() < 0.1, "success rate {rate}");
}

#[test]
fn answers_each_task_once_after_a_plausible_delay() {
    let mut child =
        SimulatedChild::new(ChildParams::default(), table(1.0, 0.0, 0.0)).expect("child");
    child.on_game_state(&state(GameState::SAYING_SEQUENCE, 1, 1));
    for w in ["happy", "sad", "angry"] {
        child.on_robot_emotion(&format!("QT/{w}"));
    }
    child.on_task(&task(1, 3), 0);
    child.on_task(&task(1, 3), 0); // transient-local redelivery
    let mut answers = Vec::new();
    let mut t = 0;
    while t < 60_000_000_000 {
        t += 50_000_000;
        answers.extend(child.poll(t).into_iter().filter_map(|o| match o {
            ChildOutput::Answer(a) => Some(a),
            ChildOutput::Frame(_) => None,
        }));
    }
    assert_eq!(answers.len(), 1);
    let a = &answers[0];
    assert_eq!(a.answer, ["happy", "sad", "angry"]);
    assert!(
        (1.0..43.0).contains(&a.response_time),
        "{}",
        a.response_time
    );
}

#[test]
fn looks_down_while_answering() {
    let mut child =
        SimulatedChild::new(ChildParams::default(), table(0.5, 0.7, 0.7)).expect("child");
    child.on_game_state(&state(GameState::SAYING_SEQUENCE, 1, 1));
    assert_eq!(child.target_engagement(), 0.7);
    child.on_game_state(&state(GameState::WAITING_FOR_ANSWER, 1, 1));
    assert_eq!(child.target_engagement(), -0.6);
}

#[test]
fn bad_parameters_are_named() {
    let e = SimulatedChild::new(
        ChildParams {
            fps: 0.0,
            ..Default::default()
        },
        table(0.5, 0.0, 0.0),
    )
    .err();
    assert!(e.is_some_and(|e| e.to_string().contains("fps")));
    let e = SimulatedChild::new(
        ChildParams {
            answer_time_mean_s: vec![1.0],
            ..Default::default()
        },
        table(0.5, 0.0, 0.0),
    )
    .err();
    assert!(e.is_some_and(|e| e.to_string().contains("answer_time_mean_s")));
}

/// Plays sequence `index` of `session` (5 words, level 2) and returns the answer; before it,
/// `frames_before` camera frames at 30 fps, and the time goes on in `step_ns` polls until the
/// answer is out.
fn answer_after_frames(
    child: &mut SimulatedChild,
    session: &str,
    index: u8,
    frames_before: u32,
    step_ns: i64,
    now: &mut i64,
) -> TabletAnswer {
    for _ in 0..frames_before {
        *now += 33_333_334;
        child.poll(*now);
    }
    let words = ["happy", "sad", "angry", "sad", "disgusted"];
    child.on_game_state(&state_in(session, GameState::SAYING_SEQUENCE, index, 2));
    for w in words {
        child.on_robot_emotion(&format!("QT/{w}"));
    }
    child.on_game_state(&state_in(session, GameState::WAITING_FOR_ANSWER, index, 2));
    child.on_task(&task_in(session, u32::from(index), 5), *now);
    let started = *now;
    loop {
        *now += step_ns;
        if let Some(a) = child.poll(*now).into_iter().find_map(|o| match o {
            ChildOutput::Answer(a) => Some(a),
            ChildOutput::Frame(_) => None,
        }) {
            return a;
        }
        assert!(*now - started < 1_000_000_000_000, "no answer");
    }
}

fn fifty_fifty_child(seed: i64) -> SimulatedChild {
    SimulatedChild::new(
        ChildParams {
            seed,
            time_scale: 0.05,
            ..Default::default()
        },
        table(0.5, 0.3, -0.3),
    )
    .expect("child")
}

/// What a sequence's answer is, apart from when it was sent.
fn answered(a: &TabletAnswer) -> (u32, Vec<String>, f32) {
    (a.sequence_id, a.answer.clone(), a.response_time)
}

#[test]
fn the_answer_does_not_depend_on_the_frames_drawn_before_it() {
    // One child puts out (almost) no frames: polled once, a long way on, per answer; the other
    // 1,000 frames before each sequence and a frame every 10 ms while it answers.
    let (mut idle, mut busy) = (fifty_fifty_child(7), fifty_fifty_child(7));
    let (mut t_idle, mut t_busy) = (0, 0);
    let mut wrong = 0;
    for index in 1..=40u8 {
        let a = answer_after_frames(&mut idle, "s", index, 0, 1_000_000_000_000, &mut t_idle);
        let b = answer_after_frames(&mut busy, "s", index, 1_000, 10_000_000, &mut t_busy);
        assert_eq!(answered(&a), answered(&b), "sequence {index}");
        wrong += usize::from(a.answer != ["happy", "sad", "angry", "sad", "disgusted"]);
    }
    // Both right and wrong answers were compared (P(success) 0.5).
    assert!((5..=35).contains(&wrong), "{wrong} of 40 wrong");
}

#[test]
fn each_session_and_sequence_has_its_own_answer() {
    // P(success) 0.5: independent draws agree on right or wrong about half the time, so
    // another session, or another seed, plays other outcomes; the same seed and session the
    // same ones.
    let outcomes = |seed: i64, session: &str| -> Vec<bool> {
        let mut child = fifty_fifty_child(seed);
        let mut now = 0;
        (1..=200u8)
            .map(|i| {
                let a = answer_after_frames(&mut child, session, i, 0, 100_000_000, &mut now);
                a.answer == ["happy", "sad", "angry", "sad", "disgusted"]
            })
            .collect()
    };
    let agreement = |a: &[bool], b: &[bool]| {
        a.iter().zip(b).filter(|(x, y)| x == y).count() as f64 / a.len() as f64
    };
    let base = outcomes(7, "session-a");
    assert_eq!(base, outcomes(7, "session-a"));
    let right = base.iter().filter(|r| **r).count() as f64 / 200.0;
    // Binomial(200, 0.5): std 0.035; 4 std either side.
    assert!((right - 0.5).abs() < 0.15, "right {right}");
    for (seed, session) in [(7, "session-b"), (8, "session-a")] {
        let agree = agreement(&base, &outcomes(seed, session));
        assert!(
            (agree - 0.5).abs() < 0.15,
            "seed {seed} {session}: agrees with seed 7 session-a on {agree}"
        );
    }
}

#[test]
fn a_frame_is_the_same_whichever_frames_were_put_out_before_it() {
    // One camera polled every 10 ms; another stalled now and then: 0.5 s (it catches up), 1.5
    // s and 5 s (it skips what is older than a second). Every frame the stalled one puts out is
    // the one the steady one put out at that time, face, gaze and lost face alike.
    let child = || {
        let mut c =
            SimulatedChild::new(ChildParams::default(), table(0.5, 0.2, 0.2)).expect("child");
        c.on_game_state(&state(GameState::SAYING_SEQUENCE, 1, 2));
        c
    };
    let frames = |c: &mut SimulatedChild, t: i64, into: &mut Vec<OpenFaceFeatures>| {
        into.extend(c.poll(t).into_iter().filter_map(|o| match o {
            ChildOutput::Frame(f) => Some(f),
            ChildOutput::Answer(_) => None,
        }))
    };
    let (mut steady, mut stalled) = (child(), child());
    let (mut all, mut some) = (Vec::new(), Vec::new());
    let ms = 1_000_000i64;
    let mut t = 0;
    while t <= 60_000 * ms {
        frames(&mut steady, t, &mut all);
        t += 10 * ms;
    }
    let mut t = 0;
    let mut step = 0u32;
    while t <= 60_000 * ms {
        frames(&mut stalled, t, &mut some);
        step += 1;
        t += match step % 300 {
            100 => 500 * ms,
            200 => 1_500 * ms,
            0 => 5_000 * ms,
            _ => 10 * ms,
        };
    }
    let by_stamp: std::collections::BTreeMap<i64, &OpenFaceFeatures> =
        all.iter().map(|f| (f.header.stamp.to_nanos(), f)).collect();
    assert!(
        some.len() + 150 < all.len(),
        "{} of {} frames",
        some.len(),
        all.len()
    );
    for f in &some {
        assert_eq!(
            Some(&f),
            by_stamp.get(&f.header.stamp.to_nanos()),
            "frame at {}",
            f.header.stamp.to_nanos()
        );
    }
    // Both kinds of face and lost faces among them.
    let engaged = |f: &&OpenFaceFeatures| {
        f.success && steady.engaged_faces.iter().any(|e| e[..] == f.features[..])
    };
    let looking = some.iter().filter(engaged).count();
    let lost = some.iter().filter(|f| !f.success).count();
    let away = some.len() - looking - lost;
    assert!(
        looking > 100 && away > 100 && lost > 5,
        "looking {looking}, away {away}, lost {lost}"
    );
}

#[test]
fn a_face_before_its_game_state_or_a_task_before_its_sequence_still_counts() {
    // DDS orders nothing across topics: the first face may come before the GameState that
    // announces the words, and the task before any GameState of its sequence (GameState keeps
    // its last sample only). The child (always right here) still answers the words, once it
    // knows the sequence's state.
    let mut child =
        SimulatedChild::new(ChildParams::default(), table(1.0, 0.0, 0.0)).expect("child");
    child.on_robot_emotion("QT/happy");
    child.on_game_state(&state(GameState::SAYING_SEQUENCE, 1, 1));
    for w in ["sad", "angry"] {
        child.on_robot_emotion(&format!("QT/{w}"));
    }
    child.on_task(&task(1, 3), 0);
    let answers = |child: &mut SimulatedChild, from: i64| -> Vec<TabletAnswer> {
        (1..=1200)
            .flat_map(|k| child.poll(from + k * 50_000_000))
            .filter_map(|o| match o {
                ChildOutput::Answer(a) => Some(a),
                ChildOutput::Frame(_) => None,
            })
            .collect()
    };
    let first = answers(&mut child, 0);
    assert_eq!(first.len(), 1);
    assert_eq!(first[0].answer, ["happy", "sad", "angry"]);

    // Sequence 2's task before any state of sequence 2: held, not answered from sequence 1's
    // plan; the words came (the feedback's face before them).
    for w in ["happy", "disgusted", "disgusted", "sad"] {
        child.on_robot_emotion(&format!("QT/{w}"));
    }
    child.on_task(&task(2, 3), 60_000_000_000);
    assert!(answers(&mut child, 60_000_000_000).is_empty());
    // Held, it asks for no wake-up in the past: the next frame is what is due.
    assert!(
        child.next_wakeup().is_some_and(|t| t > 120_000_000_000),
        "{:?}",
        child.next_wakeup()
    );
    child.on_game_state(&state(GameState::WAITING_FOR_ANSWER, 2, 1));
    let second = answers(&mut child, 120_000_000_000);
    assert_eq!(second.len(), 1);
    assert_eq!(second[0].answer, ["disgusted", "disgusted", "sad"]);
}
