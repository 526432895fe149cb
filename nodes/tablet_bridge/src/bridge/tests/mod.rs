//! Unit tests of the core: what a tablet may and may not do, fed messages and a test clock.
//! Shared helpers and the transport-level guards are here; the pages' and the game's tests
//! are in the submodules.

use super::*;
use qt_therapy_msgs::{
    Decision, ExpectedEngagement, SequenceResult, TabletAnswer, TabletTask, TherapistCommand,
};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::json;

mod child;
mod children;
mod game;
mod proposal;
mod therapist;
mod watch;

const PIN: &str = "2468";
const WALL0: i64 = 1_700_000_000_000_000_000;

/// Nothing for a page or DDS: at most lines for the log.
fn silent(out: &[Output]) -> bool {
    out.iter().all(|o| matches!(o, Output::Log(..)))
}

/// The log lines of `out`.
fn logged(out: &[Output]) -> Vec<(tracing::Level, &str)> {
    out.iter()
        .filter_map(|o| match o {
            Output::Log(level, line) => Some((*level, line.as_str())),
            _ => None,
        })
        .collect()
}

fn params() -> TabletBridgeParams {
    TabletBridgeParams {
        pin: PIN.into(),
        ..Default::default()
    }
}

fn at(ms: u64) -> Now {
    Now {
        monotonic: Duration::from_millis(ms),
        wall_nanos: WALL0 + ms as i64 * 1_000_000,
    }
}

/// What the core sent to page `id`.
fn to(out: &[Output], id: ClientId) -> Vec<ServerMessage> {
    out.iter()
        .filter_map(|o| match o {
            Output::Send(to, m) if *to == id => Some(m.clone()),
            _ => None,
        })
        .collect()
}

/// The reasons page `id` was given for refusals.
fn reasons(out: &[Output], id: ClientId) -> Vec<String> {
    to(out, id)
        .into_iter()
        .filter_map(|m| match m {
            ServerMessage::Rejected { reason } => Some(reason),
            _ => None,
        })
        .collect()
}

fn published(out: &[Output]) -> (Vec<TherapistCommand>, Vec<TabletAnswer>) {
    let commands = out.iter().filter_map(|o| match o {
        Output::Command(c) => Some(c.clone()),
        _ => None,
    });
    let answers = out.iter().filter_map(|o| match o {
        Output::Answer(a) => Some(a.clone()),
        _ => None,
    });
    (commands.collect(), answers.collect())
}

fn task(session: &str, sequence_id: u32, length: u8) -> TabletTask {
    TabletTask {
        session_id: session.into(),
        sequence_id,
        sequence_index: 1,
        length,
        choices: ["happy", "disgusted", "sad", "angry"]
            .map(String::from)
            .to_vec(),
        timeout: 30.0,
        ..Default::default()
    }
}

fn game(phase: u8, session: &str) -> GameState {
    GameState {
        phase,
        session_id: session.into(),
        ..Default::default()
    }
}

fn answer(sequence_id: u32, words: &[&str]) -> String {
    json!({"type": "answer", "sequence_id": sequence_id, "answer": words, "response_time": 2.5})
        .to_string()
}

fn cmd(pin: &str, command: &str, extra: serde_json::Value) -> String {
    let mut v = json!({"type": "command", "pin": pin, "command": command});
    if let (Some(o), serde_json::Value::Object(e)) = (v.as_object_mut(), extra) {
        o.extend(e);
    }
    v.to_string()
}

fn login(pin: &str) -> String {
    json!({"type": "login", "pin": pin}).to_string()
}

fn child(b: &mut Bridge) -> ClientId {
    b.connect(Role::Child, at(0)).expect("room").0
}

/// A therapist page that has logged in.
fn therapist(b: &mut Bridge) -> ClientId {
    let id = b.connect(Role::Therapist, at(0)).expect("room").0;
    let out = b.ws_text(id, &login(PIN), at(0));
    assert!(to(&out, id).contains(&ServerMessage::LoggedIn));
    id
}

/// A bridge with a session waiting for the answer to a 3-emotion task (sequence 7).
fn waiting() -> (Bridge, ClientId) {
    let mut b = Bridge::new(params(), at(0));
    let c = child(&mut b);
    b.dds(
        DdsInput::GameState(game(GameState::WAITING_FOR_ANSWER, "s1")),
        at(0),
    );
    let out = b.dds(DdsInput::Task(task("s1", 7, 3)), at(0));
    assert!(matches!(to(&out, c).as_slice(), [ServerMessage::Task(t)] if t.sequence_id == 7));
    (b, c)
}

