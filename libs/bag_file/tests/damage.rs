//! Bad input never panics the reader; it reads everything before the first bad record and
//! names that record: a bag truncated at any byte, a chunk with a bad CRC (compressed or not),
//! a channel whose schema was never defined, a message on an undefined channel, a chunk that
//! claims too much memory, a file that is not MCAP, and seeded random corruption.

mod common;

use bag_file::{BagError, BagReader, Compression, ReadOptions, WriterOptions};
use common::session_bytes;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::BTreeSet;

fn small_chunks(compression: Compression) -> WriterOptions {
    WriterOptions {
        compression,
        chunk_size: 4 * 1024,
        compression_threads: 0,
    }
}

fn read(bytes: &[u8]) -> BagReader {
    BagReader::from_bytes(bytes, "bag.mcap", &ReadOptions::default()).expect("is MCAP")
}

/// (offset, opcode, total length) of each top-level record.
fn records(bytes: &[u8]) -> Vec<(usize, u8, usize)> {
    let mut out = Vec::new();
    let mut pos = 8;
    while pos + 9 <= bytes.len() {
        let len = u64::from_le_bytes(bytes[pos + 1..pos + 9].try_into().expect("8 bytes")) as usize;
        out.push((pos, bytes[pos], 9 + len));
        pos += 9 + len;
    }
    out
}

fn sequences(reader: &BagReader) -> BTreeSet<u32> {
    reader.raw_messages().iter().map(|m| m.sequence).collect()
}

#[test]
fn truncated_anywhere_reads_every_complete_chunk_and_names_the_cut_record() {
    let (bytes, expected) = session_bytes(&small_chunks(Compression::Zstd));
    let all = sequences(&read(&bytes));
    assert_eq!(all.len(), expected.len());
    let chunk_ends: Vec<usize> = records(&bytes)
        .iter()
        .filter(|r| r.1 == mcap::records::op::CHUNK)
        .map(|r| r.0 + r.2)
        .collect();
    assert!(chunk_ends.len() >= 4, "{} chunks", chunk_ends.len());
    let mut boundaries: BTreeSet<usize> = records(&bytes).iter().map(|r| r.0).collect();
    // The closing magic follows the footer.
    boundaries.insert(bytes.len() - 8);
    for cut in (8..bytes.len())
        .step_by(5)
        .chain(boundaries.iter().copied())
    {
        let reader = read(&bytes[..cut]);
        let got = sequences(&reader);
        assert!(got.is_subset(&all), "cut at {cut}");
        // Exactly the messages of the chunks that ended before the cut.
        let whole = chunk_ends.iter().filter(|&&end| end <= cut).count();
        let want = match whole {
            0 => 0,
            n => read(&bytes[..chunk_ends[n - 1]]).raw_messages().len(),
        };
        assert_eq!(got.len(), want, "cut at {cut}");
        match reader.damage() {
            None => assert!(
                boundaries.contains(&cut) || cut > bytes.len() - 8,
                "cut at {cut} inside a record unnoticed"
            ),
            Some(BagError::Truncated { at, .. }) => {
                assert!(at.offset as usize <= cut && boundaries.contains(&(at.offset as usize)));
            }
            Some(other) => panic!("cut at {cut}: {other}"),
        }
        assert!(!reader.is_complete());
    }
}

fn damage_of_flipped(bytes: &mut [u8], at: usize) -> (BagReader, usize) {
    bytes[at] ^= 0x5a;
    let reader = read(bytes);
    let n = reader.raw_messages().len();
    (reader, n)
}

#[test]
fn a_bad_chunk_crc_stops_at_that_chunk() {
    let (mut bytes, _) = session_bytes(&small_chunks(Compression::Zstd));
    let chunks: Vec<(usize, (usize, u8, usize))> = records(&bytes)
        .into_iter()
        .enumerate()
        .filter(|(_, r)| r.1 == mcap::records::op::CHUNK)
        .collect();
    let (index, (offset, _, _)) = chunks[2];
    let before = read(&bytes[..offset]).raw_messages().len();
    assert!(before > 0);
    // The stored CRC of the uncompressed records: after start, end and size (3 x u64).
    let (reader, n) = damage_of_flipped(&mut bytes, offset + 9 + 24);
    assert_eq!(n, before);
    match reader.damage() {
        Some(BagError::BadChunkCrc { at, .. }) => {
            assert_eq!((at.index, at.offset), (index as u64, offset as u64));
        }
        other => panic!("{other:?}"),
    }
    let text = reader.damage().map(|e| e.to_string()).unwrap_or_default();
    assert!(
        text.contains(&format!("record #{index} (Chunk at byte {offset})")),
        "{text}"
    );
}

