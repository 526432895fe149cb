//! Writes bags the way rosbag2's MCAP storage does (profile `ros2`, one `ros2msg` schema per
//! type, `cdr` channels with `offered_qos_profiles`, chunked and compressed, summary and
//! indexes, a `rosbag2` metadata record), in-process: the recorder and simulations both use it.

use crate::cdr;
use crate::error::BagError;
use crate::qos::offered_qos_yaml;
use crate::scan::ChannelInfo;
use atomic_file::GrowingFile;
use qt_therapy_msgs::MessageDefinition;
use qt_therapy_msgs::topics::Topic;
use std::collections::BTreeMap;
use std::io::{Seek, Write};
use std::marker::PhantomData;
use std::path::{Path, PathBuf};

/// Chunk compression.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Compression {
    Zstd,
    Lz4,
    None,
}

impl std::str::FromStr for Compression {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "zstd" => Ok(Compression::Zstd),
            "lz4" => Ok(Compression::Lz4),
            "none" | "" => Ok(Compression::None),
            other => Err(format!("compression {other:?} is not zstd, lz4 or none")),
        }
    }
}

/// How a bag is written.
#[derive(Debug, Clone)]
pub struct WriterOptions {
    pub compression: Compression,
    /// A chunk is closed once it holds this many uncompressed bytes (and on every
    /// [`BagWriter::flush_chunk`]).
    pub chunk_size: u64,
    /// zstd worker threads; 0 compresses on the writing thread.
    pub compression_threads: u32,
}

impl Default for WriterOptions {
    fn default() -> Self {
        WriterOptions {
            compression: Compression::Zstd,
            chunk_size: 1024 * 1024,
            compression_threads: 0,
        }
    }
}

/// Channel metadata key: why a channel has no definition (its publisher could not be asked).
pub const DEFINITION_MISSING: &str = "definition_missing";

/// When a message was logged and published (ns since the epoch), and its sequence number.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Stamp {
    pub log_time: u64,
    pub publish_time: u64,
    pub sequence: u32,
}

/// A channel of a bag being written, typed by its message.
#[derive(Debug)]
pub struct Channel<M> {
    pub id: u16,
    message: PhantomData<fn(M)>,
}

impl<M> Clone for Channel<M> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<M> Copy for Channel<M> {}

struct TopicCount {
    topic: String,
    type_name: String,
    qos_yaml: String,
    count: u64,
}

/// A bag being written to `W`. Call [`BagWriter::finish`] to write the summary; a writer
/// dropped without it still ends its file validly, but a file bag keeps its `.partial` name.
pub struct BagWriter<W: Write + Seek> {
    mcap: Option<mcap::Writer<W>>,
    bag: String,
    topics: BTreeMap<u16, TopicCount>,
    first_log_time: Option<u64>,
    last_log_time: u64,
    // (partial, final) names of a file bag, renamed on finish so a finished bag appears whole.
    rename: Option<(PathBuf, PathBuf)>,
}

/// A bag written to a file: `<bag>.partial`, each closed chunk written whole and durable at
/// [`BagWriter::flush_chunk`] (`atomic_file::GrowingFile`), renamed when finished.
pub type FileBagWriter = BagWriter<GrowingFile>;

impl BagWriter<GrowingFile> {
    /// Creates `path` (written as `<path>.partial` until [`BagWriter::finish`]); the partial
    /// file must not exist.
    pub fn create(path: &Path, options: &WriterOptions) -> Result<Self, BagError> {
        let partial = partial_path(path);
        let bag = path.display().to_string();
        let file = GrowingFile::create_new(&partial).map_err(|source| BagError::Io {
            bag: partial.display().to_string(),
            source,
        })?;
        let mut writer = BagWriter::new(file, &bag, options)?;
        writer.rename = Some((partial, path.to_path_buf()));
        Ok(writer)
    }
}

/// Where a bag being written to `path` lives until it is finished.
pub fn partial_path(path: &Path) -> PathBuf {
    let mut name = path.as_os_str().to_os_string();
    name.push(".partial");
    PathBuf::from(name)
}

