//! The decision node of the paper's behaviour model (Q-learning itself is `q_learning`): its
//! parameters (`params`), a policy per cluster and per user bound to its Q-table file
//! (`cluster_policies`, `persistent`), per-child beliefs planned on (`child_beliefs`), the gate that holds a decision request until the result
//! it follows is learned (`learn_first`), and its run loop on any bus (`node`). The studies of
//! the policy and their figures are `tools/policy_lab`'s.

pub mod child_beliefs;
pub mod cluster_policies;
pub mod learn_first;
pub mod node;
pub mod params;
pub mod persistent;

pub use cluster_policies::{ClusterPolicies, OwnedTable, ServeError};
pub use params::BehaviourPolicyParams;
pub use persistent::{PersistentError, PersistentPolicy};
