//! Walks an MCAP file record by record (sans-IO, over bytes in memory), keeping every message
//! it can trust and stopping at the first bad record, which it names. A chunk is all or
//! nothing: its records count only once it decompressed whole and passed its CRC.
//! Not mcap 0.26's `sans_io::LinearReader`, even with `with_record_length_limit` and
//! `prevalidate_chunk_crcs`: its `LinearReadEvent::Record { data, opcode }` and errors (a bare
//! `UnexpectedEof`) carry no offset and hide chunk boundaries (`in_chunk` is `pub(crate)`), so
//! it cannot name the record where it stopped, and it streams a chunk whose CRC is 0 without
//! decompressing it first (`prevalidate_chunk_crcs && state.crc != 0`), yielding records of a
//! chunk that then fails. Its `decompress_inner` reserves (`RwBuf::reserve_exact`, zero-filled)
//! whatever a chunk's `uncompressed_size` or an inner record's length claims, capped only by
//! that limit (a 101-byte file made it allocate 256 MiB), where ours grows with the bytes that
//! really decompress; its `ChunkReader`, which sets no limit, tried to allocate 360 PB.

use crate::error::{BagError, RecordAt};
use crate::parse::{Rec, parse};
use mcap::records::op;
use std::collections::BTreeMap;

/// A schema as the bag declares it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SchemaInfo {
    pub id: u16,
    /// `pkg/msg/Type` in a rosbag2 bag.
    pub name: String,
    /// `ros2msg` in a rosbag2 bag.
    pub encoding: String,
    pub data: Vec<u8>,
}

/// A channel (one topic with one type) as the bag declares it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelInfo {
    pub id: u16,
    pub topic: String,
    pub message_encoding: String,
    pub schema: Option<SchemaInfo>,
    pub metadata: BTreeMap<String, String>,
}

/// One message, undecoded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RawMessage {
    pub channel_id: u16,
    pub sequence: u32,
    /// When the recorder received it (ns since the epoch).
    pub log_time: u64,
    /// When its publisher sent it (ns since the epoch).
    pub publish_time: u64,
    /// CDR with its 4-byte encapsulation header, for a `cdr` channel.
    pub data: Vec<u8>,
}

/// Everything a scan found.
#[derive(Debug, Default)]
pub struct Scan {
    pub profile: Option<String>,
    pub library: Option<String>,
    pub schemas: BTreeMap<u16, SchemaInfo>,
    pub channels: BTreeMap<u16, ChannelInfo>,
    /// In file order.
    pub messages: Vec<RawMessage>,
    pub chunks: u64,
    /// Compression of each chunk ("" for none), counted.
    pub compression: BTreeMap<String, u64>,
    pub metadata: Vec<(String, BTreeMap<String, String>)>,
    /// A footer and the closing magic were found: the file was finished cleanly.
    pub complete: bool,
    /// The first bad record; nothing from it on was used.
    pub damage: Option<BagError>,
}

const MAGIC: &[u8] = mcap::MAGIC;

/// Scans `bytes`; fails only when they are not MCAP at all. Chunks claiming more than
/// `max_chunk_bytes` uncompressed are refused as damage (a bad length must not exhaust memory).
pub fn scan(bytes: &[u8], bag: &str, max_chunk_bytes: u64) -> Result<Scan, BagError> {
    if bytes.len() < MAGIC.len() || &bytes[..MAGIC.len()] != MAGIC {
        return Err(BagError::NotMcap {
            bag: bag.to_string(),
        });
    }
    let mut s = Scan::default();
    let mut pos = MAGIC.len();
    let mut index = 0u64;
    let mut after_footer = false;
    while pos < bytes.len() {
        let rest = &bytes[pos..];
        if after_footer && MAGIC.starts_with(&rest[..rest.len().min(MAGIC.len())]) {
            // Every record is intact; only a whole closing magic makes the file complete.
            s.complete = rest.len() >= MAGIC.len();
            break;
        }
        let at = RecordAt {
            index,
            offset: pos as u64,
            opcode: rest[0],
            inner: None,
        };
        let (_, body) = match frame(rest) {
            Ok(f) => f,
            Err((needed, available)) => {
                s.damage = Some(truncated(bag, at, needed, available));
                break;
            }
        };
        if let Err(e) = s.record(at.clone(), body, bag, max_chunk_bytes) {
            s.damage = Some(e);
            break;
        }
        after_footer = at.opcode == op::FOOTER;
        pos += 9 + body.len();
        index += 1;
    }
    Ok(s)
}

/// Splits the record at the start of `bytes` into its opcode and body; on a short buffer,
/// the bytes the record needs and those left.
fn frame(bytes: &[u8]) -> Result<(u8, &[u8]), (u64, usize)> {
    let Some((head, rest)) = bytes.split_first_chunk::<9>() else {
        return Err((9, bytes.len()));
    };
    let mut len = [0u8; 8];
    len.copy_from_slice(&head[1..]);
    let len = u64::from_le_bytes(len);
    if len > rest.len() as u64 {
        return Err((len.saturating_add(9), bytes.len()));
    }
    Ok((head[0], &rest[..len as usize]))
}

/// A chunk's records, decompressed to exactly `size` bytes and never more: a corrupt size or
/// stream cannot make the reader allocate beyond what it claimed (already bounded).
fn decompress(compression: &str, data: &[u8], size: u64) -> Result<Vec<u8>, String> {
    use std::io::Read;
    let mut out = Vec::new();
    let limit = size.saturating_add(1);
    let read = match compression {
        "" => {
            out.extend_from_slice(data);
            Ok(out.len())
        }
        "zstd" => {
            zstd::stream::read::Decoder::new(data).and_then(|d| d.take(limit).read_to_end(&mut out))
        }
        "lz4" => lz4::Decoder::new(data).and_then(|d| d.take(limit).read_to_end(&mut out)),
        other => return Err(format!("unsupported chunk compression {other:?}")),
    };
    read.map_err(|e| format!("{compression} chunk does not decompress: {e}"))?;
    if out.len() as u64 != size {
        return Err(format!(
            "chunk holds {} bytes of records, its header says {size}",
            out.len()
        ));
    }
    Ok(out)
}

