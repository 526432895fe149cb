//! `erase`: removes or rewrites everything of the user an [`Inventory`] found, after checking
//! nothing would make that unsafe (a session of the user running, a run still writing a file
//! to change, a damaged bag without `--rewrite-damaged`): then it refuses and changes nothing.
//! While it works it holds the lock of every run directory it changes, as a game manager
//! would, so none starts there meanwhile. Each file is handled whole and at once (see
//! [`crate::replace`]); a bag is rewritten from what reads, checked to read back with exactly
//! the messages kept, and only then renamed over the old one. What erase cannot separate is
//! left and named, and the outcome says so.

use crate::bags::{Ownership, write_subset};
use crate::error::ChildDataError;
use crate::find::STAGING_PREFIX;
use crate::inventory::{
    Content, EraseAction, Inventory, Item, ItemKind, bag_part_of, csv_now, log_lines, run_dir,
};
use crate::live::{DirLock, lock_dir};
use crate::replace::{delete, replace_with_bytes, replace_with_file};
use crate::rows::gather;
use bag_file::BagReader;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// How an erase ended; [`Outcome::exit_code`] is the command's exit status.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Everything of the user found was removed.
    Done,
    /// Done, but something still holds data of the user (listed): a fitted model file, a
    /// report about someone else too, a file of unknown kind, a place that could not be read.
    StillHeld,
    /// Refused: nothing was changed.
    Refused,
    /// A file could not be changed (named); the others were.
    Failed,
}

/// The exit status of `erase` "done, but something still holds data of this user".
pub const EXIT_STILL_HELD: i32 = 3;
/// The exit status of `erase` "refused, nothing changed".
pub const EXIT_REFUSED: i32 = 4;

impl Outcome {
    pub fn exit_code(self) -> i32 {
        match self {
            Outcome::Done => 0,
            Outcome::Failed => 1,
            Outcome::StillHeld => EXIT_STILL_HELD,
            Outcome::Refused => EXIT_REFUSED,
        }
    }
}

/// What an erase did, line by line.
#[derive(Debug, Clone, Default)]
pub struct Erased {
    /// What was changed: "deleted …", "rewrote …".
    pub changed: Vec<String>,
    /// What still holds data of the user, and what to do about it.
    pub left: Vec<String>,
    /// Why erase refused, or which files failed.
    pub problems: Vec<String>,
    /// Worth knowing (owner not kept, sessions cut off, the journal, copies elsewhere).
    pub notes: Vec<String>,
}

/// Erases everything of `inv`'s user. `rewrite_damaged` lets damaged bags be rewritten from
/// what reads before the damage (the rest is lost).
pub fn erase(inv: &Inventory, rewrite_damaged: bool) -> (Outcome, Erased) {
    let mut out = Erased::default();
    let refusals = inv.refusals(rewrite_damaged);
    if !refusals.is_empty() {
        out.problems = refusals.iter().map(ToString::to_string).collect();
        return (Outcome::Refused, out);
    }
    // The run directories to change, locked before anything changes.
    let mut locks: BTreeMap<PathBuf, DirLock> = BTreeMap::new();
    for item in &inv.items {
        if item.erase_action() == EraseAction::Leave
            || !matches!(
                item.kind,
                ItemKind::Bag | ItemKind::SessionFile | ItemKind::Log
            )
        {
            continue;
        }
        let dir = run_dir(&item.path);
        if locks.contains_key(&dir) {
            continue;
        }
        match lock_dir(&dir) {
            Ok(Ok(lock)) => {
                locks.insert(dir, lock);
            }
            Ok(Err(by)) => {
                out.problems.push(format!(
                    "{} is in use ({by}) since it was searched: nothing was changed; erase \
                     again when no session runs",
                    dir.display()
                ));
                return (Outcome::Refused, out);
            }
            Err(e) => {
                out.problems.push(format!(
                    "cannot lock {}: {e}; nothing was changed",
                    dir.display()
                ));
                return (Outcome::Refused, out);
            }
        }
    }
    for item in &inv.items {
        let done = match item.erase_action() {
            EraseAction::Leave => {
                if let Content::Inseparable { todo } = &item.content {
                    out.left.push(format!(
                        "{} ({}): {}; {todo}",
                        item.path.display(),
                        item.kind.label(),
                        item.what
                    ));
                }
                continue;
            }
            _ => erase_item(inv, item),
        };
        match done {
            Ok((line, warning)) => {
                out.changed.push(line);
                out.notes.extend(warning);
            }
            Err(e) => out
                .problems
                .push(format!("{} was not changed: {e}", item.path.display())),
        }
    }
    drop(locks);
    for (p, why) in &inv.unreadable {
        out.left.push(format!(
            "{} could not be read ({why}): it may hold data of this user; read it as root, or \
             look at it by hand",
            p.display()
        ));
    }
    out.notes.extend(inv.notes.iter().cloned());
    out.notes.extend(crate::export::outside_notes(inv));
    let outcome = if !out.problems.is_empty() {
        Outcome::Failed
    } else if !out.left.is_empty() {
        Outcome::StillHeld
    } else {
        Outcome::Done
    };
    (outcome, out)
}

