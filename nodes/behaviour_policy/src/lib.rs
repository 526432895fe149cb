//! The paper's behaviour model B (section "Robot Behaviour Model", Algorithm 1): tabular
//! Q-learning over states (L, F, PS) with actions a1..a5, softmax exploration with a per-state
//! temperature, rewards RE / RE + βE / λE against a cluster's user model, an exploitation-only
//! mode, policy transfer, the evaluation's experiments with Figs. 4 and 5, Q-table files, and
//! the sans-IO core of the decision node, counterfactual evaluation of a new policy on
//! recorded sessions, and the per-child adaptation study (which fits user models, through
//! `user_models`; the rest sees user models only as `sequence_game::UserModelTable`).

pub mod cluster_policies;
pub mod evaluation_plot;
pub mod experiments;
pub mod grid;
pub mod learn_first;
pub mod learning;
pub mod mdp;
pub mod messages;
pub mod node;
pub mod off_policy;
pub mod params;
pub mod per_child;
pub mod persistent;
pub mod plot;
pub mod policy_core;
pub mod q_table_file;
pub mod recorded;
pub mod reference_tables;
pub mod report;
pub mod simulation;
pub mod softmax_cache;
pub mod stats;
pub mod supervision;

pub use cluster_policies::{ClusterPolicies, OwnedTable, ServeError};
pub use learning::{Learning, Mode, QTable, Reward, TemperatureSchedule};
pub use params::BehaviourPolicyParams;
pub use persistent::{PersistentError, PersistentPolicy};
pub use policy_core::{Decision, PolicyCore, PolicyError, Transition};
pub use q_table_file::{QTableError, QTableFile, QTableOwner};
