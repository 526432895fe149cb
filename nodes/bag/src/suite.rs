//! The suite's message types, type-erased so the recorder and the player can handle a topic
//! by its rosbag2 type name: check a CDR payload, tap a topic over DDS into CDR samples, and
//! publish CDR payloads from a bag as typed messages.

use crate::cdr::{self, CdrError};
use crate::writer::Stamp;
use node_shell::tap::tap;
use node_shell::{NodeShell, Outbox};
use qt_therapy_msgs::topics::{QosKind, Topic};
use qt_therapy_msgs::*;
use ros2_client::Message;
use std::future::Future;
use std::marker::PhantomData;
use std::pin::Pin;
use std::time::Duration;
use tokio::sync::mpsc;

/// One recorded message on its way to the writer.
#[derive(Debug, Clone)]
pub struct Sample {
    pub channel_id: u16,
    pub stamp: Stamp,
    pub payload: Vec<u8>,
}

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

/// One message type of the suite, type-erased.
pub trait SuiteType: Send + Sync {
    /// `pkg/msg/Type`
    fn type_name(&self) -> String;
    /// The rosbag2 schema text (`ros2msg`, dependencies appended).
    fn schema_text(&self) -> String;
    /// Whether `payload` decodes as this type.
    fn check_cdr(&self, payload: &[u8]) -> Result<(), CdrError>;
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

struct TypedPublisher<M: Message> {
    outbox: Outbox<M>,
}

impl<M: MessageDefinition + Message> CdrPublisher for TypedPublisher<M> {
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

impl<M: MessageDefinition + Message> SuiteType for Typed<M> {
    fn type_name(&self) -> String {
        M::full_type_name()
    }

    fn schema_text(&self) -> String {
        M::schema_text()
    }

    fn check_cdr(&self, payload: &[u8]) -> Result<(), CdrError> {
        cdr::decode::<M>(payload).map(|_| ())
    }

    fn tap(
        &self,
        shell: &mut NodeShell,
        topic: &'static str,
        qos: QosKind,
        channel_id: u16,
        tx: mpsc::Sender<Sample>,
    ) -> anyhow::Result<tokio::task::JoinHandle<()>> {
        tap(shell, Topic::<M>::new(topic, qos), tx, move |t| {
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

fn typed<M: MessageDefinition + Message>() -> Box<dyn SuiteType> {
    Box::new(Typed::<M>(PhantomData))
}

/// Every message type that travels on one of the suite's topics.
pub fn suite_types() -> Vec<Box<dyn SuiteType>> {
    vec![
        typed::<OpenFaceFeatures>(),
        typed::<EngagementEstimate>(),
        typed::<ExpectedEngagement>(),
        typed::<TherapistCommand>(),
        typed::<GameState>(),
        typed::<SequenceResult>(),
        typed::<TabletTask>(),
        typed::<TabletAnswer>(),
        typed::<Decision>(),
        typed::<UserModelInfo>(),
        typed::<Heartbeat>(),
        typed::<std_msgs::StringMsg>(),
    ]
}

/// The suite type named `type_name` (`pkg/msg/Type`).
pub fn suite_type(type_name: &str) -> Option<Box<dyn SuiteType>> {
    suite_types()
        .into_iter()
        .find(|t| t.type_name() == type_name)
}

#[cfg(test)]
mod tests {
    use super::*;
    use qt_therapy_msgs::topics::all_topics;

    #[test]
    fn every_topic_of_the_suite_has_its_type_here() {
        for topic in all_topics() {
            let t = suite_type(&topic.type_name).unwrap_or_else(|| {
                panic!("{} ({}) has no suite type", topic.name, topic.type_name)
            });
            assert_eq!(t.schema_text(), topic.schema_text);
        }
        assert!(suite_type("geometry_msgs/msg/Twist").is_none());
    }

    #[test]
    fn check_cdr_tells_types_apart() {
        let m = std_msgs::StringMsg { data: "hi".into() };
        let payload = cdr::encode(&m).expect("encodes");
        let string = suite_type("std_msgs/msg/String").expect("known");
        assert!(string.check_cdr(&payload).is_ok());
        let decision = suite_type("qt_therapy_msgs/msg/Decision").expect("known");
        assert!(decision.check_cdr(&payload).is_err());
    }
}
