//! The session state machine, sans-IO: `handle(input, now)` returns what to do, in order.
//! One session at a time: decide (policy, override or fallback) -> feedback -> say the
//! sequence -> tablet task -> answer or timeout -> score with engagement -> next, x omega.
//! The therapist can start, pause, resume, stop, override the next level or emergency-stop
//! (`commands`). A watched node that stops its heartbeat holds the session, with the robot
//! silent (`watch`). A session a killed node left unfinished is taken over, paused
//! (`recover`). A decision the policy is unsure of is proposed to the therapist first
//! (`propose`). The phase changes in two places: the session's (start, pause, hold, resume,
//! end) in `session`, a sequence's (feedback, words, task, answer, score, next) in `play`.

mod commands;
mod decide;
mod disk;
pub(crate) mod parameters;
mod play;
mod propose;
mod recover;
mod robot;
mod session;
#[cfg(test)]
mod tests;
mod timers;
mod watch;

pub use session::RECOVERED_STATUS;

use crate::params::{GameManagerParams, ParamError};
use crate::protocol::{Input, LogLevel, Now, Output};
use crate::sequence::SessionRng;
use crate::session_file::SessionEnd;
use crate::utterances::Utterances;
use clock_steps::ClockSteps;
use heartbeat_watch::{HeartbeatWatch, Twins};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::{ExpectedEngagement, GameState, SequenceResult};
use sequence_game::{Action, Emotion, Feedback, Level, State};
use session_tally::EngagementLog;
use std::collections::BTreeSet;
use timers::{Fired, Timer, Timers};

/// Where the game is (the GameState phase follows from it, PAUSED aside).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Idle,
    /// Saying the intro or a reaction, and getting the next action.
    Deciding,
    GivingFeedback,
    SayingSequence,
    WaitingForAnswer,
    /// Answer in (or timed out); waiting for the last engagement windows of the period.
    Settling,
    Ended(SessionEnd),
}

/// The action chosen for the current sequence, and why.
#[derive(Debug, Clone, PartialEq)]
struct Plan {
    action: Action,
    level: Level,
    feedback: Feedback,
    overridden: bool,
    fallback: bool,
    reason: String,
}

/// Whether the current sequence waited for a silent policy.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
enum PolicySilence {
    #[default]
    NotWaited,
    Waiting,
    Waited,
}

/// The sequence being set up or played.
#[derive(Debug, Clone, Default)]
struct Current {
    request_id: Option<u64>,
    /// The policy's deadline ran out while its heartbeat was silent: its next heartbeat asks
    /// it again (its loss holds the session instead). Once a sequence, so a policy that
    /// keeps missing deadlines cannot postpone the fallback for ever.
    policy_silence: PolicySilence,
    plan: Option<Plan>,
    speech_done: bool,
    feedback_line: Option<usize>,
    sequence: Vec<Emotion>,
    words_started_ns: i64,
    sequence_id: u32,
    task_sent_ns: i64,
    answer_deadline_ns: i64,
    /// Answer time left, while paused.
    answer_left_ns: Option<i64>,
    answer: Option<Vec<Emotion>>,
    response_time: f32,
    answered_ns: i64,
    timed_out: bool,
    rejected_answers: u32,
}

/// The session under way, or the last one.
#[derive(Debug, Clone)]
struct Session {
    id: String,
    user_id: String,
    cluster: i32,
    last_command_id: u64,
    rng: SessionRng,
    /// MDP state before the next action.
    state: State,
    /// 1-based index of the current sequence.
    index: u8,
    next_sequence_id: u32,
    /// The action the therapist set for a sequence.
    pending_override: Option<PendingOverride>,
    paused_since: Option<i64>,
    /// Held since then because a watched node is lost (a pause the therapist did not ask for).
    held_since: Option<i64>,
    /// Start of the current engagement period: end of the previous answer, or session start.
    talk_start_ns: i64,
    started_ns: i64,
    results: Vec<SequenceResult>,
    /// The last task closed (answered or timed out), to name late and repeated answers.
    closed_task: Option<(u32, bool)>,
    fallbacks: u32,
    overrides: u32,
    rejected_commands: u32,
    rejected_answers: u32,
}

