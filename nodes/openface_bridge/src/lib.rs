//! The OpenFace bridge: the camera side of the suite on a real robot. OpenFace 2's
//! `FeatureExtraction` writes one CSV row per face and frame; the bridge follows that file as it
//! grows (or reads standard input) and publishes each row as an `OpenFaceFeatures` message for
//! the engagement classifier. The core (`bridge`) is sans-IO: CSV lines and the clock in,
//! messages (with the time each is due) and log lines out; `follow` tails the file; `node` is
//! the run loop on a bus (`node_shell::Bus`), which `src/main.rs` starts over DDS.

pub mod bridge;
pub mod columns;
pub mod follow;
pub mod node;
pub mod params;
#[cfg(test)]
pub(crate) mod test_csv;

pub use bridge::{BadRow, Bridge, Counts, LogLine};
pub use columns::{ColumnMap, HeaderError};
pub use follow::{FollowEvent, Follower};
pub use params::{OpenFaceBridgeParams, ParamError, StampSource};
