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
}
