//! The tablet bridge: the child tablet and the therapist tablet as web pages served over
//! HTTP + WebSocket, bridged to the suite's DDS topics. `bridge` is the sans-IO core that
//! checks everything a tablet sends; `server` is the axum shell around it; `pages` holds the
//! HTML/CSS/JS/SVG compiled into the binary (no build step, no external resources).

pub mod bridge;
mod child;
mod game;
pub mod limits;
pub mod pages;
pub mod params;
mod proposal;
pub mod protocol;
pub mod server;
pub mod therapist;
pub mod watch;

pub use bridge::{Bridge, ClientId, DdsInput, Now, Output};
pub use params::TabletBridgeParams;
pub use protocol::{ClientMessage, CommandKind, Role, ServerMessage};
