//! Topics of the ROS 2 graph that are not the suite's, for the recorder's `--all` (as
//! `ros2 bag record -a` records every topic): which topics discovery reports, with the type,
//! QoS and node of their publishers; a tap that keeps each sample's serialized bytes (their
//! type is unknown here); and the publisher's own account of the type, asked of its node's
//! `~/get_type_description` (Jazzy's `type_description_interfaces/srv/GetTypeDescription`).

use crate::NodeShell;
use crate::type_hashes::{IndividualTypeDescriptionMsg, TypeDescriptionMsg};
use anyhow::Context as _;
use futures::StreamExt as _;
use rustdds::no_key::{Decode, DefaultDecoder, DeserializerAdapter};
use rustdds::{QosPolicies, RepresentationIdentifier};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::time::Duration;
use tokio::sync::mpsc;

/// A topic a publisher of the graph offers.
#[derive(Debug, Clone)]
pub struct ForeignTopic {
    /// `/name`.
    pub name: String,
    /// `pkg/msg/Type`.
    pub type_name: String,
    /// What a reader asks to match every publisher found (`adapt_to_offer`).
    pub qos: QosPolicies,
    /// The publisher's node (`/ns/name`), if its participant announced it.
    pub publisher_node: Option<String>,
    /// The (first) publisher's writer.
    pub publisher: rustdds::GUID,
    /// The type hash the publisher announced (`RIHS01_...`), if any.
    pub type_hash: Option<String>,
}

/// `pkg::msg::dds_::Type_` as `pkg/msg/Type`; None for a name of another form.
fn ros_type_name(dds: &str) -> Option<String> {
    let (pkg, rest) = dds.split_once("::msg::dds_::")?;
    Some(format!("{pkg}/msg/{}", rest.strip_suffix('_')?))
}

/// `typehash=RIHS01_...;` in an endpoint's USER_DATA.
fn announced_hash(user_data: &[u8]) -> Option<String> {
    let text = std::str::from_utf8(user_data).ok()?;
    text.split(';')
        .find_map(|kv| kv.trim_end_matches('\0').strip_prefix("typehash="))
        .map(str::to_string)
}

/// What a reader may ask and still match a further publisher offering `offer`, as rosbag2's
/// recorder adapts its request to every offer (`rosbag2_transport/src/rosbag2_transport/qos.cpp`,
/// `adapt_request_to_offers`): reliable and transient-local only while every publisher offers
/// them. A reader asking transient-local of a volatile publisher (rclpy's `/parameter_events`
/// beside ros2-client's transient-local one) would match none of its samples, and every ROS 2
/// tool would warn of incompatible QoS.
fn adapt_to_offer(request: &QosPolicies, offer: &QosPolicies) -> QosPolicies {
    use rustdds::policy::{Durability, Reliability};
    let mut change = rustdds::QosPolicyBuilder::new();
    if !matches!(offer.reliability(), Some(Reliability::Reliable { .. })) {
        change = change.reliability(Reliability::BestEffort);
    }
    if matches!(offer.durability(), None | Some(Durability::Volatile)) {
        change = change.durability(Durability::Volatile);
    }
    request.modify_by(&change.build())
}

impl NodeShell {
    /// The ROS topics (`rt/...`) that discovery reports a publisher of, other than those in
    /// `known` (by `/name`), one per topic.
    pub fn foreign_topics(&self, known: &dyn Fn(&str) -> bool) -> Vec<ForeignTopic> {
        let mut topics: BTreeMap<String, ForeignTopic> = BTreeMap::new();
        for w in self.context.domain_participant().discovered_writers() {
            let data = &w.publication_topic_data;
            let Some(name) = data.topic_name().strip_prefix("rt") else {
                continue;
            };
            if known(name) {
                continue;
            }
            if let Some(topic) = topics.get_mut(name) {
                topic.qos = adapt_to_offer(&topic.qos, &data.qos());
                continue;
            }
            let Some(type_name) = ros_type_name(&data.type_name) else {
                continue;
            };
            topics.insert(
                name.to_string(),
                ForeignTopic {
                    name: name.to_string(),
                    type_name,
                    qos: data.qos(),
                    publisher_node: self.graph.writer_node(w.writer_proxy.remote_writer_guid),
                    publisher: w.writer_proxy.remote_writer_guid,
                    type_hash: announced_hash(&w.user_data),
                },
            );
        }
        topics.into_values().collect()
    }

