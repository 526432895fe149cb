//! The console's commands and its live view of a session, on any bus (`node_shell::Bus`: DDS
//! for the `therapist` command line, in process in the cross-node tests): each command is sent
//! until the game manager answers it, and `run_session` starts sessions and follows each to
//! its end, a line per step, sequence and proposal. Lines go to the caller's `say`.

use crate::proposals::{self, Proposals};
use anyhow::{Context, bail};
use node_shell::{Bus, Outbox};
use qt_therapy_msgs::topics::{
    ACTION_PROPOSAL, DECISION, GAME_STATE, SEQUENCE_RESULT, THERAPIST_COMMAND,
};
use qt_therapy_msgs::{
    ActionProposal, CommandOutcome, Decision, GamePhase, GameState, SequenceResult,
    TherapistCommand,
};
use session_log::{Arrival, Once};
use session_tally::live_line::{LAST_RESULT_GRACE, reason_from_messages, sequence_line};
use std::time::Duration;
use tokio::sync::mpsc::Receiver;
use tokio::time::Instant;

/// The node's name on the graph.
pub const NODE: &str = "therapist_console";

/// How long the console waits for the game manager to confirm a command before sending it
/// again, and how many times it sends one.
pub const CONFIRM_WAIT: Duration = Duration::from_secs(2);
pub const SENDS: u32 = 3;

/// A session to start.
#[derive(Debug, Clone)]
pub struct Start {
    /// The child's pseudonymous id.
    pub user: String,
    /// The user-model cluster (-1: the policy's default).
    pub cluster: i32,
    /// The session id [default: session-<seconds since the epoch>].
    pub session: Option<String>,
    /// How long to wait for the game manager to appear.
    pub wait: Duration,
}

/// How `run_session` follows its sessions.
#[derive(Debug, Clone, Copy)]
pub struct Follow {
    /// Give up on a session after this long.
    pub timeout: Duration,
    /// Sessions back to back (ids `<session>-00001`, ...); stops at the first that does not
    /// finish.
    pub sessions: u32,
    /// Accept each proposal at once, as a therapist who agrees with the robot.
    pub accept_proposals: bool,
}

/// The console on its bus: the command topic and what it follows.
pub struct Console<'a, B: Bus> {
    bus: &'a B,
    commands: Outbox<TherapistCommand>,
    states: Receiver<GameState>,
    results: Receiver<SequenceResult>,
    decisions: Receiver<Decision>,
    proposals: Receiver<ActionProposal>,
    say: Box<dyn FnMut(&str) + Send + 'a>,
    /// The last command id sent: ids only increase, even when the wall clock steps back.
    last_command_id: std::cell::Cell<u64>,
    /// The newest session id of this console or of the game manager's last state.
    last_session: Option<String>,
}

/// What the game manager did with a command.
#[derive(Debug, PartialEq)]
pub enum Answer {
    CarriedOut,
    Refused(String),
}

/// The answer to `c` that `s` carries, if it carries one: its typed fields, never its status
/// text. A repeat of a command carried out before is refused as such: it was carried out.
pub fn answer_to(c: &TherapistCommand, s: &GameState) -> Option<Answer> {
    if s.command_session_id != c.session_id || s.command_id != c.command_id {
        return None;
    }
    match CommandOutcome::try_from(s.command_outcome) {
        Ok(CommandOutcome::CarriedOut | CommandOutcome::AlreadyCarriedOut) => {
            Some(Answer::CarriedOut)
        }
        Ok(CommandOutcome::Refused) => Some(Answer::Refused(s.command_refusal.clone())),
        Ok(CommandOutcome::None) | Err(_) => None,
    }
}

/// The session id a START gets when none is given: `session-<seconds since the epoch>`, past
/// `last` (the console's previous one, or the game manager's last session) when that has the
/// same form, so a step back of the wall clock does not make an id the game manager has used
/// (it would refuse the START).
pub fn default_session_id(now_s: i64, last: Option<&str>) -> String {
    let last_s = last
        .and_then(|id| id.strip_prefix("session-"))
        .map(|rest| rest.split('-').next().unwrap_or(rest))
        .and_then(|digits| digits.parse::<i64>().ok());
    let s = last_s.map_or(now_s, |l| now_s.max(l.saturating_add(1)));
    format!("session-{s}")
}

