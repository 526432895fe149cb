//! Subscribing over DDS: decoded samples are validated on a task of the node's, and the valid
//! ones handed to the node's channel; undecodable or invalid ones are logged once per topic and
//! kind of reason (`drops`) and dropped, so bad input never reaches a node's core.

use crate::NodeShell;
use crate::names::ros_name;
use crate::qos::qos_profile;
use anyhow::Context as _;
use qt_therapy_msgs::topics::Topic;
use qt_therapy_msgs::{MessageDefinition, Validate, dds_type_name};
use tokio::sync::mpsc;

impl NodeShell {
    /// A subscription whose decoded, validated messages arrive on the returned channel.
    /// Undecodable or invalid messages are logged once per topic and reason, and dropped.
    pub fn subscribe<M>(
        &mut self,
        topic: Topic<M>,
        capacity: usize,
    ) -> anyhow::Result<mpsc::Receiver<M>>
    where
        M: MessageDefinition + Validate,
    {
        let qos = qos_profile(topic.qos);
        crate::type_hashes::announce_message::<M>(&self.context.domain_participant())?;
        let dds_topic = self
            .node
            .create_topic(&ros_name(topic.name)?, dds_type_name::<M>(), &qos)
            .with_context(|| format!("creating topic {}", topic.name))?;
        let subscription = self
            .node
            .create_subscription::<M>(&dds_topic, Some(qos))
            .with_context(|| format!("subscribing to {}", topic.name))?;
        let (tx, rx) = mpsc::channel(capacity.max(1));
        let drops = self.drops.clone();
        let name = topic.name;
        self.tasks.push(tokio::spawn(async move {
            loop {
                match subscription.async_take().await {
                    Ok((message, _info)) => match message.validate() {
                        Ok(()) => {
                            if tx.send(message).await.is_err() {
                                break;
                            }
                        }
                        Err(e) => {
                            drops.record(name, &e.to_string());
                        }
                    },
                    Err(e) => {
                        drops.record(name, &format!("undecodable payload: {e:?}"));
                    }
                }
            }
        }));
        Ok(rx)
    }
}
