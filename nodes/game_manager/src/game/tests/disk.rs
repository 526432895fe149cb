//! The disk: a warning first in the status while it is low, a START refused below the floor
//! naming the disk, and a session that goes on while session-file writes wait for room.

use super::harness::*;
use crate::params::GameManagerParams;
use crate::protocol::{Input, Output};
use qt_therapy_msgs::{GameState, TherapistCommand as C};

fn harness() -> Harness {
    let mut p = GameManagerParams::default();
    p.files.sessions_dir = "/var/lib/qt-therapy/sessions/run".into();
    Harness::new(p, rule_policy(), scripted_child(vec![]))
}

#[test]
fn below_the_floor_a_start_is_refused_naming_the_disk() {
    let mut h = harness();
    h.feed(Input::DiskSpace { free: 50_000_000 });
    let low = h.last_state();
    assert_eq!(
        GameState::disk_warning(&low.status),
        Some(
            "50.0 MB free in /var/lib/qt-therapy/sessions/run, below 500 MB: delete old bags \
             or reports"
        ),
        "{}",
        low.status
    );
    h.start("s1");
    let refused = h.last_state();
    assert_eq!(refused.command_outcome, GameState::COMMAND_REFUSED);
    assert!(
        refused.command_refusal.starts_with(
            "too little disk space to record a session: 50.0 MB free in \
             /var/lib/qt-therapy/sessions/run, below the floor of 100 MB"
        ),
        "{}",
        refused.command_refusal
    );
    // Room again: the warning goes, and the start is carried out.
    h.feed(Input::DiskSpace {
        free: 2_000_000_000,
    });
    assert_eq!(GameState::disk_warning(&h.last_state().status), None);
    h.feed(cmd(C::START, "s2", 1));
    assert_eq!(
        h.last_state().command_outcome,
        GameState::COMMAND_CARRIED_OUT
    );
}

#[test]
fn a_session_goes_on_while_its_writes_wait_for_room() {
    let mut h = harness();
    h.start("s1");
    h.run_until(ns(30.0));
    h.feed(Input::FilesUnsaved {
        unsaved: 2,
        reason: "No space left on device (os error 28)".into(),
    });
    let full = h.last_state();
    assert!(
        GameState::disk_warning(&full.status).is_some_and(|w| w.starts_with(
            "full in /var/lib/qt-therapy/sessions/run: 2 session-file writes kept in memory"
        )),
        "{}",
        full.status
    );
    assert!(
        h.outputs()
            .any(|o| matches!(o, Output::Alarm(a) if a.starts_with("disk: full in"))),
        "the operator is told"
    );
    // The session goes on meanwhile, to its end.
    h.run(3600.0);
    assert_eq!(h.results().len(), 10);
    h.feed(Input::FilesUnsaved {
        unsaved: 0,
        reason: String::new(),
    });
    assert_eq!(GameState::disk_warning(&h.last_state().status), None);
}
