//! The bridge's sans-IO core. It is fed page messages (per connection), DDS messages and the
//! time, and returns what to publish on DDS and what to send to which page. Everything a
//! tablet sends is checked here: rate, size, schema and PIN, then by the part of the core it
//! is for. The parts keep their own state and know nothing of each other or of the pages'
//! connections: the child's task (`child`), the therapist's commands (`therapist`), the
//! proposals (`proposal`), the session so far (`game`) and the game manager's heartbeat
//! (`watch`); this is where what they say is sent to the pages.

use crate::child::ChildTask;
use crate::connections::Connections;
use crate::game::GameHistory;
use crate::io::{ClientId, DdsInput, Now, Output, StoredRead, log};
use crate::params::TabletBridgeParams;
use crate::proposal::Proposals;
use crate::protocol::{ClientMessage, CommandKind, Role, ServerMessage};
use crate::therapist::{CommandFields, Commands, Made};
use crate::watch::GameManagerWatch;
use child_sessions::UserId;
use qt_therapy_msgs::GameState;
use std::time::Duration;
use tracing::Level;

/// The bridge's state between messages.
pub struct Bridge {
    params: TabletBridgeParams,
    connections: Connections,
    /// The game's state, as the game manager last published it.
    game: Option<GameState>,
    history: GameHistory,
    task: ChildTask,
    proposals: Proposals,
    commands: Commands,
    gm_watch: GameManagerWatch,
}

impl Bridge {
    /// A bridge with validated `params`, started at `now`.
    pub fn new(params: TabletBridgeParams, now: Now) -> Self {
        Bridge {
            connections: Connections::new(&params, now),
            gm_watch: GameManagerWatch::new(params.game_manager_loss_timeout_s),
            params,
            game: None,
            history: GameHistory::default(),
            task: ChildTask::default(),
            proposals: Proposals::default(),
            commands: Commands::default(),
        }
    }

    /// A page connected. Refused (with the reason) when too many are connected.
    pub fn connect(&mut self, role: Role, now: Now) -> Result<(ClientId, Vec<Output>), String> {
        let id = self.connections.open(role, &self.params, now)?;
        let mut out = vec![log(Level::INFO, format!("page {id} ({role:?}) connected"))];
        match role {
            Role::Child => {
                if let Some(v) = self.gm_watch.child_view(self.game.as_ref()) {
                    out.push(Output::Send(id, ServerMessage::Game(v)));
                }
                out.push(Output::Send(id, self.task.message()));
            }
            Role::Therapist => out.push(Output::Send(id, ServerMessage::LoginRequired)),
        }
        Ok((id, out))
    }

    pub fn disconnect(&mut self, id: ClientId) -> Vec<Output> {
        match self.connections.close(id) {
            Some(role) => vec![log(
                Level::INFO,
                format!("page {id} ({role:?}) disconnected"),
            )],
            None => Vec::new(),
        }
    }

    /// A binary WebSocket frame: the pages never send one.
    pub fn ws_binary(&mut self, id: ClientId, len: usize, now: Now) -> Vec<Output> {
        let mut out = Vec::new();
        self.connections
            .binary(id, len, &self.params, now, &mut out);
        out
    }

    /// A text WebSocket message from page `id`.
    pub fn ws_text(&mut self, id: ClientId, text: &str, now: Now) -> Vec<Output> {
        let mut out = Vec::new();
        if let Some(message) = self.connections.text(id, text, &self.params, now, &mut out) {
            self.handle(id, message, now, &mut out);
        }
        out
    }

