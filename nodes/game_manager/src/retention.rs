//! Retention: keeps the run directories under `retention_dir` (the service's
//! `/var/lib/qt-therapy/sessions/<run>/`: bag, session files, reports, node logs) within
//! `retention_budget_mb` and the disk above `disk_warning_free_mb`, by deleting the kinds in
//! `retention_removes` (bags, then reports, then logs by default), kind by kind, oldest run
//! first. Never deleted: session files (the record of what each child did: `child_data
//! erase` is the way to delete them), Q-tables and beliefs (they live outside the run
//! directories, and no file of theirs is of a removable kind), and the run directory this node
//! writes (its running session). The game manager owns it because it owns the running
//! session: it knows which run is in use and when a session may start.
//! [`plan`] is sans-IO (a listing in, the files to delete out); [`apply`] lists, plans and
//! deletes.

use std::path::{Path, PathBuf};

/// What retention may delete.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Removable {
    /// `*.mcap`, and what a recorder leaves unfinished (`*.mcap.partial`, `*.crashed-*`).
    Bags,
    /// `*.html` (the session reports).
    Reports,
    /// The run's `logs/` (node logs).
    Logs,
}

impl Removable {
    /// The kind a `retention_removes` entry names.
    pub fn parse(name: &str) -> Option<Removable> {
        match name {
            "bags" => Some(Removable::Bags),
            "reports" => Some(Removable::Reports),
            "logs" => Some(Removable::Logs),
            _ => None,
        }
    }

    /// The kind of a file at `relative` inside a run directory, if removable.
    fn of(relative: &Path) -> Option<Removable> {
        if relative.starts_with("logs") {
            return Some(Removable::Logs);
        }
        let name = relative.file_name()?.to_string_lossy();
        if name.ends_with(".mcap") || name.ends_with(".mcap.partial") || name.contains(".crashed-")
        {
            Some(Removable::Bags)
        } else if name.ends_with(".html") {
            Some(Removable::Reports)
        } else {
            None
        }
    }
}

/// One file under the retention directory: its run directory, its path and size.
#[derive(Debug, Clone, PartialEq)]
pub struct Listed {
    /// The run directory's name (they sort oldest first: `YYYYmmdd-HHMMSS`).
    pub run: String,
    pub path: PathBuf,
    /// Its path inside the run directory.
    pub relative: PathBuf,
    pub bytes: u64,
}

/// What to delete, in order, so the runs fit `budget` bytes and the disk has `want_free`
/// bytes free (`free` now): the removable kinds in `removes`' order, oldest run first within a
/// kind; never a file of the run `current`. The files it deletes and the bytes that frees.
pub fn plan(
    listing: &[Listed],
    current: Option<&str>,
    removes: &[Removable],
    budget: u64,
    free: u64,
    want_free: u64,
) -> (Vec<PathBuf>, u64) {
    let mut total: u64 = listing.iter().map(|l| l.bytes).sum();
    let mut free = free;
    let mut chosen = Vec::new();
    let mut freed = 0;
    let satisfied = |total: u64, free: u64| total <= budget && free >= want_free;
    for kind in removes {
        let mut candidates: Vec<&Listed> = listing
            .iter()
            .filter(|l| Some(l.run.as_str()) != current)
            .filter(|l| Removable::of(&l.relative) == Some(*kind))
            .collect();
        candidates.sort_by(|a, b| (&a.run, &a.relative).cmp(&(&b.run, &b.relative)));
        for l in candidates {
            if satisfied(total, free) {
                return (chosen, freed);
            }
            chosen.push(l.path.clone());
            total = total.saturating_sub(l.bytes);
            free = free.saturating_add(l.bytes);
            freed += l.bytes;
        }
    }
    (chosen, freed)
}

/// Every file under `root` (one level of run directories, each listed recursively).
pub fn list(root: &Path) -> std::io::Result<Vec<Listed>> {
    let mut out = Vec::new();
    for run in std::fs::read_dir(root)? {
        let run = run?;
        if !run.file_type()?.is_dir() {
            continue;
        }
        let name = run.file_name().to_string_lossy().into_owned();
        let mut stack = vec![run.path()];
        while let Some(dir) = stack.pop() {
            let Ok(entries) = std::fs::read_dir(&dir) else {
                continue;
            };
            for e in entries.filter_map(Result::ok) {
                let Ok(kind) = e.file_type() else { continue };
                let path = e.path();
                if kind.is_dir() {
                    stack.push(path);
                } else if kind.is_file() {
                    let bytes = e.metadata().map_or(0, |m| m.len());
                    let relative = path
                        .strip_prefix(run.path())
                        .map(Path::to_path_buf)
                        .unwrap_or_else(|_| path.clone());
                    out.push(Listed {
                        run: name.clone(),
                        path,
                        relative,
                        bytes,
                    });
                }
            }
        }
    }
    Ok(out)
}

