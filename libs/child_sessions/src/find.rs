//! Walks the places given (`--data` directories and extra paths) for the files the suite
//! writes, told apart by name: bags (`*.mcap`, a recording still open or killed:
//! `*.mcap.partial`), the game manager's session files (`*.jsonl`, `*.journal`,
//! `*.summary.json`), JSON files (Q-tables, fitted user models: told apart by their `format`
//! field later), CSV (interaction records), HTML (session reports), `*.log` (the launcher's node
//! logs). Symbolic links are not followed; a directory that cannot be read is reported, since
//! then nobody can say what it holds.

use crate::error::StoredError;
use std::path::{Path, PathBuf};

/// What a file is, by its name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FileKind {
    Bag,
    SessionFile,
    Json,
    Csv,
    Html,
    Log,
    Other,
}

pub fn kind_of(path: &Path) -> FileKind {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let ends = |s: &str| name.ends_with(s);
    if ends(".mcap") || ends(".mcap.partial") {
        FileKind::Bag
    } else if ends(".summary.json") || ends(".jsonl") || ends(".journal") {
        FileKind::SessionFile
    } else if ends(".json") {
        FileKind::Json
    } else if ends(".csv") {
        FileKind::Csv
    } else if ends(".html") || ends(".htm") {
        FileKind::Html
    } else if ends(".log") {
        FileKind::Log
    } else {
        FileKind::Other
    }
}

/// A file found under one of the places searched.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Found {
    pub path: PathBuf,
    /// Which place (index into the places searched) it was found under.
    pub place: usize,
    /// Its path below that place (its file name for a place that is a file).
    pub rel: PathBuf,
    pub kind: FileKind,
}

/// Everything found, and the directories that could not be read.
#[derive(Debug, Default)]
pub struct Walk {
    pub places: Vec<PathBuf>,
    pub files: Vec<Found>,
    pub unreadable: Vec<(PathBuf, String)>,
}

/// Prefix of this program's own staging directories, never searched.
pub const STAGING_PREFIX: &str = ".child_data-";

/// Walks each place (made absolute and canonical, so paths compare with processes' paths);
/// a place that does not exist is an error, one that cannot be read is reported.
pub fn walk(places: &[PathBuf]) -> Result<Walk, StoredError> {
    let mut walk = Walk::default();
    for place in places {
        let canonical = match std::fs::canonicalize(place) {
            Ok(p) => p,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(StoredError::Missing {
                    path: place.clone(),
                });
            }
            Err(e) => return Err(StoredError::io(place)(e)),
        };
        if walk.places.contains(&canonical) {
            continue;
        }
        let index = walk.places.len();
        walk.places.push(canonical.clone());
        let meta = std::fs::symlink_metadata(&canonical).map_err(StoredError::io(place))?;
        if meta.is_file() {
            walk.files.push(Found {
                rel: PathBuf::from(canonical.file_name().unwrap_or_default()),
                kind: kind_of(&canonical),
                path: canonical,
                place: index,
            });
            continue;
        }
        let mut pending = vec![canonical.clone()];
        while let Some(dir) = pending.pop() {
            let entries = match std::fs::read_dir(&dir) {
                Ok(e) => e,
                Err(e) => {
                    walk.unreadable.push((dir, e.to_string()));
                    continue;
                }
            };
            for entry in entries {
                let entry = match entry {
                    Ok(e) => e,
                    Err(e) => {
                        walk.unreadable.push((dir.clone(), e.to_string()));
                        continue;
                    }
                };
                let path = entry.path();
                if entry
                    .file_name()
                    .to_string_lossy()
                    .starts_with(STAGING_PREFIX)
                {
                    continue;
                }
                match entry.file_type() {
                    Ok(t) if t.is_dir() => pending.push(path),
                    Ok(t) if t.is_file() => {
                        let rel = path.strip_prefix(&canonical).unwrap_or(&path).to_path_buf();
                        walk.files.push(Found {
                            kind: kind_of(&path),
                            path,
                            place: index,
                            rel,
                        });
                    }
                    // Links, sockets, devices: not files the suite writes.
                    Ok(_) => {}
                    Err(e) => walk.unreadable.push((path, e.to_string())),
                }
            }
        }
    }
    // A file under two places (a directory and a file in it) counts once.
    walk.files
        .sort_by(|a, b| a.path.cmp(&b.path).then(a.place.cmp(&b.place)));
    walk.files.dedup_by(|a, b| a.path == b.path);
    Ok(walk)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn files_are_told_apart_by_name() {
        for (name, kind) in [
            ("session.mcap", FileKind::Bag),
            ("session.mcap.partial", FileKind::Bag),
            ("tablet-1.jsonl", FileKind::SessionFile),
            ("tablet-1.journal", FileKind::SessionFile),
            ("tablet-1.summary.json", FileKind::SessionFile),
            ("user_a.json", FileKind::Json),
            ("records.CSV", FileKind::Csv),
            ("report.html", FileKind::Html),
            ("game_manager.log", FileKind::Log),
            ("notes.txt", FileKind::Other),
        ] {
            assert_eq!(kind_of(Path::new(name)), kind, "{name}");
        }
    }

    #[test]
    fn a_walk_finds_files_below_each_place_once_and_names_a_missing_one() {
        let dir = tempfile::tempdir().expect("temp dir");
        let run = dir.path().join("sessions/run-1");
        std::fs::create_dir_all(run.join("logs")).expect("dirs");
        std::fs::create_dir_all(dir.path().join(format!("{STAGING_PREFIX}1"))).expect("dir");
        std::fs::write(run.join("session.mcap"), b"x").expect("write");
        std::fs::write(run.join("logs/game_manager.log"), b"x").expect("write");
        std::fs::write(dir.path().join(format!("{STAGING_PREFIX}1/a.mcap")), b"x").expect("w");
        let places = vec![dir.path().to_path_buf(), run.join("session.mcap")];
        let w = walk(&places).expect("walks");
        let rels: Vec<String> = w
            .files
            .iter()
            .map(|f| f.rel.display().to_string())
            .collect();
        assert_eq!(
            rels,
            [
                "sessions/run-1/logs/game_manager.log",
                "sessions/run-1/session.mcap"
            ]
        );
        assert!(w.unreadable.is_empty());
        let e = walk(&[dir.path().join("nowhere")]).expect_err("missing");
        assert!(e.to_string().contains("nowhere does not exist"), "{e}");
    }
}
