//! The therapist console: the therapist tablet's commands from a shell, and a live view of a
//! session. `console` sends commands and follows sessions on any bus (`node_shell::Bus`: DDS
//! for the `therapist` binary, in process in the cross-node tests); `proposals` is what
//! `run-session` does with the game manager's proposals (sans-IO).

pub mod console;
pub mod proposals;
