//! Watching the game manager's heartbeat (RustDDS reports no DDS liveliness, and a dead game
//! manager publishes no state to say so). Silent for `game_manager_loss_timeout_s`, it is
//! lost: the therapist page's status says so and the child page shows the game paused (an
//! answer could reach no one); its first heartbeat again (a respawned node) says it is back.
//! The robot needs nothing from here: without a game manager nothing commands it. Watching
//! starts with the first heartbeat, so a bridge that never hears one (a replay) shows nothing.

use crate::bridge::{Bridge, Now, Output};
use crate::protocol::{GameView, Role, ServerMessage};
use qt_therapy_msgs::{GameState, Heartbeat};
use std::time::Duration;

/// The game manager's node name, as its heartbeats carry it.
pub const GAME_MANAGER_NODE: &str = "game_manager";

/// The game manager, as its heartbeats tell.
#[derive(Debug, Clone, Default)]
pub(crate) struct GameManagerWatch {
    /// Arrival of its last heartbeat; None until the first.
    last: Option<Duration>,
    pid: u32,
    /// Since when it is lost.
    lost_since: Option<Duration>,
    /// What the therapist page's status starts with while lost, or just after it came back.
    pub(crate) notice: Option<String>,
}

impl GameManagerWatch {
    pub(crate) fn lost(&self) -> bool {
        self.lost_since.is_some()
    }
}

impl Bridge {
    fn loss_timeout(&self) -> Duration {
        Duration::try_from_secs_f64(self.params.game_manager_loss_timeout_s)
            .unwrap_or(Duration::from_secs(4))
    }

    /// When [`Bridge::tick`] must next be called (monotonic), if at all.
    pub fn next_deadline(&self) -> Option<Duration> {
        let w = &self.gm_watch;
        match (w.last, w.lost()) {
            (Some(last), false) => Some(last.saturating_add(self.loss_timeout())),
            _ => None,
        }
    }

    /// The clock reached a deadline of [`Bridge::next_deadline`].
    pub fn tick(&mut self, now: Now) -> Vec<Output> {
        let mut out = Vec::new();
        let timeout = self.loss_timeout();
        let w = &mut self.gm_watch;
        let Some(last) = w.last.filter(|_| w.lost_since.is_none()) else {
            return out;
        };
        let silent = now.monotonic.saturating_sub(last);
        if silent < timeout {
            return out;
        }
        w.lost_since = Some(now.monotonic);
        let notice = format!(
            "game manager lost: no heartbeat for {:.1} s (last pid {}); the robot gets no \
             commands and answers cannot count until it is back",
            silent.as_secs_f64(),
            w.pid
        );
        tracing::warn!("{notice}");
        w.notice = Some(notice);
        self.show_game(&mut out);
        out
    }

    pub(crate) fn heartbeat(&mut self, hb: &Heartbeat, now: Now, out: &mut Vec<Output>) {
        if hb.node_name != GAME_MANAGER_NODE {
            return;
        }
        let w = &mut self.gm_watch;
        let restarted = w.last.is_some() && w.pid != hb.pid;
        let old_pid = w.pid;
        let previous = w.last.replace(now.monotonic);
        w.pid = hb.pid;
        if w.lost_since.take().is_some() {
            let silent = previous.map_or(Duration::ZERO, |p| now.monotonic.saturating_sub(p));
            let back = format!(
                "game manager back (pid {}) after {:.1} s without a heartbeat",
                hb.pid,
                silent.as_secs_f64()
            );
            tracing::info!("{back}");
            w.notice = Some(back);
            self.show_game(out);
        } else if restarted {
            tracing::warn!(
                "game manager restarted (pid {old_pid} -> {}) within the loss timeout",
                hb.pid
            );
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
        if let Some(n) = notice {
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
            view.phase = crate::protocol::phase_name(GameState::PAUSED);
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
