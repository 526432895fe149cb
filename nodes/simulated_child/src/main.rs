//! `simulated_child`: the simulated child as a DDS node. It listens to the game (state, tasks,
//! the robot's emotions), answers on the tablet topic, and streams 30 fps OpenFace frames.

use anyhow::Context;
use clap::Parser;
use node_shell::{NodeShell, ShellOptions, now_nanos};
use qt_therapy_msgs::topics::{
    GAME_STATE, OPENFACE_FEATURES, ROBOT_EMOTION, TABLET_ANSWER, TABLET_TASK,
};
use simulated_child::{ChildOutput, ChildParams, SimulatedChild};
use std::time::Duration;

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
    let cli = Cli::parse();
    let (mut shell, mut params): (NodeShell, ChildParams) =
        NodeShell::start("simulated_child", &cli.shell)?;
    if let Some(c) = cli.cluster {
        params.cluster = c;
    }
    // Every way out, errors included, stops the shell first: its DDS entities go before the
    // participant, so the error is the last line printed, not RustDDS noise.
    let outcome = play(&mut shell, params).await;
    shell.stop().await;
    outcome
}

/// Plays the child until the node is asked to stop.
async fn play(shell: &mut NodeShell, params: ChildParams) -> anyhow::Result<()> {
    let set = user_models::UserModelSet::load(std::path::Path::new(&params.user_model_file))
        .with_context(|| format!("loading user_model_file {}", params.user_model_file))?;
    let table = set
        .table(params.cluster)
        .with_context(|| format!("user_model_file {}", params.user_model_file))?
        .clone();
    tracing::info!(cluster = params.cluster, model = %params.user_model_file, "simulated child ready (SYNTHETIC faces)");
    let mut child = SimulatedChild::new(params, table)?;
    {
        let mut states = shell.subscribe(GAME_STATE, 64)?;
        let mut tasks = shell.subscribe(TABLET_TASK, 16)?;
        let mut emotions = shell.subscribe(ROBOT_EMOTION, 64)?;
        let answers = shell.publisher(TABLET_ANSWER)?;
        let frames = shell.publisher(OPENFACE_FEATURES)?;
        let mut tick = tokio::time::interval(Duration::from_millis(10));
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        let stop = shell.shutdown_signal();
        tokio::pin!(stop);
        loop {
            tokio::select! {
                _ = &mut stop => break,
                Some(s) = states.recv() => child.on_game_state(&s),
                Some(e) = emotions.recv() => child.on_robot_emotion(&e.data),
                Some(t) = tasks.recv() => child.on_task(&t, now_nanos()),
                _ = tick.tick() => {
                    for out in child.poll(now_nanos()) {
                        match out {
                            ChildOutput::Frame(f) => { frames.send(f); }
                            ChildOutput::Answer(a) => {
                                tracing::info!(sequence = a.sequence_id, answer = ?a.answer, "answering");
                                answers.send(a);
                            }
                        }
                    }
                }
            }
        }
    }
    Ok(())
}