    fn handle(&mut self, id: ClientId, message: ClientMessage, now: Now, out: &mut Vec<Output>) {
        let Some(role) = self.connections.role(id) else {
            return;
        };
        match (role, message) {
            (
                Role::Child,
                ClientMessage::Answer {
                    sequence_id,
                    answer,
                    response_time,
                },
            ) => self.answer(id, sequence_id, answer, response_time, now, out),
            (Role::Therapist, ClientMessage::Login { pin }) => self.login(id, &pin, now, out),
            (
                Role::Therapist,
                ClientMessage::Command {
                    pin,
                    command,
                    user_id,
                    cluster,
                    level,
                    proposal,
                },
            ) => {
                let fields = CommandFields {
                    user_id,
                    cluster,
                    level,
                    proposal,
                };
                self.command(id, &pin, command, fields, now, out)
            }
            (Role::Therapist, ClientMessage::Children { pin }) => {
                if self
                    .connections
                    .may_command(id, &pin, &self.params, now, out)
                {
                    out.push(Output::Read(id, StoredRead::Children));
                }
            }
            (Role::Therapist, ClientMessage::NewChild { pin, user_id }) => {
                if self
                    .connections
                    .may_command(id, &pin, &self.params, now, out)
                {
                    match UserId::new(&user_id) {
                        Ok(user) => out.push(Output::Send(
                            id,
                            ServerMessage::ChildChecked {
                                user_id: user.as_str().to_string(),
                            },
                        )),
                        Err(e) => self.connections.reject(id, e.to_string(), out),
                    }
                }
            }
            (Role::Therapist, ClientMessage::Progress { pin, user_id }) => {
                if self
                    .connections
                    .may_command(id, &pin, &self.params, now, out)
                {
                    match UserId::new(&user_id) {
                        Ok(user) => out.push(Output::Read(id, StoredRead::Progress(user))),
                        Err(e) => self.connections.reject(id, e.to_string(), out),
                    }
                }
            }
            (role, message) => {
                let kind = match message {
                    ClientMessage::Answer { .. } => "answers",
                    ClientMessage::Login { .. } => "logins",
                    ClientMessage::Command { .. } => "commands",
                    ClientMessage::Children { .. }
                    | ClientMessage::NewChild { .. }
                    | ClientMessage::Progress { .. } => "requests for children's data",
                };
                let page = if role == Role::Child {
                    "child"
                } else {
                    "therapist"
                };
                let reason = format!("the {page} page cannot send {kind}");
                self.connections.reject(id, reason, out);
            }
        }
    }

    /// A message from the game side.
    pub fn dds(&mut self, input: DdsInput, now: Now) -> Vec<Output> {
        let mut out = Vec::new();
        match input {
            DdsInput::GameState(g) => {
                self.commands.follow_game(&g);
                self.proposals.follow_game(&g, now.monotonic);
                let closed = self.task.follow_game(&g);
                self.game = Some(g);
                self.gm_watch.state_arrived();
                self.show_game(&mut out);
                if let Some(reason) = closed {
                    self.broadcast(Role::Child, &ServerMessage::NoTask { reason }, &mut out);
                }
            }
            DdsInput::Proposal(p) => {
                let kept = self
                    .proposals
                    .arrive(p, self.game.as_ref(), now.monotonic, &mut out);
                if let Some(view) = kept {
                    self.broadcast(Role::Therapist, &ServerMessage::Proposal(view), &mut out);
                }
            }
            DdsInput::Task(t) => {
                if let Some(view) = self.task.arrive(t, self.game.as_ref(), now, &mut out) {
                    self.broadcast(Role::Child, &ServerMessage::Task(view), &mut out);
                }
            }
            DdsInput::Decision(d) => {
                let view = self.history.decision(&d);
                self.broadcast(Role::Therapist, &ServerMessage::Decision(view), &mut out);
            }
            DdsInput::Result(r) => {
                let view = self.history.result(r);
                self.broadcast(Role::Therapist, &ServerMessage::Result(view), &mut out);
            }
            DdsInput::Heartbeat(hb) => {
                if self.gm_watch.heartbeat(&hb, now.monotonic, &mut out) {
                    self.show_game(&mut out);
                }
                if self.gm_watch.follow_twins(now.monotonic) {
                    self.show_game(&mut out);
                }
            }
            DdsInput::Engagement(e) => {
                let limit = self.params.engagement_history;
                let point = self.history.engagement(&e, limit);
                self.broadcast(Role::Therapist, &ServerMessage::Engagement(point), &mut out);
            }
        }
        out
    }

    /// When [`Bridge::tick`] must next be called (monotonic), if at all.
    pub fn next_deadline(&self) -> Option<Duration> {
        self.gm_watch.next_deadline()
    }

    /// The clock reached a deadline of [`Bridge::next_deadline`].
    pub fn tick(&mut self, now: Now) -> Vec<Output> {
        let mut out = Vec::new();
        if self.gm_watch.tick(now.monotonic, &mut out) {
            self.show_game(&mut out);
        }
        out
    }

