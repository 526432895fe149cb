//! The tablet bridge: the child tablet and the therapist tablet as web pages served over
//! HTTPS + WebSocket, bridged to the suite's DDS topics. `bridge` is the sans-IO core that
//! checks everything a tablet sends; `node` runs it on a bus (`node_shell::Bus`), its pages'
//! messages coming from `server`, the axum shell, over HTTPS (`tls`);
//! `pages` holds the HTML/CSS/JS/SVG compiled into the binary (no build step, no external
//! resources); `stored` reads the child list and a child's progress for the therapist page
//! from the stored sessions (off the core, which only asks for them); `certificates` makes the
//! robot's own CA and server certificate (`tablet_tls`).

pub mod bridge;
pub mod certificates;
mod child;
mod connections;
mod game;
pub mod io;
pub mod limits;
pub mod node;
pub mod pages;
pub mod params;
mod proposal;
pub mod protocol;
pub mod server;
pub mod stored;
pub mod therapist;
pub mod tls;
pub mod watch;

pub use bridge::Bridge;
pub use io::{ClientId, DdsInput, Now, Output};
pub use params::TabletBridgeParams;
pub use protocol::{ClientMessage, CommandKind, Role, ServerMessage};
