//! The game manager of the QTrobot emotion-sequence memorisation game. Its core
//! ([`GameManager`]) is a sans-IO state machine: therapist commands, tablet answers,
//! engagement, policy answers and timer firings in; robot speech, faces and gestures, tablet
//! tasks, game states, sequence results, policy requests, timer requests, session-file
//! records and log lines out; a session a killed node left unfinished is taken over from its
//! files ([`recovery`]). [`node`] runs it on a bus (`node_shell::Bus`); `src/main.rs` starts
//! that over DDS.

pub mod game;
pub mod node;
pub mod params;
pub mod protocol;
pub mod recovery;
pub mod retention;
pub mod sequence;
pub mod session_file;
pub mod utterances;

pub use game::GameManager;
pub use params::{GameManagerParams, ParamError};
pub use protocol::{Input, LogLevel, Now, Output};
