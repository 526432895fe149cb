//! Recording throughput of the bag writer, the reference half of bench/bag/bench_record.py.
//! Builds one SYNTHETIC hour of a session's traffic (OpenFace frames and engagement labels at
//! 30 Hz, heartbeats of five nodes at 10 Hz, expected engagement at 1 Hz, a game sequence every
//! 30 s), dumps the CDR payloads for the Python writer, then times, best of `REPEATS`:
//!   encode+write: typed message -> CDR -> chunked, compressed MCAP (what the recorder does
//!                 per message after DDS), and
//!   write:        the same CDR payloads -> MCAP (what the Python `mcap` writer is timed on).
//!   cargo run --release -p suite_bench --bin bench_record -- OUT_DIR zstd|lz4
//! Prints one JSON line.

use anyhow::Context as _;
use bag_file::{BagWriter, Compression, Stamp, WriterOptions};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::topics::{
    DECISION, ENGAGEMENT_ESTIMATE, EXPECTED_ENGAGEMENT, GAME_STATE, HEARTBEAT, TopicInfo,
    all_topics,
};
use qt_therapy_msgs::*;
use std::io::{BufWriter, Write};
use std::time::Instant;

const REPEATS: usize = 3;
const START: u64 = 1_700_000_000_000_000_000;
const MS: u64 = 1_000_000;

enum Item {
    Features(OpenFaceFeatures),
    Estimate(EngagementEstimate),
    Heartbeat(Heartbeat),
    Expected(ExpectedEngagement),
    State(GameState),
    Decision(Decision),
}

impl Item {
    /// Index of the item's channel.
    fn kind(&self) -> usize {
        match self {
            Item::Features(_) => 0,
            Item::Estimate(_) => 1,
            Item::Heartbeat(_) => 2,
            Item::Expected(_) => 3,
            Item::State(_) => 4,
            Item::Decision(_) => 5,
        }
    }

    fn encode(&self) -> anyhow::Result<Vec<u8>> {
        match self {
            Item::Features(m) => bag_file::cdr::encode(m),
            Item::Estimate(m) => bag_file::cdr::encode(m),
            Item::Heartbeat(m) => bag_file::cdr::encode(m),
            Item::Expected(m) => bag_file::cdr::encode(m),
            Item::State(m) => bag_file::cdr::encode(m),
            Item::Decision(m) => bag_file::cdr::encode(m),
        }
        .map_err(anyhow::Error::msg)
    }
}

fn header(t: u64) -> Header {
    Header::at(Time::from_nanos(t as i64))
}

/// One hour of traffic, in log-time order: (log time, item).
fn hour() -> Vec<(u64, Item)> {
    let mut items = Vec::new();
    for frame in 0..30 * 3600u64 {
        let t = START + frame * 1000 * MS / 30;
        let p = frame as f32 * 0.05;
        items.push((
            t,
            Item::Features(OpenFaceFeatures {
                header: header(t),
                face_id: "0".into(),
                confidence: 0.95,
                success: true,
                features: (0..32).map(|j| (p + j as f32).sin()).collect(),
            }),
        ));
        items.push((
            t + 2 * MS,
            Item::Estimate(EngagementEstimate {
                header: header(t),
                face_id: "0".into(),
                label: if frame % 9 == 0 { -1 } else { 1 },
                probability: 0.5 + 0.4 * p.sin().abs(),
            }),
        ));
    }
    for tick in 0..10 * 3600u64 {
        for node in 0..5u32 {
            let t = START + tick * 100 * MS + u64::from(node) * MS;
            items.push((
                t,
                Item::Heartbeat(Heartbeat {
                    header: header(t),
                    node_name: format!("node_{node}"),
                    pid: 1000 + node,
                    sequence: tick,
                }),
            ));
        }
    }
    for s in 0..3600u64 {
        let t = START + (s + 1) * 1000 * MS + 5 * MS;
        items.push((
            t,
            Item::Expected(ExpectedEngagement {
                header: header(t),
                source: "0".into(),
                window_start: Time::from_nanos((t - 1000 * MS) as i64),
                window_end: Time::from_nanos(t as i64),
                has_faces: true,
                mean: 0.7,
                smoothed: 0.69,
                frame_count: 30,
                missing_count: 0,
            }),
        ));
    }
    for seq in 0..120u64 {
        let t = START + seq * 30_000 * MS + 500 * MS;
        for phase in 1..=4u8 {
            items.push((
                t + u64::from(phase) * 10 * MS,
                Item::State(GameState {
                    header: header(t),
                    phase,
                    session_id: "bench".into(),
                    status: "running".into(),
                    ..Default::default()
                }),
            ));
        }
        items.push((
            t + 5 * MS,
            Item::Decision(Decision {
                header: header(t),
                session_id: "bench".into(),
                q_values: vec![0.1, 0.2, 0.3, 0.4, 0.5],
                probabilities: vec![0.2; 5],
                temperature: 0.5,
                model_used: "q_table".into(),
                ..Default::default()
            }),
        ));
    }
    items.sort_by_key(|(t, _)| *t);
    items
}

