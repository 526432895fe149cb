//! The suite's message types over DDS, for the recorder and the player: tap a topic into CDR
//! samples, and publish CDR payloads from a bag as typed messages. The list of types is the
//! bag library's ([`bag_file::suite::for_each_suite_type`]).

use bag_file::cdr;
use bag_file::suite::{PerType, Sample, for_each_suite_type};
use bag_file::writer::Stamp;
use node_shell::{Bus, NodeShell, Outbox};
use qt_therapy_msgs::MessageDefinition;
use qt_therapy_msgs::topics::{QosKind, Topic};
use std::future::Future;
use std::marker::PhantomData;
use std::pin::Pin;
use std::time::Duration;
use tokio::sync::mpsc;

/// A DDS publisher fed with CDR payloads from a bag.
pub trait CdrPublisher {
    fn topic(&self) -> &str;
    /// Decodes `payload` and publishes it.
    fn publish_cdr(&self, payload: &[u8]) -> Result<(), String>;
    /// Waits until a subscriber matched, or `timeout`; true if one did.
    fn wait_for_subscribers<'a>(
        &'a self,
        shell: &'a NodeShell,
        timeout: Duration,
    ) -> Pin<Box<dyn Future<Output = bool> + 'a>>;
}

/// One message type of the suite, over DDS.
pub trait DdsType: Send + Sync {
    /// `pkg/msg/Type`
    fn type_name(&self) -> String;
    /// Taps `topic` over DDS; every message from another process reaches `tx` as a CDR sample
    /// on `channel_id`, logged at receipt and published at its source timestamp.
    fn tap(
        &self,
        shell: &mut NodeShell,
        topic: &'static str,
        qos: QosKind,
        channel_id: u16,
        tx: mpsc::Sender<Sample>,
    ) -> anyhow::Result<tokio::task::JoinHandle<()>>;
    /// A publisher on `topic` for this type's CDR payloads.
    fn publisher(
        &self,
        shell: &mut NodeShell,
        topic: &'static str,
        qos: QosKind,
    ) -> anyhow::Result<Box<dyn CdrPublisher>>;
}

struct Typed<M>(PhantomData<fn() -> M>);

struct TypedPublisher<M: MessageDefinition> {
    outbox: Outbox<M>,
}

impl<M: MessageDefinition> CdrPublisher for TypedPublisher<M> {
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
        shell: &'a NodeShell,
        timeout: Duration,
    ) -> Pin<Box<dyn Future<Output = bool> + 'a>> {
        Box::pin(self.outbox.wait_for_subscribers(shell, timeout))
    }
}

impl<M: MessageDefinition> DdsType for Typed<M> {
    fn type_name(&self) -> String {
        M::full_type_name()
    }

    fn tap(
        &self,
        shell: &mut NodeShell,
        topic: &'static str,
        qos: QosKind,
        channel_id: u16,
        tx: mpsc::Sender<Sample>,
    ) -> anyhow::Result<tokio::task::JoinHandle<()>> {
        shell.tap(Topic::<M>::new(topic, qos), tx, move |t| {
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
        shell: &mut NodeShell,
        topic: &'static str,
        qos: QosKind,
    ) -> anyhow::Result<Box<dyn CdrPublisher>> {
        let outbox = shell.publisher(Topic::<M>::new(topic, qos))?;
        Ok(Box::new(TypedPublisher { outbox }))
    }
}

struct OverDds;

impl PerType for OverDds {
    type Made = Box<dyn DdsType>;
    fn make<M: MessageDefinition>(&self) -> Box<dyn DdsType> {
        Box::new(Typed::<M>(PhantomData))
    }
}

/// The suite type named `type_name` (`pkg/msg/Type`), over DDS.
pub fn dds_type(type_name: &str) -> Option<Box<dyn DdsType>> {
    for_each_suite_type(&OverDds)
        .into_iter()
        .find(|t| t.type_name() == type_name)
}