/// The phase in words (`saying sequence`).
pub fn phase_name(phase: u8) -> String {
    GameState::phase_name(phase).replace('_', " ")
}

impl<'a, B: Bus> Console<'a, B> {
    /// Joins the command topic and the topics a session is followed on; `say` takes the
    /// console's lines.
    pub fn new(bus: &'a mut B, say: impl FnMut(&str) + Send + 'a) -> anyhow::Result<Self> {
        let commands = bus.publisher(THERAPIST_COMMAND)?;
        let states = bus.subscribe(GAME_STATE, 64)?;
        let results = bus.subscribe(SEQUENCE_RESULT, 64)?;
        let decisions = bus.subscribe(DECISION, 64)?;
        let proposals = bus.subscribe(ACTION_PROPOSAL, 64)?;
        Ok(Console {
            bus,
            commands,
            states,
            results,
            decisions,
            proposals,
            say: Box::new(say),
            last_command_id: std::cell::Cell::new(0),
            last_session: None,
        })
    }

    /// A command of `kind` for `session`; command ids only increase: milliseconds on the
    /// bus's wall clock, past the id before even when that clock steps back (the game manager
    /// refuses an id at or below the last it carried out).
    pub fn command(&self, kind: u8, session: &str) -> TherapistCommand {
        let clock = self.bus.clock();
        let millis = (clock.now_nanos() / 1_000_000).max(1) as u64;
        let command_id = millis.max(self.last_command_id.get() + 1);
        self.last_command_id.set(command_id);
        TherapistCommand {
            header: clock.header_now(),
            command: kind,
            session_id: session.to_string(),
            command_id,
            ..Default::default()
        }
    }

    /// Sends one command once a reader listens, then waits until the game manager answers
    /// it: a GameState whose `command_session_id` and `command_id` name it, with what became
    /// of it (`command_outcome`). The answer is needed because a reliable sample still misses
    /// a reader that matched after it was sent (the recorder may match first), or when this
    /// process exits before it was delivered: an override was once lost that way. An
    /// unanswered command is sent again with the same id, which the game manager never
    /// carries out twice (it answers a repeat of one it carried out as such). Returns the
    /// exit code: 0 carried out, 4 refused (the reason is said).
    pub async fn send(&mut self, c: TherapistCommand) -> anyhow::Result<i32> {
        if !self
            .commands
            .wait_for_subscribers(self.bus, Duration::from_secs(20))
            .await
        {
            bail!("no game manager is listening on {}", THERAPIST_COMMAND.name);
        }
        let tag = format!("command {}", c.command_id);
        for attempt in 1..=SENDS {
            self.commands.send(c.clone());
            let until = Instant::now() + CONFIRM_WAIT;
            while let Ok(Some(s)) = tokio::time::timeout_at(until, self.states.recv()).await {
                match answer_to(&c, &s) {
                    None => continue,
                    Some(Answer::CarriedOut) => return Ok(0),
                    Some(Answer::Refused(reason)) => {
                        (self.say)(&format!("{tag} refused: {reason}"));
                        return Ok(4);
                    }
                }
            }
            if attempt < SENDS {
                tracing::warn!(
                    "{tag} not answered by the game manager within {CONFIRM_WAIT:?}: sending it \
                     again"
                );
            }
        }
        bail!(
            "the game manager did not answer {tag} (session {:?}) after {SENDS} sends",
            c.session_id
        )
    }

    /// The START command, once the game manager is free (`check`; not needed when the session
    /// this console followed just finished).
    pub async fn start_command(
        &mut self,
        a: &Start,
        check: bool,
    ) -> anyhow::Result<TherapistCommand> {
        if check {
            let state = self.check_free(a).await?;
            if !state.session_id.is_empty() {
                self.last_session = Some(state.session_id);
            }
        }
        let session = a.session.clone().unwrap_or_else(|| {
            default_session_id(
                self.bus.clock().now_nanos() / 1_000_000_000,
                self.last_session.as_deref(),
            )
        });
        self.last_session = Some(session.clone());
        let mut c = self.command(TherapistCommand::START, &session);
        c.user_id = a.user.clone();
        c.user_model_cluster = a.cluster;
        Ok(c)
    }

