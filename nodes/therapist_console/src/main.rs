//! `therapist`: the therapist tablet's commands from a shell, and a live view of a session.
//!   therapist start --user child-7 --cluster 0
//!   therapist run-session --user sim-child --cluster 0   (start, follow to the end)
//!   therapist override --session S --level 1 | pause | resume | stop | emergency-stop
//!   therapist encourage --session S | challenge | accept    (feedback; the open proposal)

use anyhow::{Context, bail};
use clap::{Parser, Subcommand};
use node_shell::{NoParameters, NodeShell, Outbox, ShellOptions, header_now, now_nanos};
use qt_therapy_msgs::live_line::{LAST_RESULT_GRACE, reason_from_messages, sequence_line};
use qt_therapy_msgs::topics::{
    ACTION_PROPOSAL, DECISION, GAME_STATE, SEQUENCE_RESULT, THERAPIST_COMMAND,
};
use qt_therapy_msgs::{ActionProposal, Decision, GameState, TherapistCommand};
use std::time::Duration;

mod proposals;

#[derive(Parser)]
#[command(about = "Send therapist commands to the game manager and follow a session")]
struct Cli {
    #[command(subcommand)]
    command: Command,
    #[command(flatten)]
    shell: ShellOptions,
}

#[derive(Subcommand)]
enum Command {
    /// Start a session for a user (pseudonymous id) with a user-model cluster (-1: policy default).
    Start(StartArgs),
    /// Start a session and print a line per sequence until it ends; exit 0 when it finished.
    RunSession {
        #[command(flatten)]
        start: StartArgs,
        /// Give up after this many seconds (per session).
        #[arg(long, default_value_t = 1800)]
        timeout: u64,
        /// Run this many sessions back to back from this one console (ids <session>-00001,
        /// -00002, ...); stops at the first that does not finish.
        #[arg(long, default_value_t = 1)]
        sessions: u32,
        /// Accept each action the game manager proposes (supervised autonomy) as soon as it
        /// is proposed, as a therapist who agrees with the robot would (simulated sessions).
        #[arg(long)]
        accept_proposals: bool,
    },
    Pause(SessionArg),
    Resume(SessionArg),
    Stop(SessionArg),
    EmergencyStop(SessionArg),
    /// Override the level of the next sequence (1..3).
    Override {
        #[command(flatten)]
        session: SessionArg,
        #[arg(long, value_parser = clap::value_parser!(u8).range(1..=3))]
        level: u8,
    },
    /// Give the next sequence encouraging feedback (it repeats the level; not the first
    /// sequence). Replaces a proposal open for it.
    Encourage(SessionArg),
    /// Give the next sequence challenging feedback (it repeats the level; not the first
    /// sequence). Replaces a proposal open for it.
    Challenge(SessionArg),
    /// Accept the action the game manager proposes now, before its countdown runs out
    /// (refused when none is open).
    Accept(SessionArg),
}

#[derive(clap::Args, Clone)]
struct StartArgs {
    /// The child's pseudonymous id: a code, never a name (it is stored as given).
    #[arg(long)]
    user: String,
    #[arg(long, default_value_t = -1)]
    cluster: i32,
    /// Session id [default: session-<unix time>].
    #[arg(long)]
    session: Option<String>,
    /// Seconds to wait for the game manager to appear.
    #[arg(long, default_value_t = 60)]
    wait: u64,
}

#[derive(clap::Args, Clone)]
struct SessionArg {
    #[arg(long)]
    session: String,
}

/// Command ids only increase: milliseconds since the epoch.
fn command(kind: u8, session: &str) -> TherapistCommand {
    TherapistCommand {
        header: header_now(),
        command: kind,
        session_id: session.to_string(),
        command_id: (now_nanos() / 1_000_000).max(1) as u64,
        ..Default::default()
    }
}

