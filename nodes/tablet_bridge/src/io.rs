//! What the bridge's sans-IO core takes and gives: the time its caller tells it, the DDS
//! messages it listens to, and what it asks its shell to do (send to a page, close one,
//! publish, log). Every part of the core speaks these; none of them knows the others.

use crate::protocol::ServerMessage;
use qt_therapy_msgs::{
    ActionProposal, Decision, ExpectedEngagement, GameState, Heartbeat, SequenceResult,
    TabletAnswer, TabletTask, TherapistCommand,
};
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
    /// Read what is stored for a page (off the core: files), and send it the answer.
    Read(ClientId, StoredRead),
}

/// What a therapist page asked of the stored sessions.
#[derive(Debug, Clone, PartialEq)]
pub enum StoredRead {
    /// The children the robot knows.
    Children,
    /// One child's progress.
    Progress(child_sessions::UserId),
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
