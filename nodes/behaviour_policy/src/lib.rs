//! behaviour_policy (in progress)