impl<W: Write + Seek> BagWriter<W> {
    /// Starts a bag on `w`; `bag` names it in errors.
    pub fn new(w: W, bag: &str, options: &WriterOptions) -> Result<Self, BagError> {
        let compression = match options.compression {
            Compression::Zstd => Some(mcap::Compression::Zstd),
            Compression::Lz4 => Some(mcap::Compression::Lz4),
            Compression::None => None,
        };
        let mcap = mcap::WriteOptions::new()
            .profile("ros2")
            .library(format!(
                "qt_therapy bag {} (mcap-rust {})",
                env!("CARGO_PKG_VERSION"),
                mcap::VERSION
            ))
            .compression(compression)
            .compression_threads(options.compression_threads)
            .chunk_size(Some(options.chunk_size.max(1)))
            .create(w)
            .map_err(|e| write_error(bag, "the header", e))?;
        Ok(BagWriter {
            mcap: Some(mcap),
            bag: bag.to_string(),
            topics: BTreeMap::new(),
            first_log_time: None,
            last_log_time: 0,
            rename: None,
        })
    }

    fn mcap(&mut self) -> Result<&mut mcap::Writer<W>, BagError> {
        self.mcap.as_mut().ok_or_else(|| BagError::Write {
            bag: self.bag.clone(),
            what: "a record".into(),
            reason: "the bag is already finished".into(),
        })
    }

    /// Adds one of the suite's topics (schema from the Rust mirror, QoS from the topic table).
    pub fn add_topic<M: MessageDefinition>(
        &mut self,
        topic: Topic<M>,
    ) -> Result<Channel<M>, BagError> {
        let id = self.add_channel(
            topic.name,
            &M::full_type_name(),
            &M::schema_text(),
            &offered_qos_yaml(topic.qos),
        )?;
        Ok(Channel {
            id,
            message: PhantomData,
        })
    }

    /// Adds a `cdr` channel whose schema is `ros2msg` text; returns its id. Adding the same
    /// topic, type and QoS again returns the same id.
    pub fn add_channel(
        &mut self,
        topic: &str,
        type_name: &str,
        schema_text: &str,
        qos_yaml: &str,
    ) -> Result<u16, BagError> {
        self.add_foreign_channel(topic, type_name, schema_text, qos_yaml, None)
    }

    /// As [`Self::add_channel`], for a topic whose definition may be unknown (a topic of the
    /// ROS 2 graph that is not the suite's): without one the schema is empty and the channel's
    /// metadata says why (`definition_missing`), which `bag info` shows.
    pub fn add_foreign_channel(
        &mut self,
        topic: &str,
        type_name: &str,
        schema_text: &str,
        qos_yaml: &str,
        definition_missing: Option<&str>,
    ) -> Result<u16, BagError> {
        let bag = self.bag.clone();
        let mcap = self.mcap()?;
        let schema = mcap
            .add_schema(type_name, "ros2msg", schema_text.as_bytes())
            .map_err(|e| write_error(&bag, &format!("the schema of {type_name}"), e))?;
        let mut metadata =
            BTreeMap::from([("offered_qos_profiles".to_string(), qos_yaml.to_string())]);
        if let Some(why) = definition_missing {
            metadata.insert(DEFINITION_MISSING.to_string(), why.to_string());
        }
        let id = mcap
            .add_channel(schema, topic, "cdr", &metadata)
            .map_err(|e| write_error(&bag, &format!("the channel of {topic}"), e))?;
        self.topics.entry(id).or_insert_with(|| TopicCount {
            topic: topic.to_string(),
            type_name: type_name.to_string(),
            qos_yaml: qos_yaml.to_string(),
            count: 0,
        });
        Ok(id)
    }

