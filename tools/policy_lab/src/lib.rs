//! The studies of the paper's behaviour model and their figures, on the Q-learning the node
//! runs (`q_learning`), offline:
//! - [`experiments`]: the paper's evaluation grid in simulation (every user model × reward,
//!   and policy transfer) with its curves and tables, Figs. 4 and 5;
//! - [`off_policy`]: counterfactual evaluation of a new Q-table's policy on recorded sessions
//!   (importance sampling, the rules for when it gives no estimate), sessions read from bags,
//!   and its validation where the truth is known;
//! - [`child_study`]: the leave-one-child-out studies on the study's children: per-child
//!   adaptation and supervised autonomy's proposal rules;
//! - [`stats`]: the statistics they share; [`plots`]: their figures.
//!
//! The command line is `src/main.rs` (`policy_lab`); user models come fitted through
//! `user_models` or as `sequence_game::UserModelTable`s.

pub mod child_study;
pub mod experiments;
pub mod off_policy;
pub mod plots;
pub mod stats;
