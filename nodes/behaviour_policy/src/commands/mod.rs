//! The subcommands of the `behaviour_policy` binary, one module each: the node, and a look at
//! the Q-table files it keeps.

pub mod run;
pub mod show_q_table;
