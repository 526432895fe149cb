//! The in-process bus's DDS semantics, on a virtual clock: late joiners and histories, a node
//! that leaves, validation, best effort, services and their timeouts, the waits for a match.

use super::*;
use crate::bus::CallError;
use qt_therapy_msgs::topics::{
    DECIDE_ACTION, GAME_STATE, HEARTBEAT, OPENFACE_FEATURES, SEQUENCE_RESULT, THERAPIST_COMMAND,
};
use qt_therapy_msgs::{
    BehaviourState, DecideActionRequest, DecideActionResponse, GameState, Heartbeat,
    OpenFaceFeatures, SequenceResult, TherapistCommand,
};

const T0: i64 = 1_800_000_000_000_000_000;

fn bus() -> InProcessBus {
    InProcessBus::new(Clock::starting_at(T0))
}

fn state(index: u8) -> GameState {
    GameState {
        session_id: "s".into(),
        sequence_index: index,
        ..Default::default()
    }
}

fn result(index: u8) -> SequenceResult {
    SequenceResult {
        session_id: "s".into(),
        sequence_index: index,
        sequences_planned: 10,
        level: 1,
        sequence: vec!["happy".into(); 3],
        answer: vec!["happy".into(); 3],
        outcome: 1,
        ..Default::default()
    }
}

fn command(id: u64) -> TherapistCommand {
    TherapistCommand {
        command: TherapistCommand::PAUSE,
        session_id: "s".into(),
        command_id: id,
        ..Default::default()
    }
}

/// What is waiting on `rx` now, without waiting.
fn waiting<M>(rx: &mut mpsc::Receiver<M>) -> Vec<M> {
    std::iter::from_fn(|| rx.try_recv().ok()).collect()
}

/// Lets every task run until all wait (virtual time does not move while one can run).
async fn settle() {
    for _ in 0..10 {
        tokio::task::yield_now().await;
    }
}

#[tokio::test(start_paused = true)]
async fn a_late_reader_gets_each_living_writers_kept_history_and_volatile_topics_none() {
    let bus = bus();
    let (mut game, _) = bus.join("game_manager").expect("joins");
    let states = game.publisher(GAME_STATE).expect("writer");
    let results = game.publisher(SEQUENCE_RESULT).expect("writer");
    let commands = game.publisher(THERAPIST_COMMAND).expect("writer");
    for i in 1..=3 {
        assert!(states.send(state(i)));
        assert!(results.send(result(i)));
        assert!(commands.send(command(u64::from(i))));
    }
    let (mut late, _) = bus.join("late").expect("joins");
    let mut s = late.subscribe(GAME_STATE, 16).expect("reader");
    let mut r = late.subscribe(SEQUENCE_RESULT, 16).expect("reader");
    let mut c = late.subscribe(THERAPIST_COMMAND, 16).expect("reader");
    settle().await;
    // State keeps the last one, Durable the last 100, Reliable (volatile) nothing.
    let got: Vec<u8> = waiting(&mut s).iter().map(|m| m.sequence_index).collect();
    assert_eq!(got, [3]);
    let got: Vec<u8> = waiting(&mut r).iter().map(|m| m.sequence_index).collect();
    assert_eq!(got, [1, 2, 3]);
    assert!(waiting(&mut c).is_empty());
    // Then what is new, in order.
    results.send(result(4));
    commands.send(command(9));
    settle().await;
    let got: Vec<u8> = waiting(&mut r).iter().map(|m| m.sequence_index).collect();
    assert_eq!(got, [4]);
    assert_eq!(waiting(&mut c)[0].command_id, 9);

    // A writer that leaves takes its history with it, as a process that dies does.
    drop(results);
    let (mut later, _) = bus.join("later").expect("joins");
    let mut r2 = later.subscribe(SEQUENCE_RESULT, 16).expect("reader");
    settle().await;
    assert!(waiting(&mut r2).is_empty());
}

