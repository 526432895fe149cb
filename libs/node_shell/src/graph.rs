//! Which ROS 2 node owns a remote reader or writer, as rcl knows it: every participant
//! announces its nodes and their readers' and writers' gids on `ros_discovery_info`
//! (rmw_dds_common's ParticipantEntitiesInfo; rcl's graph cache keeps the newest of each
//! participant, `rmw_dds_common/src/graph_cache.cpp` `update_participant_entities`). With
//! RustDDS's discovered endpoints this names the node behind an endpoint of a topic: the game
//! manager waits for the robot's own speech subscriber, the recorder asks a foreign topic's
//! publisher for its type description.

use anyhow::Context as _;
use futures::StreamExt as _;
use rustdds::GUID;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

/// `rmw_dds_common/msg/Gid`: a DDS GUID's 16 bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
struct Gid([u8; 16]);

/// `rmw_dds_common/msg/NodeEntitiesInfo`.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct NodeEntitiesInfo {
    node_namespace: String,
    node_name: String,
    reader_gid_seq: Vec<Gid>,
    writer_gid_seq: Vec<Gid>,
}

/// `rmw_dds_common/msg/ParticipantEntitiesInfo`.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct ParticipantEntitiesInfo {
    gid: Gid,
    node_entities_info_seq: Vec<NodeEntitiesInfo>,
}

impl ros2_client::Message for ParticipantEntitiesInfo {}

/// The nodes of every participant heard on `ros_discovery_info`, by participant gid.
#[derive(Clone, Default)]
pub struct Graph {
    participants: Arc<Mutex<BTreeMap<Gid, Vec<NodeEntitiesInfo>>>>,
}

/// A node's fully qualified name (`/name`, `/ns/name`).
fn qualified(node: &NodeEntitiesInfo) -> String {
    match node.node_namespace.trim_end_matches('/') {
        "" => format!("/{}", node.node_name),
        ns => format!("{ns}/{}", node.node_name),
    }
}

impl Graph {
    /// The node (fully qualified) whose reader `guid` is, if its participant announced it.
    pub fn reader_node(&self, guid: GUID) -> Option<String> {
        self.node_of(guid, |n| &n.reader_gid_seq)
    }

    /// The node (fully qualified) whose writer `guid` is, if its participant announced it.
    pub fn writer_node(&self, guid: GUID) -> Option<String> {
        self.node_of(guid, |n| &n.writer_gid_seq)
    }

    fn node_of(&self, guid: GUID, gids: fn(&NodeEntitiesInfo) -> &Vec<Gid>) -> Option<String> {
        let gid = Gid(guid.to_bytes());
        let participants = self.participants.lock().ok()?;
        participants
            .values()
            .flatten()
            .find(|n| gids(n).contains(&gid))
            .map(qualified)
    }

    fn update(&self, info: ParticipantEntitiesInfo) {
        if let Ok(mut participants) = self.participants.lock() {
            participants.insert(info.gid, info.node_entities_info_seq);
        }
    }
}

/// Starts reading `ros_discovery_info` into a [`Graph`]; the task ends when the reader does.
pub(crate) fn follow(
    context: &ros2_client::Context,
    node: &mut ros2_client::Node,
) -> anyhow::Result<(Graph, tokio::task::JoinHandle<()>)> {
    use ros2_client::builtin_topics::ros_discovery;
    // As rmw_fastrtps reads it (`init_rmw_context_impl.cpp`): reliable, transient-local, every
    // sample (a participant's newest replaces its older ones below).
    let qos = rustdds::QosPolicyBuilder::new()
        .history(rustdds::policy::History::KeepAll)
        .build()
        .modify_by(&ros_discovery::QOS_PUB);
    let topic = context
        .domain_participant()
        .create_topic(
            ros_discovery::TOPIC_NAME.to_string(),
            ros_discovery::TYPE_NAME.to_string(),
            &qos,
            rustdds::TopicKind::NoKey,
        )
        .context("creating the ros_discovery_info topic")?;
    let reader = node
        .create_subscription::<ParticipantEntitiesInfo>(&topic, None)
        .context("reading ros_discovery_info")?;
    let graph = Graph::default();
    let filled = graph.clone();
    let task = tokio::spawn(async move {
        let samples = reader.async_stream();
        tokio::pin!(samples);
        while let Some(sample) = samples.next().await {
            match sample {
                Ok((info, _)) => filled.update(info),
                Err(e) => tracing::debug!("an undecodable ros_discovery_info sample: {e:?}"),
            }
        }
    });
    Ok((graph, task))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_the_node_of_an_announced_endpoint() {
        let guid = GUID::from_bytes([7; 16]);
        let graph = Graph::default();
        assert_eq!(graph.reader_node(guid), None);
        graph.update(ParticipantEntitiesInfo {
            gid: Gid([1; 16]),
            node_entities_info_seq: vec![NodeEntitiesInfo {
                node_namespace: "/".into(),
                node_name: "robot".into(),
                reader_gid_seq: vec![Gid([7; 16])],
                writer_gid_seq: vec![],
            }],
        });
        assert_eq!(graph.reader_node(guid).as_deref(), Some("/robot"));
        assert_eq!(graph.writer_node(guid), None);
        // A participant's newest announcement replaces its older one.
        graph.update(ParticipantEntitiesInfo {
            gid: Gid([1; 16]),
            node_entities_info_seq: vec![],
        });
        assert_eq!(graph.reader_node(guid), None);
    }
}
