//! What goes into and comes out of the game manager's core: messages (heartbeats among them),
//! service answers and timer firings in; robot acts, tablet tasks, game states, results,
//! service requests, timer requests, session-file records and log lines out. Time is given as
//! both clocks' readings ([`Now`]); the core keeps every time of its own, timers included, on
//! the steady one.

use crate::session_file::{JournalEntry, SequenceRecord, SessionSummary};
use qt_therapy_msgs::{
    ActionProposal, DecideActionRequest, DecideActionResponse, ExpectedEngagement, GameState,
    Heartbeat, SequenceResult, TabletAnswer, TabletTask, TherapistCommand,
};

/// The time of an input, in nanoseconds since the epoch: the steady clock, which never steps
/// (timers, durations, the session's times, engagement periods), and the wall clock, which
/// stamps the messages (docs/contract.md, "Time"), read together (`node_shell::Clock`). A replay
/// or a test gives one reading for both (`From<i64>`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Now {
    pub steady_ns: i64,
    pub wall_ns: i64,
}

impl From<i64> for Now {
    fn from(t: i64) -> Now {
        Now {
            steady_ns: t,
            wall_ns: t,
        }
    }
}

impl Now {
    /// Both clocks of `clock`, now.
    pub fn of(clock: &node_shell::Clock) -> Now {
        Now {
            steady_ns: clock.steady_nanos(),
            wall_ns: clock.now_nanos(),
        }
    }
}

/// One event for the core.
#[derive(Debug, Clone, PartialEq)]
pub enum Input {
    /// From the therapist tablet.
    Command(TherapistCommand),
    /// From the child tablet.
    Answer(TabletAnswer),
    /// From the engagement classifier.
    Engagement(ExpectedEngagement),
    /// The policy answered the request `request_id`.
    Decision {
        request_id: u64,
        response: DecideActionResponse,
    },
    /// The call for `request_id` failed (no server, transport error, the caller's deadline).
    DecisionFailed { request_id: u64, reason: String },
    /// A node's heartbeat, at its arrival time (the core watches `watched_nodes`).
    Heartbeat(Heartbeat),
    /// A timer the core asked for with [`Output::SetTimer`] is due.
    TimerFired { id: u64 },
    /// `qtrobot` backend: every robot call of the step [`Output::AwaitRobot`] named finished.
    RobotDone { step: u64 },
    /// `qtrobot` backend: a call of the step failed or was not answered in time.
    RobotFailed { step: u64, reason: String },
    /// `topics` backend: the robot's speech subscriber (`robot_speech_node`) did not come; the
    /// reason is shown until the game's next change of state.
    RobotUnheard { reason: String },
    /// The node is going down: save the session.
    Shutdown { reason: String },
    /// The free space on the disk of the sessions directory (bytes), as the node measured it.
    DiskSpace { free: u64 },
    /// Session-file writes the disk had no room for, kept in memory by the node until they
    /// can be made (0: all made since), and the last error.
    FilesUnsaved { unsaved: usize, reason: String },
}

/// Severity of a log line: tracing's own, so every node's shell logs a core's lines alike
/// (`node_shell::logging::log_at`).
pub use tracing::Level as LogLevel;

/// One thing the core wants done, in order.
#[derive(Debug, Clone, PartialEq)]
pub enum Output {
    /// Speech (`/qt_robot/speech/say`, or the robot's say service).
    Say(String),
    /// Stop speaking at once, cutting short what is being said (the robot's stop or cancel
    /// service; on the speech topic, the empty utterance: `node::robot`).
    Silence,
    /// `/qt_robot/emotion/show`, e.g. `QT/happy`.
    ShowEmotion(String),
    /// `/qt_robot/gesture/play`.
    PlayGesture(String),
    /// `qtrobot` backend: the robot acts put out since the previous `AwaitRobot` (or since the
    /// start of this batch of outputs) are one step; answer with `Input::RobotDone` once every
    /// call of it has returned, or `Input::RobotFailed`. `qtrobot_ros2`: always one act, and
    /// the next goes out only once this one is answered.
    AwaitRobot {
        step: u64,
    },
    Task(TabletTask),
    State(GameState),
    /// A proposal to the therapist, or what became of it (supervised autonomy).
    Proposal(ActionProposal),
    Result(SequenceResult),
    /// Call DecideAction; the core falls back on its own at `deadline_ns`.
    Decide {
        request_id: u64,
        request: DecideActionRequest,
        deadline_ns: i64,
    },
    /// Feed back `Input::TimerFired { id }` at `at_ns` (stale timers are ignored by the core,
    /// so there is nothing to cancel).
    SetTimer {
        id: u64,
        at_ns: i64,
    },
    /// Append to the session file and fsync before anything after it.
    Record(Box<SequenceRecord>),
    /// Append to the session's journal and fsync before anything after it (start, commands
    /// carried out, tasks: what a restarted node needs to go on without repeating any).
    Journal(Box<JournalEntry>),
    /// Write the session summary.
    Summary(Box<SessionSummary>),
    /// A line for the operator (a session started, each sequence scored, a node back, the
    /// session's end): logged once.
    LiveLine(String),
    /// A line for the operator that needs a person (a node lost, two processes beating as
    /// one node, the robot did not finish, a session taken over): logged once, as a warning.
    Alarm(String),
    Log {
        level: LogLevel,
        message: String,
    },
}

impl Output {
    /// True for what makes the robot act (speech, silence, face, gesture).
    pub fn is_robot(&self) -> bool {
        matches!(
            self,
            Output::Say(_) | Output::Silence | Output::ShowEmotion(_) | Output::PlayGesture(_)
        )
    }
}
