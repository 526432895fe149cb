//! The children the robot knows: every user id (a child's code, never a name) its stored
//! session files name, with how many sessions each played and when the last one was. Read
//! from the game manager's session files as they are (`sessions`), so a child whose files are
//! erased (`qt-therapy-data erase`) is off the list, and a code typed on the therapist page is
//! on it once a session of it starts. Bags are not read here: every session the game manager
//! plays has session files, and a bag is large.

use crate::error::StoredError;
use crate::find::{FileKind, walk};
use crate::sessions::read_sessions;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// One child on the list.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Child {
    pub user_id: String,
    /// Sessions started (finished, stopped, or cut off).
    pub sessions: usize,
    /// The latest time any of its session files names (ns since the epoch).
    pub last_ns: Option<i64>,
}

/// Every child the places' session files name, the most recent first.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ChildList {
    pub children: Vec<Child>,
    /// Places that do not exist (yet): no session was stored there.
    pub missing: Vec<PathBuf>,
    /// Files and directories that could not be read: a child may be missing from the list.
    pub problems: Vec<String>,
}

/// Reads the list from the session files under `places`.
pub fn children(places: &[PathBuf]) -> Result<ChildList, StoredError> {
    let (present, missing): (Vec<PathBuf>, Vec<PathBuf>) =
        places.iter().cloned().partition(|p| p.exists());
    let found = walk(&present)?;
    let paths: Vec<&Path> = found
        .files
        .iter()
        .filter(|f| f.kind == FileKind::SessionFile)
        .map(|f| f.path.as_path())
        .collect();
    let mut by_user: BTreeMap<String, Child> = BTreeMap::new();
    let mut problems: Vec<String> = found
        .unreadable
        .iter()
        .map(|(p, why)| format!("{}: {why}", p.display()))
        .collect();
    for s in read_sessions(&paths) {
        problems.extend(s.problems.iter().cloned());
        let Some(user) = s.user_id else { continue };
        let child = by_user.entry(user.clone()).or_insert(Child {
            user_id: user,
            sessions: 0,
            last_ns: None,
        });
        child.sessions += 1;
        child.last_ns = child.last_ns.max(s.last_ns);
    }
    let mut children: Vec<Child> = by_user.into_values().collect();
    children.sort_by(|a, b| b.last_ns.cmp(&a.last_ns).then(a.user_id.cmp(&b.user_id)));
    Ok(ChildList {
        children,
        missing,
        problems,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn summary(dir: &Path, session: &str, user: &str, ended_ns: i64) {
        std::fs::write(
            dir.join(format!("{session}.summary.json")),
            format!(
                "{{\"session_id\":\"{session}\",\"user_id\":\"{user}\",\"started_ns\":{},\
                 \"ended_ns\":{ended_ns}}}",
                ended_ns - 10
            ),
        )
        .expect("write");
    }

    #[test]
    fn every_user_the_session_files_name_once_the_most_recent_first() {
        let root = tempfile::tempdir().expect("temp dir");
        let (a, b) = (root.path().join("run-a"), root.path().join("run-b"));
        std::fs::create_dir_all(&a).expect("dir");
        std::fs::create_dir_all(&b).expect("dir");
        summary(&a, "s1", "child-7", 100);
        summary(&a, "s2", "child-8", 300);
        summary(&b, "s3", "child-7", 200);
        // A session cut off before its summary still counts, by its journal.
        std::fs::write(
            b.join("s4.journal"),
            "{\"entry\":\"started\",\"session_id\":\"s4\",\"user_id\":\"child-9\",\"at_ns\":50}\n",
        )
        .expect("write");
        let list =
            children(&[root.path().to_path_buf(), root.path().join("nowhere")]).expect("reads");
        let got: Vec<(&str, usize, Option<i64>)> = list
            .children
            .iter()
            .map(|c| (c.user_id.as_str(), c.sessions, c.last_ns))
            .collect();
        assert_eq!(
            got,
            [
                ("child-8", 1, Some(300)),
                ("child-7", 2, Some(200)),
                ("child-9", 1, Some(50))
            ]
        );
        assert_eq!(list.missing, [root.path().join("nowhere")]);
        assert!(list.problems.is_empty(), "{:?}", list.problems);
    }
}