    /// Taps `topic` with the QoS its publisher offers: each sample's CDR (with its 4-byte
    /// encapsulation header, as a bag stores it), sent to `tx` with when it was received and
    /// published and its sequence number, until `tx` closes.
    pub fn tap_foreign(
        &mut self,
        topic: &ForeignTopic,
        tx: mpsc::Sender<RawSample>,
    ) -> anyhow::Result<tokio::task::JoinHandle<()>> {
        let dds_type = match topic.type_name.split('/').collect::<Vec<_>>()[..] {
            [pkg, kind, ty] => format!("{pkg}::{kind}::dds_::{ty}_"),
            _ => anyhow::bail!("{} is not pkg/msg/Type", topic.type_name),
        };
        // Our reader announces the type hash its publisher announced, as an rmw would.
        if let Some(hash) = &topic.type_hash {
            self.context
                .domain_participant()
                .set_endpoint_user_data(&dds_type, format!("typehash={hash};").into_bytes());
        }
        let dds_topic = self
            .context
            .domain_participant()
            .create_topic(
                format!("rt{}", topic.name),
                dds_type,
                &topic.qos,
                rustdds::TopicKind::NoKey,
            )
            .with_context(|| format!("creating topic {}", topic.name))?;
        let reader = self
            .node
            .create_simpledatareader::<RawCdr, RawAdapter>(&dds_topic, None)
            .with_context(|| format!("tapping {}", topic.name))?;
        let name = topic.name.clone();
        Ok(tokio::spawn(async move {
            let samples = reader.as_async_stream();
            tokio::pin!(samples);
            while let Some(sample) = samples.next().await {
                let Ok(change) = sample else {
                    continue;
                };
                let info = ros2_client::MessageInfo::from(&change);
                // The receive time on the steady clock, as every other tap's (a bag's log time).
                let received = crate::clock::steady_nanos();
                let raw = RawSample {
                    topic: name.clone(),
                    received_ns: received,
                    source_timestamp_ns: info.source_timestamp().map(|t| t.to_nanos()),
                    sequence_number: info.sequence_number(),
                    payload: change.sample.0,
                };
                if tx.send(raw).await.is_err() {
                    break;
                }
            }
        }))
    }

    /// Asks `node` for `topic`'s type description (its type sources too) and returns the
    /// definition as rosbag2 stores it (`ros2msg`: the type's text, then each type it uses
    /// after a line of `=` and `MSG: pkg/Type`). Err says why there is none.
    pub async fn foreign_definition(
        &mut self,
        node: &str,
        topic: &ForeignTopic,
        timeout: Duration,
    ) -> Result<String, String> {
        let client = self
            .node
            .create_client::<GetTypeDescriptionRequest, GetTypeDescriptionResponse>(
                self.service_mapping,
                &crate::ros_name(&format!(
                    "{}/get_type_description",
                    node.trim_end_matches('/')
                ))
                .map_err(|e| e.to_string())?,
                &ros2_client::ServiceTypeName::new(
                    "type_description_interfaces",
                    "GetTypeDescription",
                ),
                crate::service_qos(),
                crate::service_qos(),
            )
            .map_err(|e| format!("a client of {node}/get_type_description: {e:?}"))?;
        let request = GetTypeDescriptionRequest {
            type_name: topic.type_name.clone(),
            type_hash: topic.type_hash.clone().unwrap_or_default(),
            include_type_sources: true,
        };
        let answer = tokio::time::timeout(timeout, async {
            // The server may not be matched yet: ask again until the deadline.
            loop {
                match tokio::time::timeout(
                    Duration::from_millis(1500),
                    client.async_call_service(request.clone()),
                )
                .await
                {
                    Ok(Ok(response)) => break response,
                    _ => tokio::time::sleep(Duration::from_millis(200)).await,
                }
            }
        })
        .await
        .map_err(|_| format!("{node}/get_type_description did not answer within {timeout:?}"))?;
        if !answer.successful {
            return Err(format!(
                "{node} could not describe {}: {}",
                topic.type_name, answer.failure_reason
            ));
        }
        Ok(ros2msg_text(&answer))
    }
}