impl Command {
    /// The one command a session command line sends (None for start and run-session).
    fn session_command(&self) -> Option<TherapistCommand> {
        let (code, s) = match self {
            Command::Start(_) | Command::RunSession { .. } => return None,
            Command::Pause(s) => (TherapistCommand::PAUSE, s),
            Command::Resume(s) => (TherapistCommand::RESUME, s),
            Command::Stop(s) => (TherapistCommand::STOP, s),
            Command::EmergencyStop(s) => (TherapistCommand::EMERGENCY_STOP, s),
            Command::Encourage(s) => (TherapistCommand::OVERRIDE_ENCOURAGING, s),
            Command::Challenge(s) => (TherapistCommand::OVERRIDE_CHALLENGING, s),
            Command::Accept(s) => (TherapistCommand::ACCEPT_PROPOSAL, s),
            Command::Override { session, level } => {
                let mut c = command(TherapistCommand::OVERRIDE_LEVEL, &session.session);
                c.level = *level;
                return Some(c);
            }
        };
        Some(command(code, &s.session))
    }
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let (mut shell, NoParameters {}) = NodeShell::start("therapist_console", &cli.shell)?;
    // Every way out, errors included, stops the shell first: its DDS entities go before the
    // participant, so the error is the last thing the therapist reads, not RustDDS noise.
    let outcome: anyhow::Result<i32> = async {
        let commands = shell.publisher(THERAPIST_COMMAND)?;
        let mut states = shell.subscribe(GAME_STATE, 64)?;
        let mut results = shell.subscribe(SEQUENCE_RESULT, 64)?;
        let mut decisions = shell.subscribe(DECISION, 64)?;
        let mut proposals = shell.subscribe(ACTION_PROPOSAL, 64)?;
        let code = match cli.command {
            Command::Start(a) => {
                let c = start_command(&a, Some(&mut states)).await?;
                send(&commands, &shell, &mut states, c).await?
            }
            Command::RunSession {
                start,
                timeout,
                sessions,
                accept_proposals,
            } => {
                let mut code = 0;
                for k in 1..=sessions {
                    let check = (k == 1).then_some(&mut states);
                    let mut c = start_command(&start, check).await?;
                    if sessions > 1 {
                        c.session_id = format!("{}-{k:05}", c.session_id);
                    }
                    let session = c.session_id.clone();
                    let start_id = c.command_id;
                    code = send(&commands, &shell, &mut states, c).await?;
                    if code != 0 {
                        break;
                    }
                    println!(
                        "session {session} started for user {} (cluster {})",
                        start.user, start.cluster
                    );
                    let inputs = Inputs {
                        states: &mut states,
                        results: &mut results,
                        decisions: &mut decisions,
                        proposals: &mut proposals,
                    };
                    let proposals = proposals::Proposals::new(&session, accept_proposals, start_id);
                    code = follow(
                        &session,
                        inputs,
                        proposals,
                        &commands,
                        Duration::from_secs(timeout),
                        &shell,
                    )
                    .await?;
                    if code != 0 {
                        break;
                    }
                }
                code
            }
            single => {
                let c = single
                    .session_command()
                    .context("start and run-session are handled above")?;
                send(&commands, &shell, &mut states, c).await?
            }
        };
        Ok(code)
    }
    .await;
    shell.stop().await;
    std::process::exit(outcome?);
}

/// How long the console waits for the game manager to confirm a command before sending it
/// again, and how many times it sends one.
const CONFIRM_WAIT: Duration = Duration::from_secs(2);
const SENDS: u32 = 3;

