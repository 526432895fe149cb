//! The subcommands of the `user_model` binary, one module each.

pub mod fit;
pub mod predict;
pub mod run;
pub mod simulate_study;
