//! Reads a bag into messages in log-time order, raw or typed. A damaged bag (truncated, a bad
//! chunk CRC, a channel with an undefined schema) yields everything before the bad record and
//! says which record that is; nothing on the read path panics on file content.

use crate::cdr;
use crate::error::BagError;
use crate::qos::qos_kind_from_yaml;
use crate::scan::{ChannelInfo, RawMessage, Scan, scan};
use qt_therapy_msgs::MessageDefinition;
use qt_therapy_msgs::topics::{QosKind, Topic};
use std::collections::BTreeMap;
use std::path::Path;

/// How far a reader trusts a file.
#[derive(Debug, Clone)]
pub struct ReadOptions {
    /// Largest uncompressed chunk accepted; a larger claim is reported as damage.
    pub max_chunk_bytes: u64,
}

impl Default for ReadOptions {
    fn default() -> Self {
        ReadOptions {
            max_chunk_bytes: 512 * 1024 * 1024,
        }
    }
}

/// A decoded message with its times.
#[derive(Debug, Clone, PartialEq)]
pub struct Stamped<M> {
    pub log_time: u64,
    pub publish_time: u64,
    pub sequence: u32,
    pub message: M,
}

impl ChannelInfo {
    /// The channel's type as rosbag2 names it (`pkg/msg/Type`), or "" without a schema.
    pub fn type_name(&self) -> &str {
        self.schema.as_ref().map_or("", |s| s.name.as_str())
    }

    /// The schema encoding (`ros2msg` for rosbag2), or "" without a schema.
    pub fn schema_encoding(&self) -> &str {
        self.schema.as_ref().map_or("", |s| s.encoding.as_str())
    }

    /// The QoS class the recording publisher offered, from `offered_qos_profiles`.
    pub fn offered_qos(&self) -> Option<QosKind> {
        self.metadata
            .get("offered_qos_profiles")
            .and_then(|y| qos_kind_from_yaml(y))
    }
}

/// A bag read into memory.
#[derive(Debug)]
pub struct BagReader {
    bag: String,
    size: u64,
    scan: Scan,
}

impl BagReader {
    /// Reads the bag at `path`. Fails only when the file cannot be read or is not MCAP;
    /// damage further in is reported by [`BagReader::damage`].
    pub fn open(path: &Path) -> Result<BagReader, BagError> {
        Self::open_with(path, &ReadOptions::default())
    }

    pub fn open_with(path: &Path, options: &ReadOptions) -> Result<BagReader, BagError> {
        let bag = path.display().to_string();
        let bytes = std::fs::read(path).map_err(|source| BagError::Io {
            bag: bag.clone(),
            source,
        })?;
        Self::from_bytes(&bytes, &bag, options)
    }

    /// Reads a bag held in memory; `bag` names it in errors.
    pub fn from_bytes(
        bytes: &[u8],
        bag: &str,
        options: &ReadOptions,
    ) -> Result<BagReader, BagError> {
        let mut scan = scan(bytes, bag, options.max_chunk_bytes)?;
        // Log-time order; a stable sort keeps file order among equal times.
        scan.messages.sort_by_key(|m| m.log_time);
        Ok(BagReader {
            bag: bag.to_string(),
            size: bytes.len() as u64,
            scan,
        })
    }

    /// Fails with the damage, if any, instead of reading around it.
    pub fn strict(mut self) -> Result<BagReader, BagError> {
        match self.scan.damage.take() {
            Some(e) => Err(e),
            None => Ok(self),
        }
    }

    /// The bag's name in messages (its path).
    pub fn name(&self) -> &str {
        &self.bag
    }

    pub fn size_bytes(&self) -> u64 {
        self.size
    }

    /// The first bad record, if any: everything before it was read, nothing after.
    pub fn damage(&self) -> Option<&BagError> {
        self.scan.damage.as_ref()
    }

    /// Whether the file ends with a footer and the MCAP magic (it was closed cleanly). A
    /// recording that was killed is readable up to its last complete chunk but not complete.
    pub fn is_complete(&self) -> bool {
        self.scan.complete
    }

    /// The MCAP profile (`ros2` for rosbag2 bags).
    pub fn profile(&self) -> Option<&str> {
        self.scan.profile.as_deref()
    }

    pub fn library(&self) -> Option<&str> {
        self.scan.library.as_deref()
    }

    /// Chunks read, and how many used each compression ("" for none).
    pub fn chunks(&self) -> (u64, &BTreeMap<String, u64>) {
        (self.scan.chunks, &self.scan.compression)
    }

