//! What can go wrong with a bag, each error naming the bag and, for damage, the record at fault
//! (its index in the file, its kind and byte offset, and the record inside a chunk).

use std::fmt;

/// Where a record sits in an MCAP file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordAt {
    /// Index of the top-level record, counting from 0 after the magic bytes.
    pub index: u64,
    /// Byte offset of the record's opcode in the file.
    pub offset: u64,
    pub opcode: u8,
    /// For a record inside a chunk: its index within the chunk and its opcode.
    pub inner: Option<(u64, u8)>,
}

impl fmt::Display for RecordAt {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "record #{} ({} at byte {})",
            self.index,
            opcode_name(self.opcode),
            self.offset
        )?;
        if let Some((index, opcode)) = self.inner {
            write!(f, ", inner record #{index} ({})", opcode_name(opcode))?;
        }
        Ok(())
    }
}

/// The MCAP name of a record opcode.
pub fn opcode_name(opcode: u8) -> &'static str {
    use mcap::records::op;
    match opcode {
        op::HEADER => "Header",
        op::FOOTER => "Footer",
        op::SCHEMA => "Schema",
        op::CHANNEL => "Channel",
        op::MESSAGE => "Message",
        op::CHUNK => "Chunk",
        op::MESSAGE_INDEX => "MessageIndex",
        op::CHUNK_INDEX => "ChunkIndex",
        op::ATTACHMENT => "Attachment",
        op::ATTACHMENT_INDEX => "AttachmentIndex",
        op::STATISTICS => "Statistics",
        op::METADATA => "Metadata",
        op::METADATA_INDEX => "MetadataIndex",
        op::SUMMARY_OFFSET => "SummaryOffset",
        op::DATA_END => "DataEnd",
        _ => "unknown record",
    }
}

/// Why a bag could not be read, written or decoded.
#[derive(Debug, thiserror::Error)]
pub enum BagError {
    #[error("{bag}: {source}")]
    Io { bag: String, source: std::io::Error },
    #[error("{bag}: not an MCAP file (the first 8 bytes are not the MCAP magic)")]
    NotMcap { bag: String },
    #[error("{bag}: {at} is truncated: it needs {needed} bytes but only {available} remain")]
    Truncated {
        bag: String,
        at: RecordAt,
        needed: u64,
        available: u64,
    },
    #[error("{bag}: {at} is malformed: {reason}")]
    BadRecord {
        bag: String,
        at: RecordAt,
        reason: String,
    },
    #[error("{bag}: {at} fails its CRC (stored {saved:08x}, computed {calculated:08x})")]
    BadChunkCrc {
        bag: String,
        at: RecordAt,
        saved: u32,
        calculated: u32,
    },
    #[error("{bag}: {at} claims {claimed} uncompressed bytes, above the reader's limit of {limit}")]
    ChunkTooLarge {
        bag: String,
        at: RecordAt,
        claimed: u64,
        limit: u64,
    },
    #[error(
        "{bag}: {at}: channel {topic:?} refers to schema {schema_id}, which no earlier Schema record defines"
    )]
    UnknownSchema {
        bag: String,
        at: RecordAt,
        topic: String,
        schema_id: u16,
    },
    #[error(
        "{bag}: {at}: a message refers to channel {channel_id}, which no earlier Channel record defines"
    )]
    UnknownChannel {
        bag: String,
        at: RecordAt,
        channel_id: u16,
    },
    #[error("{bag}: {at}: {what} {id} is redefined with different content")]
    Conflict {
        bag: String,
        at: RecordAt,
        what: &'static str,
        id: u16,
    },
    #[error("{bag}: no topic {topic:?} in the bag")]
    NoSuchTopic { bag: String, topic: String },
    #[error("{bag}: topic {topic:?} carries {found:?}, not {expected:?}")]
    TypeMismatch {
        bag: String,
        topic: String,
        expected: String,
        found: String,
    },
    #[error("{bag}: topic {topic:?} has message encoding {found:?}; only \"cdr\" can be decoded")]
    NotCdr {
        bag: String,
        topic: String,
        found: String,
    },
    #[error(
        "{bag}: message {index} on {topic:?} (log time {log_time} ns) does not decode as {type_name}: {reason}"
    )]
    Decode {
        bag: String,
        topic: String,
        index: usize,
        log_time: u64,
        type_name: String,
        reason: String,
    },
    #[error("{bag}: writing {what}: {reason}")]
    Write {
        bag: String,
        what: String,
        reason: String,
    },
}

impl BagError {
    /// True when the disk (or the quota) is full.
    pub fn is_no_space(&self) -> bool {
        matches!(self, BagError::Io { source, .. } if atomic_file::is_no_space(source))
    }

    /// The damage errors a reader reports after reading everything before the bad record.
    pub fn record(&self) -> Option<&RecordAt> {
        match self {
            BagError::Truncated { at, .. }
            | BagError::BadRecord { at, .. }
            | BagError::BadChunkCrc { at, .. }
            | BagError::ChunkTooLarge { at, .. }
            | BagError::UnknownSchema { at, .. }
            | BagError::UnknownChannel { at, .. }
            | BagError::Conflict { at, .. } => Some(at),
            _ => None,
        }
    }
}
