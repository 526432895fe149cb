//! `bag record --all` over DDS records every topic of the ROS 2 graph, as `ros2 bag record -a`
//! does, not only the suite's: at each flush the recorder asks discovery for topics it does
//! not record yet, taps each as its publisher offers it, and takes its definition from what
//! it knows (the suite's types, ROS 2's builtin ones) or else from the publisher's own
//! `~/get_type_description`. A topic it cannot describe is recorded all the same, and the bag
//! says why (`bag info`).

use bag::recorder::{Discover, ForeignSample, ForeignTopic};
use bag_file::Stamp;
use node_shell::NodeShell;
use node_shell::foreign::RawSample;
use qt_therapy_msgs::MessageDefinition;
use qt_therapy_msgs::topics::QosKind;
use std::collections::{BTreeMap, HashSet};
use std::time::Duration;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio::time::Instant;

/// How long the recorder waits for a publisher's type description.
const DESCRIBE_TIMEOUT: Duration = Duration::from_secs(3);

/// How long the recorder waits for a publisher's node to be announced: discovery can report
/// the topic before the publisher's ros_discovery_info has arrived.
const NODE_TIMEOUT: Duration = Duration::from_secs(3);

/// How long a tapped topic stays tapped after discovery first reported it without a publisher
/// (it is released at the first flush after that): a writer's samples reach its readers before
/// its end is announced, so this only spares a publisher restarting at once a new reader.
const RELEASE_AFTER: Duration = Duration::from_millis(500);

/// One foreign topic being recorded.
struct Tapped {
    /// Its reader's task; aborting it drops the reader.
    reader: JoinHandle<()>,
    /// Since when discovery reports no publisher of it.
    unpublished_since: Option<Instant>,
    /// What its reader asked.
    qos: rustdds::QosPolicies,
}

/// The graph's topics beside the suite's, found and tapped as they appear, and released once
/// their publishers are gone: topics made per person (ROS4HRI's `/humans/persons/<id>/...`)
/// come and go with every session, and a recorder running for a year must not hold a reader
/// for each one it ever saw. A topic found again is tapped again into its channel.
pub struct GraphTopics {
    /// The suite's topics, recorded by their own taps.
    suite: HashSet<String>,
    /// Foreign topics tapped now.
    tapped: BTreeMap<String, Tapped>,
    /// Topics that could not be tapped (said once, not tried again).
    refused: HashSet<String>,
    raw: mpsc::Sender<RawSample>,
}

impl GraphTopics {
    /// Finds topics other than `recorded`; their samples go to the returned receiver.
    pub fn new(
        recorded: impl IntoIterator<Item = String>,
        capacity: usize,
    ) -> (GraphTopics, mpsc::Receiver<ForeignSample>) {
        let (raw, mut raw_rx) = mpsc::channel::<RawSample>(capacity.max(1));
        let (tx, rx) = mpsc::channel(capacity.max(1));
        tokio::spawn(async move {
            while let Some(s) = raw_rx.recv().await {
                let log_time = s.received_ns.max(0) as u64;
                let sample = ForeignSample {
                    topic: s.topic,
                    stamp: Stamp {
                        log_time,
                        publish_time: s.source_timestamp_ns.map_or(log_time, |t| t.max(0) as u64),
                        sequence: s.sequence_number as u32,
                    },
                    payload: s.payload,
                };
                if tx.send(sample).await.is_err() {
                    break;
                }
            }
        });
        (
            GraphTopics {
                suite: recorded.into_iter().collect(),
                tapped: BTreeMap::new(),
                refused: HashSet::new(),
                raw,
            },
            rx,
        )
    }
}

/// The definition of a type this program knows: the suite's, the other ROS 2 types our nodes
/// publish (a person's `std_msgs/Bool` and `hri_msgs/EngagementLevel`, `rosgraph_msgs/Clock`)
/// and the builtin ones (`/rosout`, `/parameter_events`).
fn known_definition(type_name: &str) -> Option<String> {
    use qt_therapy_msgs::{hri_msgs, rosgraph_msgs, std_msgs};
    if let Some(t) = bag_file::suite::suite_type(type_name) {
        return Some(t.schema_text());
    }
    let others = [
        (
            std_msgs::BoolMsg::full_type_name(),
            std_msgs::BoolMsg::schema_text(),
        ),
        (
            hri_msgs::EngagementLevel::full_type_name(),
            hri_msgs::EngagementLevel::schema_text(),
        ),
        (
            rosgraph_msgs::Clock::full_type_name(),
            rosgraph_msgs::Clock::schema_text(),
        ),
    ];
    others
        .into_iter()
        .find(|(name, _)| name == type_name)
        .map(|(_, text)| text)
        .or_else(|| node_shell::type_hashes::builtin_definition(type_name))
}

