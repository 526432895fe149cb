//! The seam between a node's code and the bus it runs on. A node is written once against
//! [`Bus`]: typed publishers and validated subscriptions on the suite's topics
//! (`Topic<M>` with its QoS class), services (`Service<S>`), a clock, and its stop signal.
//! Two buses implement it: [`NodeShell`](crate::NodeShell), a ROS 2 node over DDS (the robot,
//! and the tests of the wire), and [`InProcessNode`](crate::in_process::InProcessNode), a node
//! of an in-process bus on which the whole suite runs in one process on a virtual clock (the
//! cross-node tests). The node's code cannot tell them apart; only its `main.rs` chooses.

use crate::clock::Clock;
use crate::drops::DropLog;
use crate::parameters::{NodeParameters, ParameterChange};
use crate::tap::Tapped;
use qt_therapy_msgs::services::ServiceDefinition;
use qt_therapy_msgs::topics::{Service, Topic};
use qt_therapy_msgs::{InvalidMessage, MessageDefinition, Validate};
use std::future::Future;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{mpsc, oneshot};

/// What a node needs of the bus it runs on.
pub trait Bus {
    /// The node's name on the graph (its heartbeat's `node_name`).
    fn name(&self) -> &str;

    /// The process its heartbeat names: the process id over DDS, the node's instance number on
    /// the in-process bus (a node started again there is a new instance, as a respawn is a
    /// new process).
    fn process_id(&self) -> u32;

    /// The node's clock: every time the node reads and every timer it sets.
    fn clock(&self) -> Clock;

    /// Counts of the input this node refused, per topic and reason.
    fn drops(&self) -> Arc<DropLog>;

    /// A publisher on one of the suite's topics, with the topic's QoS.
    fn publisher<M: MessageDefinition>(&mut self, topic: Topic<M>) -> anyhow::Result<Outbox<M>>;

    /// A subscription whose validated messages arrive on the returned channel (at most
    /// `capacity` waiting). Invalid (and over DDS, undecodable) messages are logged once per
    /// topic and kind of reason, counted in [`Bus::drops`], and dropped.
    fn subscribe<M>(
        &mut self,
        topic: Topic<M>,
        capacity: usize,
    ) -> anyhow::Result<mpsc::Receiver<M>>
    where
        M: MessageDefinition + Validate;

    /// Every message on `topic` as it arrived, NOT validated (a recording keeps the nonsense
    /// too), with when and by whom it was sent; `map(message)` goes to `tx` until `tx` closes.
    /// For tools that observe the graph (the recorder). Abort the task before the node stops.
    fn tap<M, T, F>(
        &mut self,
        topic: Topic<M>,
        tx: mpsc::Sender<T>,
        map: F,
    ) -> anyhow::Result<tokio::task::JoinHandle<()>>
    where
        M: MessageDefinition,
        T: Send + 'static,
        F: Fn(Tapped<M>) -> Option<T> + Send + 'static;

    /// Serves a service: validated requests arrive on the channel with a responder, one at a
    /// time (the next is taken once this one is answered); invalid ones get `invalid(reason)`
    /// as their response without reaching the node.
    fn serve<S>(
        &mut self,
        service: Service<S>,
        invalid: fn(&InvalidMessage) -> S::Response,
    ) -> anyhow::Result<mpsc::Receiver<ServiceCall<S>>>
    where
        S: ServiceDefinition + 'static,
        S::Request: Validate;

    /// A client for one of the suite's services.
    fn client<S: ServiceDefinition + 'static>(
        &mut self,
        service: Service<S>,
    ) -> anyhow::Result<ServiceClient<S>>;

    /// Waits until a server for `client` is there, or `timeout` passes; true if it is.
    fn wait_for_service<S: ServiceDefinition + 'static>(
        &self,
        client: &ServiceClient<S>,
        timeout: Duration,
    ) -> impl Future<Output = bool>;

    /// Waits until a subscriber of `outbox`'s topic is there, or `timeout` passes; true if
    /// one is.
    fn wait_for_subscribers<M: MessageDefinition>(
        &self,
        outbox: &Outbox<M>,
        timeout: Duration,
    ) -> impl Future<Output = bool>;

    /// Waits until node `node` subscribes to `outbox`'s topic, or `timeout` passes; true if it
    /// does. Over DDS the node is the one its participant announces on ros_discovery_info; the
    /// in-process bus has no ROS graph, and any subscriber will do.
    fn wait_for_node_subscription<M: MessageDefinition>(
        &self,
        outbox: &Outbox<M>,
        node: &str,
        timeout: Duration,
    ) -> impl Future<Output = bool> {
        let _ = node;
        self.wait_for_subscribers(outbox, timeout)
    }

    /// Changes to the node's writable parameters asked for over the graph (`ros2 param set`,
    /// `parameters`), each to be handed to the node's core and answered with what it said.
    /// `P` is the node's parameter type. The in-process bus has no ROS graph: none come.
    fn parameter_changes<P: NodeParameters>(&mut self) -> mpsc::Receiver<ParameterChange<P>>;

    /// Resolves when the node is asked to stop (SIGINT or SIGTERM over DDS).
    fn shutdown_signal(&self) -> impl Future<Output = ()> + Send + 'static;
}

