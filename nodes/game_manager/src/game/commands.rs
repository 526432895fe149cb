//! The therapist's commands. Each names its session and carries an id that must increase
//! within the session: stale, duplicated and wrong-session commands are rejected with a
//! reason (log and GameState.status) and the session goes on. An emergency stop for the
//! running session is honoured even with an out-of-order id: silencing the robot is never
//! the unsafe choice. What a command carried out does to the session is `session.rs`'s.

use super::propose::Settled;
use super::{CommandAnswer, GameManager, PendingOverride, Phase, Session};
use crate::protocol::{LogLevel, Output};
use crate::session_file::{JournalCommand, JournalEntry, SessionEnd};
use qt_therapy_msgs::{Command, GameState, TherapistCommand};
use sequence_game::{Action, Feedback, Level};

fn command_name(code: u8) -> &'static str {
    Command::try_from(code).map_or("unknown", Command::name)
}

impl GameManager {
    pub(super) fn on_command(&mut self, c: TherapistCommand, now: i64) {
        let what = format!(
            "command {} ({}) for session {:?}",
            c.command_id,
            command_name(c.command),
            c.session_id
        );
        let kind = match self.check_command(&c) {
            Ok(kind) => kind,
            Err(refusal) => {
                if let Some(s) = self.session.as_mut() {
                    s.rejected_commands += 1;
                }
                let text = format!("{what}: {refusal}");
                self.answered = CommandAnswer {
                    session_id: c.session_id.clone(),
                    command_id: c.command_id,
                    outcome: match refusal {
                        Refusal::AlreadyCarriedOut(_) => GameState::COMMAND_ALREADY_CARRIED_OUT,
                        Refusal::Refused(_) => GameState::COMMAND_REFUSED,
                    },
                    refusal: refusal.to_string(),
                };
                self.reject(text, now);
                return;
            }
        };
        // Carried out: the state that shows its effect says so.
        self.answered = CommandAnswer {
            session_id: c.session_id.clone(),
            command_id: c.command_id,
            outcome: GameState::COMMAND_CARRIED_OUT,
            refusal: String::new(),
        };
        if kind == Command::Start {
            self.start_session(&c, now);
            return;
        }
        // Only an emergency stop gets here with an id that is not new.
        let out_of_order = self.session.as_mut().and_then(|s| {
            let last = s.last_command_id;
            s.last_command_id = last.max(c.command_id);
            (c.command_id <= last).then_some(last)
        });
        if kind == Command::EmergencyStop {
            // Silence first; explain afterwards.
            self.end_session(
                SessionEnd::EmergencyStopped,
                &format!("emergency stop by the therapist (command {})", c.command_id),
                now,
            );
            if let Some(last) = out_of_order {
                self.log(
                    LogLevel::WARN,
                    format!("{what}: out-of-order id (last {last}) honoured for an emergency stop"),
                );
            }
            return;
        }
        self.log(LogLevel::INFO, format!("accepted {what}"));
        match kind {
            Command::Pause => {
                self.journal_command(c.command_id, JournalCommand::Pause, None, now);
                self.pause(c.command_id, now)
            }
            Command::Resume => {
                self.journal_command(c.command_id, JournalCommand::Resume, None, now);
                self.resume(c.command_id, now)
            }
            Command::Stop => self.end_session(
                SessionEnd::Stopped,
                &format!("stopped by the therapist (command {})", c.command_id),
                now,
            ),
            Command::AcceptProposal => {
                self.journal_command(c.command_id, JournalCommand::AcceptProposal, None, now);
                let accepted = Settled::Accepted {
                    command_id: c.command_id,
                };
                self.settle_proposal(accepted, None, now);
            }
            Command::OverrideEncouraging => {
                self.override_action(Action::Encourage, c.command_id, now)
            }
            Command::OverrideChallenging => {
                self.override_action(Action::Challenge, c.command_id, now)
            }
            Command::OverrideLevel => {
                if let Ok(level) = Level::new(c.level.into()) {
                    self.override_action(Action::SetLevel(level), c.command_id, now)
                }
            }
            // Handled above.
            Command::Start | Command::EmergencyStop => {}
        }
    }

    /// The command, or why it cannot be carried out now.
    fn check_command(&self, c: &TherapistCommand) -> Result<Command, Refusal> {
        let Ok(kind) = Command::try_from(c.command) else {
            return refuse(format!("unknown command code {}", c.command));
        };
        self.check_now(kind, c).map(|()| kind)
    }

