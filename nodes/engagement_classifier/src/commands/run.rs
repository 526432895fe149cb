//! `engagement_classifier run`: the engagement node over DDS (its run loop is the library's
//! `node::run`).

use anyhow::Context;
use engagement_classifier::EngagementClassifierParams;
use engagement_classifier::node::{NODE, estimator, run as run_node};
use node_shell::{NodeShell, ShellOptions};

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    shell: ShellOptions,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    // One thread: each frame is microseconds of work and nothing here blocks, and a frame
    // handed from node_shell's reader task to this loop then wakes no other thread (40-50 µs
    // a frame at the median on the multi-threaded runtime: docs/performance.md, "DDS").
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?
        .block_on(serve(args))
}

async fn serve(args: Args) -> anyhow::Result<()> {
    // The parameters and the model, read before the node joins the ROS graph: a bad parameter
    // or model file stops it at start-up without it ever appearing to its peers.
    let (params, path): (EngagementClassifierParams, _) = args.shell.parameters(NODE)?;
    let estimator = estimator(&params, &path)?;
    // The shell reads the same file and overrides again; those parameters are already checked.
    let (mut shell, _): (NodeShell, EngagementClassifierParams) =
        NodeShell::start(NODE, &args.shell)?;
    let outcome = run_node(&mut shell, params, estimator).await;
    shell.stop().await;
    outcome
}