    /// Adds a channel as another bag declares it (its schema, message encoding and metadata
    /// as they are), so a tool copying messages between bags keeps them; returns its id.
    pub fn add_channel_like(&mut self, channel: &ChannelInfo) -> Result<u16, BagError> {
        let bag = self.bag.clone();
        let mcap = self.mcap()?;
        let schema = match &channel.schema {
            Some(s) => mcap
                .add_schema(&s.name, &s.encoding, &s.data)
                .map_err(|e| write_error(&bag, &format!("the schema of {}", s.name), e))?,
            None => 0,
        };
        let id = mcap
            .add_channel(
                schema,
                &channel.topic,
                &channel.message_encoding,
                &channel.metadata,
            )
            .map_err(|e| write_error(&bag, &format!("the channel of {}", channel.topic), e))?;
        self.topics.entry(id).or_insert_with(|| TopicCount {
            topic: channel.topic.clone(),
            type_name: channel.type_name().to_string(),
            qos_yaml: channel
                .metadata
                .get("offered_qos_profiles")
                .cloned()
                .unwrap_or_default(),
            count: 0,
        });
        Ok(id)
    }

    /// Writes `message` logged and published at `log_time`, numbered in its channel.
    pub fn write<M: MessageDefinition>(
        &mut self,
        channel: Channel<M>,
        log_time: u64,
        message: &M,
    ) -> Result<(), BagError> {
        let sequence = self.topics.get(&channel.id).map_or(0, |t| t.count as u32);
        let stamp = Stamp {
            log_time,
            publish_time: log_time,
            sequence,
        };
        self.write_stamped(channel, stamp, message)
    }

    /// Writes `message` with explicit times and sequence number.
    pub fn write_stamped<M: MessageDefinition>(
        &mut self,
        channel: Channel<M>,
        stamp: Stamp,
        message: &M,
    ) -> Result<(), BagError> {
        let payload = cdr::encode(message).map_err(|e| BagError::Write {
            bag: self.bag.clone(),
            what: format!("a {} message", M::full_type_name()),
            reason: e.to_string(),
        })?;
        self.write_cdr(channel.id, stamp, &payload)
    }