/// The QoS class nearest to what a publisher offers.
fn qos_class(qos: &rustdds::QosPolicies) -> QosKind {
    use rustdds::policy::{Durability, History, Reliability};
    let reliable = matches!(qos.reliability(), Some(Reliability::Reliable { .. }));
    let transient = !matches!(qos.durability(), None | Some(Durability::Volatile));
    let deep = !matches!(qos.history(), None | Some(History::KeepLast { depth: 1 }));
    match (reliable, transient, deep) {
        (false, _, _) => QosKind::Features,
        (true, false, _) => QosKind::Reliable,
        (true, true, false) => QosKind::State,
        (true, true, true) => QosKind::Durable,
    }
}

impl GraphTopics {
    /// Releases the readers of topics no publisher has offered for `RELEASE_AFTER`.
    fn release_unpublished(&mut self, published: &HashSet<String>) {
        let now = Instant::now();
        self.tapped.retain(|name, tap| {
            if published.contains(name) {
                tap.unpublished_since = None;
                return true;
            }
            let since = *tap.unpublished_since.get_or_insert(now);
            if now.duration_since(since) < RELEASE_AFTER {
                return true;
            }
            tap.reader.abort();
            tracing::debug!(topic = %name, "no publisher left: reader released");
            false
        });
    }

    /// Topics recorded now, by the suite's taps or ours.
    fn recorded(&self, name: &str) -> bool {
        self.suite.contains(name) || self.tapped.contains_key(name) || self.refused.contains(name)
    }
}

impl Discover<NodeShell> for GraphTopics {
    async fn discover(&mut self, shell: &mut NodeShell) -> Vec<ForeignTopic> {
        let offered = shell.foreign_topics(&|name| self.suite.contains(name));
        let published: HashSet<String> = offered.iter().map(|t| t.name.clone()).collect();
        self.release_unpublished(&published);
        // A publisher found since a topic was tapped may offer less than the reader asked
        // (volatile where the first offered transient-local): the reader is made again with
        // what matches every publisher, the new one before the old goes, so nothing is lost.
        for topic in &offered {
            let Some(tap) = self.tapped.get_mut(&topic.name) else {
                continue;
            };
            if qos_class(&topic.qos) == qos_class(&tap.qos) {
                continue;
            }
            match shell.tap_foreign(topic, self.raw.clone()) {
                Ok(reader) => {
                    let old = std::mem::replace(&mut tap.reader, reader);
                    old.abort();
                    tap.qos = topic.qos.clone();
                    tracing::debug!(topic = %topic.name, "a publisher offers less: reader made again to match it");
                }
                Err(e) => tracing::warn!(topic = %topic.name, "cannot tap again: {e:#}"),
            }
        }
        let found = shell.foreign_topics(&|name| self.recorded(name));
        let mut out = Vec::new();
        for topic in found {
            // The tap first, so nothing is lost while the publisher is asked.
            match shell.tap_foreign(&topic, self.raw.clone()) {
                Ok(reader) => {
                    self.tapped.insert(
                        topic.name.clone(),
                        Tapped {
                            reader,
                            unpublished_since: None,
                            qos: topic.qos.clone(),
                        },
                    );
                }
                Err(e) => {
                    tracing::warn!(topic = %topic.name, "cannot record: {e:#}");
                    self.refused.insert(topic.name.clone());
                    continue;
                }
            }
            let mut topic = topic;
            if topic.publisher_node.is_none() && known_definition(&topic.type_name).is_none() {
                let deadline = tokio::time::Instant::now() + NODE_TIMEOUT;
                while topic.publisher_node.is_none() && tokio::time::Instant::now() < deadline {
                    tokio::time::sleep(Duration::from_millis(100)).await;
                    topic.publisher_node = shell.graph().writer_node(topic.publisher);
                }
            }
            let definition = match known_definition(&topic.type_name) {
                Some(text) => Ok(text),
                None => match &topic.publisher_node {
                    Some(node) => {
                        shell
                            .foreign_definition(node, &topic, DESCRIBE_TIMEOUT)
                            .await
                    }
                    None => {
                        Err("its publisher's node is not announced (ros_discovery_info)".into())
                    }
                },
            };
            out.push(ForeignTopic {
                topic: topic.name.clone(),
                type_name: topic.type_name.clone(),
                definition,
                qos: qos_class(&topic.qos),
            });
        }
        out
    }
}
