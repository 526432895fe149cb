//! Core tests of the game side: tasks opening and closing, late pages, per-session history.

use super::*;

#[test]
fn stopping_the_game_closes_the_task_and_stale_tasks_stay_closed() {
    let (mut b, c) = waiting();
    let out = b.dds(DdsInput::GameState(game(GameState::STOPPED, "s1")), at(100));
    assert!(to(&out, c).contains(&ServerMessage::NoTask {
        reason: "the game is stopped".into()
    }));
    // The transient-local topic re-delivers the last task, and an older one arrives late.
    for seq in [7, 6] {
        assert!(silent(&b.dds(DdsInput::Task(task("s1", seq, 3)), at(200))));
    }
    let out = b.ws_text(c, &answer(7, &["sad", "sad", "sad"]), at(300));
    assert_eq!(
        reasons(&out, c),
        vec!["no task is waiting for an answer".to_string()]
    );
    // A new session's task opens.
    let out = b.dds(DdsInput::Task(task("s2", 1, 5)), at(400));
    assert!(matches!(to(&out, c).as_slice(), [ServerMessage::Task(t)] if t.length == 5));
}

#[test]
fn a_bridge_started_after_the_session_ended_ignores_its_last_task() {
    let mut b = Bridge::new(params(), at(0));
    let c = child(&mut b);
    b.dds(DdsInput::GameState(game(GameState::FINISHED, "s1")), at(0));
    assert!(silent(&b.dds(DdsInput::Task(task("s1", 9, 3)), at(0))));
    let out = b.ws_text(c, &answer(9, &["sad", "sad", "sad"]), at(10));
    assert_eq!(
        reasons(&out, c),
        vec!["no task is waiting for an answer".to_string()]
    );
}

#[test]
fn a_game_state_of_another_session_closes_the_task() {
    let (mut b, c) = waiting();
    let out = b.dds(DdsInput::GameState(game(GameState::DECIDING, "s2")), at(10));
    assert!(
        to(&out, c)
            .iter()
            .any(|m| matches!(m, ServerMessage::NoTask { .. }))
    );
}

#[test]
fn a_page_that_connects_late_gets_the_open_task() {
    let (mut b, _) = waiting();
    let (late, out) = b.connect(Role::Child, at(10)).expect("room");
    let got = to(&out, late);
    assert!(matches!(got[0], ServerMessage::Game(ref g) if g.phase == "waiting_for_answer"));
    assert!(matches!(got[1], ServerMessage::Task(ref t) if t.sequence_id == 7));
}

#[test]
fn the_child_page_gets_no_user_id_and_a_therapist_page_nothing_before_login() {
    let mut b = Bridge::new(params(), at(0));
    let c = child(&mut b);
    let waiting_for_pin = b.connect(Role::Therapist, at(0)).expect("room").0;
    let t = therapist(&mut b);
    let g = GameState {
        user_id: "child-7".into(),
        ..game(GameState::DECIDING, "s1")
    };
    let out = b.dds(DdsInput::GameState(g), at(0));
    assert!(matches!(&to(&out, c)[..], [ServerMessage::Game(v)] if v.user_id.is_empty()));
    assert!(matches!(&to(&out, t)[..], [ServerMessage::Game(v)] if v.user_id == "child-7"));
    assert!(to(&out, waiting_for_pin).is_empty());
}

#[test]
fn a_page_that_logs_in_mid_session_gets_the_history_of_this_session_only() {
    let mut b = Bridge::new(
        TabletBridgeParams {
            engagement_history: 3,
            ..params()
        },
        at(0),
    );
    let d = |session: &str, step| Decision {
        session_id: session.into(),
        step,
        q_values: vec![0.1, 0.2, f64::NAN, 0.0, -1.0],
        ..Default::default()
    };
    b.dds(DdsInput::Decision(d("old", 1)), at(0));
    b.dds(DdsInput::Decision(d("s1", 1)), at(0));
    b.dds(DdsInput::Decision(d("s1", 2)), at(0));
    let r = SequenceResult {
        session_id: "s1".into(),
        sequence_index: 1,
        ..Default::default()
    };
    b.dds(DdsInput::Result(r), at(0));
    for i in 0..5 {
        let e = ExpectedEngagement {
            mean: i as f32 / 10.0,
            ..Default::default()
        };
        b.dds(DdsInput::Engagement(e), at(0));
    }
    let t = b.connect(Role::Therapist, at(0)).expect("room").0;
    let out = b.ws_text(t, &login(PIN), at(0));
    let got = to(&out, t);
    let steps: Vec<u8> = got
        .iter()
        .filter_map(|m| match m {
            ServerMessage::Decision(d) => Some(d.step),
            _ => None,
        })
        .collect();
    assert_eq!(steps, vec![1, 2]);
    assert_eq!(
        got.iter()
            .filter(|m| matches!(m, ServerMessage::Result(_)))
            .count(),
        1
    );
    let history = got.iter().find_map(|m| match m {
        ServerMessage::EngagementHistory { points } => Some(points.clone()),
        _ => None,
    });
    let means = history.map(|p| p.iter().map(|x| x.mean).collect::<Vec<_>>());
    assert_eq!(means, Some(vec![0.2, 0.3, 0.4]));
    // A NaN Q-value is encoded as null, not as invalid JSON.
    let decision = got.iter().find(|m| matches!(m, ServerMessage::Decision(_)));
    let json = serde_json::to_string(&decision).expect("encodes");
    assert!(json.contains("null"), "{json}");
}
