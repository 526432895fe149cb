//! Writes the seed corpus for `read_bag`: small bags of every compression, with one message
//! of several suite types each, so the fuzzer starts from valid files.
//!   make_seeds CORPUS_DIR

use bag::{BagWriter, Compression, WriterOptions};
use qt_therapy_msgs::std_msgs::StringMsg;
use qt_therapy_msgs::topics::{GAME_STATE, OPENFACE_FEATURES, ROBOT_SPEECH};
use qt_therapy_msgs::{GameState, OpenFaceFeatures};
use std::io::Cursor;

fn main() -> anyhow::Result<()> {
    let dir = std::path::PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "corpus/read_bag".into()),
    );
    std::fs::create_dir_all(&dir)?;
    for (name, compression) in [
        ("zstd", Compression::Zstd),
        ("lz4", Compression::Lz4),
        ("none", Compression::None),
    ] {
        let options = WriterOptions {
            compression,
            chunk_size: 256,
            compression_threads: 0,
        };
        let mut w = BagWriter::new(Cursor::new(Vec::new()), "seed", &options)?;
        let speech = w.add_topic(ROBOT_SPEECH)?;
        let state = w.add_topic(GAME_STATE)?;
        let face = w.add_topic(OPENFACE_FEATURES)?;
        w.write(
            speech,
            10,
            &StringMsg {
                data: "happy".into(),
            },
        )?;
        w.write(
            state,
            20,
            &GameState {
                phase: 3,
                status: "saying".into(),
                ..Default::default()
            },
        )?;
        w.write(
            face,
            30,
            &OpenFaceFeatures {
                features: vec![0.5; 32],
                success: true,
                ..Default::default()
            },
        )?;
        w.write(speech, 5, &StringMsg { data: "sad".into() })?;
        let bytes = w.finish()?.into_inner();
        std::fs::write(dir.join(format!("seed_{name}.mcap")), bytes)?;
    }
    Ok(())
}
