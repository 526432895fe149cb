//! The child answers as its user model says, once per task, and looks away while answering
//! (its face through the real classifier: tests/simulated_child_faces.rs).

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
    GameState {
        phase,
        session_id: "s".into(),
        sequence_index: index,
        level,
        feedback: 0,
        last_score: 1,
        ..Default::default()
    }
}

fn task(id: u32, length: u8) -> TabletTask {
    TabletTask {
        session_id: "s".into(),
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
