//! The bridge's sans-IO core. It is fed page messages (per connection), DDS messages and the
//! time, and returns what to publish on DDS and what to send to which page. Everything a
//! tablet sends is checked here: rate, size, schema, PIN, and the game it refers to.

use crate::limits::TokenBucket;
use crate::params::TabletBridgeParams;
use crate::proposal::KeptProposal;
use crate::protocol::{
    ClientMessage, CommandKind, DecisionView, EngagementPoint, ResultView, Role, ServerMessage,
    TaskView, parse_client_message,
};
use crate::therapist::CommandIds;
use crate::watch::GameManagerWatch;
use qt_therapy_msgs::{
    ActionProposal, Decision, ExpectedEngagement, GameState, Heartbeat, SequenceResult,
    TabletAnswer, TabletTask, TherapistCommand,
};
use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;
use tracing::Level;

/// One WebSocket connection, numbered by the bridge.
pub type ClientId = u64;

/// The time, as the caller's clock tells it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Now {
    /// Monotonic time (rate limits, timeouts).
    pub monotonic: Duration,
    /// Wall-clock nanoseconds since the epoch (message headers, session and command ids).
    pub wall_nanos: i64,
}

/// What the core asks its shell to do.
#[derive(Debug, Clone, PartialEq)]
pub enum Output {
    Send(ClientId, ServerMessage),
    /// Close the connection; the reason was already sent as a `rejected` message.
    Close(ClientId, String),
    Command(TherapistCommand),
    Answer(TabletAnswer),
    /// A line for the log (the shell logs it with `node_shell::logging::log_at`).
    Log(Level, String),
}

/// A log line as an output.
pub(crate) fn log(level: Level, message: String) -> Output {
    Output::Log(level, message)
}

/// A DDS message the bridge listens to.
#[derive(Debug, Clone)]
pub enum DdsInput {
    GameState(GameState),
    Task(TabletTask),
    Decision(Decision),
    Engagement(ExpectedEngagement),
    Result(SequenceResult),
    /// The game manager's proposal (supervised autonomy), for the therapist page only.
    Proposal(ActionProposal),
    /// Any node's heartbeat; the game manager's are watched.
    Heartbeat(Heartbeat),
}

/// At most one "too many messages" notice per connection per this long.
const NOTICE_INTERVAL: Duration = Duration::from_secs(1);

pub(crate) struct Client {
    pub role: Role,
    bucket: TokenBucket,
    pub logged_in: bool,
    pub pin_failures: u32,
    dropped_in_a_row: u32,
    last_notice: Option<Duration>,
}

pub(crate) struct OpenTask {
    pub task: TabletTask,
    pub received: Duration,
    pub answered: bool,
}

/// The bridge's state between messages.
pub struct Bridge {
    pub(crate) params: TabletBridgeParams,
    pub(crate) clients: BTreeMap<ClientId, Client>,
    next_id: ClientId,
    pub(crate) game: Option<GameState>,
    pub(crate) task: Option<OpenTask>,
    /// (session, sequence_id) of the newest task seen, so re-delivered tasks stay closed.
    pub(crate) last_task: Option<(String, u32)>,
    pub(crate) engagement: VecDeque<EngagementPoint>,
    pub(crate) decisions: VecDeque<DecisionView>,
    pub(crate) results: VecDeque<ResultView>,
    /// The results of the session the newest result belongs to, for its running tally.
    pub(crate) session_results: Vec<SequenceResult>,
    /// The newest proposal of the game's session, open or settled.
    pub(crate) proposal: Option<KeptProposal>,
    /// Every proposal message taken, by the suite's rule for what arrives twice
    /// (`session_log`): one delivered again must not start its countdown again.
    pub(crate) proposals_taken: session_log::Once<ActionProposal>,
    /// The session commands go to: the game's, or the one this bridge just started.
    pub(crate) current_session: Option<String>,
    pub(crate) command_ids: CommandIds,
    /// Wrong PINs left over all connections; refilled over a minute.
    pub(crate) pin_budget: TokenBucket,
    pub(crate) last_emergency_stop: Option<(String, Duration)>,
    pub(crate) gm_watch: GameManagerWatch,
}