/// Sends one command once a reader listens, then waits until the game manager answers it: a
/// GameState whose `command_session_id` and `command_id` name it, with what became of it
/// (`command_outcome`). The answer is needed because a reliable sample still misses a reader
/// that matched after it was sent (the recorder may match first), or when this process exits
/// before it was delivered: an override was once lost that way. An unanswered command is sent
/// again with the same id, which the game manager never carries out twice (it answers a repeat
/// of one it carried out as such). Returns the exit code: 0 carried out, 4 refused (the reason
/// is printed).
async fn send(
    commands: &Outbox<TherapistCommand>,
    shell: &NodeShell,
    states: &mut tokio::sync::mpsc::Receiver<GameState>,
    c: TherapistCommand,
) -> anyhow::Result<i32> {
    if !commands
        .wait_for_subscribers(shell, Duration::from_secs(20))
        .await
    {
        bail!("no game manager is listening on {}", THERAPIST_COMMAND.name);
    }
    let tag = format!("command {}", c.command_id);
    for attempt in 1..=SENDS {
        commands.send(c.clone());
        let until = tokio::time::Instant::now() + CONFIRM_WAIT;
        while let Ok(Some(s)) = tokio::time::timeout_at(until, states.recv()).await {
            match answer_to(&c, &s) {
                None => continue,
                Some(Answer::CarriedOut) => return Ok(0),
                Some(Answer::Refused(reason)) => {
                    println!("{tag} refused: {reason}");
                    return Ok(4);
                }
            }
        }
        if attempt < SENDS {
            tracing::warn!(
                "{tag} not answered by the game manager within {CONFIRM_WAIT:?}: sending it again"
            );
        }
    }
    bail!(
        "the game manager did not answer {tag} (session {:?}) after {SENDS} sends",
        c.session_id
    )
}

/// What the game manager did with a command.
#[derive(Debug, PartialEq)]
enum Answer {
    CarriedOut,
    Refused(String),
}

/// The answer to `c` that `s` carries, if it carries one: its typed fields, never its status
/// text. A repeat of a command carried out before is refused as such: it was carried out.
fn answer_to(c: &TherapistCommand, s: &GameState) -> Option<Answer> {
    if s.command_session_id != c.session_id || s.command_id != c.command_id {
        return None;
    }
    match s.command_outcome {
        GameState::COMMAND_CARRIED_OUT | GameState::COMMAND_ALREADY_CARRIED_OUT => {
            Some(Answer::CarriedOut)
        }
        GameState::COMMAND_REFUSED => Some(Answer::Refused(s.command_refusal.clone())),
        _ => None,
    }
}

/// The START command, once the game manager is free. `states` None: it is known to be (the
/// session this console followed just finished).
async fn start_command(
    a: &StartArgs,
    states: Option<&mut tokio::sync::mpsc::Receiver<GameState>>,
) -> anyhow::Result<TherapistCommand> {
    if let Some(states) = states {
        check_free(a, states).await?;
    }
    let session = a
        .session
        .clone()
        .unwrap_or_else(|| format!("session-{}", now_nanos() / 1_000_000_000));
    let mut c = command(TherapistCommand::START, &session);
    c.user_id = a.user.clone();
    c.user_model_cluster = a.cluster;
    Ok(c)
}

/// Fails when no game manager answers or it is busy with a session.
async fn check_free(
    a: &StartArgs,
    states: &mut tokio::sync::mpsc::Receiver<GameState>,
) -> anyhow::Result<()> {
    // The game state is transient-local: a running game manager's last state arrives at once.
    let state = tokio::time::timeout(Duration::from_secs(a.wait), states.recv())
        .await
        .with_context(|| {
            format!(
                "no game manager published {} within {} s",
                GAME_STATE.name, a.wait
            )
        })?
        .context("game state channel closed")?;
    // RustDDS hands a new transient-local reader every sample its writer still keeps for a
    // reader that has not acknowledged it yet (e.g. the console of the session before, just
    // gone), oldest first: the game's state now is the newest that arrives in a short while.
    let mut state = state;
    let settle = tokio::time::Instant::now() + Duration::from_millis(500);
    while let Ok(Some(s)) = tokio::time::timeout_at(settle, states.recv()).await {
        if (s.header.stamp.sec, s.header.stamp.nanosec)
            >= (state.header.stamp.sec, state.header.stamp.nanosec)
        {
            state = s;
        }
    }
    if !matches!(
        state.phase,
        GameState::IDLE | GameState::FINISHED | GameState::STOPPED | GameState::EMERGENCY_STOPPED
    ) {
        bail!(
            "the game manager is busy with session {} (phase {}): stop it first",
            state.session_id,
            state.phase
        );
    }
    Ok(())
}

