//! The therapist page's commands, turned into `TherapistCommand`s: the fields each command
//! takes, the session it is for (a start opens a new one) and a command id that only
//! increases. A logged-in page and its PIN are checked before (`bridge`), an answer to a
//! proposal by the proposal kept (`proposal`).

use crate::io::Now;
use crate::protocol::CommandKind;
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::{GamePhase, GameState, TherapistCommand, Validate};
use std::collections::VecDeque;
use std::time::Duration;

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

/// What a command the checks let through becomes.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Made {
    /// The command to publish.
    Command(TherapistCommand),
    /// An emergency stop for the session repeated within [`EMERGENCY_REPEAT`]: acknowledged,
    /// not published again.
    EmergencyStopRepeated,
}

/// The commands' memory: the session they go to, the ids given, the last emergency stop.
#[derive(Debug, Default)]
pub(crate) struct Commands {
    ids: CommandIds,
    /// The session commands go to: the game's, or the one this bridge just started.
    current_session: Option<String>,
    last_emergency_stop: Option<(String, Duration)>,
}

impl Commands {
    /// The game's new state: commands go to its session from now on.
    pub(crate) fn follow_game(&mut self, g: &GameState) {
        if !g.session_id.is_empty() {
            self.current_session = Some(g.session_id.clone());
        }
    }

    /// The session command `kind` with `fields` goes to, with the game's state as last heard
    /// (`game`); or why it cannot go out.
    pub(crate) fn session_for(
        &self,
        kind: CommandKind,
        fields: &CommandFields,
        game: Option<&GameState>,
        now: Now,
    ) -> Result<String, String> {
        check_fields(kind, fields)?;
        // A session under way, paused or not.
        let running = game.filter(|g| {
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
                // The wall clock's millisecond, past the last session's when that was made
                // here too: after a step back of the clock, a millisecond of the repeated
                // time could name a session the game manager has had (it refuses the START).
                let millis = now.wall_nanos / 1_000_000;
                let last = self
                    .current_session
                    .as_deref()
                    .and_then(|s| s.strip_prefix("tablet-"))
                    .and_then(|rest| rest.split('-').next())
                    .and_then(|m| m.parse::<i64>().ok());
                Ok(match last {
                    Some(l) if l >= millis => format!("tablet-{}", l.saturating_add(1)),
                    _ => format!("tablet-{millis}"),
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

    /// Command `kind` with `fields` for `session` (checked by [`Self::session_for`]), with
    /// its id; or why it is not valid.
    pub(crate) fn make(
        &mut self,
        kind: CommandKind,
        session: String,
        fields: CommandFields,
        now: Now,
    ) -> Result<Made, String> {
        if kind == CommandKind::EmergencyStop
            && let Some((s, at)) = &self.last_emergency_stop
            && *s == session
            && now.monotonic.saturating_sub(*at) < EMERGENCY_REPEAT
        {
            return Ok(Made::EmergencyStopRepeated);
        }
        let command = TherapistCommand {
            header: Header::at(Time::from_nanos(now.wall_nanos)),
            command: kind.code(),
            command_id: self.ids.next(&session, now.wall_nanos),
            session_id: session,
            user_id: fields.user_id.unwrap_or_default(),
            user_model_cluster: fields.cluster.unwrap_or(-1),
            level: fields.level.unwrap_or(0),
        };
        command.validate().map_err(|e| e.reason)?;
        if kind == CommandKind::EmergencyStop {
            self.last_emergency_stop = Some((command.session_id.clone(), now.monotonic));
        }
        if kind == CommandKind::Start {
            self.current_session = Some(command.session_id.clone());
        }
        Ok(Made::Command(command))
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
            // Without a cluster the policy's default plays (-1); a cluster may still be chosen.
            match &f.user_id {
                Some(u) if !u.trim().is_empty() => Ok(()),
                _ => Err("start needs a user_id (the child's code)".into()),
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