#[tokio::test(start_paused = true)]
async fn invalid_messages_are_refused_counted_and_the_valid_ones_go_on() {
    let bus = bus();
    let (mut a, _) = bus.join("a").expect("joins");
    let (mut b, _) = bus.join("b").expect("joins");
    let out = a.publisher(GAME_STATE).expect("writer");
    let mut rx = b.subscribe(GAME_STATE, 16).expect("reader");
    let mut bad = state(1);
    bad.level = 4;
    out.send(state(1));
    out.send(bad.clone());
    out.send(bad);
    out.send(state(2));
    settle().await;
    let got: Vec<u8> = waiting(&mut rx).iter().map(|m| m.sequence_index).collect();
    assert_eq!(got, [1, 2]);
    assert_eq!(b.drops().total(GAME_STATE.name), 2);
    assert_eq!(a.drops().total(GAME_STATE.name), 0);
}

#[tokio::test(start_paused = true)]
async fn a_best_effort_reader_that_falls_behind_keeps_the_newest_ten() {
    let bus = bus();
    let (mut camera, _) = bus.join("camera").expect("joins");
    let (mut classifier, _) = bus.join("classifier").expect("joins");
    let frames = camera.publisher(OPENFACE_FEATURES).expect("writer");
    // A channel of one, and 20 frames at once before the reader takes any.
    let mut rx = classifier.subscribe(OPENFACE_FEATURES, 1).expect("reader");
    for i in 0..20 {
        frames.send(OpenFaceFeatures {
            face_id: format!("{i}"),
            features: vec![0.0; usize::from(OpenFaceFeatures::FEATURE_COUNT)],
            ..Default::default()
        });
    }
    let mut got = Vec::new();
    for _ in 0..20 {
        settle().await;
        got.extend(waiting(&mut rx).into_iter().map(|f| f.face_id));
    }
    // The reader's history kept the newest 10.
    assert_eq!(got, (10..20).map(|i| i.to_string()).collect::<Vec<_>>());
    assert_eq!(bus.replaced_samples(), 10);
}

fn decide(step: u8, after: u8) -> DecideActionRequest {
    DecideActionRequest {
        session_id: "s".into(),
        step,
        after_sequence: after,
        state: if step == 1 {
            BehaviourState::default()
        } else {
            BehaviourState {
                level: 1,
                feedback: 0,
                previous_score: 1,
            }
        },
        ..Default::default()
    }
}

#[tokio::test(start_paused = true)]
async fn a_service_answers_one_call_at_a_time_refuses_invalid_requests_and_times_out_alone() {
    let bus = bus();
    let (mut policy, _) = bus.join("behaviour_policy").expect("joins");
    let (mut game, _) = bus.join("game_manager").expect("joins");
    let client = game.client(DECIDE_ACTION).expect("client");
    let wait = Duration::from_secs(2);

    // No server: the call runs to its timeout, and the wait for one says none came.
    let t = tokio::time::Instant::now();
    let e = client
        .call(decide(1, 0), wait)
        .await
        .expect_err("no server");
    assert!(matches!(e, CallError::Timeout { .. }), "{e}");
    assert_eq!(t.elapsed(), wait);
    assert!(!game.wait_for_service(&client, wait).await);

    let mut calls = policy
        .serve(DECIDE_ACTION, |e| DecideActionResponse {
            ok: false,
            error: e.to_string(),
            ..Default::default()
        })
        .expect("server");
    assert!(game.wait_for_service(&client, wait).await);
    let serving = tokio::spawn(async move {
        let mut steps = Vec::new();
        while let Some(call) = calls.recv().await {
            steps.push(call.request.step);
            // Slow: a second call meanwhile waits its turn.
            tokio::time::sleep(Duration::from_millis(300)).await;
            let step = call.request.step;
            call.respond(DecideActionResponse {
                ok: true,
                error: format!("decided step {step}"),
                ..Default::default()
            });
        }
        steps
    });
    let (c1, c2) = (client.clone(), client.clone());
    let t = tokio::time::Instant::now();
    let (a, b) = tokio::join!(c1.call(decide(1, 0), wait), c2.call(decide(2, 1), wait));
    assert_eq!(a.expect("answered").error, "decided step 1");
    assert_eq!(b.expect("answered").error, "decided step 2");
    assert_eq!(
        t.elapsed(),
        Duration::from_millis(600),
        "one after the other"
    );
    // An invalid request is answered by the shell, never reaching the node.
    let refused = client.call(decide(1, 3), wait).await.expect("answered");
    assert!(
        !refused.ok
            && refused
                .error
                .contains("after_sequence 3 is not before step 1")
    );
    assert_eq!(policy.drops().total(DECIDE_ACTION.name), 1);

    // A server that goes before it answers: the call times out, as over DDS.
    policy.stop().await;
    let steps = serving.await.expect("the serving task");
    assert_eq!(steps, [1, 2]);
    let e = client.call(decide(1, 0), wait).await.expect_err("gone");
    assert!(matches!(e, CallError::Timeout { .. }), "{e}");
}

