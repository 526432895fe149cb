//! Every node's heartbeat: a [`Heartbeat`] at 10 Hz on `/qt_therapy/heartbeat` for as long as
//! the node runs, on whichever bus it runs (the game manager and the tablet bridge tell a lost
//! or restarted node by it: `libs/heartbeat_watch`).

use crate::bus::Bus;
use qt_therapy_msgs::Heartbeat;
use qt_therapy_msgs::topics::HEARTBEAT;
use std::time::Duration;

/// How often a node beats.
pub const PERIOD: Duration = Duration::from_millis(100);

/// Starts the node's heartbeat; abort the task to stop it.
pub(crate) fn start<B: Bus>(bus: &mut B) -> anyhow::Result<tokio::task::JoinHandle<()>> {
    let outbox = bus.publisher(HEARTBEAT)?;
    let node_name = bus.name().to_string();
    let pid = bus.process_id();
    let clock = bus.clock();
    Ok(tokio::spawn(async move {
        let mut tick = tokio::time::interval(PERIOD);
        let mut sequence = 0u64;
        loop {
            tick.tick().await;
            outbox.send(Heartbeat {
                header: clock.header_now(),
                node_name: node_name.clone(),
                pid,
                sequence,
            });
            sequence += 1;
        }
    }))
}
