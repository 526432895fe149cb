//! A DDS node's end: SIGINT or SIGTERM asks it to stop, and [`NodeShell::stop`] frees its DDS
//! entities before the participant so that peers see it leave at once.

use crate::NodeShell;
use anyhow::Context as _;
use tokio::sync::watch;

/// Listens for SIGINT and SIGTERM; the receiver turns true at the first.
pub(crate) fn spawn_signal_listener() -> anyhow::Result<watch::Receiver<bool>> {
    use tokio::signal::unix::{SignalKind, signal};
    let mut interrupt = signal(SignalKind::interrupt()).context("installing the SIGINT handler")?;
    let mut terminate =
        signal(SignalKind::terminate()).context("installing the SIGTERM handler")?;
    let (tx, rx) = watch::channel(false);
    tokio::spawn(async move {
        tokio::select! {
            _ = interrupt.recv() => tracing::info!("SIGINT: shutting down"),
            _ = terminate.recv() => tracing::info!("SIGTERM: shutting down"),
        }
        let _ = tx.send(true);
    });
    Ok(rx)
}

/// Resolves when `stop` turns true. A sender gone without (an in-process node's `NodeStop`
/// dropped) asks nothing: it never resolves then.
pub(crate) fn when_stopped(
    stop: &watch::Receiver<bool>,
) -> impl std::future::Future<Output = ()> + Send + 'static {
    let mut rx = stop.clone();
    async move {
        if rx.wait_for(|stop| *stop).await.is_err() {
            std::future::pending::<()>().await;
        }
    }
}

impl NodeShell {
    /// Resolves when SIGINT or SIGTERM arrives.
    pub fn shutdown_signal(&self) -> impl std::future::Future<Output = ()> + Send + 'static {
        when_stopped(&self.shutdown)
    }

    /// Leaves the graph cleanly so peers see the participant go at once. Drop the node's own
    /// publishers, clients and receivers before calling this.
    pub async fn stop(self) {
        for task in &self.tasks {
            task.abort();
        }
        for task in self.tasks {
            let _ = task.await;
        }
        tracing::info!(node = %self.name, "node stopped");
    }
}
