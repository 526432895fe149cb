//! What a therapist page asks of the stored sessions: the children the robot knows and one
//! child's progress, read from the sessions root the parameters name (`sessions_root`, where
//! the game manager's runs are) with `child_sessions`, never from a store of the bridge's own.
//! The core only decides that a logged-in page may ask (`Output::Read`); the shell answers
//! here on a blocking thread, so reading files never holds up the tablets.

use crate::io::StoredRead;
use crate::protocol::{ChildView, ServerMessage};
use child_sessions::{Language, Progress, children, progress_fragment};
use std::path::Path;

/// The answer to `read`, from what is stored under `root` now (`now_ns`: the report's date).
pub fn answer(read: &StoredRead, root: &Path, language: Language, now_ns: i64) -> ServerMessage {
    let places = [root.to_path_buf()];
    match read {
        StoredRead::Children => match children(&places) {
            Ok(list) => {
                // Not shown on the page (a torn line of a power cut would stay there for
                // good); a child missing from the list is explained in the log.
                if let Some(first) = list.problems.first() {
                    tracing::warn!(
                        "the list of children: {} stored file(s) not read whole, the first: {first}",
                        list.problems.len()
                    );
                }
                ServerMessage::Children {
                    children: list.children.iter().map(ChildView::of).collect(),
                    missing: list.missing.first().map(|p| p.display().to_string()),
                    problems: list.problems,
                }
            }
            Err(e) => ServerMessage::Rejected {
                reason: format!("the list of children: {e}"),
            },
        },
        StoredRead::Progress(user) => {
            // A root not made yet (no session stored on a fresh install) holds nothing.
            let searched: &[_] = if root.exists() { &places } else { &[] };
            match Progress::build(user, searched) {
                Ok(mut progress) => {
                    progress.places = places.to_vec();
                    ServerMessage::Progress {
                        user_id: user.as_str().to_string(),
                        sessions: progress.sessions.len(),
                        // Inside the therapist page, under its level-one heading.
                        html: progress_fragment(&progress, language, 2, now_ns),
                    }
                }
                Err(e) => ServerMessage::Rejected {
                    reason: format!("the progress of {:?}: {e}", user.as_str()),
                },
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use child_sessions::UserId;

    #[test]
    fn a_root_not_made_yet_holds_no_child_and_no_session() {
        let dir = tempfile::tempdir().expect("temp dir");
        let root = dir.path().join("sessions");
        match answer(&StoredRead::Children, &root, Language::En, 0) {
            ServerMessage::Children {
                children,
                missing,
                problems,
            } => {
                assert!(children.is_empty() && problems.is_empty());
                assert_eq!(missing, Some(root.display().to_string()));
            }
            other => panic!("{other:?}"),
        }
        let user = UserId::new("child-7").expect("id");
        match answer(&StoredRead::Progress(user), &root, Language::De, 0) {
            ServerMessage::Progress { sessions, html, .. } => {
                assert_eq!(sessions, 0);
                assert!(html.contains("<h2>Verlauf von child-7</h2>"), "{html}");
                assert!(html.contains("noch keine Sitzung"), "{html}");
            }
            other => panic!("{other:?}"),
        }
    }
}