    /// The wall clock's steps the recorder recorded ([`crate::CLOCK_STEP`]), in order; records
    /// that do not read as one are left out.
    pub fn clock_steps(&self) -> Vec<clock_steps::Step> {
        self.metadata()
            .iter()
            .filter(|(name, _)| name == crate::CLOCK_STEP)
            .filter_map(|(_, m)| {
                Some(clock_steps::Step {
                    at_steady_ns: m.get("log_time")?.parse().ok()?,
                    by_ns: m.get("by_ns")?.parse().ok()?,
                })
            })
            .collect()
    }

    /// Metadata records (name, key/values), e.g. rosbag2's `serialized_metadata`.
    pub fn metadata(&self) -> &[(String, BTreeMap<String, String>)] {
        &self.scan.metadata
    }

    pub fn channels(&self) -> impl Iterator<Item = &ChannelInfo> {
        self.scan.channels.values()
    }

    pub fn channel(&self, id: u16) -> Option<&ChannelInfo> {
        self.scan.channels.get(&id)
    }

    /// The channels that carry `topic`.
    pub fn topic_channels(&self, topic: &str) -> Vec<&ChannelInfo> {
        self.channels().filter(|c| c.topic == topic).collect()
    }

    /// Every message in log-time order.
    pub fn raw_messages(&self) -> &[RawMessage] {
        &self.scan.messages
    }

    /// Every message in log-time order with its channel.
    pub fn iter(&self) -> impl Iterator<Item = (&ChannelInfo, &RawMessage)> {
        self.scan
            .messages
            .iter()
            .filter_map(|m| self.scan.channels.get(&m.channel_id).map(|c| (c, m)))
    }

    /// The messages on `topic`, decoded as `M`, in log-time order. The topic's channels must
    /// carry `M`'s type (`pkg/msg/Type`) in `cdr`.
    pub fn messages<M: MessageDefinition>(&self, topic: &str) -> Result<Vec<Stamped<M>>, BagError> {
        let channels = self.topic_channels(topic);
        if channels.is_empty() {
            return Err(BagError::NoSuchTopic {
                bag: self.bag.clone(),
                topic: topic.to_string(),
            });
        }
        let expected = M::full_type_name();
        for c in &channels {
            if c.type_name() != expected {
                return Err(BagError::TypeMismatch {
                    bag: self.bag.clone(),
                    topic: topic.to_string(),
                    expected,
                    found: c.type_name().to_string(),
                });
            }
            if c.message_encoding != "cdr" {
                return Err(BagError::NotCdr {
                    bag: self.bag.clone(),
                    topic: topic.to_string(),
                    found: c.message_encoding.clone(),
                });
            }
        }
        let ids: Vec<u16> = channels.iter().map(|c| c.id).collect();
        self.scan
            .messages
            .iter()
            .filter(|m| ids.contains(&m.channel_id))
            .enumerate()
            .map(|(index, m)| {
                let message = cdr::decode::<M>(&m.data).map_err(|e| BagError::Decode {
                    bag: self.bag.clone(),
                    topic: topic.to_string(),
                    index,
                    log_time: m.log_time,
                    type_name: expected.clone(),
                    reason: e.to_string(),
                })?;
                Ok(Stamped {
                    log_time: m.log_time,
                    publish_time: m.publish_time,
                    sequence: m.sequence,
                    message,
                })
            })
            .collect()
    }

    /// The messages of one of the suite's topics, typed by the topic (`reader.topic(GAME_STATE)`).
    pub fn topic<M: MessageDefinition>(
        &self,
        topic: Topic<M>,
    ) -> Result<Vec<Stamped<M>>, BagError> {
        self.messages::<M>(topic.name)
    }

    /// The messages of one of the suite's topics without their stamps, none when the bag does
    /// not have the topic (a session where nothing was sent on it).
    pub fn topic_messages<M: MessageDefinition>(
        &self,
        topic: Topic<M>,
    ) -> Result<Vec<M>, BagError> {
        match self.messages::<M>(topic.name) {
            Ok(v) => Ok(v.into_iter().map(|s| s.message).collect()),
            Err(BagError::NoSuchTopic { .. }) => Ok(Vec::new()),
            Err(e) => Err(e),
        }
    }

    /// Messages per channel id.
    pub fn counts(&self) -> BTreeMap<u16, u64> {
        let mut counts: BTreeMap<u16, u64> = self.scan.channels.keys().map(|&id| (id, 0)).collect();
        for m in &self.scan.messages {
            *counts.entry(m.channel_id).or_insert(0) += 1;
        }
        counts
    }

    /// First and last log time, if there are messages.
    pub fn time_range(&self) -> Option<(u64, u64)> {
        let first = self.scan.messages.first()?.log_time;
        let last = self.scan.messages.last()?.log_time;
        Some((first, last))
    }
}
