//! The paper's behaviour model B (section "Robot Behaviour Model", Algorithm 1): tabular
//! Q-learning over states (L, F, PS) with actions a1..a5, softmax exploration with a per-state
//! temperature, rewards RE / RE + βE / λE against a cluster's user model, policy transfer, the
//! experiments of the evaluation with plots, Q-table files, and the decision node's core.

pub mod experiments;
pub mod learning;
pub mod plot;
pub mod policy_core;
pub mod q_table_file;

pub use learning::{Learning, Mode, QTable, Reward};
pub use policy_core::{PolicyCore, PolicyError, PolicyParams};
