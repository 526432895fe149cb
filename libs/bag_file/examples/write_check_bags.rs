//! Writes the synthetic test session (tests/common) as three bags, zstd, lz4 and uncompressed
//! chunks, plus `expected.json` (every message as JSON with its topic, type and times), for
//! tests/bags/check_bag.py to read back with the Python `mcap` and `rosbags` packages.
//!   cargo run -p bag_file --example write_check_bags -- OUT_DIR

#[path = "../tests/common/mod.rs"]
mod common;

use anyhow::Context as _;
use bag_file::{BagWriter, Compression, WriterOptions};
use qt_therapy_msgs::topics::all_topics;
use std::path::PathBuf;

fn main() -> anyhow::Result<()> {
    let dir = PathBuf::from(
        std::env::args()
            .nth(1)
            .context("usage: write_check_bags OUT_DIR")?,
    );
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut expected = Vec::new();
    for (name, compression) in [
        ("zstd", Compression::Zstd),
        ("lz4", Compression::Lz4),
        ("none", Compression::None),
    ] {
        let options = WriterOptions {
            compression,
            // Small chunks, so a reader must cross chunk boundaries.
            chunk_size: 16 * 1024,
            compression_threads: 0,
        };
        let path = dir.join(format!("session_{name}.mcap"));
        let mut w = BagWriter::create(&path, &options)?;
        expected = common::write_session(&mut w);
        w.finish()?;
        println!("{}", path.display());
    }
    let json: Vec<serde_json::Value> = expected
        .iter()
        .map(|e| {
            let qos = all_topics()
                .into_iter()
                .find(|t| t.name == e.topic)
                .map(|t| format!("{:?}", t.qos).to_ascii_lowercase());
            serde_json::json!({
                "topic": e.topic, "type": e.type_name, "log_time": e.log_time,
                "publish_time": e.publish_time, "qos": qos, "message": e.message,
            })
        })
        .collect();
    let out = dir.join("expected.json");
    let tmp = dir.join("expected.json.tmp");
    std::fs::write(&tmp, serde_json::to_string_pretty(&json)?)?;
    std::fs::rename(&tmp, &out)?;
    Ok(())
}
