//! `game_manager run`: the game manager node over DDS (its run loop is the library's
//! `node::run`). At start-up, a session a killed predecessor left unfinished in the sessions
//! directory is taken over.
//!   game_manager run [--sessions-dir DIR] [--params-file params/game_manager.yaml]

use anyhow::Context as _;
use clap::{Parser, Subcommand};
use game_manager::GameManagerParams;
use game_manager::node::NODE;
use node_shell::instance_lock::InstanceLock;
use node_shell::{NodeShell, ShellOptions};
use std::path::PathBuf;

#[derive(Parser)]
#[command(about = "The emotion-sequence memorisation game on QTrobot, over ROS 2 / DDS")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the node until SIGINT/SIGTERM (a running session is then saved as stopped).
    Run(RunArgs),
}

#[derive(clap::Args)]
struct RunArgs {
    /// Directory of the session files [default: the sessions_dir parameter].
    #[arg(long)]
    sessions_dir: Option<PathBuf>,
    #[command(flatten)]
    shell: ShellOptions,
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    // packaging/deb/build.sh asks each program for its manual pages.
    man_pages::write_if_asked::<Cli>();
    let Command::Run(mut args) = Cli::parse().command;
    if let Some(dir) = &args.sessions_dir {
        // As the parameter's override, so the node reads it, and ROS 2 tools see it, as
        // sessions_dir (a JSON string is a YAML string, whatever the path looks like).
        let value = serde_json::to_string(&dir.display().to_string())?;
        args.shell
            .param_overrides
            .push(format!("sessions_dir:={value}"));
    }
    let (params, _): (GameManagerParams, _) = args.shell.parameters(NODE)?;
    let sessions_dir = PathBuf::from(&params.files.sessions_dir);
    // Held while the node runs: a second game manager on the same directory would recover
    // this one's session and write its files too. Taken before joining the graph, so a
    // refused copy never beats under our name.
    let _sessions_dir =
        InstanceLock::acquire(&sessions_dir, NODE, "session files").context("sessions_dir")?;
    let (mut shell, params): (NodeShell, GameManagerParams) = NodeShell::start(NODE, &args.shell)?;
    // Parameter errors name the file actually read (--params-file, QT_PARAMS_DIR or params/).
    let params_file = args.shell.params_path(shell.name());
    let result = game_manager::node::run(&mut shell, params, &params_file).await;
    shell.stop().await;
    result
}
