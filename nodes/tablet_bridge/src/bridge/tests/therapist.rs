//! Core tests of the therapist page: login, PIN, command fields and command ids.

use super::*;
use crate::protocol::CommandKind;
use crate::therapist::CommandIds;

#[test]
fn commands_need_login_and_the_right_pin() {
    let mut b = Bridge::new(params(), at(0));
    let t = b.connect(Role::Therapist, at(0)).expect("room").0;
    let start = cmd(PIN, "start", json!({"user_id": "child-7", "cluster": 1}));
    let out = b.ws_text(t, &start, at(10));
    assert_eq!(
        reasons(&out, t),
        vec!["log in with the PIN first".to_string()]
    );
    assert!(published(&out).0.is_empty());

    let t = therapist(&mut b);
    let wrong = cmd("2469", "start", json!({"user_id": "child-7", "cluster": 1}));
    let out = b.ws_text(t, &wrong, at(30));
    assert_eq!(reasons(&out, t), vec!["wrong PIN".to_string()]);
    assert!(published(&out).0.is_empty());
    let out = b.ws_text(t, &cmd("", "pause", json!({})), at(40));
    assert_eq!(reasons(&out, t), vec!["wrong PIN".to_string()]);
    let out = b.ws_text(t, r#"{"type":"command","command":"pause"}"#, at(50));
    assert!(
        reasons(&out, t)[0].contains("missing field `pin`"),
        "{out:?}"
    );

    let out = b.ws_text(t, &start, at(60));
    let (commands, _) = published(&out);
    assert_eq!(commands.len(), 1);
    let c = &commands[0];
    assert_eq!(c.command, TherapistCommand::START);
    assert_eq!((c.user_id.as_str(), c.user_model_cluster), ("child-7", 1));
    assert_eq!(
        c.session_id,
        format!("tablet-{}", at(60).wall_nanos / 1_000_000)
    );
    assert_eq!(c.header.stamp.to_nanos(), at(60).wall_nanos);
    let sent = to(&out, t);
    assert!(matches!(
        &sent[..],
        [ServerMessage::CommandSent {
            command: CommandKind::Start,
            ..
        }]
    ));
}

#[test]
fn wrong_pins_close_the_connection_and_lock_out_new_logins_but_not_a_logged_in_page() {
    let mut b = Bridge::new(params(), at(0));
    let logged_in = therapist(&mut b);
    let guesser = b.connect(Role::Therapist, at(0)).expect("room").0;
    let mut closed = false;
    for i in 0..5 {
        let out = b.ws_text(guesser, &login(&format!("000{i}")), at(i));
        assert_eq!(reasons(&out, guesser)[0], "wrong PIN");
        closed = out
            .iter()
            .any(|o| matches!(o, Output::Close(id, _) if *id == guesser));
    }
    assert!(closed, "closed after pin_max_failures wrong PINs");
    // The budget over all connections is spent: even the right PIN is refused for a while.
    let other = b.connect(Role::Therapist, at(100)).expect("room").0;
    let out = b.ws_text(other, &login(PIN), at(100));
    assert!(
        reasons(&out, other)[0].starts_with("too many wrong PINs"),
        "{out:?}"
    );
    // The page already logged in still stops the robot.
    let out = b.ws_text(logged_in, &cmd(PIN, "emergency_stop", json!({})), at(200));
    assert_eq!(published(&out).0.len(), 1);
    // Five wrong PINs a minute: one attempt is possible again 12 s after the last one.
    let out = b.ws_text(other, &login(PIN), at(13_000));
    assert!(
        to(&out, other).contains(&ServerMessage::LoggedIn),
        "{out:?}"
    );
}

#[test]
fn command_ids_only_increase_per_session_even_when_the_clock_steps_back() {
    let mut b = Bridge::new(params(), at(0));
    let t = therapist(&mut b);
    b.dds(
        DdsInput::GameState(game(GameState::WAITING_FOR_ANSWER, "s1")),
        at(0),
    );
    let mut ids = Vec::new();
    // The wall clock steps back from 5 s to 1 s between the second and third command.
    for (kind, ms) in [
        ("pause", 5000),
        ("resume", 5000),
        ("pause", 1000),
        ("resume", 9000),
    ] {
        let out = b.ws_text(t, &cmd(PIN, kind, json!({})), at(ms));
        let (commands, _) = published(&out);
        assert_eq!(commands.len(), 1, "{kind}: {out:?}");
        assert_eq!(commands[0].session_id, "s1");
        ids.push(commands[0].command_id);
    }
    assert!(ids.windows(2).all(|w| w[1] > w[0]), "{ids:?}");
    let mut fresh = CommandIds::default();
    assert_eq!(fresh.next("a", 0), 1, "ids start at 1 even at the epoch");
    assert_eq!(fresh.next("b", 5_000_000), 5);
    assert_eq!(
        fresh.next("a", -7),
        2,
        "a clock before the epoch still moves ids on"
    );
    assert_eq!(fresh.next("b", 5_000_000), 6);
}

#[test]
fn commands_are_checked_against_their_fields_and_the_game() {
    let mut b = Bridge::new(params(), at(0));
    let t = therapist(&mut b);
    let cases = [
        ("pause", json!({}), "no session is known yet"),
        ("start", json!({"cluster": 1}), "start needs a user_id"),
        (
            "start",
            json!({"user_id": "  ", "cluster": 0}),
            "start needs a user_id",
        ),
        (
            "start",
            json!({"user_id": "c", "cluster": 64}),
            "user_model_cluster = 64",
        ),
        (
            "start",
            json!({"user_id": "c\u{7}", "cluster": 0}),
            "control characters",
        ),
        (
            "start",
            json!({"user_id": "c", "cluster": 0, "level": 2}),
            "start takes no level",
        ),
        (
            "override_level",
            json!({"level": 4}),
            "level = 4 is outside 1..=3",
        ),
        ("override_level", json!({}), "override_level needs a level"),
        (
            "override_level",
            json!({"level": 2, "cluster": 1}),
            "takes only a level",
        ),
        (
            "stop",
            json!({"level": 1}),
            "stop takes no user_id, cluster or level",
        ),
    ];
    for (kind, extra, reason) in cases {
        let out = b.ws_text(t, &cmd(PIN, kind, extra.clone()), at(0));
        let got = reasons(&out, t);
        assert!(
            got.len() == 1 && got[0].contains(reason),
            "{kind} {extra}: {got:?}"
        );
        assert!(published(&out).0.is_empty());
    }
    b.dds(
        DdsInput::GameState(game(GameState::SAYING_SEQUENCE, "s1")),
        at(0),
    );
    let out = b.ws_text(
        t,
        &cmd(PIN, "start", json!({"user_id": "c", "cluster": 0})),
        at(0),
    );
    assert_eq!(
        reasons(&out, t),
        vec!["session s1 is still running (saying_sequence): stop it first".to_string()]
    );
    let out = b.ws_text(t, &cmd(PIN, "override_level", json!({"level": 3})), at(0));
    let (commands, _) = published(&out);
    assert_eq!(
        (commands[0].level, commands[0].session_id.as_str()),
        (3, "s1")
    );
}

#[test]
fn an_emergency_stop_goes_out_even_before_any_session() {
    let mut b = Bridge::new(params(), at(0));
    let t = therapist(&mut b);
    let out = b.ws_text(t, &cmd(PIN, "emergency_stop", json!({})), at(0));
    let (commands, _) = published(&out);
    assert_eq!(commands.len(), 1);
    assert_eq!(commands[0].session_id, "none");
}

#[test]
fn two_starts_in_one_millisecond_open_two_sessions() {
    let mut b = Bridge::new(params(), at(0));
    let t = therapist(&mut b);
    let start = cmd(PIN, "start", json!({"user_id": "c", "cluster": -1}));
    let first = published(&b.ws_text(t, &start, at(5))).0;
    let second = published(&b.ws_text(t, &start, at(5))).0;
    assert_ne!(first[0].session_id, second[0].session_id);
    let millis = |id: &str| {
        id.strip_prefix("tablet-")
            .and_then(|m| m.parse::<i64>().ok())
    };
    assert_eq!(
        millis(&second[0].session_id),
        millis(&first[0].session_id).map(|m| m + 1)
    );
}

#[test]
fn a_start_after_the_wall_clock_stepped_back_gets_an_id_past_the_last_session() {
    let mut b = Bridge::new(params(), at(0));
    let t = therapist(&mut b);
    let start = cmd(PIN, "start", json!({"user_id": "c", "cluster": -1}));
    let first = published(&b.ws_text(t, &start, at(5))).0;
    // An hour back: the millisecond then may name a session of the hour before.
    let back = Now {
        monotonic: Duration::from_millis(10),
        wall_nanos: WALL0 - 3_600_000_000_000,
    };
    let second = published(&b.ws_text(t, &start, back)).0;
    assert_eq!(
        first[0].session_id,
        format!("tablet-{}", WALL0 / 1_000_000 + 5)
    );
    assert_eq!(
        second[0].session_id,
        format!("tablet-{}", WALL0 / 1_000_000 + 6)
    );
}