    /// Fails when no game manager answers or it is busy with a session; its state otherwise.
    async fn check_free(&mut self, a: &Start) -> anyhow::Result<GameState> {
        // The game state is transient-local: a running game manager's last state arrives at
        // once.
        let state = tokio::time::timeout(a.wait, self.states.recv())
            .await
            .with_context(|| {
                format!(
                    "no game manager published {} within {} s",
                    GAME_STATE.name,
                    a.wait.as_secs()
                )
            })?
            .context("game state channel closed")?;
        // RustDDS hands a new transient-local reader every sample its writer still keeps for
        // a reader that has not acknowledged it yet (e.g. the console of the session before,
        // just gone), oldest first: the game's state now is the last that arrives in a short
        // while. (Not the newest stamp: a step back of the wall clock stamps it older.)
        let mut state = state;
        let settle = Instant::now() + Duration::from_millis(500);
        while let Ok(Some(s)) = tokio::time::timeout_at(settle, self.states.recv()).await {
            state = s;
        }
        if !matches!(
            GamePhase::try_from(state.phase),
            Ok(GamePhase::Idle
                | GamePhase::Finished
                | GamePhase::Stopped
                | GamePhase::EmergencyStopped)
        ) {
            bail!(
                "the game manager is busy with session {} (phase {}): stop it first",
                state.session_id,
                state.phase
            );
        }
        Ok(state)
    }

    /// Starts `follow.sessions` sessions one after the other and follows each to its end;
    /// the exit code: 0 when every one finished.
    pub async fn run_session(&mut self, start: &Start, follow: Follow) -> anyhow::Result<i32> {
        let mut code = 0;
        for k in 1..=follow.sessions {
            let mut c = self.start_command(start, k == 1).await?;
            if follow.sessions > 1 {
                c.session_id = format!("{}-{k:05}", c.session_id);
            }
            let session = c.session_id.clone();
            let start_id = c.command_id;
            code = self.send(c).await?;
            if code != 0 {
                break;
            }
            (self.say)(&format!(
                "session {session} started for user {} (cluster {})",
                start.user, start.cluster
            ));
            let proposals = Proposals::new(&session, follow.accept_proposals, start_id);
            code = self.follow(&session, proposals, follow.timeout).await?;
            if code != 0 {
                break;
            }
        }
        Ok(code)
    }

