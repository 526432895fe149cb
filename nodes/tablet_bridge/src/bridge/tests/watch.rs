//! Core tests of the game manager's heartbeat watch: lost after the timeout (not before) on
//! both pages, answers refused meanwhile, back with its next heartbeat.

use super::*;
use crate::protocol::GameView;
use qt_therapy_msgs::Heartbeat;

fn beat(node: &str, pid: u32) -> DdsInput {
    DdsInput::Heartbeat(Heartbeat {
        node_name: node.into(),
        pid,
        ..Default::default()
    })
}

/// The game views page `id` was sent.
fn games(out: &[Output], id: ClientId) -> Vec<GameView> {
    to(out, id)
        .into_iter()
        .filter_map(|m| match m {
            ServerMessage::Game(g) => Some(g),
            _ => None,
        })
        .collect()
}

#[test]
fn a_silent_game_manager_is_shown_lost_after_the_timeout_and_back_with_its_heartbeat() {
    let (mut b, c) = waiting();
    let t = therapist(&mut b);
    let mut g = game(GameState::WAITING_FOR_ANSWER, "s1");
    g.status = "sequence 3: waiting".into();
    b.dds(DdsInput::GameState(g), at(0));
    // Other nodes' heartbeats are not watched, and nothing is watched before the first.
    b.dds(beat("behaviour_policy", 7), at(0));
    assert_eq!(b.next_deadline(), None);
    for ms in (0..=1000).step_by(100) {
        assert!(silent(&b.dds(beat("game_manager", 100), at(ms))));
    }
    assert_eq!(b.next_deadline(), Some(Duration::from_millis(5000)));
    assert!(silent(&b.tick(at(4999))), "not lost before the timeout");

    let out = b.tick(at(5000));
    let shown = games(&out, t);
    assert_eq!(shown.len(), 1);
    assert!(
        shown[0].status.starts_with(
            "game manager lost: no heartbeat for 4.0 s (last pid 100); the robot gets no commands"
        ) && shown[0].status.ends_with("; sequence 3: waiting"),
        "{}",
        shown[0].status
    );
    assert_eq!(shown[0].phase, "waiting_for_answer");
    assert_eq!(games(&out, c)[0].phase, "paused");
    assert_eq!(b.next_deadline(), None);
    // Nobody would score an answer now.
    let out = b.ws_text(c, &answer(7, &["happy", "sad", "angry"]), at(5100));
    assert_eq!(
        reasons(&out, c),
        vec!["the game manager is lost: the answer could not be scored".to_string()]
    );
    assert!(published(&out).1.is_empty());
    // A therapist page that logs in meanwhile is told at once.
    let late = therapist(&mut b);
    let out = b.ws_text(late, &login(PIN), at(6000));
    assert!(games(&out, late)[0].status.starts_with("game manager lost"));

    // The respawned game manager's first heartbeat: back, on both pages.
    let out = b.dds(beat("game_manager", 200), at(10_000));
    let shown = games(&out, t);
    assert!(
        shown[0]
            .status
            .starts_with("game manager back (pid 200) after 9.0 s without a heartbeat; "),
        "{}",
        shown[0].status
    );
    assert_eq!(games(&out, c)[0].phase, "waiting_for_answer");
    assert_eq!(b.next_deadline(), Some(Duration::from_millis(14_000)));
    // Its own state then says what it does.
    let mut g = game(GameState::PAUSED, "s1");
    g.status = "recovered after a game manager restart; resume to go on".into();
    let out = b.dds(DdsInput::GameState(g), at(10_100));
    assert_eq!(
        games(&out, t)[0].status,
        "recovered after a game manager restart; resume to go on"
    );
}

#[test]
fn a_restart_within_the_timeout_and_a_late_tick_show_no_loss() {
    let mut b = Bridge::new(params(), at(0));
    let t = therapist(&mut b);
    b.dds(beat("game_manager", 1), at(0));
    // A new pid within the timeout: the node restarted, nothing was lost.
    let restarted = b.dds(beat("game_manager", 2), at(3000));
    assert!(silent(&restarted));
    assert!(
        logged(&restarted)
            .iter()
            .any(|(level, line)| *level == tracing::Level::WARN
                && line.contains("game manager restarted")),
        "{restarted:?}"
    );
    assert!(silent(&b.tick(at(4000))));
    assert_eq!(b.next_deadline(), Some(Duration::from_millis(7000)));
    // Lost with no game state yet: the page still gets the status.
    let out = b.tick(at(7000));
    assert!(games(&out, t)[0].status.starts_with("game manager lost"));
}

#[test]
fn two_game_managers_stay_on_the_therapist_status_until_one_stops() {
    let (mut b, _c) = waiting();
    let t = therapist(&mut b);
    let mut g = game(GameState::WAITING_FOR_ANSWER, "s1");
    g.status = "sequence 3: waiting".into();
    b.dds(DdsInput::GameState(g.clone()), at(0));
    // Pid 100 beats throughout; pid 101, started by mistake, 50 ms after it until 2 s.
    let twice = "two game managers beat (pids 100 and 101): stop one; sequence 3: waiting";
    let mut statuses = Vec::new();
    for ms in (0..8000).step_by(50) {
        let pid = if ms % 100 == 0 { 100 } else { 101 };
        if pid == 101 && ms > 2000 {
            continue;
        }
        let out = b.dds(beat("game_manager", pid), at(ms));
        statuses.extend(games(&out, t).into_iter().map(|v| (ms, v.status)));
        // A state of its own meanwhile keeps the warning in view.
        if ms == 1000 {
            let out = b.dds(DdsInput::GameState(g.clone()), at(ms));
            statuses.extend(games(&out, t).into_iter().map(|v| (ms, v.status)));
        }
    }
    // Told when pid 100 beats again after 101 replaced it (at 0.1 s), kept by the state at 1 s,
    // gone with pid 100's first beat once 101 was silent for the 4 s timeout (last beat 1.95 s).
    assert_eq!(
        statuses,
        vec![
            (100, twice.to_string()),
            (1000, twice.to_string()),
            (6000, "sequence 3: waiting".to_string()),
        ]
    );
    assert!(silent(&b.tick(at(8000))), "one game manager still beats");
}
