//! The simulated child's run loop, on any bus (`node_shell::Bus`: DDS in the main job, in
//! process in the cross-node tests): it listens to the game (state, tasks, the robot's
//! emotions), answers on the tablet topic, and streams 30 fps OpenFace frames, on the bus's
//! clock.

use crate::{ChildOutput, ChildParams, SimulatedChild};
use anyhow::Context;
use node_shell::Bus;
use qt_therapy_msgs::topics::{
    GAME_STATE, OPENFACE_FEATURES, ROBOT_EMOTION, TABLET_ANSWER, TABLET_TASK,
};
use std::time::Duration;

/// The node's name on the graph (and its parameter file's).
pub const NODE: &str = "simulated_child";

/// Plays the child until the node is asked to stop.
pub async fn run(bus: &mut impl Bus, params: ChildParams) -> anyhow::Result<()> {
    let set = user_models::UserModelSet::load(std::path::Path::new(&params.user_model_file))
        .with_context(|| format!("loading user_model_file {}", params.user_model_file))?;
    let table = set
        .table(params.cluster)
        .with_context(|| format!("user_model_file {}", params.user_model_file))?
        .clone();
    tracing::info!(cluster = params.cluster, model = %params.user_model_file, "simulated child ready (SYNTHETIC faces)");
    let mut child = SimulatedChild::new(params, table)?;
    let mut states = bus.subscribe(GAME_STATE, 64)?;
    let mut tasks = bus.subscribe(TABLET_TASK, 16)?;
    let mut emotions = bus.subscribe(ROBOT_EMOTION, 64)?;
    let answers = bus.publisher(TABLET_ANSWER)?;
    let frames = bus.publisher(OPENFACE_FEATURES)?;
    let clock = bus.clock();
    let mut tick = tokio::time::interval(Duration::from_millis(10));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let stop = bus.shutdown_signal();
    tokio::pin!(stop);
    loop {
        // Biased: what is ready is taken in this order, never by tokio's random pick, so a
        // run on the in-process bus is the same every time.
        tokio::select! {
            biased;
            _ = &mut stop => break,
            Some(s) = states.recv() => child.on_game_state(&s),
            Some(e) = emotions.recv() => child.on_robot_emotion(&e.data),
            Some(t) = tasks.recv() => child.on_task(&t, clock.steady_nanos()),
            _ = tick.tick() => {
                let steady = clock.steady_nanos();
                child.set_wall_offset(clock.now_nanos() - steady);
                for out in child.poll(steady) {
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
    Ok(())
}