fn topic(name: &str) -> anyhow::Result<TopicInfo> {
    all_topics()
        .into_iter()
        .find(|t| t.name == name)
        .context("a suite topic")
}

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let dir = std::path::PathBuf::from(
        args.next()
            .context("usage: bench_record OUT_DIR zstd|lz4")?,
    );
    let compression: Compression = args
        .next()
        .unwrap_or_else(|| "zstd".into())
        .parse()
        .map_err(anyhow::Error::msg)?;
    std::fs::create_dir_all(&dir)?;
    let items = hour();
    let options = WriterOptions {
        compression,
        ..WriterOptions::default()
    };
    let names = [
        qt_therapy_msgs::topics::OPENFACE_FEATURES.name,
        ENGAGEMENT_ESTIMATE.name,
        HEARTBEAT.name,
        EXPECTED_ENGAGEMENT.name,
        GAME_STATE.name,
        DECISION.name,
    ];
    let topics: Vec<TopicInfo> = names
        .iter()
        .map(|n| topic(n))
        .collect::<anyhow::Result<_>>()?;
    let open = |path: &std::path::Path| -> anyhow::Result<(BagWriter<_>, Vec<u16>)> {
        let mut w = BagWriter::create(path, &options)?;
        let ids = topics
            .iter()
            .map(|t| {
                w.add_channel(
                    t.name,
                    &t.type_name,
                    &t.schema_text,
                    &bag_file::qos::offered_qos_yaml(t.qos),
                )
            })
            .collect::<Result<_, _>>()?;
        Ok((w, ids))
    };
    // The payloads and their channels, for the Python writer and the write-only timing.
    let mut payloads = Vec::with_capacity(items.len());
    for (t, item) in &items {
        let cdr = item.encode()?;
        payloads.push((item.kind(), *t, cdr));
    }
    let dump = dir.join("payloads.bin");
    let mut f = BufWriter::new(std::fs::File::create(&dump)?);
    for (k, t, p) in &payloads {
        f.write_all(&[*k as u8])?;
        f.write_all(&t.to_le_bytes())?;
        f.write_all(&(p.len() as u32).to_le_bytes())?;
        f.write_all(p)?;
    }
    f.flush()?;
    let channels: Vec<_> = topics
        .iter()
        .map(|t| {
            serde_json::json!({"topic": t.name, "type": t.type_name, "schema": t.schema_text,
            "qos": bag_file::qos::offered_qos_yaml(t.qos)})
        })
        .collect();
    std::fs::write(dir.join("channels.json"), serde_json::to_string(&channels)?)?;

    let mut best_encode = f64::INFINITY;
    let mut best_write = f64::INFINITY;
    let mut size = 0;
    for _ in 0..REPEATS {
        let path = dir.join("rust_encode.mcap");
        let started = Instant::now();
        let (mut w, ids) = open(&path)?;
        for (seq, (t, item)) in items.iter().enumerate() {
            let stamp = Stamp {
                log_time: *t,
                publish_time: *t,
                sequence: seq as u32,
            };
            let id = ids[item.kind()];
            let cdr = item.encode()?;
            w.write_cdr(id, stamp, &cdr)?;
        }
        w.finish()?;
        best_encode = best_encode.min(started.elapsed().as_secs_f64());

        let path = dir.join("rust_write.mcap");
        let started = Instant::now();
        let (mut w, ids) = open(&path)?;
        for (seq, (k, t, p)) in payloads.iter().enumerate() {
            let stamp = Stamp {
                log_time: *t,
                publish_time: *t,
                sequence: seq as u32,
            };
            w.write_cdr(ids[*k], stamp, p)?;
        }
        w.finish()?;
        best_write = best_write.min(started.elapsed().as_secs_f64());
        size = std::fs::metadata(&path)?.len();
    }
    // The file must read back whole.
    let back = bag_file::BagReader::open(&dir.join("rust_write.mcap"))?.strict()?;
    anyhow::ensure!(
        back.raw_messages().len() == payloads.len(),
        "read back a different count"
    );
    println!(
        "{}",
        serde_json::json!({
            "messages": payloads.len(),
            "payload_bytes": payloads.iter().map(|p| p.2.len()).sum::<usize>(),
            "encode_write_s": best_encode,
            "write_s": best_write,
            "file_bytes": size,
        })
    );
    Ok(())
}
