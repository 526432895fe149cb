//! Topics on the in-process bus: each writer's kept history (transient-local topics), the
//! readers' inboxes, and delivery in the order things were sent.

use super::{Entity, Inbox, Leave, Shared};
use qt_therapy_msgs::MessageDefinition;
use qt_therapy_msgs::topics::{QosKind, Topic};
use std::any::Any;
use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;
use tokio::sync::mpsc;
use tokio::time::Instant;

/// One message on its way to a reader.
#[derive(Clone)]
pub(crate) struct Delivery<M> {
    pub message: M,
    /// On the bus's clock.
    pub published_ns: i64,
    /// The writer's sequence number of it (from 1).
    pub sequence: i64,
    /// The node instance that sent it.
    pub instance: u32,
}

pub(crate) struct TopicEntry {
    type_name: String,
    qos: QosKind,
    pub(super) typed: Box<dyn AnyTopic>,
}

/// A topic whose message type is known only to its writers and readers.
pub(super) trait AnyTopic: Send {
    fn as_any(&mut self) -> &mut dyn Any;
    /// Removes the writer or reader `id`.
    fn remove(&mut self, id: u64);
    fn readers(&self) -> usize;
}

struct TypedTopic<M> {
    writers: BTreeMap<u64, WriterState<M>>,
    readers: BTreeMap<u64, Reader<M>>,
}

/// Where a reader's deliveries go: its inbox, or first a queue that holds each for a while
/// (`InProcessBus::delay`).
enum Reader<M> {
    Now(Arc<Inbox<Delivery<M>>>),
    Later(mpsc::UnboundedSender<(Instant, Delivery<M>)>, Duration),
}

impl<M: Send + 'static> Reader<M> {
    /// Hands `d` over; false when it replaced an older one (best effort).
    fn deliver(&self, d: Delivery<M>) -> bool {
        match self {
            Reader::Now(inbox) => inbox.push(d),
            Reader::Later(queue, by) => {
                let _ = queue.send((Instant::now() + *by, d));
                true
            }
        }
    }

    /// A reader whose deliveries reach `inbox` `by` after they were sent, in order.
    fn later(inbox: Arc<Inbox<Delivery<M>>>, by: Duration) -> Reader<M> {
        let (tx, mut rx) = mpsc::unbounded_channel::<(Instant, Delivery<M>)>();
        tokio::spawn(async move {
            while let Some((due, d)) = rx.recv().await {
                tokio::time::sleep_until(due).await;
                inbox.push(d);
            }
        });
        Reader::Later(tx, by)
    }
}

struct WriterState<M> {
    sequence: i64,
    /// What a reader that joins later is sent (transient-local topics only).
    history: VecDeque<Delivery<M>>,
}

impl<M: Send + 'static> AnyTopic for TypedTopic<M> {
    fn as_any(&mut self) -> &mut dyn Any {
        self
    }

    fn remove(&mut self, id: u64) {
        self.writers.remove(&id);
        self.readers.remove(&id);
    }

    fn readers(&self) -> usize {
        self.readers.len()
    }
}

/// How many samples of each writer a reader joining later gets.
fn kept(qos: QosKind) -> usize {
    match qos {
        QosKind::State => 1,
        QosKind::Durable => 100,
        QosKind::Reliable | QosKind::Features => 0,
    }
}

/// The unread samples a best-effort reader keeps (keep last 10).
fn reader_depth(qos: QosKind) -> Option<usize> {
    (qos == QosKind::Features).then_some(10)
}

