//! The decision node of the paper's behaviour model (Q-learning itself: `q_learning`): its
//! parameters, a policy per cluster (and per user) bound to its Q-table file, the learn-first
//! gate and its run loop; and, for now, the evaluation's studies: experiments with Figs. 4 and
//! 5, counterfactual evaluation of a new policy on recorded sessions, and the per-child
//! adaptation and supervision studies (which fit user models through `user_models`).

pub mod cluster_policies;
pub mod evaluation_plot;
pub mod grid;
pub mod learn_first;
pub mod node;
pub mod off_policy;
pub mod params;
pub mod per_child;
pub mod persistent;
pub mod plot;
pub mod recorded;
pub mod report;
pub mod stats;
pub mod supervision;

pub use cluster_policies::{ClusterPolicies, OwnedTable, ServeError};
pub use params::BehaviourPolicyParams;
pub use persistent::{PersistentError, PersistentPolicy};