/// An override waiting for its sequence's decision.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct PendingOverride {
    sequence_index: u8,
    action: Action,
    /// The command that set it (0: from a recovered journal): a proposal it replaces names it.
    command_id: u64,
}

/// The game manager core.
pub struct GameManager {
    params: GameManagerParams,
    utterances: Utterances,
    phase: Phase,
    session: Option<Session>,
    current: Current,
    used_sessions: BTreeSet<String>,
    engagement: EngagementLog,
    /// The timers set (`timers.rs`).
    timers: Timers,
    next_request_id: u64,
    /// The heartbeats of `watched_nodes`.
    watched: HeartbeatWatch,
    /// Watched names two processes beat under (a node started twice), as last shown.
    twins: Vec<Twins>,
    status: String,
    /// The therapist command answered last, as every GameState tells it.
    answered: CommandAnswer,
    /// The robot's steps and calls (`robot.rs`).
    robot: robot::RobotSteps,
    /// Supervised autonomy's proposals (`propose.rs`).
    proposals: propose::ProposalDesk,
    /// The wall clock's offset from the steady clock, and its steps: every time the core keeps
    /// is steady, and is stamped by the wall clock's offset now.
    clock: ClockSteps,
    /// The sessions' disk: free space and writes kept for want of it (`disk.rs`).
    disk: disk::DiskWatch,
    out: Vec<Output>,
}

/// What became of a therapist command (GameState's `command_*` fields).
#[derive(Debug, Clone, Default, PartialEq)]
struct CommandAnswer {
    session_id: String,
    command_id: u64,
    /// `GameState::COMMAND_*`
    outcome: u8,
    refusal: String,
}

impl GameManager {
    pub fn new(params: GameManagerParams) -> Result<Self, ParamError> {
        params.validate()?;
        let robot = robot::RobotSteps::new(params.robot.backend()?);
        let proposals = propose::ProposalDesk::new(&params.supervision, params.timing.time_scale);
        let watched = HeartbeatWatch::with_timeout_s(
            params.reliability.watched_nodes.iter().cloned(),
            params.reliability.node_loss_timeout_s,
        );
        Ok(GameManager {
            utterances: Utterances::from_params(&params.lines),
            params,
            phase: Phase::Idle,
            session: None,
            current: Current::default(),
            used_sessions: BTreeSet::new(),
            engagement: EngagementLog::default(),
            timers: Timers::new(),
            next_request_id: 1,
            watched,
            twins: Vec::new(),
            status: "waiting for a therapist to start a session".into(),
            answered: CommandAnswer::default(),
            robot,
            proposals,
            clock: ClockSteps::new(),
            disk: disk::DiskWatch::default(),
            out: Vec::new(),
        })
    }

    pub fn params(&self) -> &GameManagerParams {
        &self.params
    }

    /// The first state to publish (transient-local, so consoles see an idle game at once).
    pub fn initial_outputs(&mut self, now: impl Into<Now>) -> Vec<Output> {
        let now = self.read_clocks(now.into());
        self.publish_state(now);
        std::mem::take(&mut self.out)
    }

    /// The session under way or last played, and its current sequence (for log spans).
    pub fn session_id(&self) -> Option<&str> {
        self.session.as_ref().map(|s| s.id.as_str())
    }

    pub fn sequence_index(&self) -> u8 {
        self.session.as_ref().map_or(0, |s| s.index)
    }

    /// True while a session runs (not idle, not ended).
    pub fn session_running(&self) -> bool {
        !matches!(self.phase, Phase::Idle | Phase::Ended(_))
    }

