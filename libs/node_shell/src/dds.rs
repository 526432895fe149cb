//! [`NodeShell`] as a [`Bus`]: each part of the seam is NodeShell's own method, in the module
//! of its job (`publish`, `subscribe`, `services`, `tap`, `shutdown`, `participant`), which
//! tools that only ever speak DDS call directly; the clock is the wall clock.

use crate::NodeShell;
use crate::bus::{Bus, Outbox, ServiceCall, ServiceClient};
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
use tokio::sync::mpsc;

impl Bus for NodeShell {
    fn name(&self) -> &str {
        NodeShell::name(self)
    }

    fn process_id(&self) -> u32 {
        std::process::id()
    }

    fn clock(&self) -> Clock {
        self.clock
    }

    fn drops(&self) -> Arc<DropLog> {
        NodeShell::drops(self)
    }

    fn publisher<M: MessageDefinition>(&mut self, topic: Topic<M>) -> anyhow::Result<Outbox<M>> {
        NodeShell::publisher(self, topic)
    }

    fn subscribe<M>(
        &mut self,
        topic: Topic<M>,
        capacity: usize,
    ) -> anyhow::Result<mpsc::Receiver<M>>
    where
        M: MessageDefinition + Validate,
    {
        NodeShell::subscribe(self, topic, capacity)
    }

    fn tap<M, T, F>(
        &mut self,
        topic: Topic<M>,
        tx: mpsc::Sender<T>,
        map: F,
    ) -> anyhow::Result<tokio::task::JoinHandle<()>>
    where
        M: MessageDefinition,
        T: Send + 'static,
        F: Fn(Tapped<M>) -> Option<T> + Send + 'static,
    {
        self.dds_tap(topic, tx, map)
    }

    fn serve<S>(
        &mut self,
        service: Service<S>,
        invalid: fn(&InvalidMessage) -> S::Response,
    ) -> anyhow::Result<mpsc::Receiver<ServiceCall<S>>>
    where
        S: ServiceDefinition + 'static,
        S::Request: Validate,
    {
        NodeShell::serve(self, service, invalid)
    }

    fn client<S: ServiceDefinition + 'static>(
        &mut self,
        service: Service<S>,
    ) -> anyhow::Result<ServiceClient<S>> {
        NodeShell::client(self, service)
    }

    fn wait_for_service<S: ServiceDefinition + 'static>(
        &self,
        client: &ServiceClient<S>,
        timeout: Duration,
    ) -> impl Future<Output = bool> {
        NodeShell::wait_for_service(self, client, timeout)
    }

    fn wait_for_subscribers<M: MessageDefinition>(
        &self,
        outbox: &Outbox<M>,
        timeout: Duration,
    ) -> impl Future<Output = bool> {
        self.dds_wait_for_subscribers(outbox, timeout)
    }

    fn wait_for_node_subscription<M: MessageDefinition>(
        &self,
        outbox: &Outbox<M>,
        node: &str,
        timeout: Duration,
    ) -> impl Future<Output = bool> {
        self.dds_wait_for_node_subscription(outbox, node, timeout)
    }

    fn parameter_changes<P: NodeParameters>(&mut self) -> mpsc::Receiver<ParameterChange<P>> {
        NodeShell::parameter_changes(self)
    }

    fn shutdown_signal(&self) -> impl Future<Output = ()> + Send + 'static {
        NodeShell::shutdown_signal(self)
    }
}
