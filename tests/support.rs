//! Helpers for the cross-node tests: where the workspace and its binaries are, running a
//! script inside a private loopback-only network namespace (DDS multicasts; nothing may leave
//! the machine), and deadlines on every wait.

use std::path::PathBuf;

pub use loopback_netns::{can_make_network_namespace, run_in_loopback_netns, workspace_root};

/// A binary of another package of the workspace, built by `cargo build --workspace --bins`
/// (the README's test command does that first). Panics with that advice when it is missing.
pub fn workspace_bin(name: &str) -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root().join("target"));
    let profile = if cfg!(debug_assertions) {
        "debug"
    } else {
        "release"
    };
    let path = target.join(profile).join(name);
    assert!(
        path.exists(),
        "{} is not built: run `cargo build --workspace --bins` first (the README's test command does)",
        path.display()
    );
    path
}

/// The JSON lines of `text` (others ignored).
pub fn json_lines(text: &str) -> Vec<serde_json::Value> {
    text.lines()
        .filter_map(|l| serde_json::from_str(l.trim()).ok())
        .collect()
}

/// A whole session's bag as both main-job tests (over DDS and in one process) read it: its
/// results, seconds of engagement and decisions.
pub struct SessionBag {
    pub results: Vec<qt_therapy_msgs::SequenceResult>,
    pub engagement: Vec<qt_therapy_msgs::ExpectedEngagement>,
    pub decisions: Vec<qt_therapy_msgs::Decision>,
}

/// Reads `bag` and checks what every whole simulated session's bag holds: the ten results of
/// one session in order, each sequence as long as its level says, at least 8 answered (the
/// simulated child answers), at least 10 seconds with a face (the classifier saw it), and no
/// feedback before the first sequence. `context` ends each failure's message.
pub fn whole_session_bag(bag: &std::path::Path, context: &str) -> SessionBag {
    whole_session_in_bag(bag, None, context)
}

/// The same for session `wanted` of a bag that holds several (a day's run on the robot); None:
/// the bag holds one session. The seconds with a face are then the seconds of engagement of the
/// session's results (ExpectedEngagement names no session), and `engagement` holds the whole
/// bag's.
pub fn whole_session_in_bag(
    bag: &std::path::Path,
    wanted: Option<&str>,
    context: &str,
) -> SessionBag {
    use qt_therapy_msgs::topics::{DECISION, EXPECTED_ENGAGEMENT, SEQUENCE_RESULT};
    let reader = bag_file::BagReader::open(bag).expect("the recorder wrote a readable bag");
    let results: Vec<qt_therapy_msgs::SequenceResult> = reader
        .messages(SEQUENCE_RESULT.name)
        .expect("results")
        .into_iter()
        .map(|s| s.message)
        .filter(|r: &qt_therapy_msgs::SequenceResult| wanted.is_none_or(|id| r.session_id == id))
        .collect();
    assert_eq!(
        results.iter().map(|r| r.sequence_index).collect::<Vec<_>>(),
        (1..=10).collect::<Vec<u8>>(),
        "{context}"
    );
    let session = &results[0].session_id;
    assert!(
        results
            .iter()
            .all(|r| &r.session_id == session && r.sequence.len() == 2 * usize::from(r.level) + 1)
    );
    assert!(
        results.iter().filter(|r| !r.timed_out).count() >= 8,
        "{context}"
    );
    let engagement: Vec<qt_therapy_msgs::ExpectedEngagement> = reader
        .messages(EXPECTED_ENGAGEMENT.name)
        .expect("engagement")
        .into_iter()
        .map(|s| s.message)
        .collect();
    let with_faces = match wanted {
        None => engagement.iter().filter(|e| e.has_faces).count(),
        Some(_) => results.iter().map(|r| r.engagement_per_second.len()).sum(),
    };
    assert!(
        with_faces >= 10,
        "{with_faces} seconds with faces; {context}"
    );
    let decisions: Vec<qt_therapy_msgs::Decision> = reader
        .messages(DECISION.name)
        .expect("decisions")
        .into_iter()
        .map(|s| s.message)
        .filter(|d: &qt_therapy_msgs::Decision| wanted.is_none_or(|id| d.session_id == id))
        .collect();
    assert!(
        decisions.iter().all(|d| d.step != 1 || d.feedback == 0),
        "no feedback on the first sequence"
    );
    SessionBag {
        results,
        engagement,
        decisions,
    }
}

/// Reliable topics with one publisher in the main job and a history deep enough (100) to hold
/// what is published while a reader is stopped or a clock is stepped: every sequence number
/// between the first and the last recorded must be in the bag once. The keep-last-1 topics
/// (GameState, TabletTask, UserModelInfo) keep only their newest sample by design.
pub const COUNTED_TOPICS: [&str; 7] = [
    qt_therapy_msgs::topics::SEQUENCE_RESULT.name,
    qt_therapy_msgs::topics::TABLET_ANSWER.name,
    qt_therapy_msgs::topics::DECISION.name,
    qt_therapy_msgs::topics::EXPECTED_ENGAGEMENT.name,
    qt_therapy_msgs::topics::ROBOT_SPEECH.name,
    qt_therapy_msgs::topics::ROBOT_EMOTION.name,
    qt_therapy_msgs::topics::ROBOT_GESTURE.name,
];

/// Lost (gaps) and duplicated sequence numbers of one publisher.
pub fn gaps_and_repeats(numbers: &[u64]) -> (u64, u64) {
    let distinct: std::collections::BTreeSet<u64> = numbers.iter().copied().collect();
    let span = match (distinct.first(), distinct.last()) {
        (Some(a), Some(b)) => b - a + 1,
        _ => 0,
    };
    (
        span - distinct.len() as u64,
        (numbers.len() - distinct.len()) as u64,
    )
}
