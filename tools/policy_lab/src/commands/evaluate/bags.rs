//! The bags `evaluate` reads: every .mcap under the paths given, and their decisions, results
//! and game states as logged sessions, with the bags that could not be read or were damaged.

use anyhow::{Context, bail};
use policy_lab::off_policy::recorded::{LoggedSessions, logged_sessions};
use std::path::{Path, PathBuf};

/// Every .mcap under the given paths, sorted, each once.
pub(super) fn bag_files(paths: &[PathBuf]) -> anyhow::Result<Vec<PathBuf>> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) -> anyhow::Result<()> {
        let entries =
            std::fs::read_dir(dir).with_context(|| format!("reading folder {}", dir.display()))?;
        for entry in entries {
            let path = entry
                .with_context(|| format!("reading folder {}", dir.display()))?
                .path();
            if path.is_dir() {
                walk(&path, out)?;
            } else if path.extension().is_some_and(|e| e == "mcap") {
                out.push(path);
            }
        }
        Ok(())
    }
    let mut out = Vec::new();
    for p in paths {
        if p.is_dir() {
            walk(p, &mut out)?;
        } else if p.exists() {
            out.push(p.clone());
        } else {
            bail!("{}: no such bag or folder", p.display());
        }
    }
    out.sort();
    out.dedup();
    Ok(out)
}

/// What the bags gave.
#[derive(Debug, Default, serde::Serialize)]
pub(super) struct BagsRead {
    pub read: usize,
    /// Bags that could not be read at all: (bag, why).
    pub skipped: Vec<(PathBuf, String)>,
    /// Bags read only up to damage, or never closed: (bag, what is wrong).
    pub damaged: Vec<(PathBuf, String)>,
}

/// The decisions, results and game states of every readable bag, taken through the suite's
/// rule for what arrives twice (`session_log`): a message delivered again is taken once, in a
/// bag or across bags. A bag that cannot be read, or holds a message that contradicts one
/// taken before (same identity, other content), is named and skipped; a damaged one is read
/// up to the damage, and the damage named.
pub(super) fn read_bags(files: &[PathBuf]) -> (LoggedSessions, BagsRead) {
    let mut rule = session_log::SessionReader::new();
    let mut messages = session_log::Messages::default();
    let mut bags = BagsRead::default();
    for f in files {
        let read = bag_file::BagReader::open(f)
            .map_err(session_log::SessionLogError::from)
            .and_then(|reader| rule.read_bag(&reader));
        match read {
            Ok(log) => {
                let (d, r) = (log.messages.decisions.len(), log.messages.results.len());
                let damage = match (&log.damage, log.complete) {
                    (Some(e), _) => Some(format!(
                        "{e}; read up to it ({d} decisions, {r} results), nothing after"
                    )),
                    (None, false) => Some(format!(
                        "{}: not closed cleanly (no footer: the recording was cut off); read to \
                         its last whole record ({d} decisions, {r} results)",
                        log.source
                    )),
                    (None, true) => None,
                };
                if let Some(repeats) = log.repeats_warning() {
                    tracing::info!("{repeats}");
                }
                messages.extend(log.messages);
                bags.read += 1;
                if let Some(why) = damage {
                    bags.damaged.push((f.clone(), why));
                }
            }
            Err(e) => bags.skipped.push((f.clone(), e.to_string())),
        }
    }
    (logged_sessions(&messages), bags)
}