/// The typed topic `topic`, made on first use; another type or QoS under its name is an error.
fn typed<'g, M: MessageDefinition>(
    topics: &'g mut BTreeMap<&'static str, TopicEntry>,
    topic: Topic<M>,
) -> anyhow::Result<&'g mut TypedTopic<M>> {
    let entry = topics.entry(topic.name).or_insert_with(|| TopicEntry {
        type_name: M::full_type_name(),
        qos: topic.qos,
        typed: Box::new(TypedTopic::<M> {
            writers: BTreeMap::new(),
            readers: BTreeMap::new(),
        }),
    });
    if entry.type_name != M::full_type_name() {
        anyhow::bail!(
            "{} carries {} on this bus, not {}",
            topic.name,
            entry.type_name,
            M::full_type_name()
        );
    }
    if entry.qos != topic.qos {
        anyhow::bail!(
            "{} is {} on this bus, not {}",
            topic.name,
            entry.qos.describe(),
            topic.qos.describe()
        );
    }
    entry
        .typed
        .as_any()
        .downcast_mut::<TypedTopic<M>>()
        .ok_or_else(|| anyhow::anyhow!("{}: two Rust types for one message type", topic.name))
}

/// A writer on the in-process bus (inside an [`Outbox`](crate::Outbox)); it leaves, with its
/// history, when dropped.
pub(crate) struct Writer<M: MessageDefinition> {
    shared: Arc<Shared>,
    topic: Topic<M>,
    id: u64,
    instance: u32,
}

pub(super) fn add_writer<M: MessageDefinition>(
    shared: &Arc<Shared>,
    topic: Topic<M>,
    instance: u32,
) -> anyhow::Result<Writer<M>> {
    let id = {
        let mut graph = shared.graph();
        let id = graph.new_entity();
        typed(&mut graph.topics, topic)?.writers.insert(
            id,
            WriterState {
                sequence: 0,
                history: VecDeque::new(),
            },
        );
        id
    };
    shared.changed();
    Ok(Writer {
        shared: shared.clone(),
        topic,
        id,
        instance,
    })
}

/// A new reader of `topic` for `node`: its inbox, holding the kept history of every writer
/// already there, and what removes it.
pub(super) fn add_reader<M: MessageDefinition>(
    shared: &Arc<Shared>,
    topic: Topic<M>,
    node: &str,
) -> anyhow::Result<(Arc<Inbox<Delivery<M>>>, Leave)> {
    let inbox = Inbox::new(reader_depth(topic.qos));
    let id = {
        let mut graph = shared.graph();
        let id = graph.new_entity();
        let delay = graph
            .delays
            .get(&(topic.name.to_string(), node.to_string()))
            .copied();
        let reader = match delay {
            Some(by) => Reader::later(inbox.clone(), by),
            None => Reader::Now(inbox.clone()),
        };
        let t = typed(&mut graph.topics, topic)?;
        for w in t.writers.values() {
            for d in &w.history {
                reader.deliver(d.clone());
            }
        }
        t.readers.insert(id, reader);
        id
    };
    shared.changed();
    let leave = Leave {
        shared: shared.clone(),
        what: Entity::Reader(topic.name, id),
    };
    Ok((inbox, leave))
}

impl<M: MessageDefinition> Writer<M> {
    /// Sends `message` to every reader now, keeping it for later ones on a transient-local
    /// topic.
    pub(crate) fn publish(&self, message: M) -> Result<(), String> {
        let published_ns = self.shared.clock.now_nanos();
        let mut graph = self.shared.graph();
        let t = typed(&mut graph.topics, self.topic).map_err(|e| e.to_string())?;
        let Some(w) = t.writers.get_mut(&self.id) else {
            return Err("this publisher has left the bus".into());
        };
        w.sequence += 1;
        let delivery = Delivery {
            message,
            published_ns,
            sequence: w.sequence,
            instance: self.instance,
        };
        let keep = kept(self.topic.qos);
        if keep > 0 {
            w.history.push_back(delivery.clone());
            while w.history.len() > keep {
                w.history.pop_front();
            }
        }
        for reader in t.readers.values() {
            if !reader.deliver(delivery.clone()) {
                self.shared.replaced.fetch_add(1, Ordering::Relaxed);
            }
        }
        Ok(())
    }
}

impl<M: MessageDefinition> Drop for Writer<M> {
    fn drop(&mut self) {
        {
            let mut graph = self.shared.graph();
            if let Some(t) = graph.topics.get_mut(self.topic.name) {
                t.typed.remove(self.id);
            }
        }
        self.shared.changed();
    }
}