/// Lists `root`, plans and deletes (durably: `atomic_file::remove_file`); `current` is this
/// node's sessions directory. Returns a line per file deleted, and one per failure.
pub fn apply(
    root: &Path,
    current: &Path,
    removes: &[Removable],
    budget: u64,
    want_free: u64,
) -> Vec<String> {
    let listing = match list(root) {
        Ok(l) => l,
        Err(e) => return vec![format!("retention: cannot list {}: {e}", root.display())],
    };
    let current_run = std::fs::canonicalize(current).ok().and_then(|c| {
        let root = std::fs::canonicalize(root).ok()?;
        let inside = c.strip_prefix(&root).ok()?;
        inside
            .components()
            .next()
            .map(|first| first.as_os_str().to_string_lossy().into_owned())
    });
    let free = atomic_file::disk_space(root).map_or(u64::MAX, |s| s.free);
    let (files, _) = plan(
        &listing,
        current_run.as_deref(),
        removes,
        budget,
        free,
        want_free,
    );
    let sizes: std::collections::BTreeMap<&Path, u64> = listing
        .iter()
        .map(|l| (l.path.as_path(), l.bytes))
        .collect();
    files
        .iter()
        .map(|f| match atomic_file::remove_file(f) {
            Ok(()) => format!(
                "retention: deleted {} ({} bytes) to keep {} within its budget and the disk \
                 above its warning",
                f.display(),
                sizes.get(f.as_path()).copied().unwrap_or(0),
                root.display()
            ),
            Err(e) => format!("retention: could not delete {}: {e}", f.display()),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(run: &str, relative: &str, bytes: u64) -> Listed {
        Listed {
            run: run.into(),
            path: PathBuf::from(format!("/s/{run}/{relative}")),
            relative: relative.into(),
            bytes,
        }
    }

    fn listing() -> Vec<Listed> {
        vec![
            file("20260301-090000", "session.mcap", 100),
            file("20260301-090000", "s-1.jsonl", 5),
            file("20260301-090000", "s-1.summary.json", 2),
            file("20260301-090000", "report-s-1.html", 30),
            file("20260301-090000", "logs/game_manager.log", 10),
            file("20260302-090000", "session.mcap", 200),
            file("20260302-090000", "s-2.journal", 3),
            file("20260303-090000", "session.mcap.partial", 400),
        ]
    }

    const ALL: [Removable; 3] = [Removable::Bags, Removable::Reports, Removable::Logs];

    #[test]
    fn the_oldest_bags_go_first_and_only_as_many_as_needed() {
        // 750 bytes, a budget of 600: the oldest bag (100) and the next (200) go.
        let (files, freed) = plan(&listing(), Some("20260303-090000"), &ALL, 600, 1000, 0);
        assert_eq!(
            files,
            [
                PathBuf::from("/s/20260301-090000/session.mcap"),
                PathBuf::from("/s/20260302-090000/session.mcap")
            ]
        );
        assert_eq!(freed, 300);
        // Within budget: nothing.
        assert!(plan(&listing(), None, &ALL, 750, 1000, 0).0.is_empty());
    }

    #[test]
    fn the_running_session_and_session_files_are_never_deleted() {
        // Nothing is enough: everything removable but the current run's goes, in kind order.
        let (files, freed) = plan(&listing(), Some("20260303-090000"), &ALL, 0, 0, 0);
        let names: Vec<String> = files.iter().map(|p| p.display().to_string()).collect();
        assert_eq!(
            names,
            [
                "/s/20260301-090000/session.mcap",
                "/s/20260302-090000/session.mcap",
                "/s/20260301-090000/report-s-1.html",
                "/s/20260301-090000/logs/game_manager.log",
            ]
        );
        assert_eq!(freed, 340);
        assert!(names.iter().all(|n| !n.contains("20260303")));
        assert!(names.iter().all(|n| !n.contains("json")));
    }

    #[test]
    fn low_free_space_deletes_within_the_budget_too() {
        // Within the budget, but 50 bytes free where 150 are wanted: the oldest bag goes.
        let (files, _) = plan(&listing(), None, &ALL, 10_000, 50, 150);
        assert_eq!(files, [PathBuf::from("/s/20260301-090000/session.mcap")]);
    }

    #[test]
    fn only_the_kinds_named_are_deleted() {
        let (files, _) = plan(&listing(), None, &[Removable::Logs], 0, 0, 0);
        assert_eq!(
            files,
            [PathBuf::from("/s/20260301-090000/logs/game_manager.log")]
        );
        assert_eq!(Removable::parse("bags"), Some(Removable::Bags));
        assert_eq!(Removable::parse("q_tables"), None);
    }

    #[test]
    fn apply_deletes_old_bags_on_disk_and_keeps_the_rest() {
        let root = tempfile::tempdir().expect("temp dir");
        let write = |rel: &str, n: usize| {
            let p = root.path().join(rel);
            std::fs::create_dir_all(p.parent().expect("parent")).expect("dir");
            std::fs::write(&p, vec![b'x'; n]).expect("write");
        };
        write("20260301-090000/session.mcap", 1000);
        write("20260301-090000/s-1.jsonl", 10);
        write("20260302-090000/session.mcap", 1000);
        write("20260303-090000/session.mcap.partial", 1000);
        let lines = apply(
            root.path(),
            &root.path().join("20260303-090000"),
            &ALL,
            2500,
            0,
        );
        assert_eq!(lines.len(), 1, "{lines:?}");
        assert!(!root.path().join("20260301-090000/session.mcap").exists());
        assert!(root.path().join("20260301-090000/s-1.jsonl").exists());
        assert!(root.path().join("20260302-090000/session.mcap").exists());
        assert!(
            root.path()
                .join("20260303-090000/session.mcap.partial")
                .exists()
        );
    }
}