impl Bridge {
    /// A bridge with validated `params`, started at `now`.
    pub fn new(params: TabletBridgeParams, now: Now) -> Self {
        let failures = f64::from(params.pin_max_failures);
        let gm_watch = GameManagerWatch::new(params.game_manager_loss_timeout_s);
        Bridge {
            pin_budget: TokenBucket::new(failures, failures / 60.0, now.monotonic),
            params,
            clients: BTreeMap::new(),
            next_id: 1,
            game: None,
            task: None,
            last_task: None,
            engagement: VecDeque::new(),
            decisions: VecDeque::new(),
            results: VecDeque::new(),
            session_results: Vec::new(),
            proposal: None,
            proposals_taken: session_log::Once::new(),
            current_session: None,
            command_ids: CommandIds::default(),
            last_emergency_stop: None,
            gm_watch,
        }
    }

    /// A page connected. Refused (with the reason) when too many are connected.
    pub fn connect(&mut self, role: Role, now: Now) -> Result<(ClientId, Vec<Output>), String> {
        if self.clients.len() >= self.params.max_clients {
            let reason = format!(
                "too many tablet connections (at most {})",
                self.params.max_clients
            );
            return Err(reason);
        }
        let id = self.next_id;
        self.next_id += 1;
        let burst = f64::from(self.params.ws_burst);
        self.clients.insert(
            id,
            Client {
                role,
                bucket: TokenBucket::new(burst, self.params.ws_messages_per_second, now.monotonic),
                logged_in: false,
                pin_failures: 0,
                dropped_in_a_row: 0,
                last_notice: None,
            },
        );
        let mut out = vec![log(Level::INFO, format!("page {id} ({role:?}) connected"))];
        match role {
            Role::Child => {
                if let Some(v) = self.child_view() {
                    out.push(Output::Send(id, ServerMessage::Game(v)));
                }
                out.push(Output::Send(id, self.child_task_message()));
            }
            Role::Therapist => out.push(Output::Send(id, ServerMessage::LoginRequired)),
        }
        Ok((id, out))
    }

    pub fn disconnect(&mut self, id: ClientId) -> Vec<Output> {
        match self.clients.remove(&id) {
            Some(c) => vec![log(
                Level::INFO,
                format!("page {id} ({:?}) disconnected", c.role),
            )],
            None => Vec::new(),
        }
    }

    /// A binary WebSocket frame: the pages never send one.
    pub fn ws_binary(&mut self, id: ClientId, len: usize, now: Now) -> Vec<Output> {
        let mut out = Vec::new();
        if self.take_token(id, now, &mut out) {
            self.reject(
                id,
                format!("binary messages ({len} bytes) are not accepted"),
                &mut out,
            );
        }
        out
    }

    /// A text WebSocket message from page `id`.
    pub fn ws_text(&mut self, id: ClientId, text: &str, now: Now) -> Vec<Output> {
        let mut out = Vec::new();
        let max = self.params.ws_max_message_bytes;
        if !self.take_token(id, now, &mut out) {
            // The emergency stop is never refused for rate: the therapist may be tapping it
            // while the connection is flooded.
            let emergency = text.len() <= max
                && matches!(
                    parse_client_message(text),
                    Ok(ClientMessage::Command {
                        command: CommandKind::EmergencyStop,
                        ..
                    })
                );
            if !emergency || !self.clients.contains_key(&id) {
                return out;
            }
        }
        if text.len() > max {
            let reason = format!(
                "message of {} bytes is over the limit of {max} bytes",
                text.len()
            );
            self.reject(id, reason, &mut out);
            return out;
        }
        match parse_client_message(text) {
            Err(reason) => self.reject(id, reason, &mut out),
            Ok(message) => self.handle(id, message, now, &mut out),
        }
        out
    }

