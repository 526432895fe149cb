//! Parses the MCAP records the reader uses (header, schema, channel, message, chunk, metadata,
//! footer) from a record body, checking every length against the bytes that are really there.
//! mcap 0.26's `sans_io::LinearReader` only frames records and leaves parsing to
//! `mcap::parse_record`, whose strings (`McapString`, binrw `#[br(count = len)]`) call
//! `reserve_exact(len)` before reading: a channel whose topic claims `u32::MAX` bytes asks for
//! 4 GiB in a record of a few bytes, which `with_record_length_limit` does not prevent (the
//! fuzzer found it with a chunk's compression string). mcap stays the writer.

use mcap::records::op;
use std::collections::BTreeMap;

/// A record body, parsed. Records the reader has no use for are `Other`.
#[derive(Debug)]
pub enum Rec<'a> {
    Header {
        profile: String,
        library: String,
    },
    Schema {
        id: u16,
        name: String,
        encoding: String,
        data: &'a [u8],
    },
    Channel {
        id: u16,
        schema_id: u16,
        topic: String,
        message_encoding: String,
        metadata: BTreeMap<String, String>,
    },
    Message {
        channel_id: u16,
        sequence: u32,
        log_time: u64,
        publish_time: u64,
        data: &'a [u8],
    },
    Chunk {
        uncompressed_size: u64,
        uncompressed_crc: u32,
        compression: String,
        records: &'a [u8],
    },
    Metadata {
        name: String,
        metadata: BTreeMap<String, String>,
    },
    Footer,
    Other,
}

struct Fields<'a> {
    body: &'a [u8],
    pos: usize,
}

impl<'a> Fields<'a> {
    fn take(&mut self, n: u64, field: &str) -> Result<&'a [u8], String> {
        let left = self.body.len() - self.pos;
        if n > left as u64 {
            return Err(format!(
                "{field} needs {n} bytes, the record has {left} left"
            ));
        }
        let bytes = &self.body[self.pos..self.pos + n as usize];
        self.pos += n as usize;
        Ok(bytes)
    }

    fn array<const N: usize>(&mut self, field: &str) -> Result<[u8; N], String> {
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(N as u64, field)?);
        Ok(out)
    }

    fn u16(&mut self, field: &str) -> Result<u16, String> {
        self.array(field).map(u16::from_le_bytes)
    }

    fn u32(&mut self, field: &str) -> Result<u32, String> {
        self.array(field).map(u32::from_le_bytes)
    }

    fn u64(&mut self, field: &str) -> Result<u64, String> {
        self.array(field).map(u64::from_le_bytes)
    }

    /// `u32` length + bytes.
    fn bytes32(&mut self, field: &str) -> Result<&'a [u8], String> {
        let n = self.u32(field)?;
        self.take(u64::from(n), field)
    }

    /// `u32` length + UTF-8.
    fn string(&mut self, field: &str) -> Result<String, String> {
        let bytes = self.bytes32(field)?;
        String::from_utf8(bytes.to_vec()).map_err(|_| format!("{field} is not UTF-8"))
    }

    /// `u32` byte length + (string, string) pairs.
    fn map(&mut self, field: &str) -> Result<BTreeMap<String, String>, String> {
        let inner = self.bytes32(field)?;
        let mut entries = Fields {
            body: inner,
            pos: 0,
        };
        let mut map = BTreeMap::new();
        while entries.pos < inner.len() {
            let key = entries.string(&format!("{field} key"))?;
            let value = entries.string(&format!("{field}[{key:?}]"))?;
            map.insert(key, value);
        }
        Ok(map)
    }

    fn rest(&mut self) -> &'a [u8] {
        let rest = &self.body[self.pos..];
        self.pos = self.body.len();
        rest
    }
}

/// Parses `body` as a record of kind `opcode`; the error names the field at fault.
pub fn parse(opcode: u8, body: &[u8]) -> Result<Rec<'_>, String> {
    let mut f = Fields { body, pos: 0 };
    Ok(match opcode {
        op::HEADER => Rec::Header {
            profile: f.string("profile")?,
            library: f.string("library")?,
        },
        op::SCHEMA => Rec::Schema {
            id: f.u16("id")?,
            name: f.string("name")?,
            encoding: f.string("encoding")?,
            data: f.bytes32("data")?,
        },
        op::CHANNEL => Rec::Channel {
            id: f.u16("id")?,
            schema_id: f.u16("schema_id")?,
            topic: f.string("topic")?,
            message_encoding: f.string("message_encoding")?,
            metadata: f.map("metadata")?,
        },
        op::MESSAGE => Rec::Message {
            channel_id: f.u16("channel_id")?,
            sequence: f.u32("sequence")?,
            log_time: f.u64("log_time")?,
            publish_time: f.u64("publish_time")?,
            data: f.rest(),
        },
        op::CHUNK => {
            let _start = f.u64("message_start_time")?;
            let _end = f.u64("message_end_time")?;
            let uncompressed_size = f.u64("uncompressed_size")?;
            let uncompressed_crc = f.u32("uncompressed_crc")?;
            let compression = f.string("compression")?;
            let size = f.u64("compressed_size")?;
            Rec::Chunk {
                uncompressed_size,
                uncompressed_crc,
                compression,
                records: f.take(size, "records")?,
            }
        }
        op::METADATA => Rec::Metadata {
            name: f.string("name")?,
            metadata: f.map("metadata")?,
        },
        op::FOOTER => Rec::Footer,
        _ => Rec::Other,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lengths_beyond_the_record_are_refused_without_allocating_them() {
        // A channel whose topic claims 4 GiB.
        let mut body = vec![1, 0, 1, 0];
        body.extend_from_slice(&u32::MAX.to_le_bytes());
        body.extend_from_slice(b"/t");
        let e = parse(op::CHANNEL, &body).expect_err("too long");
        assert_eq!(e, "topic needs 4294967295 bytes, the record has 2 left");
        let mut map = vec![1, 0, 1, 0, 2, 0, 0, 0];
        map.extend_from_slice(b"/t");
        map.extend_from_slice(&3u32.to_le_bytes());
        map.extend_from_slice(b"cdr");
        map.extend_from_slice(&9u32.to_le_bytes());
        map.extend_from_slice(&[6, 0, 0, 0, b'k', b'e', b'y', 0, 0]);
        let e = parse(op::CHANNEL, &map).expect_err("bad map");
        assert_eq!(e, "metadata key needs 6 bytes, the record has 5 left");
        assert!(matches!(parse(0x42, b"whatever"), Ok(Rec::Other)));
        assert!(parse(op::MESSAGE, &[1, 0, 0]).is_err());
    }
}