    /// Why the command `kind` cannot be carried out now, if it cannot.
    fn check_now(&self, kind: Command, c: &TherapistCommand) -> Result<(), Refusal> {
        if c.session_id.is_empty() {
            return refuse("session_id is empty");
        }
        let running = self.session_running();
        let session = self.session.as_ref();
        if kind == Command::Start {
            if running && let Some(s) = session {
                if s.id == c.session_id {
                    check_order(s, c)?;
                    return refuse("this session is already running");
                }
                return refuse(format!("busy with session {:?}: stop it first", s.id));
            }
            let lost = self.lost_names();
            if !lost.is_empty() {
                return refuse(format!(
                    "node lost: {lost}; a session can start when it is back"
                ));
            }
            if self.used_sessions.contains(&c.session_id) {
                return refuse("this session id was already used; start a new session id");
            }
            if let Some(why) = self.disk_refusal() {
                return refuse(why);
            }
            if c.user_id.is_empty() {
                return refuse("user_id is empty");
            }
            if !(-1..=63).contains(&c.user_model_cluster) {
                return refuse(format!(
                    "user_model_cluster {} is outside -1..=63",
                    c.user_model_cluster
                ));
            }
            return Ok(());
        }
        let Some(s) = session else {
            return refuse("no session is running");
        };
        if s.id != c.session_id {
            return refuse(if running {
                format!("wrong session: session {:?} is running", s.id)
            } else {
                "no session is running".into()
            });
        }
        if !running {
            return refuse(format!("session has already ended ({})", self.ended_name()));
        }
        if kind != Command::EmergencyStop {
            check_order(s, c)?;
        }
        match kind {
            Command::Pause if s.paused_since.is_some() => refuse("already paused"),
            Command::Resume if s.paused_since.is_none() && s.held_since.is_some() => {
                refuse(format!(
                    "held because a node is lost ({}): it can go on when the node is back",
                    self.lost_names()
                ))
            }
            Command::Resume if s.paused_since.is_none() => refuse("not paused"),
            Command::OverrideLevel => {
                if Level::new(c.level.into()).is_err() {
                    return refuse(format!("level {} is not 1, 2 or 3", c.level));
                }
                if self.override_target() > self.sequences() {
                    return refuse("no sequence is left to override");
                }
                Ok(())
            }
            Command::OverrideEncouraging | Command::OverrideChallenging => {
                let target = self.override_target();
                if target > self.sequences() {
                    return refuse("no sequence is left to override");
                }
                if target == 1 {
                    return refuse("feedback needs a sequence before it: not on the first");
                }
                Ok(())
            }
            Command::AcceptProposal if !self.proposals.is_open() => {
                refuse("no proposal is open (one that ran out was played)")
            }
            _ => Ok(()),
        }
    }

    fn ended_name(&self) -> &'static str {
        match self.phase {
            Phase::Ended(SessionEnd::Finished) => "finished",
            Phase::Ended(SessionEnd::EmergencyStopped) => "emergency-stopped",
            Phase::Ended(SessionEnd::NodeShutdown) => "node shut down",
            _ => "stopped",
        }
    }

    /// The sequence an override now applies to: the one being decided, else the next.
    fn override_target(&self) -> u8 {
        let index = self.session.as_ref().map_or(1, |s| s.index);
        if self.phase == Phase::Deciding {
            index
        } else {
            index + 1
        }
    }

    /// Journals a command carried out (before its effect is published), so a restarted node
    /// never carries out its id again; an override with its sequence and action.
    fn journal_command(
        &mut self,
        command_id: u64,
        command: JournalCommand,
        over: Option<(u8, Action)>,
        now: i64,
    ) {
        let Some(s) = self.session.as_ref() else {
            return;
        };
        let (level, feedback) = match over.map(|(_, a)| a) {
            Some(Action::SetLevel(l)) => (Some(l.get()), None),
            Some(Action::Encourage) => (None, Some(Feedback::Encouraging as u8)),
            Some(Action::Challenge) => (None, Some(Feedback::Challenging as u8)),
            None => (None, None),
        };
        self.out
            .push(Output::Journal(Box::new(JournalEntry::Command {
                session_id: s.id.clone(),
                command_id,
                command,
                level,
                feedback,
                sequence_index: over.map(|(i, _)| i),
                at_ns: now,
            })));
    }

    /// The therapist sets the next sequence's level or feedback (replacing a proposal open
    /// for it).
    fn override_action(&mut self, action: Action, command_id: u64, now: i64) {
        let target = self.override_target();
        let kind = match action {
            Action::SetLevel(_) => JournalCommand::OverrideLevel,
            _ => JournalCommand::OverrideFeedback,
        };
        self.journal_command(command_id, kind, Some((target, action)), now);
        if let Some(s) = self.session.as_mut() {
            s.pending_override = Some(PendingOverride {
                sequence_index: target,
                action,
                command_id,
            });
        }
        let what = match action {
            Action::SetLevel(level) => format!("set to {level}"),
            Action::Encourage => "given encouraging feedback".into(),
            Action::Challenge => "given challenging feedback".into(),
        };
        self.log(
            LogLevel::INFO,
            format!("sequence {target} {what} by the therapist"),
        );
        // Every accepted command's first state names it: the console waits for that.
        self.status =
            format!("next sequence ({target}) {what} by the therapist (command {command_id})");
        self.publish_state(now);
        if self.phase == Phase::Deciding {
            self.apply_override(now);
            self.maybe_present(now);
        }
    }
}

/// Why a command was not carried out.
#[derive(Debug, Clone, PartialEq)]
enum Refusal {
    /// Its id is the last one carried out in the session: a repeat (a console that did not
    /// see the answer sends a command again with its id).
    AlreadyCarriedOut(u64),
    Refused(String),
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Refusal::AlreadyCarriedOut(id) => write!(f, "duplicate command id {id}"),
            Refusal::Refused(reason) => f.write_str(reason),
        }
    }
}

fn refuse<T>(reason: impl Into<String>) -> Result<T, Refusal> {
    Err(Refusal::Refused(reason.into()))
}

/// Command ids must increase within a session.
fn check_order(s: &Session, c: &TherapistCommand) -> Result<(), Refusal> {
    if c.command_id == s.last_command_id {
        return Err(Refusal::AlreadyCarriedOut(c.command_id));
    }
    if c.command_id < s.last_command_id {
        return refuse(format!(
            "stale command id {} (last accepted {})",
            c.command_id, s.last_command_id
        ));
    }
    Ok(())
}
