//! The therapist page's side of the core: PIN login, and commands turned into
//! `TherapistCommand`s with the session they are for and a command id that only increases.

use crate::bridge::{Bridge, ClientId, Now, Output, log};
use crate::limits::pin_matches;
use crate::protocol::{CommandKind, Role, ServerMessage};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::{GamePhase, GameState, TherapistCommand, Validate};
use std::collections::VecDeque;
use std::time::Duration;
use tracing::Level;

/// Sessions whose last command id is remembered.
const SESSIONS_REMEMBERED: usize = 16;
/// A repeated emergency stop within this long is acknowledged but not published again.
const EMERGENCY_REPEAT: Duration = Duration::from_millis(500);

/// Command ids per session. An id is the wall-clock millisecond, bumped past the previous id
/// of the session: ids only increase even if the clock steps back, and they stay above those
/// of the `therapist` console (which uses the millisecond too) and of an earlier bridge run.
#[derive(Debug, Default)]
pub struct CommandIds {
    last: VecDeque<(String, u64)>,
}

impl CommandIds {
    pub fn next(&mut self, session: &str, wall_nanos: i64) -> u64 {
        let millis = u64::try_from(wall_nanos / 1_000_000).unwrap_or(0).max(1);
        let position = self.last.iter().position(|(s, _)| s == session);
        let previous = position.and_then(|i| self.last.remove(i)).map(|(_, id)| id);
        let id = previous.map_or(millis, |p| millis.max(p.saturating_add(1)));
        if self.last.len() >= SESSIONS_REMEMBERED {
            self.last.pop_front();
        }
        self.last.push_back((session.to_string(), id));
        id
    }
}

/// The optional fields of a command message.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CommandFields {
    pub user_id: Option<String>,
    pub cluster: Option<i32>,
    pub level: Option<u8>,
    /// The step of the proposal the command answers (the proposal card's buttons).
    pub proposal: Option<u8>,
}

impl Bridge {
    pub(crate) fn login(&mut self, id: ClientId, pin: &str, now: Now, out: &mut Vec<Output>) {
        if self.clients.get(&id).is_some_and(|c| c.logged_in) {
            self.therapist_snapshot(id, now, out);
            return;
        }
        if !self.pin_budget.has_token(now.monotonic) {
            let wait = self.pin_budget.wait_secs(now.monotonic).ceil();
            let reason = format!("too many wrong PINs: try again in {wait} s");
            self.reject(id, reason, out);
            return;
        }
        if !pin_matches(pin, &self.params.pin) {
            self.wrong_pin(id, now, out);
            return;
        }
        if let Some(c) = self.clients.get_mut(&id) {
            c.logged_in = true;
            c.pin_failures = 0;
        }
        out.push(log(Level::INFO, format!("page {id}: therapist logged in")));
        self.therapist_snapshot(id, now, out);
    }

    fn wrong_pin(&mut self, id: ClientId, now: Now, out: &mut Vec<Output>) {
        self.pin_budget.try_take(now.monotonic);
        let max = self.params.pin_max_failures;
        let Some(c) = self.clients.get_mut(&id) else {
            return;
        };
        c.pin_failures += 1;
        let failures = c.pin_failures;
        self.reject(id, "wrong PIN".into(), out);
        if failures >= max {
            let reason = format!("closed after {failures} wrong PINs");
            out.push(log(Level::WARN, format!("page {id}: {reason}")));
            out.push(Output::Close(id, reason));
            self.clients.remove(&id);
        }
    }