/// What `follow` listens to.
struct Inputs<'a> {
    states: &'a mut tokio::sync::mpsc::Receiver<GameState>,
    results: &'a mut tokio::sync::mpsc::Receiver<qt_therapy_msgs::SequenceResult>,
    decisions: &'a mut tokio::sync::mpsc::Receiver<Decision>,
    proposals: &'a mut tokio::sync::mpsc::Receiver<ActionProposal>,
}

/// Prints the session's steps, a line per sequence and per proposal and its settlement, until
/// the session ends; with `proposals` accepting, accepts each proposal (answers to those
/// accepts come on the game states, read here as well).
async fn follow(
    session: &str,
    inputs: Inputs<'_>,
    mut proposals: proposals::Proposals,
    commands: &Outbox<TherapistCommand>,
    timeout: Duration,
    shell: &NodeShell,
) -> anyhow::Result<i32> {
    let Inputs {
        states,
        results,
        decisions,
        proposals: proposal_messages,
    } = inputs;
    let carry_out = |events: Vec<proposals::Event>| {
        for e in events {
            match e {
                proposals::Event::Print(line) => println!("{line}"),
                proposals::Event::Send(c) => {
                    commands.send(c);
                }
            }
        }
    };
    let deadline = tokio::time::sleep(timeout);
    tokio::pin!(deadline);
    let stop = shell.shutdown_signal();
    tokio::pin!(stop);
    let mut seen: Vec<Decision> = Vec::new();
    let mut last_status = String::new();
    let mut results_seen = 0;
    loop {
        let resend = proposals.next_send();
        // Far enough never to come: the branch is disabled without a send due.
        let resend_at = resend.unwrap_or_else(|| std::time::Instant::now() + timeout);
        tokio::select! {
            _ = &mut deadline => { println!("session {session}: no end within {timeout:?}"); return Ok(2); }
            _ = &mut stop => return Ok(130),
            _ = tokio::time::sleep_until(resend_at.into()), if resend.is_some() => {
                carry_out(proposals.on_tick(std::time::Instant::now()));
            }
            Some(p) = proposal_messages.recv() => {
                let now_ms = (now_nanos() / 1_000_000).max(1) as u64;
                carry_out(proposals.on_proposal(&p, std::time::Instant::now(), now_ms));
            }
            Some(d) = decisions.recv() => if d.session_id == session { seen.push(d) },
            Some(r) = results.recv() => if r.session_id == session {
                let d = seen.iter().rev().find(|d| d.step == r.sequence_index);
                println!("{}", sequence_line(&r, &reason_from_messages(&r, d)));
                results_seen += 1;
            },
            Some(s) = states.recv() => {
                carry_out(proposals.on_state(&s));
                if s.session_id != session { continue; }
                if !s.status.is_empty() && s.status != last_status {
                    println!("  [{}] {}", phase_name(s.phase), s.status);
                    last_status = s.status.clone();
                }
                match s.phase {
                    GameState::FINISHED => {
                        let grace = tokio::time::Instant::now() + LAST_RESULT_GRACE;
                        while results_seen < usize::from(s.sequence_index) {
                            match tokio::time::timeout_at(grace, results.recv()).await {
                                Ok(Some(r)) if r.session_id == session => {
                                    let d = seen.iter().rev().find(|d| d.step == r.sequence_index);
                                    println!("{}", sequence_line(&r, &reason_from_messages(&r, d)));
                                    results_seen += 1;
                                }
                                Ok(Some(_)) => {}
                                _ => break,
                            }
                        }
                        println!("session {session} finished: {results_seen} sequences");
                        return Ok(0);
                    }
                    GameState::STOPPED | GameState::EMERGENCY_STOPPED => {
                        println!("session {session} {}", phase_name(s.phase));
                        return Ok(3);
                    }
                    _ => {}
                }
            }
        }
    }
}

/// The phase in words (`saying sequence`).
fn phase_name(phase: u8) -> String {
    GameState::phase_name(phase).replace('_', " ")
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
}
