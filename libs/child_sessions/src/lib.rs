//! A child's sessions as the robot stores them, read from the game manager's session files and
//! the bags, never from a store of its own that could drift from them:
//!
//! - [`find`] walks the places given for the files the suite writes; [`sessions`] reads whose
//!   each session is; [`user`] checks a user id (a child's code) as the game manager does.
//!   `child_data` (list, export, erase of a child's files) builds its inventory on these;
//! - [`children`]: every child the stored sessions name, with how many sessions and when the
//!   last one was;
//! - [`progress`]: one child's sessions side by side (score of the maximum, levels, engagement,
//!   feedback, the therapist's overrides, pauses and proposals), the bags read through the
//!   suite's one rule for what arrived twice (`session_log`), a damaged or missing bag named;
//! - [`report`]: that progress as HTML, in English or German, with its figures; one
//!   self-contained file that prints on A4 (`session_report --user`), or the same body inside
//!   the therapist page.

pub mod children;
pub mod error;
pub mod find;
pub mod progress;
pub mod report;
pub mod sessions;
pub mod user;
mod words;

pub use children::{Child, ChildList, children};
pub use error::StoredError;
pub use progress::{Belief, Progress, SessionProgress};
pub use report::{Language, progress_document, progress_fragment, progress_report_of};
pub use user::UserId;