/// A typed publisher that logs (never panics on) failed writes.
pub struct Outbox<M: MessageDefinition> {
    pub(crate) topic: &'static str,
    pub(crate) writer: Writer<M>,
}

/// Where an [`Outbox`] writes.
// Made once per topic and node, never copied: the DDS publisher's size costs nothing.
#[allow(clippy::large_enum_variant)]
pub(crate) enum Writer<M: MessageDefinition> {
    Dds(ros2_client::Publisher<M>),
    InProcess(crate::in_process::Writer<M>),
}

impl<M: MessageDefinition> Outbox<M> {
    /// Publishes; a failure is logged with the topic and returned as false.
    pub fn send(&self, message: M) -> bool {
        let outcome = match &self.writer {
            Writer::Dds(publisher) => publisher.publish(message).map_err(|e| format!("{e:?}")),
            Writer::InProcess(writer) => writer.publish(message),
        };
        match outcome {
            Ok(()) => true,
            Err(e) => {
                tracing::warn!(topic = self.topic, "publish failed: {e}");
                false
            }
        }
    }

    pub fn topic(&self) -> &'static str {
        self.topic
    }

    /// Waits until a subscriber is there (see [`Bus::wait_for_subscribers`]).
    pub async fn wait_for_subscribers(&self, bus: &impl Bus, timeout: Duration) -> bool {
        bus.wait_for_subscribers(self, timeout).await
    }
}

/// One validated service request and the way to answer it.
pub struct ServiceCall<S: ServiceDefinition> {
    pub request: S::Request,
    pub(crate) responder: oneshot::Sender<S::Response>,
}

impl<S: ServiceDefinition> ServiceCall<S> {
    pub fn respond(self, response: S::Response) {
        // The caller may have gone; nothing to do then.
        let _ = self.responder.send(response);
    }
}

/// What became of a request a server took: one rule for both buses' servers.
pub(crate) enum Handed<R> {
    /// The response to send: the node's, or `invalid(reason)` for a request that failed
    /// validation (logged in the drop log, never shown to the node).
    Answer(R),
    /// The node dropped the call without answering: nothing to send.
    Unanswered,
    /// The node no longer takes calls: the server stops.
    NodeGone,
}

/// Validates `request`; an invalid one is answered `invalid(reason)` and recorded in `drops`
/// under `service`, a valid one goes to the node on `node` and its answer is awaited (so the
/// node takes its requests one at a time).
pub(crate) async fn hand_to_node<S: ServiceDefinition>(
    request: S::Request,
    node: &mpsc::Sender<ServiceCall<S>>,
    drops: &DropLog,
    service: &str,
    invalid: fn(&InvalidMessage) -> S::Response,
) -> Handed<S::Response>
where
    S::Request: Validate,
{
    if let Err(e) = request.validate() {
        drops.record(service, &e.to_string());
        return Handed::Answer(invalid(&e));
    }
    let (responder, answer) = oneshot::channel();
    if node.send(ServiceCall { request, responder }).await.is_err() {
        return Handed::NodeGone;
    }
    match answer.await {
        Ok(response) => Handed::Answer(response),
        Err(_) => Handed::Unanswered,
    }
}

/// Why a service call gave no answer.
#[derive(Debug, thiserror::Error)]
pub enum CallError {
    #[error("{service} did not answer within {timeout:?}")]
    Timeout {
        service: &'static str,
        timeout: Duration,
    },
    #[error("{service}: {reason}")]
    Failed {
        service: &'static str,
        reason: String,
    },
}

/// A typed service client with a deadline on every call.
pub struct ServiceClient<S: ServiceDefinition> {
    pub(crate) name: &'static str,
    pub(crate) caller: Caller<S>,
}

/// How a [`ServiceClient`] reaches its server.
pub(crate) enum Caller<S: ServiceDefinition> {
    Dds(Arc<ros2_client::Client<S::Request, S::Response>>),
    InProcess(crate::in_process::Caller<S>),
}

impl<S: ServiceDefinition> Clone for ServiceClient<S> {
    fn clone(&self) -> Self {
        ServiceClient {
            name: self.name,
            caller: match &self.caller {
                Caller::Dds(c) => Caller::Dds(c.clone()),
                Caller::InProcess(c) => Caller::InProcess(c.clone()),
            },
        }
    }
}

impl<S: ServiceDefinition + 'static> ServiceClient<S> {
    /// The service's name.
    pub fn name(&self) -> &'static str {
        self.name
    }

    /// Calls the service; no answer within `timeout` is [`CallError::Timeout`].
    pub async fn call(
        &self,
        request: S::Request,
        timeout: Duration,
    ) -> Result<S::Response, CallError> {
        let answer = match &self.caller {
            Caller::Dds(client) => {
                tokio::time::timeout(timeout, async {
                    client
                        .async_call_service(request)
                        .await
                        .map_err(|e| format!("{e:?}"))
                })
                .await
            }
            Caller::InProcess(caller) => tokio::time::timeout(timeout, caller.call(request)).await,
        };
        match answer {
            Err(_) => Err(CallError::Timeout {
                service: self.name,
                timeout,
            }),
            Ok(Err(reason)) => Err(CallError::Failed {
                service: self.name,
                reason,
            }),
            Ok(Ok(response)) => Ok(response),
        }
    }
}
