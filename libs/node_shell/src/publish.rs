//! Publishing over DDS: a typed ros2-client publisher on one of the suite's topics, with the
//! topic's QoS, behind an [`Outbox`].

use crate::NodeShell;
use crate::bus::{Outbox, Writer};
use crate::names::ros_name;
use crate::qos::qos_profile;
use anyhow::Context as _;
use qt_therapy_msgs::topics::Topic;
use qt_therapy_msgs::{MessageDefinition, dds_type_name};

impl NodeShell {
    /// A publisher on one of the suite's topics.
    pub fn publisher<M: MessageDefinition>(
        &mut self,
        topic: Topic<M>,
    ) -> anyhow::Result<Outbox<M>> {
        let qos = qos_profile(topic.qos);
        crate::type_hashes::announce_message::<M>(&self.context.domain_participant())?;
        let dds_topic = self
            .node
            .create_topic(&ros_name(topic.name)?, dds_type_name::<M>(), &qos)
            .with_context(|| format!("creating topic {}", topic.name))?;
        let publisher = self
            .node
            .create_publisher::<M>(&dds_topic, Some(qos))
            .with_context(|| format!("creating a publisher on {}", topic.name))?;
        Ok(Outbox {
            topic: topic.name,
            writer: Writer::Dds(publisher),
        })
    }

    /// Waits until a DDS subscriber matched `outbox` (then a short settle, since the remote
    /// side may match us a moment later), or `timeout` passes; true if matched.
    pub(crate) async fn dds_wait_for_subscribers<M: MessageDefinition>(
        &self,
        outbox: &Outbox<M>,
        timeout: std::time::Duration,
    ) -> bool {
        let Writer::Dds(publisher) = &outbox.writer else {
            tracing::warn!(
                topic = outbox.topic,
                "an in-process publisher waited on for DDS subscribers: none"
            );
            return false;
        };
        let matched = crate::services::wait_rechecking(timeout, || {
            publisher.wait_for_subscription(&self.node)
        })
        .await;
        if matched {
            tokio::time::sleep(std::time::Duration::from_millis(200)).await;
        }
        matched
    }

    /// Waits until node `node` (`name` or `/ns/name`) has a subscriber of `outbox`'s topic
    /// that discovery reported and our writer matched (then the same settle), or `timeout`
    /// passes; true if it has. The node is known by what its participant announces on
    /// ros_discovery_info (`graph`).
    pub(crate) async fn dds_wait_for_node_subscription<M: MessageDefinition>(
        &self,
        outbox: &Outbox<M>,
        node: &str,
        timeout: std::time::Duration,
    ) -> bool {
        let Writer::Dds(publisher) = &outbox.writer else {
            return false;
        };
        let wanted = if node.starts_with('/') {
            node.to_string()
        } else {
            format!("/{node}")
        };
        // The suite's topics are absolute: `/a/b` is `rt/a/b` on DDS.
        let dds_topic = format!("rt{}", outbox.topic);
        let participant = self.context.domain_participant();
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            let announced = participant.discovered_readers().iter().any(|r| {
                r.subscription_topic_data.topic_name() == &dds_topic
                    && self
                        .graph
                        .reader_node(r.reader_proxy.remote_reader_guid)
                        .as_deref()
                        == Some(wanted.as_str())
            });
            if announced && publisher.get_subscription_count(&self.node) > 0 {
                tokio::time::sleep(std::time::Duration::from_millis(200)).await;
                return true;
            }
            if tokio::time::Instant::now() >= deadline {
                return false;
            }
            tokio::time::sleep(std::time::Duration::from_millis(100)).await;
        }
    }
}
