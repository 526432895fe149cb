//! The leave-one-child-out studies on a study's children, each child's own fitted model
//! standing in for the child: per-child adaptation (`per_child`), adaptation by a belief about
//! the child on the same children and draws (`per_child_belief`), and supervised autonomy's
//! proposal rules (`supervision`, on `per_child`'s children, policy and draws).

pub mod per_child;
pub mod per_child_belief;
pub mod supervision;