    /// Feeds one input at `now`; returns what to do, in order.
    pub fn handle(&mut self, input: Input, now: impl Into<Now>) -> Vec<Output> {
        let now = self.read_clocks(now.into());
        match input {
            Input::Command(c) => self.on_command(c, now),
            Input::Answer(a) => self.on_answer(a, now),
            Input::Engagement(e) => {
                if self.session_running() {
                    let e = self.on_steady_clock(e, now);
                    self.engagement.push(&e);
                }
            }
            Input::Decision {
                request_id,
                response,
            } => self.on_decision(request_id, Ok(response), now),
            Input::DecisionFailed { request_id, reason } => {
                self.on_decision(request_id, Err(reason), now)
            }
            Input::Heartbeat(hb) => self.on_heartbeat(hb, now),
            Input::TimerFired { id } => match self.timers.fired(id) {
                Fired::Watchdog => self.on_watchdog(now),
                Fired::Game(timer) => self.on_timer(timer, now),
                Fired::Stale => {}
            },
            Input::RobotDone { step } => self.on_robot_done(step, now),
            Input::RobotFailed { step, reason } => self.on_robot_failed(step, &reason, now),
            Input::RobotUnheard { reason } => {
                self.out.push(Output::Alarm(reason.clone()));
                self.status = reason;
                self.publish_state(now);
            }
            Input::Shutdown { reason } => {
                if self.session_running() {
                    self.end_session(SessionEnd::NodeShutdown, &reason, now);
                }
            }
            Input::DiskSpace { free } => self.on_disk_space(free, now),
            Input::FilesUnsaved { unsaved, reason } => self.on_files_unsaved(unsaved, reason, now),
        }
        self.settle_robot();
        std::mem::take(&mut self.out)
    }

    /// Follows the wall clock's offset from the steady clock (a step is logged); returns the
    /// steady time, on which the core keeps every time.
    fn read_clocks(&mut self, now: Now) -> i64 {
        if let Some(step) = self.clock.observe(now.steady_ns, now.wall_ns) {
            self.log(
                LogLevel::WARN,
                format!(
                    "the wall clock stepped {:+.3} s: timers and the session's times go on by \
                     the steady clock, stamps follow the wall clock",
                    step.by_ns as f64 * 1e-9
                ),
            );
        }
        now.steady_ns
    }

    /// A stamp for steady time `steady_ns`: the wall clock's reading for it now.
    fn stamp(&self, steady_ns: i64) -> Time {
        Time::from_nanos(self.clock.wall_of(steady_ns))
    }

    /// A second of engagement, stamped by the classifier's wall clock, with its window moved
    /// onto the steady clock (on the right side of a step of the wall clock), where the
    /// sequences' periods are.
    fn on_steady_clock(&self, mut e: ExpectedEngagement, now: i64) -> ExpectedEngagement {
        let (start, end) = (e.window_start.to_nanos(), e.window_end.to_nanos());
        let mid = start + (end - start) / 2;
        let shift = self.clock.steady_of(mid, now) - mid;
        e.window_start = Time::from_nanos(start + shift);
        e.window_end = Time::from_nanos(end + shift);
        e
    }

    /// What a game timer (or the robot step it stood for) sets off.
    fn on_timer(&mut self, timer: Timer, now: i64) {
        match timer {
            Timer::PolicyDeadline { request_id } => self.on_policy_deadline(request_id, false, now),
            Timer::PolicyHeartbeatLook { request_id } => {
                self.on_policy_deadline(request_id, true, now)
            }
            Timer::SpeechDone => self.speech_done(now),
            Timer::FeedbackDone => self.start_words(now),
            Timer::Word(i) => self.say_word(i),
            Timer::SequenceSaid => self.send_task(now),
            Timer::AnswerTimeout => self.answer_timed_out(now),
            Timer::Settled => self.finalize(now, true),
            Timer::ProposalRunsOut => self.on_proposal_runs_out(now),
        }
    }

