//! The paper's behaviour model B (section "Robot Behaviour Model", Algorithm 1): tabular
//! Q-learning over states (L, F, PS) with actions a1..a5, softmax exploration with a per-state
//! temperature, rewards RE / RE + βE / λE against a cluster's user model, and an
//! exploitation-only mode. One implementation for the decision node (`nodes/behaviour_policy`)
//! and the studies (`tools/policy_lab`), so what is measured is what runs:
//! - [`learning`]: Algorithm 1's pieces (rewards, temperature, the Q-table, softmax, update);
//! - [`policy_core`]: the live policy, sans-IO, and [`messages`], its conversion from and to
//!   the suite's messages; [`q_table_file`]: Q-tables on disk;
//! - [`simulation`]: Algorithm 1 against a user model as a tight loop, and [`training`]: runs
//!   of simulated sessions (the node pretrains a table with them);
//! - [`mdp`]: a session against a user model as a decision problem: sessions played by any
//!   policy, a policy's exact value and the optimal policy (backward induction);
//! - [`reference_tables`]: hand-made user-model tables for tests and trials.
//!
//! No DDS, no plotting, no threads: user models come as `sequence_game::UserModelTable`.

pub mod learning;
pub mod mdp;
pub mod messages;
pub mod policy_core;
pub mod q_table_file;
pub mod reference_tables;
pub mod simulation;
pub mod training;

pub use learning::{
    Learning, LearningConstants, LearningError, Mode, QTable, Reward, TemperatureSchedule,
};
pub use policy_core::{Decision, PolicyCore, PolicyError, Transition};
pub use q_table_file::{QTableError, QTableFile, QTableOwner};