    /// Takes a rate token for `id`; when there is none, counts the drop, sends a notice at
    /// most once a second and closes a connection that keeps flooding.
    fn take_token(&mut self, id: ClientId, now: Now, out: &mut Vec<Output>) -> bool {
        let (rate, burst) = (self.params.ws_messages_per_second, self.params.ws_burst);
        let max_dropped = self.params.ws_max_dropped_before_close;
        let Some(c) = self.clients.get_mut(&id) else {
            return false;
        };
        if c.bucket.try_take(now.monotonic) {
            c.dropped_in_a_row = 0;
            return true;
        }
        c.dropped_in_a_row += 1;
        if c.dropped_in_a_row >= max_dropped {
            let reason = format!("closed: {max_dropped} messages in a row over the rate limit");
            out.push(log(
                Level::WARN,
                format!("page {id} ({:?}): {reason}", c.role),
            ));
            out.push(Output::Send(
                id,
                ServerMessage::Rejected {
                    reason: reason.clone(),
                },
            ));
            out.push(Output::Close(id, reason));
            self.clients.remove(&id);
        } else if c
            .last_notice
            .is_none_or(|t| now.monotonic.saturating_sub(t) >= NOTICE_INTERVAL)
        {
            c.last_notice = Some(now.monotonic);
            let reason = format!(
                "too many messages: at most {rate} per second (bursts of {burst}); {} dropped",
                c.dropped_in_a_row
            );
            out.push(log(
                Level::WARN,
                format!("page {id} ({:?}): {reason}", c.role),
            ));
            out.push(Output::Send(id, ServerMessage::Rejected { reason }));
        }
        false
    }

    fn handle(&mut self, id: ClientId, message: ClientMessage, now: Now, out: &mut Vec<Output>) {
        let Some(role) = self.clients.get(&id).map(|c| c.role) else {
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
                let fields = crate::therapist::CommandFields {
                    user_id,
                    cluster,
                    level,
                    proposal,
                };
                self.command(id, &pin, command, fields, now, out)
            }
            (role, message) => {
                let kind = match message {
                    ClientMessage::Answer { .. } => "answers",
                    ClientMessage::Login { .. } => "logins",
                    ClientMessage::Command { .. } => "commands",
                };
                let page = if role == Role::Child {
                    "child"
                } else {
                    "therapist"
                };
                self.reject(id, format!("the {page} page cannot send {kind}"), out);
            }
        }
    }

    /// Refuses what page `id` sent: logged, and the reason goes back to the page.
    pub(crate) fn reject(&self, id: ClientId, reason: String, out: &mut Vec<Output>) {
        let role = self.clients.get(&id).map(|c| c.role);
        out.push(log(
            Level::WARN,
            format!("page {id} ({role:?}) rejected: {reason}"),
        ));
        out.push(Output::Send(id, ServerMessage::Rejected { reason }));
    }

    /// Sends `message` to every child page, or every logged-in therapist page.
    pub(crate) fn broadcast(&self, role: Role, message: &ServerMessage, out: &mut Vec<Output>) {
        for (id, c) in &self.clients {
            if c.role == role && (role == Role::Child || c.logged_in) {
                out.push(Output::Send(*id, message.clone()));
            }
        }
    }

    /// Everything a therapist page shows, for one that just logged in.
    pub(crate) fn therapist_snapshot(&self, id: ClientId, now: Now, out: &mut Vec<Output>) {
        out.push(Output::Send(id, ServerMessage::LoggedIn));
        if let Some(v) = self.therapist_view() {
            out.push(Output::Send(id, ServerMessage::Game(v)));
        }
        let points = self.engagement.iter().cloned().collect();
        out.push(Output::Send(
            id,
            ServerMessage::EngagementHistory { points },
        ));
        for d in &self.decisions {
            out.push(Output::Send(id, ServerMessage::Decision(d.clone())));
        }
        for r in &self.results {
            out.push(Output::Send(id, ServerMessage::Result(r.clone())));
        }
        // Only a proposal still waiting for an answer: a settled one is history.
        if let Some(p) = self.open_proposal_view(now) {
            out.push(Output::Send(id, ServerMessage::Proposal(p)));
        }
    }

    pub(crate) fn child_task_message(&self) -> ServerMessage {
        match &self.task {
            Some(t) if !t.answered => ServerMessage::Task(TaskView::of(&t.task)),
            Some(_) => ServerMessage::NoTask {
                reason: "answered".into(),
            },
            None => ServerMessage::NoTask {
                reason: "waiting".into(),
            },
        }
    }
}

#[cfg(test)]
mod tests;
