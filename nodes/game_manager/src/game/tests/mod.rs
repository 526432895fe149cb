//! Unit tests of the session state machine, driven through a simulated clock.

mod answers;
mod clock;
mod commands;
mod disk;
mod harness;
mod heartbeats;
mod parameters;
mod proposals;
mod recovery;
mod robot;
mod session;
