//! The in-process bus: the nodes of the suite in one process, each an [`InProcessNode`] (a
//! [`Bus`]) of one [`InProcessBus`], their messages on channels and their time on one clock,
//! virtual in tests (tokio's paused time), so a whole session runs as an ordinary test in a
//! fraction of a second, the same for a seed every time. The nodes' code is the code that runs
//! over DDS; what differs is only what this module models of DDS:
//!
//! - every node sees every other at once (no discovery delay), and a node that stops or is
//!   killed (its task dropped) leaves at once, its writers' histories with it, as a process's
//!   do when it dies;
//! - reliable topics lose nothing and keep each writer's order; messages of different writers
//!   arrive in the order they were sent;
//! - transient-local topics (`State`: keep last 1, `Durable`: keep last 100) hand a reader
//!   that joins later each living writer's kept history, writer by writer in the order the
//!   writers joined, before anything new; volatile ones (`Reliable`, `Features`) only what is
//!   sent after it joined;
//! - best effort (`Features`) keeps the newest 10 samples a reader has not taken yet, and a
//!   reader that falls further behind loses the oldest ([`InProcessBus::replaced_samples`]
//!   counts them); nothing is lost on the way otherwise;
//! - a message a node takes is validated as over DDS (an invalid one is logged once per topic
//!   and kind of reason, counted, and dropped; an invalid request is answered `invalid(..)`),
//!   so bad input is refused in process too; undecodable bytes cannot happen here;
//! - a service call goes to every server of the name, the first answer wins; with no server,
//!   or a server gone before it answers, the call runs to its timeout, as over DDS.
//!
//! For the tests of what a slow link does, [`InProcessBus::delay`] holds what one node takes
//! from one topic for a while (in order). Not modelled otherwise: network loss and delay, a writer blocking on a full reliable reader, QoS
//! mismatches (the suite's table gives each topic one QoS: a mismatch here is an error), DDS
//! Security, and the wire format (the DDS process tests keep those).

mod services;
mod topics;

pub(crate) use services::Caller;
pub(crate) use topics::Writer;

use crate::bus::{Bus, Outbox, ServiceCall, ServiceClient};
use crate::clock::Clock;
use crate::drops::DropLog;
use crate::tap::Tapped;
use qt_therapy_msgs::services::ServiceDefinition;
use qt_therapy_msgs::topics::{Service, Topic};
use qt_therapy_msgs::{InvalidMessage, MessageDefinition, Validate};
use std::collections::{BTreeMap, VecDeque};
use std::future::Future;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;
use tokio::sync::{Notify, mpsc, watch};

/// One bus: the graph its nodes share and their clock.
#[derive(Clone)]
pub struct InProcessBus {
    shared: Arc<Shared>,
}

pub(crate) struct Shared {
    graph: Mutex<Graph>,
    /// Bumped at every change of the graph (a writer, reader or server added or gone), for
    /// the waits for a match.
    changed: watch::Sender<u64>,
    clock: Clock,
    next_instance: AtomicU32,
    replaced: AtomicU64,
}

/// Who is on the bus. Ordered maps, so that delivery order never depends on a hash.
#[derive(Default)]
struct Graph {
    next_entity: u64,
    topics: BTreeMap<&'static str, topics::TopicEntry>,
    services: BTreeMap<&'static str, services::ServiceEntry>,
    /// (topic, reading node) -> how long what it takes is held (`InProcessBus::delay`).
    delays: BTreeMap<(String, String), Duration>,
}

impl Graph {
    fn new_entity(&mut self) -> u64 {
        self.next_entity += 1;
        self.next_entity
    }
}

impl Shared {
    fn graph(&self) -> MutexGuard<'_, Graph> {
        // A node that panicked while holding it left the graph as it was: still usable.
        self.graph.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn changed(&self) {
        self.changed.send_modify(|g| *g += 1);
    }

    /// Waits until `holds(graph)`, or `timeout` passes on the bus's clock; true if it holds.
    async fn wait_until(&self, timeout: Duration, holds: impl Fn(&Graph) -> bool) -> bool {
        let mut changes = self.changed.subscribe();
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            if holds(&self.graph()) {
                return true;
            }
            match tokio::time::timeout_at(deadline, changes.changed()).await {
                Ok(Ok(())) => continue,
                _ => return false,
            }
        }
    }
}

