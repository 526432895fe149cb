//! The suite's message types on a bus (`node_shell::Bus`: DDS, or in process), for the
//! recorder and the player: tap a topic into CDR samples, and publish CDR payloads from a bag
//! as typed messages. The list of types is the bag library's
//! ([`bag_file::suite::for_each_suite_type`]).

use bag_file::cdr;
use bag_file::suite::{PerType, Sample, for_each_suite_type};
use bag_file::writer::Stamp;
use node_shell::{Bus, Outbox};
use qt_therapy_msgs::MessageDefinition;
use qt_therapy_msgs::topics::{QosKind, Topic};
use std::future::Future;
use std::marker::PhantomData;
use std::pin::Pin;
use std::time::Duration;
use tokio::sync::mpsc;

/// A publisher on bus `B` fed with CDR payloads from a bag.
pub trait CdrPublisher<B: Bus> {
    fn topic(&self) -> &str;
    /// Decodes `payload` and publishes it.
    fn publish_cdr(&self, payload: &[u8]) -> Result<(), String>;
    /// Waits until a subscriber is there, or `timeout`; true if one is.
    fn wait_for_subscribers<'a>(
        &'a self,
        bus: &'a B,
        timeout: Duration,
    ) -> Pin<Box<dyn Future<Output = bool> + 'a>>;
}

/// One message type of the suite, on bus `B`.
pub trait BusType<B: Bus>: Send + Sync {
    /// `pkg/msg/Type`
    fn type_name(&self) -> String;
    /// Taps `topic`; every message from another node reaches `tx` as a CDR sample on
    /// `channel_id`, logged at receipt and published at its source timestamp.
    fn tap(
        &self,
        bus: &mut B,
        topic: &'static str,
        qos: QosKind,
        channel_id: u16,
        tx: mpsc::Sender<Sample>,
    ) -> anyhow::Result<tokio::task::JoinHandle<()>>;
    /// A publisher on `topic` for this type's CDR payloads.
    fn publisher(
        &self,
        bus: &mut B,
        topic: &'static str,
        qos: QosKind,
    ) -> anyhow::Result<Box<dyn CdrPublisher<B>>>;
}

struct Typed<M, B>(PhantomData<fn() -> (M, B)>);

struct TypedPublisher<M: MessageDefinition> {
    outbox: Outbox<M>,
}

impl<M: MessageDefinition, B: Bus> CdrPublisher<B> for TypedPublisher<M> {
    fn topic(&self) -> &str {
        self.outbox.topic()
    }

    fn publish_cdr(&self, payload: &[u8]) -> Result<(), String> {
        let message = cdr::decode::<M>(payload).map_err(|e| e.to_string())?;
        if self.outbox.send(message) {
            Ok(())
        } else {
            Err(format!("publishing on {} failed", self.outbox.topic()))
        }
    }

    fn wait_for_subscribers<'a>(
        &'a self,
        bus: &'a B,
        timeout: Duration,
    ) -> Pin<Box<dyn Future<Output = bool> + 'a>> {
        Box::pin(self.outbox.wait_for_subscribers(bus, timeout))
    }
}

impl<M: MessageDefinition, B: Bus + 'static> BusType<B> for Typed<M, B> {
    fn type_name(&self) -> String {
        M::full_type_name()
    }

    fn tap(
        &self,
        bus: &mut B,
        topic: &'static str,
        qos: QosKind,
        channel_id: u16,
        tx: mpsc::Sender<Sample>,
    ) -> anyhow::Result<tokio::task::JoinHandle<()>> {
        bus.tap(Topic::<M>::new(topic, qos), tx, move |t| {
            // The recorder's own heartbeat is not part of the session.
            if t.from_this_participant {
                return None;
            }
            let payload = match cdr::encode(&t.message) {
                Ok(p) => p,
                Err(e) => {
                    tracing::warn!(topic, "cannot re-encode a message: {e}");
                    return None;
                }
            };
            let log_time = t.received_ns.max(0) as u64;
            Some(Sample {
                channel_id,
                stamp: Stamp {
                    log_time,
                    publish_time: t.source_timestamp_ns.map_or(log_time, |s| s.max(0) as u64),
                    // MCAP keeps 32 bits of the publisher's 64-bit sequence number.
                    sequence: t.sequence_number as u32,
                },
                payload,
            })
        })
    }

    fn publisher(
        &self,
        bus: &mut B,
        topic: &'static str,
        qos: QosKind,
    ) -> anyhow::Result<Box<dyn CdrPublisher<B>>> {
        let outbox = bus.publisher(Topic::<M>::new(topic, qos))?;
        Ok(Box::new(TypedPublisher { outbox }))
    }
}

struct OnBus<B>(PhantomData<fn() -> B>);

impl<B: Bus + 'static> PerType for OnBus<B> {
    type Made = Box<dyn BusType<B>>;
    fn make<M: MessageDefinition>(&self) -> Box<dyn BusType<B>> {
        Box::new(Typed::<M, B>(PhantomData))
    }
}

/// The suite type named `type_name` (`pkg/msg/Type`), on bus `B`.
pub fn bus_type<B: Bus + 'static>(type_name: &str) -> Option<Box<dyn BusType<B>>> {
    for_each_suite_type(&OnBus::<B>(PhantomData))
        .into_iter()
        .find(|t| t.type_name() == type_name)
}