#[test]
fn a_flood_is_dropped_with_one_notice_a_second_then_closed_but_an_emergency_stop_gets_through() {
    let p = TabletBridgeParams {
        ws_burst: 3,
        ws_messages_per_second: 1.0,
        ws_max_dropped_before_close: 50,
        ..params()
    };
    let mut b = Bridge::new(p, at(0));
    let t = therapist(&mut b);
    let junk = r#"{"type":"nonsense"}"#;
    let (mut notices, mut rejections) = (0, 0);
    for i in 0..40 {
        let out = b.ws_text(t, junk, at(i * 10));
        for r in reasons(&out, t) {
            if r.starts_with("too many messages") {
                notices += 1
            } else {
                rejections += 1
            }
        }
        assert!(published(&out).0.is_empty());
    }
    // The login used one token: two junk messages get a schema reason, 38 are dropped with
    // one notice (they all came within one second).
    assert_eq!((rejections, notices), (2, 1));
    let out = b.ws_text(t, &cmd(PIN, "emergency_stop", json!({})), at(400));
    assert_eq!(published(&out).0.len(), 1, "{out:?}");
    assert_eq!(
        published(&out).0[0].command,
        TherapistCommand::EMERGENCY_STOP
    );
    let out = b.ws_text(t, &cmd(PIN, "emergency_stop", json!({})), at(450));
    assert!(
        published(&out).0.is_empty(),
        "a repeat within 500 ms is acknowledged, not re-sent"
    );
    assert!(
        matches!(&to(&out, t)[..], [ServerMessage::Accepted { .. }]),
        "{out:?}"
    );
    let mut closed = false;
    for i in 0..20 {
        let out = b.ws_text(t, junk, at(500 + i));
        closed |= out
            .iter()
            .any(|o| matches!(o, Output::Close(id, _) if *id == t));
    }
    assert!(closed, "closed after 50 drops in a row");
    assert!(
        b.ws_text(t, junk, at(600)).is_empty(),
        "a closed page is gone"
    );
}

#[test]
fn the_rate_limit_refills_and_a_good_message_resets_the_drop_count() {
    let p = TabletBridgeParams {
        ws_burst: 2,
        ws_messages_per_second: 2.0,
        ws_max_dropped_before_close: 3,
        ..params()
    };
    let (mut b, _) = waiting();
    b.params = p;
    let c = b.connect(Role::Child, at(0)).expect("room").0;
    let bad = answer(7, &["sad"]);
    for round in 0..5u64 {
        // Two within the burst, two dropped: never three in a row, so never closed.
        let start = round * 1000;
        for i in 0..4 {
            let out = b.ws_text(c, &bad, at(start + i));
            assert!(
                !out.iter().any(|o| matches!(o, Output::Close(..))),
                "round {round}"
            );
        }
    }
}

#[test]
fn oversized_binary_and_misrouted_messages_are_rejected() {
    let p = TabletBridgeParams {
        ws_max_message_bytes: 64,
        ..params()
    };
    let mut b = Bridge::new(p, at(0));
    let c = child(&mut b);
    let out = b.ws_text(c, &"x".repeat(65), at(0));
    assert_eq!(
        reasons(&out, c),
        vec!["message of 65 bytes is over the limit of 64 bytes".to_string()]
    );
    let out = b.ws_binary(c, 10, at(0));
    assert_eq!(
        reasons(&out, c),
        vec!["binary messages (10 bytes) are not accepted".to_string()]
    );
    let out = b.ws_text(c, &cmd(PIN, "stop", json!({})), at(0));
    assert_eq!(
        reasons(&out, c),
        vec!["the child page cannot send commands".to_string()]
    );
    let out = b.ws_text(c, &login(PIN), at(0));
    assert_eq!(
        reasons(&out, c),
        vec!["the child page cannot send logins".to_string()]
    );
    let t = therapist(&mut b);
    let short = r#"{"type":"answer","sequence_id":1,"answer":[],"response_time":0}"#;
    let out = b.ws_text(t, short, at(0));
    assert_eq!(
        reasons(&out, t),
        vec!["the therapist page cannot send answers".to_string()]
    );
}

#[test]
fn connections_are_capped() {
    let mut b = Bridge::new(
        TabletBridgeParams {
            max_clients: 2,
            ..params()
        },
        at(0),
    );
    let first = child(&mut b);
    child(&mut b);
    assert!(
        b.connect(Role::Therapist, at(0))
            .expect_err("full")
            .contains("at most 2")
    );
    b.disconnect(first);
    assert!(b.connect(Role::Therapist, at(0)).is_ok());
    assert!(
        b.ws_text(first, &login(PIN), at(0)).is_empty(),
        "a gone page is ignored"
    );
}

/// Nothing a tablet sends can crash the core: random bytes, mutated valid messages and
/// messages at odd times, from both pages.
#[test]
fn random_input_never_panics_and_the_game_goes_on() {
    let mut rng = ChaCha8Rng::seed_from_u64(6);
    let (mut b, c) = waiting();
    let t = therapist(&mut b);
    let seeds = [
        answer(7, &["happy", "sad", "angry"]),
        cmd(PIN, "start", json!({"user_id": "x", "cluster": 0})),
        cmd(PIN, "override_level", json!({"level": 2})),
        cmd(PIN, "accept_proposal", json!({"proposal": 2})),
        login(PIN),
    ];
    for i in 0..20_000u64 {
        let mut bytes = seeds[rng.random_range(0..seeds.len())].clone().into_bytes();
        for _ in 0..rng.random_range(0..4) {
            if bytes.is_empty() {
                break;
            }
            let at_ = rng.random_range(0..bytes.len());
            match rng.random_range(0..3) {
                0 => bytes[at_] = rng.random(),
                1 => bytes.truncate(at_),
                _ => bytes.insert(at_, rng.random()),
            }
        }
        let text = String::from_utf8_lossy(&bytes);
        let id = if rng.random_bool(0.5) { c } else { t };
        b.ws_text(id, &text, at(i * 300));
    }
    // The child page is still there and a fresh task can still be answered.
    b.dds(
        DdsInput::GameState(game(GameState::WAITING_FOR_ANSWER, "z")),
        at(7_000_000),
    );
    b.dds(DdsInput::Task(task("z", 1, 3)), at(7_000_000));
    let out = b.ws_text(c, &answer(1, &["angry", "angry", "sad"]), at(7_001_000));
    assert_eq!(published(&out).1.len(), 1, "{out:?}");
}