#[tokio::test(start_paused = true)]
async fn a_node_beats_at_10_hz_under_its_instance_and_a_killed_one_leaves_at_once() {
    let bus = bus();
    let (mut watcher, _) = bus.join("watcher").expect("joins");
    let mut beats = watcher.subscribe(HEARTBEAT, 256).expect("reader");
    let (mut node, _) = bus.join("user_model").expect("joins");
    let pid = node.process_id();
    assert_ne!(pid, watcher.process_id());
    let _reader = node.subscribe(GAME_STATE, 4).expect("reader");
    assert_eq!(bus.readers(GAME_STATE.name), 1);
    tokio::time::sleep(Duration::from_millis(1050)).await;
    let theirs: Vec<Heartbeat> = waiting(&mut beats)
        .into_iter()
        .filter(|h| h.node_name == "user_model")
        .collect();
    assert_eq!(theirs.len(), 11, "at 0, 100, ..., 1000 ms");
    assert!(theirs.iter().all(|h| h.pid == pid));
    assert_eq!(
        theirs[10].header.stamp.to_nanos() - theirs[0].header.stamp.to_nanos(),
        1_000_000_000
    );
    // Killed: dropped without a stop. Its reader and heartbeat go at once.
    drop(node);
    settle().await;
    assert_eq!(bus.readers(GAME_STATE.name), 0);
    waiting(&mut beats);
    tokio::time::sleep(Duration::from_secs(1)).await;
    assert!(
        waiting(&mut beats)
            .iter()
            .all(|h| h.node_name != "user_model")
    );
}

#[tokio::test(start_paused = true)]
async fn waits_for_a_subscriber_end_when_one_joins_or_at_the_timeout() {
    let bus = bus();
    let (mut console, _) = bus.join("therapist_console").expect("joins");
    let commands = console.publisher(THERAPIST_COMMAND).expect("writer");
    let t = tokio::time::Instant::now();
    assert!(
        !commands
            .wait_for_subscribers(&console, Duration::from_secs(3))
            .await
    );
    assert_eq!(t.elapsed(), Duration::from_secs(3));
    let joining = bus.clone();
    tokio::spawn(async move {
        tokio::time::sleep(Duration::from_secs(1)).await;
        let (mut game, _) = joining.join("game_manager").expect("joins");
        let _rx = game.subscribe(THERAPIST_COMMAND, 4).expect("reader");
        std::future::pending::<()>().await;
    });
    let t = tokio::time::Instant::now();
    assert!(
        commands
            .wait_for_subscribers(&console, Duration::from_secs(3))
            .await
    );
    assert_eq!(t.elapsed(), Duration::from_secs(1));
}