    fn sequences(&self) -> u8 {
        self.params.session.sequences_per_session as u8
    }

    fn scaled_ns(&self, seconds: f64) -> i64 {
        (seconds * self.params.timing.time_scale * 1e9).round() as i64
    }

    fn set_timer(&mut self, timer: Timer, at_ns: i64) {
        let set = self.timers.set(timer, at_ns);
        self.out.push(set);
    }

    /// Forgets timers of one kind (they still fire, and are then ignored).
    fn drop_timers(&mut self, keep: impl Fn(&Timer) -> bool) {
        self.timers.forget_unless(keep);
    }

    fn paused(&self) -> bool {
        self.session
            .as_ref()
            .is_some_and(|s| s.paused_since.is_some() || s.held_since.is_some())
    }

    fn log(&mut self, level: LogLevel, message: String) {
        self.out.push(Output::Log { level, message });
    }

    fn set_phase(&mut self, phase: Phase, status: String, now: i64) {
        self.phase = phase;
        self.status = status;
        self.publish_state(now);
    }

    /// A rejected input: counted, logged, and shown in GameState.status.
    fn reject(&mut self, what: String, now: i64) {
        self.log(LogLevel::WARN, format!("rejected {what}"));
        self.status = format!("rejected {what}");
        self.publish_state(now);
    }

    fn publish_state(&mut self, now: i64) {
        let phase = if self.paused() && self.session_running() {
            GameState::PAUSED
        } else {
            match self.phase {
                Phase::Idle => GameState::IDLE,
                Phase::Deciding => GameState::DECIDING,
                Phase::GivingFeedback => GameState::GIVING_FEEDBACK,
                Phase::SayingSequence => GameState::SAYING_SEQUENCE,
                Phase::WaitingForAnswer | Phase::Settling => GameState::WAITING_FOR_ANSWER,
                Phase::Ended(SessionEnd::Finished) => GameState::FINISHED,
                Phase::Ended(SessionEnd::EmergencyStopped) => GameState::EMERGENCY_STOPPED,
                Phase::Ended(_) => GameState::STOPPED,
            }
        };
        let plan = self.current.plan.as_ref();
        // Which node is lost, or started twice, stays in view whatever else happens meanwhile.
        let lost = self.lost_names();
        let mut status = self.status.clone();
        if !self.twins.is_empty() {
            status = format!("{}; {status}", self.twins_text());
        }
        if !lost.is_empty() {
            status = format!("node lost: {lost}; {status}");
        }
        // The disk first: the page takes it out for its own warning (GameState::disk_warning).
        if let Some(warning) = self.disk_warning() {
            status = format!("{}{warning}; {status}", GameState::DISK_WARNING_PREFIX);
        }
        let answered = &self.answered;
        let msg = match &self.session {
            None => GameState {
                header: Header::at(self.stamp(now)),
                phase,
                user_model_cluster: -1,
                status: status.clone(),
                command_session_id: answered.session_id.clone(),
                command_id: answered.command_id,
                command_outcome: answered.outcome,
                command_refusal: answered.refusal.clone(),
                ..Default::default()
            },
            Some(s) => GameState {
                header: Header::at(self.stamp(now)),
                phase,
                session_id: s.id.clone(),
                user_id: s.user_id.clone(),
                user_model_cluster: s.cluster,
                sequence_index: s.index,
                level: plan.map_or(s.state.level, |p| p.level.get()),
                feedback: plan.map_or(s.state.feedback, |p| p.feedback) as u8,
                last_score: s.state.previous_score,
                policy_fallback: plan.is_some_and(|p| p.fallback),
                status: status.clone(),
                sequences_planned: self.sequences(),
                command_session_id: answered.session_id.clone(),
                command_id: answered.command_id,
                command_outcome: answered.outcome,
                command_refusal: answered.refusal.clone(),
            },
        };
        self.out.push(Output::State(msg));
    }
}