#[test]
fn a_flipped_byte_in_an_uncompressed_chunk_fails_its_crc() {
    let (mut bytes, _) = session_bytes(&small_chunks(Compression::None));
    let needle = b"Listen carefully";
    let at = bytes
        .windows(needle.len())
        .position(|w| w == needle)
        .expect("the speech is in the bag");
    let (index, (offset, _, _)) = records(&bytes)
        .into_iter()
        .enumerate()
        .find(|(_, r)| r.0 <= at && at < r.0 + r.2)
        .expect("inside a record");
    let before = read(&bytes[..offset]).raw_messages().len();
    let (reader, n) = damage_of_flipped(&mut bytes, at + 3);
    assert_eq!(n, before);
    assert!(
        matches!(reader.damage(), Some(BagError::BadChunkCrc { at, .. }) if at.index == index as u64),
        "{:?}",
        reader.damage()
    );
}

/// MCAP records written by hand, for files the `mcap` writer refuses to make.
mod raw {
    pub fn string(out: &mut Vec<u8>, s: &str) {
        out.extend_from_slice(&(s.len() as u32).to_le_bytes());
        out.extend_from_slice(s.as_bytes());
    }
    pub fn record(out: &mut Vec<u8>, opcode: u8, body: &[u8]) {
        out.push(opcode);
        out.extend_from_slice(&(body.len() as u64).to_le_bytes());
        out.extend_from_slice(body);
    }
    pub fn start() -> Vec<u8> {
        let mut out = mcap::MAGIC.to_vec();
        let mut h = Vec::new();
        string(&mut h, "ros2");
        string(&mut h, "hand-made");
        record(&mut out, 0x01, &h);
        out
    }
    pub fn schema(out: &mut Vec<u8>, id: u16, name: &str, text: &str) {
        let mut b = id.to_le_bytes().to_vec();
        string(&mut b, name);
        string(&mut b, "ros2msg");
        string(&mut b, text);
        record(out, 0x03, &b);
    }
    pub fn channel(out: &mut Vec<u8>, id: u16, schema: u16, topic: &str) {
        let mut b = id.to_le_bytes().to_vec();
        b.extend_from_slice(&schema.to_le_bytes());
        string(&mut b, topic);
        string(&mut b, "cdr");
        b.extend_from_slice(&0u32.to_le_bytes());
        record(out, 0x04, &b);
    }
    pub fn message(out: &mut Vec<u8>, channel: u16, time: u64, payload: &[u8]) {
        let mut b = channel.to_le_bytes().to_vec();
        b.extend_from_slice(&1u32.to_le_bytes());
        b.extend_from_slice(&time.to_le_bytes());
        b.extend_from_slice(&time.to_le_bytes());
        b.extend_from_slice(payload);
        record(out, 0x05, &b);
    }
    pub fn end(out: &mut Vec<u8>) {
        record(out, 0x0f, &0u32.to_le_bytes());
        record(out, 0x02, &[0u8; 20]);
        out.extend_from_slice(mcap::MAGIC);
    }
}

fn hello() -> Vec<u8> {
    bag_file::cdr::encode(&qt_therapy_msgs::std_msgs::StringMsg {
        data: "hello".into(),
    })
    .expect("cdr")
}

#[test]
fn a_channel_with_an_undefined_schema_is_named_and_what_precedes_it_is_read() {
    let mut b = raw::start();
    raw::schema(&mut b, 1, "std_msgs/msg/String", "string data\n");
    raw::channel(&mut b, 1, 1, "/qt_robot/speech/say");
    raw::message(&mut b, 1, 5, &hello());
    raw::channel(&mut b, 2, 9, "/mystery");
    raw::message(&mut b, 2, 6, &hello());
    raw::end(&mut b);
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("unknown_schema.mcap");
    std::fs::write(&path, &b).expect("write");
    let reader = BagReader::open(&path).expect("is MCAP");
    let said = reader
        .messages::<qt_therapy_msgs::std_msgs::StringMsg>("/qt_robot/speech/say")
        .expect("typed");
    assert_eq!(said.len(), 1);
    assert_eq!(said[0].message.data, "hello");
    let e = reader.damage().expect("damage").to_string();
    assert!(e.starts_with(&path.display().to_string()), "{e}");
    assert!(e.contains("record #4 (Channel at byte"), "{e}");
    assert!(e.contains("\"/mystery\" refers to schema 9"), "{e}");
    assert!(BagReader::open(&path).expect("is MCAP").strict().is_err());
}