    pub(crate) fn command(
        &mut self,
        id: ClientId,
        pin: &str,
        kind: CommandKind,
        fields: CommandFields,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        if !self.clients.get(&id).is_some_and(|c| c.logged_in) {
            self.reject(id, "log in with the PIN first".into(), out);
            return;
        }
        if !pin_matches(pin, &self.params.pin) {
            self.wrong_pin(id, now, out);
            return;
        }
        if let Err(reason) = check_fields(kind, &fields) {
            self.reject(id, reason, out);
            return;
        }
        let session = match self.session_for(kind, now) {
            Ok(s) => s,
            Err(reason) => {
                self.reject(id, reason, out);
                return;
            }
        };
        if let Err(reason) = self.check_proposal_answer(kind, fields.proposal, &session) {
            self.reject(id, reason, out);
            return;
        }
        if kind == CommandKind::EmergencyStop
            && let Some((s, at)) = &self.last_emergency_stop
            && *s == session
            && now.monotonic.saturating_sub(*at) < EMERGENCY_REPEAT
        {
            let what = "emergency stop (already sent)".to_string();
            out.push(Output::Send(id, ServerMessage::Accepted { what }));
            return;
        }
        let command = TherapistCommand {
            header: Header::at(Time::from_nanos(now.wall_nanos)),
            command: kind.code(),
            session_id: session.clone(),
            command_id: self.command_ids.next(&session, now.wall_nanos),
            user_id: fields.user_id.unwrap_or_default(),
            user_model_cluster: fields.cluster.unwrap_or(-1),
            level: fields.level.unwrap_or(0),
        };
        if let Err(e) = command.validate() {
            self.reject(id, e.reason, out);
            return;
        }
        if kind == CommandKind::EmergencyStop {
            self.last_emergency_stop = Some((session.clone(), now.monotonic));
        }
        if kind == CommandKind::Start {
            self.current_session = Some(session.clone());
        }
        out.push(log(
            Level::INFO,
            format!(
                "page {id}: command {} ({kind:?}) sent for session {session:?}",
                command.command_id
            ),
        ));
        let sent = ServerMessage::CommandSent {
            command: kind,
            session_id: session,
            command_id: command.command_id,
        };
        self.broadcast(Role::Therapist, &sent, out);
        out.push(Output::Command(command));
    }

    /// The session a command goes to; START opens a new one.
    fn session_for(&self, kind: CommandKind, now: Now) -> Result<String, String> {
        // A session under way, paused or not.
        let running = self.game.as_ref().filter(|g| {
            GamePhase::try_from(g.phase).is_ok_and(|p| p.is_running() || p == GamePhase::Paused)
        });
        match kind {
            CommandKind::Start => {
                if let Some(g) = running {
                    return Err(format!(
                        "session {} is still running ({}): stop it first",
                        g.session_id,
                        GameState::phase_name(g.phase)
                    ));
                }
                let base = format!("tablet-{}", now.wall_nanos / 1_000_000);
                Ok(match &self.current_session {
                    // Two starts within one millisecond still get two sessions.
                    Some(s) if s.starts_with(&base) => format!("{base}-{}", now.wall_nanos),
                    _ => base,
                })
            }
            // An emergency stop goes out even when no session is known: it costs nothing.
            CommandKind::EmergencyStop => Ok(self
                .current_session
                .clone()
                .unwrap_or_else(|| "none".into())),
            _ => self
                .current_session
                .clone()
                .ok_or_else(|| "no session is known yet: start one first".to_string()),
        }
    }
}

/// Which optional fields each command needs and allows.
fn check_fields(kind: CommandKind, f: &CommandFields) -> Result<(), String> {
    let name = kind.name();
    if f.proposal.is_some() && !kind.answers_proposal() {
        return Err(format!("{name} answers no proposal"));
    }
    match kind {
        CommandKind::Start => {
            if f.level.is_some() {
                return Err("start takes no level".into());
            }
            match (&f.user_id, f.cluster) {
                (Some(u), Some(_)) if !u.trim().is_empty() => Ok(()),
                _ => Err("start needs a user_id and a cluster (-1: the policy's default)".into()),
            }
        }
        CommandKind::OverrideLevel => {
            if f.user_id.is_some() || f.cluster.is_some() {
                return Err("override_level takes only a level".into());
            }
            match f.level {
                Some(1..=3) => Ok(()),
                Some(l) => Err(format!("level = {l} is outside 1..=3")),
                None => Err("override_level needs a level 1..=3".into()),
            }
        }
        _ if f.user_id.is_some() || f.cluster.is_some() || f.level.is_some() => {
            Err(format!("{name} takes no user_id, cluster or level"))
        }
        _ => Ok(()),
    }
}