#[tokio::test(start_paused = true)]
async fn a_tap_sees_every_message_unvalidated_with_its_writer_and_times() {
    let bus = bus();
    let (mut recorder, _) = bus.join("bag_recorder").expect("joins");
    let (mut game, _) = bus.join("game_manager").expect("joins");
    let (tx, mut rx) = mpsc::channel(16);
    let _tap = recorder
        .tap(HEARTBEAT, tx, |t| {
            Some((t.message.node_name, t.from_this_participant))
        })
        .expect("tap");
    let (tx, mut states) = mpsc::channel(16);
    let _tap2 = recorder
        .tap(GAME_STATE, tx, |t| {
            Some((t.message.level, t.sequence_number, t.source_timestamp_ns))
        })
        .expect("tap");
    let out = game.publisher(GAME_STATE).expect("writer");
    tokio::time::sleep(Duration::from_millis(500)).await;
    let mut bad = state(1);
    bad.level = 9;
    out.send(bad);
    settle().await;
    let beats = waiting(&mut rx);
    assert!(beats.contains(&("bag_recorder".to_string(), true)));
    assert!(beats.contains(&("game_manager".to_string(), false)));
    assert_eq!(waiting(&mut states), [(9, 1, Some(T0 + 500_000_000))]);
}

#[tokio::test(start_paused = true)]
async fn one_name_one_type_and_one_qos() {
    let bus = bus();
    let (mut a, _) = bus.join("a").expect("joins");
    a.publisher(GAME_STATE).expect("writer");
    let other =
        Topic::<SequenceResult>::new(GAME_STATE.name, qt_therapy_msgs::topics::QosKind::State);
    let e = a.publisher(other).err().expect("another type").to_string();
    assert!(e.contains("carries qt_therapy_msgs/msg/GameState"), "{e}");
    let volatile =
        Topic::<GameState>::new(GAME_STATE.name, qt_therapy_msgs::topics::QosKind::Reliable);
    let e = a
        .subscribe(volatile, 1)
        .expect_err("another QoS")
        .to_string();
    assert!(e.contains("transient-local"), "{e}");
}

#[tokio::test(start_paused = true)]
async fn a_delayed_reader_gets_what_it_takes_later_in_order_and_the_others_at_once() {
    let bus = bus();
    bus.delay(
        SEQUENCE_RESULT.name,
        "behaviour_policy",
        Duration::from_millis(1500),
    );
    let (mut game, _) = bus.join("game_manager").expect("joins");
    let (mut policy, _) = bus.join("behaviour_policy").expect("joins");
    let (mut recorder, _) = bus.join("bag_recorder").expect("joins");
    let out = game.publisher(SEQUENCE_RESULT).expect("writer");
    let mut slow = policy.subscribe(SEQUENCE_RESULT, 16).expect("reader");
    let mut fast = recorder.subscribe(SEQUENCE_RESULT, 16).expect("reader");
    out.send(result(1));
    tokio::time::sleep(Duration::from_millis(500)).await;
    out.send(result(2));
    settle().await;
    assert_eq!(waiting(&mut fast).len(), 2);
    assert!(waiting(&mut slow).is_empty());
    tokio::time::sleep(Duration::from_millis(999)).await;
    settle().await;
    assert!(waiting(&mut slow).is_empty(), "not before 1.5 s");
    tokio::time::sleep(Duration::from_millis(1)).await;
    settle().await;
    let got: Vec<u8> = waiting(&mut slow)
        .iter()
        .map(|m| m.sequence_index)
        .collect();
    assert_eq!(got, [1], "1.5 s after the first was sent");
    tokio::time::sleep(Duration::from_millis(500)).await;
    settle().await;
    let got: Vec<u8> = waiting(&mut slow)
        .iter()
        .map(|m| m.sequence_index)
        .collect();
    assert_eq!(got, [2]);
}

#[tokio::test(start_paused = true)]
async fn a_node_stops_when_asked_and_not_when_no_one_can_ask_any_more() {
    let bus = bus();
    let (asked, stop) = bus.join("asked").expect("joins");
    let (alone, unheld) = bus.join("alone").expect("joins");
    drop(unheld);
    let asked = tokio::spawn(asked.shutdown_signal());
    let alone = tokio::spawn(alone.shutdown_signal());
    tokio::time::sleep(Duration::from_secs(60)).await;
    assert!(!asked.is_finished() && !alone.is_finished());
    stop.stop();
    asked.await.expect("stopped when asked");
    tokio::time::sleep(Duration::from_secs(60)).await;
    assert!(!alone.is_finished(), "a dropped NodeStop is no stop");
}