/// One sample of a foreign topic, its type unknown.
#[derive(Debug, Clone)]
pub struct RawSample {
    pub topic: String,
    pub received_ns: i64,
    pub source_timestamp_ns: Option<i64>,
    pub sequence_number: i64,
    /// The serialized message with its encapsulation header.
    pub payload: Vec<u8>,
}

/// A sample's serialized bytes, its encapsulation header first.
struct RawCdr(Vec<u8>);

/// A RustDDS deserializer that keeps the bytes.
struct RawAdapter;

#[derive(Clone)]
struct RawDecoder;

impl DeserializerAdapter<RawCdr> for RawAdapter {
    type Error = std::convert::Infallible;
    type Decoded = RawCdr;

    fn supported_encodings() -> &'static [RepresentationIdentifier] {
        &[
            RepresentationIdentifier::CDR_LE,
            RepresentationIdentifier::CDR_BE,
        ]
    }

    fn transform_decoded(decoded: RawCdr) -> RawCdr {
        decoded
    }
}

impl DefaultDecoder<RawCdr> for RawAdapter {
    type Decoder = RawDecoder;
    const DECODER: RawDecoder = RawDecoder;
}

impl<'de> Decode<'de, RawCdr> for RawDecoder {
    type Error = std::convert::Infallible;

    fn decode_bytes(
        self,
        input_bytes: &'de [u8],
        encoding: RepresentationIdentifier,
    ) -> Result<RawCdr, Self::Error> {
        let mut bytes = Vec::with_capacity(input_bytes.len() + 4);
        bytes.extend_from_slice(&encoding.to_bytes());
        bytes.extend_from_slice(&[0, 0]);
        bytes.extend_from_slice(input_bytes);
        Ok(RawCdr(bytes))
    }
}

/// `type_description_interfaces/srv/GetTypeDescription` request.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GetTypeDescriptionRequest {
    pub type_name: String,
    pub type_hash: String,
    pub include_type_sources: bool,
}
impl ros2_client::Message for GetTypeDescriptionRequest {}

/// `type_description_interfaces/msg/TypeSource`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct TypeSource {
    pub type_name: String,
    pub encoding: String,
    pub raw_file_contents: String,
}

/// `type_description_interfaces/msg/KeyValue`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct KeyValue {
    pub key: String,
    pub value: String,
}

/// `type_description_interfaces/srv/GetTypeDescription` response.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct GetTypeDescriptionResponse {
    pub successful: bool,
    pub failure_reason: String,
    pub type_description: TypeDescriptionMsg,
    pub type_sources: Vec<TypeSource>,
    pub extra_information: Vec<KeyValue>,
}
impl ros2_client::Message for GetTypeDescriptionResponse {}

/// The `.msg` text of one type: its source when the node sent it, else written from its
/// fields.
fn type_text(d: &IndividualTypeDescriptionMsg, sources: &[TypeSource]) -> String {
    if let Some(s) = sources
        .iter()
        .find(|s| s.type_name == d.type_name && s.encoding == "msg")
    {
        return s.raw_file_contents.trim_end().to_string();
    }
    d.fields
        .iter()
        .map(|f| {
            format!(
                "{} {}",
                crate::type_hashes::msg_type_text(&f.r#type),
                f.name
            )
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// The definition as rosbag2 writes an MCAP schema (`ros2msg`).
fn ros2msg_text(answer: &GetTypeDescriptionResponse) -> String {
    let d = &answer.type_description;
    let mut text = type_text(&d.type_description, &answer.type_sources);
    text.push('\n');
    for r in &d.referenced_type_descriptions {
        text.push_str(&"=".repeat(80));
        text.push_str(&format!(
            "\nMSG: {}\n",
            r.type_name.replacen("/msg/", "/", 1)
        ));
        text.push_str(&type_text(r, &answer.type_sources));
        text.push('\n');
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_hashes_are_read_as_rmw_writes_them() {
        assert_eq!(
            ros_type_name("std_msgs::msg::dds_::String_").as_deref(),
            Some("std_msgs/msg/String")
        );
        assert_eq!(ros_type_name("Foo"), None);
        assert_eq!(
            announced_hash(b"typehash=RIHS01_ab;\0").as_deref(),
            Some("RIHS01_ab")
        );
        assert_eq!(announced_hash(b"enclave=/;"), None);
    }
}
