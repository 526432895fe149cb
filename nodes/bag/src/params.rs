//! The parameters of the two DDS nodes of the `bag` binary, as `params/bag_recorder.yaml`
//! and `params/bag_player.yaml` hold them; command-line flags override them.

use node_shell::parameters::DescribedParameters;
use serde::{Deserialize, Serialize};

/// `bag record` (node `bag_recorder`).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize, DescribedParameters)]
#[serde(deny_unknown_fields, default)]
pub struct RecorderParams {
    /// Topics to record; empty records every topic of the suite.
    pub topics: Vec<String>,
    /// `zstd`, `lz4` or `none`.
    pub compression: String,
    /// A chunk closes when it holds this many uncompressed bytes.
    pub chunk_size_bytes: i64,
    /// A chunk also closes (and reaches the disk) at least this often, in seconds.
    pub flush_interval_s: f64,
    /// Messages queued between the DDS readers and the writer.
    pub queue_capacity: i64,
    /// zstd worker threads; 0 compresses on the writing thread.
    pub compression_threads: i64,
}

impl Default for RecorderParams {
    fn default() -> Self {
        RecorderParams {
            topics: Vec::new(),
            compression: "zstd".into(),
            chunk_size_bytes: 1024 * 1024,
            flush_interval_s: 1.0,
            queue_capacity: 4096,
            compression_threads: 0,
        }
    }
}

/// `bag play` (node `bag_player`).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize, DescribedParameters)]
#[serde(deny_unknown_fields, default)]
pub struct PlayerParams {
    /// Speed over the original timing (2.0 plays twice as fast).
    pub rate: f64,
    /// Ignore the timing and publish every message at once.
    pub as_fast_as_possible: bool,
    /// Topics to play; empty plays every playable topic.
    pub topics: Vec<String>,
    /// Remappings `/from:=/to`.
    pub remap: Vec<String>,
    /// Start again from the start offset after the end, until stopped.
    #[serde(rename = "loop")]
    pub looped: bool,
    /// Seconds of the bag to skip at its start.
    pub start_offset_s: f64,
    /// How long to wait for subscribers before the first message, in seconds.
    pub wait_for_subscribers_s: f64,
    /// How long to stay after the last message so reliable samples get delivered, in seconds.
    pub linger_s: f64,
}

impl Default for PlayerParams {
    fn default() -> Self {
        PlayerParams {
            rate: 1.0,
            as_fast_as_possible: false,
            topics: Vec::new(),
            remap: Vec::new(),
            looped: false,
            start_offset_s: 0.0,
            wait_for_subscribers_s: 3.0,
            linger_s: 1.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use node_shell::params::load_parameters;
    use std::path::Path;

    fn params_dir() -> &'static Path {
        Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../params"))
    }

    #[test]
    fn the_shipped_files_hold_the_defaults() {
        let recorder: RecorderParams =
            load_parameters(&params_dir().join("bag_recorder.yaml"), "bag_recorder")
                .expect("bag_recorder.yaml loads");
        assert_eq!(recorder, RecorderParams::default());
        let player: PlayerParams =
            load_parameters(&params_dir().join("bag_player.yaml"), "bag_player")
                .expect("bag_player.yaml loads");
        assert_eq!(player, PlayerParams::default());
    }
}
