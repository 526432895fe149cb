//! user_model (in progress)
