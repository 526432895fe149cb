//! `simulated_child`: the simulated child as a DDS node (its run loop is the library's
//! `node::run`). It listens to the game (state, tasks, the robot's emotions), answers on the
//! tablet topic, and streams 30 fps OpenFace frames.

use clap::Parser;
use node_shell::{NodeShell, ShellOptions};
use simulated_child::ChildParams;
use simulated_child::node::NODE;

#[derive(Parser)]
#[command(
    about = "A simulated child: answers tablet tasks and shows the camera a face, driven by a user model"
)]
struct Cli {
    /// Override the cluster of the parameter file.
    #[arg(long)]
    cluster: Option<i64>,
    #[command(flatten)]
    shell: ShellOptions,
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    // packaging/deb/build.sh asks each program for its manual pages.
    man_pages::write_if_asked::<Cli>();
    let mut cli = Cli::parse();
    if let Some(c) = cli.cluster {
        // As the parameter's override, so ROS 2 tools see (and `ros2 param dump` writes) the
        // cluster the child runs with.
        cli.shell.param_overrides.push(format!("cluster:={c}"));
    }
    let (mut shell, params): (NodeShell, ChildParams) = NodeShell::start(NODE, &cli.shell)?;
    // Every way out, errors included, stops the shell first: its DDS entities go before the
    // participant, so the error is the last line printed, not RustDDS noise.
    let outcome = simulated_child::node::run(&mut shell, params).await;
    shell.stop().await;
    outcome
}
