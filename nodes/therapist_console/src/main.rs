//! `therapist`: the therapist tablet's commands from a shell, and a live view of a session.
//!   therapist start --user child-7 --cluster 0
//!   therapist run-session --user sim-child --cluster 0   (start, follow to the end)
//!   therapist override --session S --level 1 | pause | resume | stop | emergency-stop
//!   therapist encourage --session S | challenge | accept    (feedback; the open proposal)
//! The console's logic is the library's (`therapist_console::console`); this parses the
//! command line, starts the DDS shell and hands over.

use anyhow::Context;
use clap::{Parser, Subcommand};
use node_shell::{Bus, NoParameters, NodeShell, ShellOptions};
use qt_therapy_msgs::TherapistCommand;
use std::time::Duration;
use therapist_console::console::{Console, Follow, NODE, Start};

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
    /// Pause the session: the game stands still (the answer's time stops; a sequence cut off
    /// is said again on resume).
    Pause(SessionArg),
    /// Resume a paused session.
    Resume(SessionArg),
    /// End the session now; what was played is saved.
    Stop(SessionArg),
    /// Silence the robot at once: nothing reaches it again; the session is saved.
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

impl Command {
    /// The one command a session command line sends (None for start and run-session).
    fn session_command<B: Bus>(&self, console: &Console<'_, B>) -> Option<TherapistCommand> {
        let command = |kind, session: &str| console.command(kind, session);
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

impl StartArgs {
    fn start(&self) -> Start {
        Start {
            user: self.user.clone(),
            cluster: self.cluster,
            session: self.session.clone(),
            wait: Duration::from_secs(self.wait),
        }
    }
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    // packaging/deb/build.sh asks each program for its manual pages.
    man_pages::write_if_asked::<Cli>();
    let cli = Cli::parse();
    let (mut shell, NoParameters {}) = NodeShell::start(NODE, &cli.shell)?;
    // Every way out, errors included, stops the shell first: its DDS entities go before the
    // participant, so the error is the last thing the therapist reads, not RustDDS noise.
    let outcome: anyhow::Result<i32> = async {
        let mut console = Console::new(&mut shell, |line: &str| println!("{line}"))?;
        match cli.command {
            Command::Start(a) => {
                let c = console.start_command(&a.start(), true).await?;
                console.send(c).await
            }
            Command::RunSession {
                start,
                timeout,
                sessions,
                accept_proposals,
            } => {
                let follow = Follow {
                    timeout: Duration::from_secs(timeout),
                    sessions,
                    accept_proposals,
                };
                console.run_session(&start.start(), follow).await
            }
            single => {
                let c = single
                    .session_command(&console)
                    .context("start and run-session are handled above")?;
                console.send(c).await
            }
        }
    }
    .await;
    shell.stop().await;
    std::process::exit(outcome?);
}
