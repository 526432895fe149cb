//! Bags of the suite's sessions as MCAP files, written the way rosbag2's MCAP storage writes
//! them (readable by `ros2 bag`, the Python `rosbags` and `mcap` packages, Foxglove): an
//! in-process writer, a damage-tolerant reader with typed access, `bag info`'s summary, the
//! player's plan, and the type table the `bag` binary's DDS recorder and player use.
//!
//! ```no_run
//! use bag_file::{BagReader, BagWriter, WriterOptions};
//! use qt_therapy_msgs::topics::GAME_STATE;
//! # fn main() -> Result<(), bag_file::BagError> {
//! let path = std::path::Path::new("session.mcap");
//! let mut w = BagWriter::create(path, &WriterOptions::default())?;
//! let state = w.add_topic(GAME_STATE)?;
//! w.write(state, 1_700_000_000_000_000_000, &qt_therapy_msgs::GameState::default())?;
//! w.finish()?;
//! let r = BagReader::open(path)?;
//! for m in r.messages::<qt_therapy_msgs::GameState>(GAME_STATE.name)? {
//!     println!("{} {:?}", m.log_time, m.message.phase);
//! }
//! # Ok(()) }
//! ```

pub mod bag_info;
pub mod cdr;
pub mod error;
mod parse;
pub mod qos;
pub mod reader;
pub mod scan;
pub mod schedule;
pub mod suite;
pub mod writer;

pub use bag_info::BagInfo;
pub use error::{BagError, RecordAt};
pub use reader::{BagReader, ReadOptions, Stamped};
pub use scan::{ChannelInfo, RawMessage, SchemaInfo};
pub use writer::{
    BagWriter, Channel, Compression, FileBagWriter, Stamp, WriterOptions, partial_path,
};

/// The name of the metadata records of the wall clock's steps a recorder saw: `log_time` (on
/// the recorder's steady clock, as every log time) and `by_ns` (negative: set back), decimal.
/// Log times never step; the messages' stamps (the senders' wall clocks) step with the clock.
pub const CLOCK_STEP: &str = "qt_therapy.clock_step";
