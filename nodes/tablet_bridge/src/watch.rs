//! Watching the game manager's heartbeat (RustDDS reports no DDS liveliness, and a dead game
//! manager publishes no state to say so). Silent for `game_manager_loss_timeout_s`, it is
//! lost: the therapist page's status says so and the child page shows the game paused (an
//! answer could reach no one); its first heartbeat again (a respawned node) says it is back.
//! The robot needs nothing from here: without a game manager nothing commands it. The
//! bookkeeping is the shared [`HeartbeatWatch`]'s: watching starts with the first heartbeat, so
//! a bridge that never hears one (a replay) shows nothing. Two game managers beating (one
//! started twice) stay on the therapist page's status until one of them stops.

use crate::io::{Output, log};
use crate::protocol::GameView;
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
    notice: Option<String>,
    /// Two game manager processes beating, as last shown.
    twins: Vec<Twins>,
}

/// The bridge's monotonic clock in the watch's nanoseconds.
fn nanos(t: Duration) -> i64 {
    i64::try_from(t.as_nanos()).unwrap_or(i64::MAX)
}

fn seconds(ns: i64) -> f64 {
    ns as f64 * 1e-9
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

    /// When [`Self::tick`] must next be called (monotonic), if at all.
    pub(crate) fn next_deadline(&self) -> Option<Duration> {
        let ns = self.heartbeats.next_deadline_ns()?;
        Some(Duration::from_nanos(u64::try_from(ns).unwrap_or(0)))
    }

    /// The clock reached a deadline of [`Self::next_deadline`]: true when the game manager
    /// is lost now (the pages must be shown the game again).
    pub(crate) fn tick(&mut self, now: Duration, out: &mut Vec<Output>) -> bool {
        let Some(lost) = self.heartbeats.check(nanos(now)).pop() else {
            return false;
        };
        let notice = format!(
            "game manager lost: no heartbeat for {:.1} s (last pid {}); the robot gets no \
             commands and answers cannot count until it is back",
            seconds(lost.silent_ns),
            lost.last_pid.unwrap_or(0)
        );
        out.push(log(Level::WARN, notice.clone()));
        self.notice = Some(notice);
        self.twins = self.heartbeats.twins(nanos(now));
        true
    }

    /// Any node's heartbeat: true when it is the lost game manager's, back (the pages must
    /// be shown the game again). [`Self::follow_twins`] comes after it.
    pub(crate) fn heartbeat(
        &mut self,
        hb: &Heartbeat,
        now: Duration,
        out: &mut Vec<Output>,
    ) -> bool {
        match self.heartbeats.heartbeat(&hb.node_name, hb.pid, nanos(now)) {
            Heard::Unwatched | Heard::WatchStarted | Heard::Alive => false,
            Heard::Back { silent_ns, .. } => {
                let back = format!(
                    "game manager back (pid {}) after {:.1} s without a heartbeat",
                    hb.pid,
                    seconds(silent_ns)
                );
                out.push(log(Level::INFO, back.clone()));
                self.notice = Some(back);
                true
            }
            Heard::Restarted { old_pid } => {
                out.push(log(
                    Level::WARN,
                    format!(
                        "game manager restarted (pid {old_pid} -> {}) within the loss timeout",
                        hb.pid
                    ),
                ));
                false
            }
            Heard::Twice { other_pid } => {
                out.push(log(
                    Level::WARN,
                    format!(
                        "two game managers beat (pids {other_pid} and {}): one was started \
                         twice; stop one",
                        hb.pid
                    ),
                ));
                false
            }
        }
    }

    /// Follows the pairs of game managers beating: true when that changed (the pages must be
    /// shown the game again).
    pub(crate) fn follow_twins(&mut self, now: Duration) -> bool {
        let twins = self.heartbeats.twins(nanos(now));
        if twins == self.twins {
            return false;
        }
        self.twins = twins;
        true
    }

    /// The game manager's own state arrived: once it is not lost, that state says what it
    /// does now, and the notice of its return goes.
    pub(crate) fn state_arrived(&mut self) {
        if !self.lost() {
            self.notice = None;
        }
    }

    /// The game view for the therapist page: the game manager's own (`game`), its status
    /// prefixed by the loss (or the return) while there is one to tell.
    pub(crate) fn therapist_view(&self, game: Option<&GameState>) -> Option<GameView> {
        let notice = self.notice.as_ref();
        let g = match (game, notice) {
            (Some(g), _) => g.clone(),
            (None, Some(_)) => GameState {
                user_model_cluster: -1,
                ..Default::default()
            },
            (None, None) => return None,
        };
        let mut view = GameView::of(&g);
        let twins = self.twins.first().map(|t| {
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
    pub(crate) fn child_view(&self, game: Option<&GameState>) -> Option<GameView> {
        let mut view = GameView::for_child(game?);
        if self.lost() {
            view.phase = GameState::phase_name(GameState::PAUSED);
        }
        Some(view)
    }
}