    /// Says the session's steps, a line per sequence and per proposal and its settlement,
    /// until the session ends; with `proposals` accepting, accepts each proposal (answers to
    /// those accepts come on the game states, read here as well).
    async fn follow(
        &mut self,
        session: &str,
        mut proposals: Proposals,
        timeout: Duration,
    ) -> anyhow::Result<i32> {
        let Console {
            bus,
            commands,
            states,
            results,
            decisions,
            proposals: proposal_messages,
            say,
            ..
        } = self;
        let clock = bus.clock();
        let carry_out = |events: Vec<proposals::Event>, say: &mut dyn FnMut(&str)| {
            for e in events {
                match e {
                    proposals::Event::Print(line) => say(&line),
                    proposals::Event::Send(c) => {
                        commands.send(c);
                    }
                }
            }
        };
        let deadline = tokio::time::sleep(timeout);
        tokio::pin!(deadline);
        let stop = bus.shutdown_signal();
        tokio::pin!(stop);
        let mut followed = Followed::new(session);
        let mut last_status = String::new();
        loop {
            let resend = proposals.next_send();
            // Far enough never to come: the branch is disabled without a send due.
            let resend_at = resend.map_or_else(|| Instant::now() + timeout, Instant::from_std);
            // Biased: what is ready is taken in this order, never by tokio's random pick, so
            // a run on the in-process bus is the same every time.
            tokio::select! {
                biased;
                _ = &mut stop => return Ok(130),
                _ = &mut deadline => {
                    say(&format!("session {session}: no end within {timeout:?}"));
                    return Ok(2);
                }
                Some(d) = decisions.recv() => followed.decision(d),
                Some(r) = results.recv() => if let Some(line) = followed.result(&r) {
                    say(&line);
                },
                Some(p) = proposal_messages.recv() => {
                    let now_ms = (clock.now_nanos() / 1_000_000).max(1) as u64;
                    carry_out(proposals.on_proposal(&p, Instant::now().into_std(), now_ms), say);
                }
                Some(s) = states.recv() => {
                    carry_out(proposals.on_state(&s), say);
                    if s.session_id != session { continue; }
                    if !s.status.is_empty() && s.status != last_status {
                        say(&format!("  [{}] {}", phase_name(s.phase), s.status));
                        last_status = s.status.clone();
                    }
                    match GamePhase::try_from(s.phase) {
                        Ok(GamePhase::Finished) => {
                            let grace = Instant::now() + LAST_RESULT_GRACE;
                            while followed.sequences() < usize::from(s.sequence_index) {
                                match tokio::time::timeout_at(grace, results.recv()).await {
                                    Ok(Some(r)) => if let Some(line) = followed.result(&r) {
                                        say(&line);
                                    },
                                    _ => break,
                                }
                            }
                            say(&format!(
                                "session {session} finished: {} sequences",
                                followed.sequences()
                            ));
                            return Ok(0);
                        }
                        Ok(GamePhase::Stopped | GamePhase::EmergencyStopped) => {
                            say(&format!("session {session} {}", phase_name(s.phase)));
                            return Ok(3);
                        }
                        _ => {}
                    }
                }
                _ = tokio::time::sleep_until(resend_at), if resend.is_some() => {
                    carry_out(proposals.on_tick(Instant::now().into_std()), say);
                }
            }
        }
    }
}

/// The results and decisions of the session `run_session` follows, each taken once by the
/// suite's rule for what arrives twice (`session_log`, docs/session_log.md): a result the
/// durable topic delivers again is neither said nor counted again.
#[derive(Debug)]
pub struct Followed {
    session: String,
    decisions: Vec<Decision>,
    decisions_taken: Once<Decision>,
    results: Once<SequenceResult>,
}

impl Followed {
    pub fn new(session: &str) -> Followed {
        Followed {
            session: session.to_string(),
            decisions: Vec::new(),
            decisions_taken: Once::new(),
            results: Once::new(),
        }
    }

    /// A decision on the topic: kept to explain its sequence's result.
    pub fn decision(&mut self, d: Decision) {
        if d.session_id == self.session
            && self.decisions_taken.arrive(&d, DECISION.name) == Ok(Arrival::New)
        {
            self.decisions.push(d);
        }
    }

    /// A result on the topic: the sequence's line the first time, nothing for a repeat or
    /// another session's, and what differs for a result that contradicts the first.
    pub fn result(&mut self, r: &SequenceResult) -> Option<String> {
        if r.session_id != self.session {
            return None;
        }
        match self.results.arrive(r, SEQUENCE_RESULT.name) {
            Ok(Arrival::New) => {
                let d = self
                    .decisions
                    .iter()
                    .rev()
                    .find(|d| d.step == r.sequence_index);
                Some(sequence_line(r, &reason_from_messages(r, d)))
            }
            Ok(Arrival::Repeat) => None,
            Err(conflict) => Some(format!("  {conflict}; the first is kept")),
        }
    }

