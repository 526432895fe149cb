//! A child's data on the robot: everything the suite holds for one user id, listed, exported
//! into one archive, or erased (`qt-therapy-data list|export|erase --user ID`, docs/privacy.md).
//!
//! - [`find`] walks the places given for the files the suite writes, [`sessions`] reads whose
//!   each session file is and [`user`] checks the id (all three `child_sessions`'s, shared
//!   with the child list and the progress report); [`bags`], [`rows`] read whose each
//!   message, row and line is;
//! - [`inventory`] gathers what one user has where, what erase would do and what stops it;
//! - [`export`] writes the archive and its manifest; [`erase`] removes and rewrites, through
//!   [`replace`] (whole-file replacement keeping owner and mode) and [`live`] (is a run still
//!   going: the game manager's lock, the launcher's command line).
//!
//! ```no_run
//! use child_data::{Inventory, UserId};
//! # fn main() -> Result<(), child_data::ChildDataError> {
//! let user = UserId::new("child-7")?;
//! let inv = Inventory::build(&user, &["/var/lib/qt-therapy".into()])?;
//! print!("{}", inv.to_text());
//! let exported = child_data::export::export(&inv, std::path::Path::new("child-7.tar.gz"))?;
//! let (outcome, erased) = child_data::erase::erase(&inv, false);
//! # Ok(()) }
//! ```

pub mod bags;
pub mod erase;
pub mod error;
pub mod export;
pub mod inventory;
pub mod live;
pub mod replace;
pub mod rows;

pub use child_sessions::{find, sessions, user};

pub use error::ChildDataError;
pub use inventory::{Inventory, Item, ItemKind};
pub use user::UserId;
