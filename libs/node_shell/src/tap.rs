//! Subscriptions for tools that observe the graph instead of acting on it (the bag recorder):
//! every decodable message as it arrived, NOT validated (a recording must keep the nonsense
//! too), with when and by whom it was sent: `Tapped`. This file holds the DDS tap (with its
//! DDS sample info); `Bus::tap` is the way in on either bus.

use crate::NodeShell;
use crate::names::ros_name;
use crate::qos::qos_profile;
use anyhow::Context as _;
use qt_therapy_msgs::topics::Topic;
use qt_therapy_msgs::{MessageDefinition, dds_type_name};
use tokio::sync::mpsc;

/// One message as a tap saw it.
#[derive(Debug, Clone)]
pub struct Tapped<M> {
    pub message: M,
    /// When it reached this node, on the node's steady clock (never stepped; a recorder's log
    /// time): RustDDS's receive time, which the suite's patch keeps on that clock.
    pub received_ns: i64,
    /// When its publisher wrote it (ns since the epoch), if the sample carried a timestamp.
    pub source_timestamp_ns: Option<i64>,
    /// The publisher's sequence number of this sample.
    pub sequence_number: i64,
    /// Published by this very node (e.g. its own heartbeat): over DDS, by an entity of this
    /// participant.
    pub from_this_participant: bool,
}

impl NodeShell {
    /// Subscribes to `topic` with the topic's QoS and forwards `map(message)` to `tx` until
    /// `tx` closes. Undecodable samples are counted in the shell's drop log.
    pub(crate) fn dds_tap<M, T, F>(
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
        let qos = qos_profile(topic.qos);
        crate::type_hashes::announce_message::<M>(&self.context.domain_participant())?;
        let name = ros_name(topic.name)?;
        let drops = self.drops.clone();
        let node = &mut self.node;
        let dds_topic = node
            .create_topic(&name, dds_type_name::<M>(), &qos)
            .with_context(|| format!("creating topic {}", topic.name))?;
        let subscription = node
            .create_subscription::<M>(&dds_topic, Some(qos))
            .with_context(|| format!("tapping {}", topic.name))?;
        // Entities of one participant share the GUID prefix (the first 12 bytes of a GID).
        let own_prefix: Vec<u8> = subscription.gid().as_bytes()[..12].to_vec();
        let topic_name = topic.name;
        Ok(tokio::spawn(async move {
            loop {
                match subscription.async_take().await {
                    Ok((message, info)) => {
                        let tapped = Tapped {
                            message,
                            received_ns: info
                                .received_timestamp()
                                .map_or_else(crate::clock::steady_nanos, |t| t.to_nanos()),
                            source_timestamp_ns: info.source_timestamp().map(|t| t.to_nanos()),
                            sequence_number: info.sequence_number(),
                            from_this_participant: info.publisher_gid().as_bytes()[..12]
                                == own_prefix[..],
                        };
                        if let Some(item) = map(tapped)
                            && tx.send(item).await.is_err()
                        {
                            break;
                        }
                    }
                    Err(e) => {
                        drops.record(topic_name, &format!("undecodable payload: {e:?}"));
                    }
                }
            }
        }))
    }
}
