//! What a session's messages add up to, by the game's rules, for every node and tool that
//! reads a session: the tally of its results ([`Tally`]), a sequence's engagement from the
//! per-second ExpectedEngagement windows ([`engagement`]) and the operator's lines
//! ([`live_line`]: the same words in the game manager, the console, the tablet and the report). The
//! messages themselves, their validation and their codes are `qt_therapy_msgs`'s.

pub mod engagement;
pub mod live_line;
pub mod tally;

pub use engagement::{EngagementLog, SequenceEngagement};
pub use tally::Tally;