fn truncated(bag: &str, at: RecordAt, needed: u64, available: usize) -> BagError {
    BagError::Truncated {
        bag: bag.to_string(),
        at,
        needed,
        available: available as u64,
    }
}

fn malformed(bag: &str, at: RecordAt, reason: impl ToString) -> BagError {
    BagError::BadRecord {
        bag: bag.to_string(),
        at,
        reason: reason.to_string(),
    }
}

impl Scan {
    /// Takes one top-level record.
    fn record(
        &mut self,
        at: RecordAt,
        body: &[u8],
        bag: &str,
        max_chunk_bytes: u64,
    ) -> Result<(), BagError> {
        match parse(at.opcode, body).map_err(|e| malformed(bag, at.clone(), e))? {
            Rec::Header { profile, library } => {
                self.profile = Some(profile);
                self.library = Some(library);
            }
            Rec::Chunk {
                uncompressed_size,
                uncompressed_crc,
                compression,
                records,
            } => {
                if uncompressed_size > max_chunk_bytes {
                    return Err(BagError::ChunkTooLarge {
                        bag: bag.to_string(),
                        at,
                        claimed: uncompressed_size,
                        limit: max_chunk_bytes,
                    });
                }
                let records = decompress(&compression, records, uncompressed_size)
                    .map_err(|reason| malformed(bag, at.clone(), reason))?;
                // The CRC covers the whole chunk, so nothing in it counts before it is checked.
                let calculated = crc32fast::hash(&records);
                if uncompressed_crc != 0 && uncompressed_crc != calculated {
                    return Err(BagError::BadChunkCrc {
                        bag: bag.to_string(),
                        at,
                        saved: uncompressed_crc,
                        calculated,
                    });
                }
                self.chunks += 1;
                *self.compression.entry(compression).or_insert(0) += 1;
                self.chunk_records(&at, &records, bag)?;
            }
            Rec::Metadata { name, metadata } => self.metadata.push((name, metadata)),
            other => self.content(other, at, bag)?,
        }
        Ok(())
    }

    /// The records of a decompressed, checked chunk.
    fn chunk_records(&mut self, at: &RecordAt, records: &[u8], bag: &str) -> Result<(), BagError> {
        let mut pos = 0;
        let mut index = 0u64;
        while pos < records.len() {
            let mut inner_at = at.clone();
            inner_at.inner = Some((index, records[pos]));
            let (opcode, body) = frame(&records[pos..])
                .map_err(|(needed, left)| truncated(bag, inner_at.clone(), needed, left))?;
            // The spec allows only these three in a chunk; others are skipped.
            if let r @ (Rec::Schema { .. } | Rec::Channel { .. } | Rec::Message { .. }) =
                parse(opcode, body).map_err(|e| malformed(bag, inner_at.clone(), e))?
            {
                self.content(r, inner_at, bag)?;
            }
            pos += 9 + body.len();
            index += 1;
        }
        Ok(())
    }

    /// A schema, channel or message, top-level or from a chunk; other records are skipped.
    fn content(&mut self, record: Rec<'_>, at: RecordAt, bag: &str) -> Result<(), BagError> {
        match record {
            Rec::Schema {
                id,
                name,
                encoding,
                data,
            } => {
                if id == 0 {
                    return Err(malformed(
                        bag,
                        at,
                        "schema id 0 is reserved for \"no schema\"",
                    ));
                }
                let schema = SchemaInfo {
                    id,
                    name,
                    encoding,
                    data: data.to_vec(),
                };
                match self.schemas.get(&id) {
                    Some(known) if *known != schema => return Err(conflict(bag, at, "schema", id)),
                    Some(_) => {}
                    None => {
                        self.schemas.insert(id, schema);
                    }
                }
            }
            Rec::Channel {
                id,
                schema_id,
                topic,
                message_encoding,
                metadata,
            } => {
                let schema = match schema_id {
                    0 => None,
                    sid => match self.schemas.get(&sid) {
                        Some(s) => Some(s.clone()),
                        None => {
                            return Err(BagError::UnknownSchema {
                                bag: bag.to_string(),
                                at,
                                topic,
                                schema_id: sid,
                            });
                        }
                    },
                };
                let channel = ChannelInfo {
                    id,
                    topic,
                    message_encoding,
                    schema,
                    metadata,
                };
                match self.channels.get(&id) {
                    Some(known) if *known != channel => {
                        return Err(conflict(bag, at, "channel", id));
                    }
                    Some(_) => {}
                    None => {
                        self.channels.insert(id, channel);
                    }
                }
            }
            Rec::Message {
                channel_id,
                sequence,
                log_time,
                publish_time,
                data,
            } => {
                if !self.channels.contains_key(&channel_id) {
                    return Err(BagError::UnknownChannel {
                        bag: bag.to_string(),
                        at,
                        channel_id,
                    });
                }
                self.messages.push(RawMessage {
                    channel_id,
                    sequence,
                    log_time,
                    publish_time,
                    data: data.to_vec(),
                });
            }
            // Indexes, statistics, attachments, data end, footer: nothing to keep.
            _ => {}
        }
        Ok(())
    }
}

fn conflict(bag: &str, at: RecordAt, what: &'static str, id: u16) -> BagError {
    BagError::Conflict {
        bag: bag.to_string(),
        at,
        what,
        id,
    }
}