    /// Writes a CDR payload (with its encapsulation header) on channel `channel_id`.
    pub fn write_cdr(
        &mut self,
        channel_id: u16,
        stamp: Stamp,
        payload: &[u8],
    ) -> Result<(), BagError> {
        let bag = self.bag.clone();
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: stamp.sequence,
            log_time: stamp.log_time,
            publish_time: stamp.publish_time,
        };
        self.mcap()?
            .write_to_known_channel(&header, payload)
            .map_err(|e| write_error(&bag, &format!("a message on channel {channel_id}"), e))?;
        if let Some(t) = self.topics.get_mut(&channel_id) {
            t.count += 1;
        }
        self.first_log_time = Some(
            self.first_log_time
                .map_or(stamp.log_time, |f| f.min(stamp.log_time)),
        );
        self.last_log_time = self.last_log_time.max(stamp.log_time);
        Ok(())
    }

    /// Closes the current chunk and flushes the bytes: a reader (or a recovery after a crash)
    /// sees every message written so far, and for a file bag they are on disk (fdatasync), so
    /// a power cut keeps them too.
    pub fn flush_chunk(&mut self) -> Result<(), BagError> {
        let bag = self.bag.clone();
        self.mcap()?
            .flush()
            .map_err(|e| write_error(&bag, "a chunk", e))
    }

    /// Records a step of the wall clock the recorder saw (`step.at_steady_ns` on its log-time
    /// clock) as a metadata record of its own, read back by [`crate::BagReader::clock_steps`]
    /// and told by `bag info`. The chunk so far is closed first.
    pub fn write_clock_step(&mut self, step: clock_steps::Step) -> Result<(), BagError> {
        let bag = self.bag.clone();
        let record = mcap::records::Metadata {
            name: crate::CLOCK_STEP.to_string(),
            metadata: BTreeMap::from([
                ("log_time".to_string(), step.at_steady_ns.to_string()),
                ("by_ns".to_string(), step.by_ns.to_string()),
            ]),
        };
        self.mcap()?
            .write_metadata(&record)
            .map_err(|e| write_error(&bag, "a clock step", e))
    }

    /// Messages written so far.
    pub fn message_count(&self) -> u64 {
        self.topics.values().map(|t| t.count).sum()
    }

    /// Writes the rosbag2 metadata record, the summary and the footer; a file bag is synced
    /// and renamed to its final name (durably). Returns the underlying writer.
    pub fn finish(mut self) -> Result<W, BagError> {
        let bag = self.bag.clone();
        let final_name = self.rename.as_ref().map(|(_, f)| f.clone());
        let metadata = self.rosbag2_metadata(final_name.as_deref());
        let mut mcap = self.mcap.take().ok_or_else(|| BagError::Write {
            bag: bag.clone(),
            what: "the summary".into(),
            reason: "the bag is already finished".into(),
        })?;
        mcap.write_metadata(&metadata)
            .map_err(|e| write_error(&bag, "the rosbag2 metadata", e))?;
        mcap.finish()
            .map_err(|e| write_error(&bag, "the summary", e))?;
        let mut inner = mcap.into_inner();
        inner.flush().map_err(|source| BagError::Io {
            bag: bag.clone(),
            source,
        })?;
        if let Some((partial, path)) = self.rename.take() {
            atomic_file::rename(&partial, &path).map_err(|source| BagError::Io { bag, source })?;
        }
        Ok(inner)
    }

    /// rosbag2's `serialized_metadata` (its `metadata.yaml` body), as its MCAP storage stores it.
    fn rosbag2_metadata(&self, path: Option<&Path>) -> mcap::records::Metadata {
        let start = self.first_log_time.unwrap_or(0);
        let duration = self.last_log_time.saturating_sub(start);
        let count = self.message_count();
        let file = path.and_then(|p| p.file_name()).map_or_else(
            || "bag.mcap".to_string(),
            |n| n.to_string_lossy().into_owned(),
        );
        let mut y = format!(
            "version: 9\nstorage_identifier: mcap\nduration:\n  nanoseconds: {duration}\n\
             starting_time:\n  nanoseconds_since_epoch: {start}\nmessage_count: {count}\n\
             topics_with_message_count:\n"
        );
        for t in self.topics.values() {
            let qos: String = t
                .qos_yaml
                .lines()
                .map(|l| format!("\n        {l}"))
                .collect();
            y.push_str(&format!(
                "  - topic_metadata:\n      name: {}\n      type: {}\n      \
                 serialization_format: cdr\n      offered_qos_profiles:{qos}\n      \
                 type_description_hash: \"\"\n    message_count: {}\n",
                t.topic, t.type_name, t.count
            ));
        }
        y.push_str(&format!(
            "compression_format: \"\"\ncompression_mode: \"\"\nrelative_file_paths:\n  - {file}\n\
             files:\n  - path: {file}\n    starting_time:\n      nanoseconds_since_epoch: {start}\n    \
             duration:\n      nanoseconds: {duration}\n    message_count: {count}\n\
             custom_data: ~\nros_distro: jazzy"
        ));
        mcap::records::Metadata {
            name: "rosbag2".into(),
            metadata: BTreeMap::from([("serialized_metadata".to_string(), y)]),
        }
    }
}

impl<W: Write + Seek> Drop for BagWriter<W> {
    fn drop(&mut self) {
        if self.mcap.is_some()
            && let Some((partial, _)) = &self.rename
        {
            tracing::warn!(
                bag = %self.bag,
                "bag dropped without finish(): it stays at {}",
                partial.display()
            );
        }
    }
}

fn write_error(bag: &str, what: &str, e: mcap::McapError) -> BagError {
    // The operating system's error stays whole, so a full disk is told apart.
    if let mcap::McapError::Io(source) = e {
        return BagError::Io {
            bag: format!("{bag}: writing {what}"),
            source,
        };
    }
    BagError::Write {
        bag: bag.to_string(),
        what: what.to_string(),
        reason: e.to_string(),
    }
}
