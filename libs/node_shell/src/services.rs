//! Services over DDS: a server whose validated requests reach the node one at a time with a
//! responder (invalid ones are answered without reaching it), clients, and the wait for a
//! server, which works around ros2-client's dropped discovery events.

use crate::NodeShell;
use crate::bus::{Caller, Handed, ServiceCall, ServiceClient, hand_to_node};
use crate::names::ros_name;
use crate::qos::service_qos;
use anyhow::Context as _;
use qt_therapy_msgs::services::ServiceDefinition;
use qt_therapy_msgs::topics::Service;
use qt_therapy_msgs::{InvalidMessage, Validate};
use ros2_client::ServiceTypeName;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::mpsc;

impl NodeShell {
    /// Serves a service: validated requests arrive on the channel with a responder; invalid
    /// ones get `invalid(reason)` as their response without reaching the node.
    pub fn serve<S>(
        &mut self,
        service: Service<S>,
        invalid: fn(&InvalidMessage) -> S::Response,
    ) -> anyhow::Result<mpsc::Receiver<ServiceCall<S>>>
    where
        S: ServiceDefinition + 'static,
        S::Request: Validate,
    {
        crate::type_hashes::announce_service::<S>(&self.context.domain_participant())?;
        let server = self
            .node
            .create_server::<S::Request, S::Response>(
                self.service_mapping,
                &ros_name(service.name)?,
                &ServiceTypeName::new(S::PACKAGE, S::NAME),
                service_qos(),
                service_qos(),
            )
            .with_context(|| format!("creating service {}", service.name))?;
        let (tx, rx) = mpsc::channel(16);
        let drops = self.drops.clone();
        let name = service.name;
        self.tasks.push(tokio::spawn(async move {
            loop {
                let (id, request) = match server.async_receive_request().await {
                    Ok(r) => r,
                    Err(e) => {
                        drops.record(name, &format!("undecodable request: {e:?}"));
                        continue;
                    }
                };
                let response = match hand_to_node(request, &tx, &drops, name, invalid).await {
                    Handed::Answer(response) => response,
                    Handed::Unanswered => continue,
                    Handed::NodeGone => break,
                };
                if let Err(e) = server.async_send_response(id, response).await {
                    tracing::warn!(service = name, "could not send a response: {e:?}");
                }
            }
        }));
        Ok(rx)
    }

    /// A client for one of the suite's services.
    pub fn client<S: ServiceDefinition>(
        &mut self,
        service: Service<S>,
    ) -> anyhow::Result<ServiceClient<S>> {
        crate::type_hashes::announce_service::<S>(&self.context.domain_participant())?;
        let client = self
            .node
            .create_client::<S::Request, S::Response>(
                self.service_mapping,
                &ros_name(service.name)?,
                &ServiceTypeName::new(S::PACKAGE, S::NAME),
                service_qos(),
                service_qos(),
            )
            .with_context(|| format!("creating a client for {}", service.name))?;
        Ok(ServiceClient {
            name: service.name,
            caller: Caller::Dds(Arc::new(client)),
        })
    }

    /// Waits until a server for `client` is matched, or `timeout` passes; true if matched.
    pub async fn wait_for_service<S: ServiceDefinition>(
        &self,
        client: &ServiceClient<S>,
        timeout: Duration,
    ) -> bool {
        let Caller::Dds(client) = &client.caller else {
            tracing::warn!(
                service = client.name,
                "an in-process client waited on for a DDS server: none"
            );
            return false;
        };
        wait_rechecking(timeout, || client.wait_for_service(&self.node)).await
    }
}

/// How often a wait for a match starts again (see [`wait_rechecking`]).
const MATCH_RECHECK: Duration = Duration::from_millis(200);

/// Runs `wait` (one of ros2-client's waits for a match) until it resolves or `timeout` passes,
/// starting it anew every [`MATCH_RECHECK`]; true if it resolved. ros2-client's waits look at
/// the match state when they start, then only when a discovery event reaches them, through a
/// channel of 8 that drops events when full. A node joining a whole graph gets a burst of
/// them, so the one that matters can be dropped and the wait then runs its whole timeout: a
/// respawned game manager waited its 10 s for a running policy in 1 of 10 kill-test runs. A
/// new wait checks the state first, so a dropped event costs at most one recheck.
pub(crate) async fn wait_rechecking<F, W>(timeout: Duration, mut wait: F) -> bool
where
    F: FnMut() -> W,
    W: std::future::Future<Output = ()>,
{
    let deadline = tokio::time::Instant::now() + timeout;
    loop {
        let left = deadline.saturating_duration_since(tokio::time::Instant::now());
        if left.is_zero() {
            return false;
        }
        if tokio::time::timeout(left.min(MATCH_RECHECK), wait())
            .await
            .is_ok()
        {
            return true;
        }
    }
}

#[cfg(test)]
mod tests {
    use std::future::Future;
    use std::pin::Pin;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::time::{Duration, Instant};

    /// A wait that checks the state only when it starts, as ros2-client's does once its
    /// event was dropped: it resolves if `matched` is set by then, else never.
    fn wait_missing_its_event(matched: &AtomicBool) -> Pin<Box<dyn Future<Output = ()> + Send>> {
        if matched.load(Ordering::SeqCst) {
            Box::pin(std::future::ready(()))
        } else {
            Box::pin(std::future::pending())
        }
    }

    #[tokio::test]
    async fn a_match_whose_event_was_dropped_is_seen_at_the_next_recheck() {
        let matched = Arc::new(AtomicBool::new(false));
        let set = matched.clone();
        tokio::spawn(async move {
            tokio::time::sleep(Duration::from_millis(50)).await;
            set.store(true, Ordering::SeqCst);
        });
        let started = Instant::now();
        let found =
            super::wait_rechecking(Duration::from_secs(30), || wait_missing_its_event(&matched))
                .await;
        assert!(found);
        // One recheck after the match, not the 30 s timeout.
        assert!(
            started.elapsed() < Duration::from_secs(10),
            "{:?}",
            started.elapsed()
        );
    }

    #[tokio::test]
    async fn no_match_waits_the_whole_timeout_and_says_so() {
        let matched = AtomicBool::new(false);
        let started = Instant::now();
        let found = super::wait_rechecking(Duration::from_millis(500), || {
            wait_missing_its_event(&matched)
        })
        .await;
        assert!(!found);
        assert!(started.elapsed() >= Duration::from_millis(500));
    }
}