    /// Sequences whose result came (each once).
    pub fn sequences(&self) -> usize {
        self.results.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pause(id: u64) -> TherapistCommand {
        TherapistCommand {
            command: TherapistCommand::PAUSE,
            session_id: "s1".into(),
            command_id: id,
            ..Default::default()
        }
    }

    fn state(session: &str, id: u64, outcome: u8, refusal: &str, status: &str) -> GameState {
        GameState {
            command_session_id: session.into(),
            command_id: id,
            command_outcome: outcome,
            command_refusal: refusal.into(),
            status: status.into(),
            ..Default::default()
        }
    }

    #[test]
    fn a_default_session_id_comes_after_the_last_one_when_the_clock_stepped_back() {
        assert_eq!(default_session_id(1000, None), "session-1000");
        assert_eq!(
            default_session_id(1000, Some("session-900")),
            "session-1000"
        );
        // An hour back: past the last session instead of one the game manager may have had.
        assert_eq!(
            default_session_id(1000, Some("session-4600")),
            "session-4601"
        );
        assert_eq!(
            default_session_id(1000, Some("session-4600-00003")),
            "session-4601"
        );
        assert_eq!(
            default_session_id(1000, Some("tablet-4600000")),
            "session-1000"
        );
    }

    #[tokio::test(start_paused = true)]
    async fn command_ids_only_increase_on_one_console() {
        let bus = node_shell::in_process::InProcessBus::new(node_shell::Clock::starting_at(
            1_000_000_000_000,
        ));
        let (mut node, _stop) = bus.join("therapist_console").expect("joins");
        let console = Console::new(&mut node, |_: &str| {}).expect("console");
        // The clock stands still: three commands within one millisecond.
        let ids: Vec<u64> = (0..3)
            .map(|_| console.command(TherapistCommand::PAUSE, "s1").command_id)
            .collect();
        assert!(ids.windows(2).all(|w| w[1] > w[0]), "{ids:?}");
    }

    #[test]
    fn the_answer_is_read_from_the_typed_fields_whatever_the_status_says() {
        let c = pause(7);
        // Statuses that name the command, or say "rejected", decide nothing.
        for status in [
            "",
            "rejected command 7 (pause)",
            "paused (command 7)",
            "session started",
        ] {
            assert_eq!(
                answer_to(
                    &c,
                    &state("s1", 7, GameState::COMMAND_CARRIED_OUT, "", status)
                ),
                Some(Answer::CarriedOut)
            );
            assert_eq!(
                answer_to(
                    &c,
                    &state(
                        "s1",
                        7,
                        GameState::COMMAND_REFUSED,
                        "already paused",
                        status
                    )
                ),
                Some(Answer::Refused("already paused".into()))
            );
            assert_eq!(
                answer_to(
                    &c,
                    &state("s1", 6, GameState::COMMAND_CARRIED_OUT, "", status)
                ),
                None,
                "another command's answer"
            );
            assert_eq!(
                answer_to(
                    &c,
                    &state("s2", 7, GameState::COMMAND_CARRIED_OUT, "", status)
                ),
                None,
                "the same id in another session"
            );
        }
        assert_eq!(
            answer_to(
                &c,
                &state("s1", 7, GameState::COMMAND_ALREADY_CARRIED_OUT, "x", "")
            ),
            Some(Answer::CarriedOut),
            "a repeat of a command carried out is done"
        );
        assert_eq!(
            answer_to(&c, &state("s1", 7, GameState::COMMAND_NONE, "", "")),
            None
        );
    }

    #[test]
    fn a_result_delivered_again_is_said_and_counted_once() {
        let result = |index: u8, outcome: i8| SequenceResult {
            session_id: "s1".into(),
            user_id: "u1".into(),
            sequence_index: index,
            level: 1,
            outcome,
            sequence: vec!["happy".into(); 3],
            answer: vec!["happy".into(); 3],
            ..Default::default()
        };
        let mut f = Followed::new("s1");
        assert!(
            f.result(&result(1, 1))
                .is_some_and(|l| l.starts_with("seq "))
        );
        // The durable topic's history again (a reader matched once more).
        assert_eq!(f.result(&result(1, 1)), None);
        assert!(f.result(&result(2, 1)).is_some());
        assert_eq!(
            f.result(&SequenceResult {
                session_id: "s2".into(),
                ..result(3, 1)
            }),
            None
        );
        let conflict = f.result(&result(2, -1)).expect("said");
        assert!(
            conflict.contains("arrived twice and differs (outcome: 1 -> -1)"),
            "{conflict}"
        );
        assert_eq!(f.sequences(), 2);
    }
}