    /// A child page's answer: published when it counts, refused with the reason otherwise.
    fn answer(
        &mut self,
        id: ClientId,
        sequence_id: u32,
        answer: Vec<String>,
        response_time: f64,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        let lost = self.gm_watch.lost();
        let game = self.game.as_ref();
        let message = match self
            .task
            .answer(sequence_id, &answer, response_time, game, lost, now)
        {
            Ok(message) => message,
            Err(reason) => {
                self.connections.reject(id, reason, out);
                return;
            }
        };
        out.push(log(
            Level::INFO,
            format!(
                "page {id}: answer to sequence {sequence_id} of session {:?} sent: {:?}",
                message.session_id, message.answer
            ),
        ));
        out.push(Output::Send(
            id,
            ServerMessage::Accepted {
                what: "answer".into(),
            },
        ));
        // Another child page showing the same task now has nothing to answer.
        let done = ServerMessage::NoTask {
            reason: "answered".into(),
        };
        self.connections.send_to(Role::Child, Some(id), &done, out);
        out.push(Output::Answer(message));
    }

    /// A therapist page's login with the PIN: once in, it gets what a therapist page shows.
    fn login(&mut self, id: ClientId, pin: &str, now: Now, out: &mut Vec<Output>) {
        if self.connections.log_in(id, pin, &self.params, now, out) {
            self.therapist_snapshot(id, now, out);
        }
    }

    /// A therapist page's command: published when the page is logged in, the PIN is right
    /// and the command fits (`therapist`, and `proposal` for an answer to a proposal).
    fn command(
        &mut self,
        id: ClientId,
        pin: &str,
        kind: CommandKind,
        fields: CommandFields,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        if !self
            .connections
            .may_command(id, pin, &self.params, now, out)
        {
            return;
        }
        let made = self
            .commands
            .session_for(kind, &fields, self.game.as_ref(), now)
            .and_then(|session| {
                self.proposals
                    .check_answer(kind, fields.proposal, &session)
                    .map(|()| session)
            })
            .and_then(|session| self.commands.make(kind, session, fields, now));
        let command = match made {
            Ok(Made::Command(command)) => command,
            Ok(Made::EmergencyStopRepeated) => {
                let what = "emergency stop (already sent)".to_string();
                out.push(Output::Send(id, ServerMessage::Accepted { what }));
                return;
            }
            Err(reason) => {
                self.connections.reject(id, reason, out);
                return;
            }
        };
        let session = &command.session_id;
        out.push(log(
            Level::INFO,
            format!(
                "page {id}: command {} ({kind:?}) sent for session {session:?}",
                command.command_id
            ),
        ));
        let sent = ServerMessage::CommandSent {
            command: kind,
            session_id: session.clone(),
            command_id: command.command_id,
        };
        self.broadcast(Role::Therapist, &sent, out);
        out.push(Output::Command(command));
    }

    /// Sends `message` to every child page, or every logged-in therapist page.
    fn broadcast(&self, role: Role, message: &ServerMessage, out: &mut Vec<Output>) {
        self.connections.broadcast(role, message, out);
    }

    /// Everything a therapist page shows, for one that just logged in.
    fn therapist_snapshot(&self, id: ClientId, now: Now, out: &mut Vec<Output>) {
        out.push(Output::Send(id, ServerMessage::LoggedIn));
        if let Some(v) = self.gm_watch.therapist_view(self.game.as_ref()) {
            out.push(Output::Send(id, ServerMessage::Game(v)));
        }
        let points = self.history.engagement.iter().cloned().collect();
        out.push(Output::Send(
            id,
            ServerMessage::EngagementHistory { points },
        ));
        for d in &self.history.decisions {
            out.push(Output::Send(id, ServerMessage::Decision(d.clone())));
        }
        for r in &self.history.results {
            out.push(Output::Send(id, ServerMessage::Result(r.clone())));
        }
        // Only a proposal still waiting for an answer: a settled one is history.
        let open = self.proposals.open_view(self.game.as_ref(), now.monotonic);
        if let Some(p) = open {
            out.push(Output::Send(id, ServerMessage::Proposal(p)));
        }
    }

    /// Sends both pages the game as it now stands.
    fn show_game(&self, out: &mut Vec<Output>) {
        let game = self.game.as_ref();
        if let Some(v) = self.gm_watch.therapist_view(game) {
            self.broadcast(Role::Therapist, &ServerMessage::Game(v), out);
        }
        if let Some(v) = self.gm_watch.child_view(game) {
            self.broadcast(Role::Child, &ServerMessage::Game(v), out);
        }
    }
}

#[cfg(test)]
mod tests;