impl InProcessBus {
    /// An empty bus whose nodes read `clock` (`Clock::starting_at` for a virtual one).
    pub fn new(clock: Clock) -> InProcessBus {
        InProcessBus {
            shared: Arc::new(Shared {
                graph: Mutex::new(Graph::default()),
                changed: watch::channel(0).0,
                clock,
                next_instance: AtomicU32::new(1),
                replaced: AtomicU64::new(0),
            }),
        }
    }

    /// The bus's clock.
    pub fn clock(&self) -> Clock {
        self.shared.clock
    }

    /// A new node named `name` joins the bus and starts its heartbeat (inside the runtime);
    /// the [`NodeStop`] asks it to stop as SIGINT would.
    pub fn join(&self, name: &str) -> anyhow::Result<(InProcessNode, NodeStop)> {
        let (stop_tx, stop_rx) = watch::channel(false);
        let mut node = InProcessNode {
            shared: self.shared.clone(),
            name: name.to_string(),
            instance: self.shared.next_instance.fetch_add(1, Ordering::Relaxed),
            drops: Arc::new(DropLog::default()),
            shutdown: stop_rx,
            tasks: Vec::new(),
        };
        let heartbeat = crate::heartbeat::start(&mut node)?;
        node.tasks.push(heartbeat);
        Ok((node, NodeStop(stop_tx)))
    }

    /// From now on, what `node` takes from `topic` (readers it makes from now) reaches it
    /// `by` later than it was sent, in the order sent: a slow link or a loaded reader, for the
    /// tests of what the nodes do then.
    pub fn delay(&self, topic: &str, node: &str, by: Duration) {
        self.shared
            .graph()
            .delays
            .insert((topic.to_string(), node.to_string()), by);
    }

    /// Best-effort samples a reader lost because it had 10 newer ones waiting.
    pub fn replaced_samples(&self) -> u64 {
        self.shared.replaced.load(Ordering::Relaxed)
    }

    /// Readers of `topic` on the bus now.
    pub fn readers(&self, topic: &str) -> usize {
        self.shared
            .graph()
            .topics
            .get(topic)
            .map_or(0, |t| t.typed.readers())
    }
}

/// Asks one node to stop, as SIGINT asks a DDS node.
#[derive(Clone)]
pub struct NodeStop(watch::Sender<bool>);

impl NodeStop {
    pub fn stop(&self) {
        let _ = self.0.send(true);
    }
}

/// One node on an [`InProcessBus`]: the [`Bus`] its code runs on.
pub struct InProcessNode {
    shared: Arc<Shared>,
    name: String,
    instance: u32,
    drops: Arc<DropLog>,
    shutdown: watch::Receiver<bool>,
    /// Its readers, servers and heartbeat: aborted when it stops or is dropped (killed).
    tasks: Vec<tokio::task::JoinHandle<()>>,
}

impl InProcessNode {
    /// Leaves the bus: its readers, servers and heartbeat go (its publishers went with the
    /// node's code).
    pub async fn stop(mut self) {
        let tasks = std::mem::take(&mut self.tasks);
        for task in &tasks {
            task.abort();
        }
        for task in tasks {
            let _ = task.await;
        }
    }
}

impl Drop for InProcessNode {
    /// A node dropped without `stop` (its task aborted: killed) leaves at once.
    fn drop(&mut self) {
        for task in &self.tasks {
            task.abort();
        }
    }
}

/// Removes one entity from the graph when dropped (with the task or handle that owns it).
pub(crate) struct Leave {
    shared: Arc<Shared>,
    what: Entity,
}

