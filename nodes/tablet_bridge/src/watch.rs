//! Watching the game manager's heartbeat (RustDDS reports no DDS liveliness, and a dead game
//! manager publishes no state to say so). Silent for `game_manager_loss_timeout_s`, it is
//! lost: the therapist page's status says so and the child page shows the game paused (an
//! answer could reach no one); its first heartbeat again (a respawned node) says it is back.
//! The robot needs nothing from here: without a game manager nothing commands it. The
//! bookkeeping is the shared [`HeartbeatWatch`]'s: watching starts with the first heartbeat, so
//! a bridge that never hears one (a replay) shows nothing. Two game managers beating (one
//! started twice) stay on the therapist page's status until one of them stops.

use crate::bridge::{Bridge, Now, Output, log};
use crate::protocol::{GameView, Role, ServerMessage};
use heartbeat_watch::{Heard, HeartbeatWatch, Twins};
use qt_therapy_msgs::{GameState, Heartbeat};
use std::time::Duration;
use tracing::Level;

/// The game manager's node name, as its heartbeats carry it.
pub const GAME_MANAGER_NODE: &str = "game_manager";

/// The game manager, as its heartbeats tell.
#[derive(Debug, Clone)]
pub(crate) struct GameManagerWatch {
    heartbeats: HeartbeatWatch,
    /// What the therapist page's status starts with while lost, or just after it came back.
    pub(crate) notice: Option<String>,
    /// Two game manager processes beating, as last shown.
    twins: Vec<Twins>,
}

impl GameManagerWatch {
    /// Lost after `timeout_s` without a heartbeat.
    pub(crate) fn new(timeout_s: f64) -> Self {
        GameManagerWatch {
            heartbeats: HeartbeatWatch::with_timeout_s([GAME_MANAGER_NODE], timeout_s),
            notice: None,
            twins: Vec::new(),
        }
    }

    pub(crate) fn lost(&self) -> bool {
        self.heartbeats.is_lost(GAME_MANAGER_NODE)
    }
}

/// The bridge's monotonic clock in the watch's nanoseconds.
fn nanos(t: Duration) -> i64 {
    i64::try_from(t.as_nanos()).unwrap_or(i64::MAX)
}

fn seconds(ns: i64) -> f64 {
    ns as f64 * 1e-9
}

impl Bridge {
    /// When [`Bridge::tick`] must next be called (monotonic), if at all.
    pub fn next_deadline(&self) -> Option<Duration> {
        let ns = self.gm_watch.heartbeats.next_deadline_ns()?;
        Some(Duration::from_nanos(u64::try_from(ns).unwrap_or(0)))
    }

    /// The clock reached a deadline of [`Bridge::next_deadline`].
    pub fn tick(&mut self, now: Now) -> Vec<Output> {
        let mut out = Vec::new();
        let w = &mut self.gm_watch;
        let Some(lost) = w.heartbeats.check(nanos(now.monotonic)).pop() else {
            return out;
        };
        let notice = format!(
            "game manager lost: no heartbeat for {:.1} s (last pid {}); the robot gets no \
             commands and answers cannot count until it is back",
            seconds(lost.silent_ns),
            lost.last_pid.unwrap_or(0)
        );
        out.push(log(Level::WARN, notice.clone()));
        w.notice = Some(notice);
        w.twins = w.heartbeats.twins(nanos(now.monotonic));
        self.show_game(&mut out);
        out
    }

    pub(crate) fn heartbeat(&mut self, hb: &Heartbeat, now: Now, out: &mut Vec<Output>) {
        let w = &mut self.gm_watch;
        match w
            .heartbeats
            .heartbeat(&hb.node_name, hb.pid, nanos(now.monotonic))
        {
            Heard::Unwatched | Heard::WatchStarted | Heard::Alive => {}
            Heard::Back { silent_ns, .. } => {
                let back = format!(
                    "game manager back (pid {}) after {:.1} s without a heartbeat",
                    hb.pid,
                    seconds(silent_ns)
                );
                out.push(log(Level::INFO, back.clone()));
                w.notice = Some(back);
                self.show_game(out);
            }
            Heard::Restarted { old_pid } => out.push(log(
                Level::WARN,
                format!(
                    "game manager restarted (pid {old_pid} -> {}) within the loss timeout",
                    hb.pid
                ),
            )),
            Heard::Twice { other_pid } => out.push(log(
                Level::WARN,
                format!(
                    "two game managers beat (pids {other_pid} and {}): one was started twice; \
                     stop one",
                    hb.pid
                ),
            )),
        }
        let w = &mut self.gm_watch;
        let twins = w.heartbeats.twins(nanos(now.monotonic));
        if twins != w.twins {
            w.twins = twins;
            self.show_game(out);
        }
    }

    /// The game view for the therapist page: the game manager's own, its status prefixed by
    /// the loss (or the return) while there is one to tell.
    pub(crate) fn therapist_view(&self) -> Option<GameView> {
        let notice = self.gm_watch.notice.as_ref();
        let g = match (&self.game, notice) {
            (Some(g), _) => g.clone(),
            (None, Some(_)) => GameState {
                user_model_cluster: -1,
                ..Default::default()
            },
            (None, None) => return None,
        };
        let mut view = GameView::of(&g);
        let twins = self.gm_watch.twins.first().map(|t| {
            format!(
                "two game managers beat (pids {} and {}): stop one",
                t.pids.0, t.pids.1
            )
        });
        for n in [notice, twins.as_ref()].into_iter().flatten() {
            view.status = if view.status.is_empty() {
                n.clone()
            } else {
                format!("{n}; {}", view.status)
            };
        }
        Some(view)
    }

    /// The game view for the child page: paused while the game manager is lost.
    pub(crate) fn child_view(&self) -> Option<GameView> {
        let mut view = GameView::for_child(self.game.as_ref()?);
        if self.gm_watch.lost() {
            view.phase = GameState::phase_name(GameState::PAUSED);
        }
        Some(view)
    }

    /// Sends both pages the game as it now stands.
    pub(crate) fn show_game(&self, out: &mut Vec<Output>) {
        if let Some(v) = self.therapist_view() {
            self.broadcast(Role::Therapist, &ServerMessage::Game(v), out);
        }
        if let Some(v) = self.child_view() {
            self.broadcast(Role::Child, &ServerMessage::Game(v), out);
        }
    }
}