/// Erases one item as it is now; returns what was done and a warning.
fn erase_item(inv: &Inventory, item: &Item) -> Result<(String, Option<String>), ChildDataError> {
    let shown = item.path.display();
    match (&item.content, item.kind) {
        (Content::Whole, _) => {
            delete(&item.path)?;
            Ok((
                format!("deleted {shown} ({}: {})", item.kind.label(), item.what),
                None,
            ))
        }
        (Content::Bag(_), _) => erase_from_bag(inv, item),
        (Content::Rows { .. }, ItemKind::InteractionCsv) => {
            let (bytes, rows) = csv_now(&item.path, &inv.user)?;
            let Some(rows) = rows else {
                return Ok((
                    format!("left {shown}: it no longer has a user column"),
                    None,
                ));
            };
            let users = rows.users_rows();
            let kept = rows.rows.len() - users;
            if kept == 0 {
                delete(&item.path)?;
                return Ok((
                    format!("deleted {shown}: all its {users} rows were this user's"),
                    None,
                ));
            }
            let mut new = bytes[rows.header.clone()].to_vec();
            new.extend(gather(&bytes, &rows.rows, false));
            let warning = replace_with_bytes(&item.path, &new)?;
            Ok((
                format!("rewrote {shown}: removed this user's {users} rows, kept {kept}"),
                warning,
            ))
        }
        (Content::Rows { .. }, _) => {
            let bytes = std::fs::read(&item.path).map_err(ChildDataError::io(&item.path))?;
            let Some(lines) = log_lines(inv, &item.path) else {
                return Ok((format!("left {shown}: it is no longer text"), None));
            };
            let users = lines.iter().filter(|(_, p)| *p).count();
            let kept = lines.len() - users;
            if kept == 0 {
                delete(&item.path)?;
                return Ok((
                    format!("deleted {shown}: all its {users} lines named this user"),
                    None,
                ));
            }
            let warning = replace_with_bytes(&item.path, &gather(&bytes, &lines, false))?;
            Ok((
                format!(
                    "rewrote {shown}: removed the {users} lines naming this user or their \
                     sessions, kept {kept}"
                ),
                warning,
            ))
        }
        (Content::Inseparable { .. }, _) => Ok((format!("left {shown}"), None)),
    }
}

/// Rewrites a bag without the user's messages (or deletes it when they are all it holds).
fn erase_from_bag(
    inv: &Inventory,
    item: &Item,
) -> Result<(String, Option<String>), ChildDataError> {
    let shown = item.path.display();
    let reader = BagReader::open(&item.path)?;
    let ownership = Ownership::of(&reader);
    let Some(part) = bag_part_of(&reader, &ownership, &inv.user, &[]) else {
        return Ok((
            format!("left {shown}: it no longer holds messages of this user"),
            None,
        ));
    };
    if part.user_messages == part.total {
        drop(reader);
        delete(&item.path)?;
        let damaged = part.damage.as_ref().map_or(String::new(), |_| {
            format!(
                ", and {} unreadable bytes after them",
                part.unreadable_bytes
            )
        });
        return Ok((
            format!(
                "deleted {shown}: all its {} messages were this user's (sessions {}){damaged}",
                part.total,
                part.sessions.join(", ")
            ),
            None,
        ));
    }
    let k = ownership.user_index(inv.user.as_str());
    let keep = |i: usize| !ownership.is(i, k);
    let dir = item.path.parent().unwrap_or(Path::new("/"));
    let staging = tempfile::Builder::new()
        .prefix(STAGING_PREFIX)
        .tempdir_in(dir)
        .map_err(ChildDataError::io(dir))?;
    let staged = staging
        .path()
        .join(item.path.file_name().unwrap_or_default());
    let written = write_subset(&reader, &keep, &staged)?;
    let kept = part.total - part.user_messages;
    // The new bag must read back whole with exactly the messages kept before it replaces
    // the old one.
    let check = BagReader::open(&staged)?.strict()?;
    if written != kept || check.raw_messages().len() != kept {
        return Err(ChildDataError::Changed {
            path: item.path.clone(),
            what: format!(
                "{kept} messages to keep, {written} written, {} read back",
                check.raw_messages().len()
            ),
        });
    }
    drop(check);
    drop(reader);
    let warning = replace_with_file(&item.path, &staged)?;
    let mut line = format!(
        "rewrote {shown}: removed this user's {} messages (sessions {}), kept {kept}",
        part.user_messages,
        part.sessions.join(", ")
    );
    if !part.others.is_empty() {
        line.push_str(&format!(" of users {}", part.others.join(", ")));
    }
    if part.damage.is_some() {
        line.push_str(&format!(
            "; it was damaged: the {} unreadable bytes after the damage are gone",
            part.unreadable_bytes
        ));
    }
    Ok((line, warning))
}