enum Entity {
    Reader(&'static str, u64),
    Server(&'static str, u64),
}

impl Drop for Leave {
    fn drop(&mut self) {
        {
            let mut graph = self.shared.graph();
            match self.what {
                Entity::Reader(topic, id) => {
                    if let Some(t) = graph.topics.get_mut(topic) {
                        t.typed.remove(id);
                    }
                }
                Entity::Server(service, id) => {
                    if let Some(s) = graph.services.get_mut(service) {
                        s.typed.remove(id);
                    }
                }
            }
        }
        self.shared.changed();
    }
}

/// What a reader or server has been sent and not taken yet.
pub(crate) struct Inbox<T> {
    queue: Mutex<VecDeque<T>>,
    arrived: Notify,
    /// Best effort: the most kept; the oldest goes when a newer one comes.
    keep_last: Option<usize>,
}

impl<T> Inbox<T> {
    fn new(keep_last: Option<usize>) -> Arc<Inbox<T>> {
        Arc::new(Inbox {
            queue: Mutex::new(VecDeque::new()),
            arrived: Notify::new(),
            keep_last,
        })
    }

    /// Adds `item`; false when it replaced the oldest.
    fn push(&self, item: T) -> bool {
        let mut kept = true;
        {
            let mut queue = self.queue.lock().unwrap_or_else(|e| e.into_inner());
            queue.push_back(item);
            if let Some(depth) = self.keep_last
                && queue.len() > depth
            {
                queue.pop_front();
                kept = false;
            }
        }
        self.arrived.notify_one();
        kept
    }

    /// The oldest item, once there is one (one taker per inbox).
    async fn pop(&self) -> T {
        loop {
            if let Some(item) = self
                .queue
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .pop_front()
            {
                return item;
            }
            self.arrived.notified().await;
        }
    }
}

impl Bus for InProcessNode {
    fn name(&self) -> &str {
        &self.name
    }

    fn process_id(&self) -> u32 {
        self.instance
    }

    fn clock(&self) -> Clock {
        self.shared.clock
    }

    fn drops(&self) -> Arc<DropLog> {
        self.drops.clone()
    }

    fn publisher<M: MessageDefinition>(&mut self, topic: Topic<M>) -> anyhow::Result<Outbox<M>> {
        let writer = topics::add_writer(&self.shared, topic, self.instance)?;
        Ok(Outbox {
            topic: topic.name,
            writer: crate::bus::Writer::InProcess(writer),
        })
    }

    fn subscribe<M>(
        &mut self,
        topic: Topic<M>,
        capacity: usize,
    ) -> anyhow::Result<mpsc::Receiver<M>>
    where
        M: MessageDefinition + Validate,
    {
        let (inbox, leave) = topics::add_reader(&self.shared, topic, &self.name)?;
        let (tx, rx) = mpsc::channel(capacity.max(1));
        let drops = self.drops.clone();
        let name = topic.name;
        self.tasks.push(tokio::spawn(async move {
            let _leave = leave;
            loop {
                let delivery = inbox.pop().await;
                match delivery.message.validate() {
                    Ok(()) => {
                        if tx.send(delivery.message).await.is_err() {
                            break;
                        }
                    }
                    Err(e) => {
                        drops.record(name, &e.to_string());
                    }
                }
            }
        }));
        Ok(rx)
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
        let (inbox, leave) = topics::add_reader(&self.shared, topic, &self.name)?;
        let clock = self.shared.clock;
        let own = self.instance;
        Ok(tokio::spawn(async move {
            let _leave = leave;
            loop {
                let d = inbox.pop().await;
                let tapped = Tapped {
                    message: d.message,
                    received_ns: clock.steady_nanos(),
                    source_timestamp_ns: Some(d.published_ns),
                    sequence_number: d.sequence,
                    from_this_participant: d.instance == own,
                };
                if let Some(item) = map(tapped)
                    && tx.send(item).await.is_err()
                {
                    break;
                }
            }
        }))
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
        let (rx, task) = services::serve(&self.shared, service, invalid, self.drops.clone())?;
        self.tasks.push(task);
        Ok(rx)
    }

    fn client<S: ServiceDefinition + 'static>(
        &mut self,
        service: Service<S>,
    ) -> anyhow::Result<ServiceClient<S>> {
        Ok(ServiceClient {
            name: service.name,
            caller: crate::bus::Caller::InProcess(services::Caller::new(&self.shared, service)),
        })
    }

    fn wait_for_service<S: ServiceDefinition + 'static>(
        &self,
        client: &ServiceClient<S>,
        timeout: Duration,
    ) -> impl Future<Output = bool> {
        let name = client.name;
        let shared = self.shared.clone();
        async move {
            shared
                .wait_until(timeout, |g| {
                    g.services.get(name).is_some_and(|s| s.typed.servers() > 0)
                })
                .await
        }
    }

    fn wait_for_subscribers<M: MessageDefinition>(
        &self,
        outbox: &Outbox<M>,
        timeout: Duration,
    ) -> impl Future<Output = bool> {
        let name = outbox.topic;
        let shared = self.shared.clone();
        async move {
            shared
                .wait_until(timeout, |g| {
                    g.topics.get(name).is_some_and(|t| t.typed.readers() > 0)
                })
                .await
        }
    }

    fn parameter_changes<P: crate::parameters::NodeParameters>(
        &mut self,
    ) -> mpsc::Receiver<crate::parameters::ParameterChange<P>> {
        // No ROS graph, so no parameter services: a channel that never yields.
        mpsc::channel(1).1
    }

    fn shutdown_signal(&self) -> impl Future<Output = ()> + Send + 'static {
        crate::shutdown::when_stopped(&self.shutdown)
    }
}

#[cfg(test)]
mod tests;