#[test]
fn a_schema_of_a_type_the_suite_does_not_know_reads_but_does_not_decode_or_play() {
    let mut b = raw::start();
    raw::schema(&mut b, 1, "other_pkg/msg/Thing", "int32 x\n");
    raw::channel(&mut b, 1, 1, "/thing");
    raw::message(&mut b, 1, 5, &[0, 1, 0, 0, 7, 0, 0, 0]);
    raw::schema(&mut b, 2, "std_msgs/msg/String", "string data\n");
    raw::channel(&mut b, 2, 2, "/qt_robot/speech/say");
    raw::message(&mut b, 2, 6, &hello());
    raw::end(&mut b);
    let reader = read(&b);
    assert!(reader.damage().is_none() && reader.is_complete());
    assert_eq!(reader.raw_messages().len(), 2);
    let e = reader
        .messages::<qt_therapy_msgs::std_msgs::StringMsg>("/thing")
        .expect_err("not a String");
    assert!(e.to_string().contains("other_pkg/msg/Thing"), "{e}");
    let options = bag_file::schedule::PlayOptions {
        rate: Some(1.0),
        start_offset: std::time::Duration::ZERO,
        topics: vec![],
        remap: vec![],
    };
    let plan = bag_file::schedule::plan(&reader, &options, |c| {
        bag_file::suite::suite_type(c.type_name())
            .map(|_| ())
            .ok_or("unknown type".to_string())
    })
    .expect("plans");
    assert_eq!(plan.outputs.len(), 1);
    assert_eq!(
        plan.skipped,
        vec![("/thing".to_string(), "unknown type".to_string())]
    );
    assert_eq!(plan.due.len(), 1);
}

#[test]
fn a_message_on_an_undefined_channel_is_named() {
    let mut b = raw::start();
    raw::schema(&mut b, 1, "std_msgs/msg/String", "string data\n");
    raw::channel(&mut b, 1, 1, "/qt_robot/speech/say");
    raw::message(&mut b, 1, 5, &hello());
    raw::message(&mut b, 3, 6, &hello());
    raw::end(&mut b);
    let reader = read(&b);
    assert_eq!(reader.raw_messages().len(), 1);
    match reader.damage() {
        Some(BagError::UnknownChannel {
            at, channel_id: 3, ..
        }) => assert_eq!(at.index, 4),
        other => panic!("{other:?}"),
    }
}

#[test]
fn not_mcap_and_oversized_chunks_are_refused() {
    for bytes in [&b""[..], b"\x89MCAP0\r", b"PK\x03\x04 a zip file"] {
        assert!(matches!(
            BagReader::from_bytes(bytes, "x", &ReadOptions::default()),
            Err(BagError::NotMcap { .. })
        ));
    }
    let (bytes, _) = session_bytes(&small_chunks(Compression::Lz4));
    let tight = ReadOptions {
        max_chunk_bytes: 100,
    };
    let reader = BagReader::from_bytes(&bytes, "x", &tight).expect("is MCAP");
    assert!(matches!(
        reader.damage(),
        Some(BagError::ChunkTooLarge { .. })
    ));
    assert!(reader.raw_messages().is_empty());
}

#[test]
fn seeded_random_corruption_never_panics() {
    let seed = 7;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for compression in [Compression::Zstd, Compression::Lz4, Compression::None] {
        let (bytes, _) = session_bytes(&small_chunks(compression));
        for _ in 0..400 {
            let mut bad = bytes.clone();
            for _ in 0..rng.random_range(1..8) {
                let i = rng.random_range(8..bad.len());
                bad[i] = rng.random();
            }
            if rng.random_bool(0.3) {
                bad.truncate(rng.random_range(8..bad.len()));
            }
            let reader = read(&bad);
            if let Some(e) = reader.damage() {
                assert!(e.record().is_some(), "{e}");
            }
        }
    }
}

#[test]
fn inputs_the_fuzzer_found_read_without_panicking_or_huge_allocations() {
    let dir =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/regressions/read_bag");
    let mut seen = 0;
    for entry in std::fs::read_dir(&dir).expect("fuzz/regressions/read_bag") {
        let path = entry.expect("entry").path();
        let bytes = std::fs::read(&path).expect("read");
        // Any outcome but a panic or an abort will do; damage must name its record.
        if let Ok(reader) = BagReader::from_bytes(&bytes, "regression", &ReadOptions::default())
            && let Some(e) = reader.damage()
        {
            assert!(e.record().is_some(), "{}: {e}", path.display());
        }
        seen += 1;
    }
    assert!(seen > 0);
}
