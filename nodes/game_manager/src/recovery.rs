//! Taking over a session a killed game manager left unfinished, sans-IO: the text of its
//! session file (`<stem>.jsonl`, one record per scored sequence) and journal (`<stem>.journal`:
//! start, therapist commands carried out, tablet tasks) in, what the core needs to go on out
//! ([`RecoveredSession`], fed to `GameManager::recover`). Damage never stops it: every whole
//! line is used, every damaged one is named in `damage`, and the files are never rewritten.

use crate::session_file::{JournalCommand, JournalEntry, SequenceRecord};
use qt_therapy_msgs::Validate;
use sequence_game::{Action, Feedback, Level};
use serde::de::DeserializeOwned;
use std::collections::BTreeMap;

/// An unfinished session, as its files tell it.
#[derive(Debug, Clone, PartialEq)]
pub struct RecoveredSession {
    /// File stem of the session's files, to go on appending to them.
    pub stem: String,
    pub session_id: String,
    pub user_id: String,
    pub user_model_cluster: i32,
    pub started_ns: i64,
    /// The scored sequences, by sequence index, each once.
    pub records: Vec<SequenceRecord>,
    /// Highest therapist command id carried out (START included): never carried out again.
    pub last_command_id: u64,
    /// Highest tablet task id possibly sent; the next task gets a higher one.
    pub last_task_id: u32,
    /// (sequence index, action) of an override the therapist set and no sequence used yet.
    pub pending_override: Option<(u8, Action)>,
    /// Message time of the last thing the files record.
    pub last_activity_ns: i64,
    /// Each damaged, skipped or doubtful line, named with its file and line number.
    pub damage: Vec<String>,
}

impl RecoveredSession {
    /// Index of the next sequence to play (1-based; above the last scored one).
    pub fn next_index(&self) -> u8 {
        self.records
            .last()
            .map_or(1, |r| r.result.sequence_index.saturating_add(1))
    }
}

/// Most damage lines named one by one.
const MAX_DAMAGE_NAMED: usize = 50;

/// Lines of one file that parsed, with their 1-based numbers, and what did not.
struct Lines<T> {
    items: Vec<(usize, T)>,
    damage: Vec<String>,
}

fn parse_lines<T: DeserializeOwned>(file: &str, text: &str) -> Lines<T> {
    let mut lines = Lines {
        items: Vec::new(),
        damage: Vec::new(),
    };
    let ended = text.is_empty() || text.ends_with('\n');
    let parts: Vec<&str> = text.split('\n').collect();
    for (i, line) in parts.iter().enumerate() {
        let n = i + 1;
        let unended = i + 1 == parts.len() && !ended;
        if line.trim().is_empty() {
            continue;
        }
        match serde_json::from_str::<T>(line) {
            Ok(v) => {
                if unended {
                    lines.damage.push(format!(
                        "{file} line {n}: no newline at its end, but whole: used"
                    ));
                }
                lines.items.push((n, v));
            }
            Err(_) if unended => lines.damage.push(format!(
                "{file} line {n}: torn ({} bytes without a newline, cut by the crash): not used",
                line.len()
            )),
            Err(e) => lines
                .damage
                .push(format!("{file} line {n}: not a valid line ({e}): not used")),
        }
    }
    lines
}

/// What the files of `stem` tell. Err (with why) only when they do not name a session at all.
pub fn recover_session(
    stem: &str,
    records_text: &str,
    journal_text: &str,
) -> Result<RecoveredSession, String> {
    let records_file = format!("{stem}.jsonl");
    let journal_file = format!("{stem}.journal");
    let records = parse_lines::<SequenceRecord>(&records_file, records_text);
    let journal = parse_lines::<JournalEntry>(&journal_file, journal_text);
    let mut damage = records.damage;
    damage.extend(journal.damage);

    let mut start = None;
    for (n, e) in &journal.items {
        if let JournalEntry::Started {
            session_id,
            user_id,
            user_model_cluster,
            command_id,
            at_ns,
        } = e
        {
            match check_start(session_id, user_id, *user_model_cluster) {
                Ok(()) => {
                    start = Some((
                        session_id.clone(),
                        user_id.clone(),
                        *user_model_cluster,
                        *command_id,
                        *at_ns,
                    ));
                    break;
                }
                Err(why) => damage.push(format!("{journal_file} line {n}: {why}: not used")),
            }
        }
    }
    let first_record = records
        .items
        .iter()
        .find(|(_, r)| r.result.validate().is_ok());
    let session_id = match (&start, first_record) {
        (Some((id, ..)), _) => id.clone(),
        (None, Some((_, r))) => {
            damage.push(format!(
                "{journal_file}: no start entry; the session is taken from {records_file}"
            ));
            r.result.session_id.clone()
        }
        (None, None) => {
            return Err(format!(
                "neither {journal_file} nor {records_file} names a session"
            ));
        }
    };

    // The scored sequences, by index: the first whole record of each index counts.
    let mut by_index: BTreeMap<u8, SequenceRecord> = BTreeMap::new();
    for (n, r) in records.items {
        let at = format!("{records_file} line {n}");
        if r.result.session_id != session_id {
            damage.push(format!(
                "{at}: for session {:?}, not {session_id:?}: not used",
                r.result.session_id
            ));
            continue;
        }
        if let Err(e) = r.result.validate() {
            damage.push(format!("{at}: {e}: not used"));
            continue;
        }
        let index = r.result.sequence_index;
        if by_index.contains_key(&index) {
            damage.push(format!("{at}: sequence {index} again: not used"));
            continue;
        }
        by_index.insert(index, r);
    }
    let records: Vec<SequenceRecord> = by_index.into_values().collect();
    let mut expected = 1u8;
    for r in &records {
        let index = r.result.sequence_index;
        if index > expected {
            let missing = if index - expected == 1 {
                format!("sequence {expected} is")
            } else {
                format!("sequences {expected}..{} are", index - 1)
            };
            damage.push(format!(
                "{records_file}: {missing} missing (a damaged line?); its result is lost"
            ));
        }
        expected = index.saturating_add(1);
    }
    let max_index = records.last().map_or(0, |r| r.result.sequence_index);

    let (user_id, user_model_cluster, mut last_command_id, started_ns) =
        match (start, records.first()) {
            (Some((_, user, cluster, command_id, at)), _) => (user, cluster, command_id, at),
            (None, Some(r)) => (
                r.result.user_id.clone(),
                r.result.user_model_cluster,
                0,
                r.talk_start_ns,
            ),
            (None, None) => return Err(format!("{records_file}: no usable record")),
        };
    let mut last_task_id = u32::from(max_index);
    let mut pending_override = None;
    let mut last_activity_ns = started_ns;
    for (n, e) in &journal.items {
        if e.session_id() != session_id {
            damage.push(format!(
                "{journal_file} line {n}: for session {:?}, not {session_id:?}: not used",
                e.session_id()
            ));
            continue;
        }
        last_activity_ns = last_activity_ns.max(e.at_ns());
        match e {
            JournalEntry::Command {
                command_id,
                command,
                level,
                feedback,
                sequence_index,
                ..
            } => {
                last_command_id = last_command_id.max(*command_id);
                let action = match (command, level, feedback) {
                    (JournalCommand::OverrideLevel, Some(l), _) => {
                        Level::new((*l).into()).ok().map(Action::SetLevel)
                    }
                    (JournalCommand::OverrideFeedback, _, Some(f)) => {
                        match Feedback::new((*f).into()) {
                            Ok(Feedback::Encouraging) => Some(Action::Encourage),
                            Ok(Feedback::Challenging) => Some(Action::Challenge),
                            _ => None,
                        }
                    }
                    _ => None,
                };
                if let (Some(action), Some(index)) = (action, sequence_index) {
                    // One override slot, as in the core: the last one set counts.
                    pending_override = Some((*index, action));
                }
            }
            JournalEntry::Task { task_id, .. } => last_task_id = last_task_id.max(*task_id),
            JournalEntry::Started { command_id, .. } => {
                last_command_id = last_command_id.max(*command_id)
            }
            JournalEntry::Recovered { .. } => {}
        }
    }
    // Within one run a task id is its sequence index: the interrupted sequence's task may
    // have gone out before the crash even if the journal (older files have none) lacks it.
    last_task_id = last_task_id.max(u32::from(max_index) + 1);
    let pending_override = pending_override.filter(|(index, _)| *index > max_index);
    for r in &records {
        last_activity_ns = last_activity_ns.max(r.answered_ns);
    }
    // A file of garbage must not flood the log and the journal: name the first ones.
    if damage.len() > MAX_DAMAGE_NAMED {
        let more = damage.len() - (MAX_DAMAGE_NAMED - 1);
        damage.truncate(MAX_DAMAGE_NAMED - 1);
        damage.push(format!("... and {more} more damaged or doubtful lines"));
    }
    Ok(RecoveredSession {
        stem: stem.to_string(),
        session_id,
        user_id,
        user_model_cluster,
        started_ns,
        records,
        last_command_id,
        last_task_id,
        pending_override,
        last_activity_ns,
        damage,
    })
}

/// A start entry holds what its START command held: checked as that command is.
fn check_start(session_id: &str, user_id: &str, cluster: i32) -> Result<(), String> {
    qt_therapy_msgs::TherapistCommand {
        command: qt_therapy_msgs::TherapistCommand::START,
        session_id: session_id.to_string(),
        user_id: user_id.to_string(),
        user_model_cluster: cluster,
        ..Default::default()
    }
    .validate()
    .map_err(|e| format!("start entry not valid as a START: {e}"))
}

/// Which unfinished session a start-up at `now_ns` takes over: the one with the latest
/// activity, if no older than `max_age_s` (0: none). Returns it and a line for each session
/// left as it is.
pub fn choose(
    mut candidates: Vec<RecoveredSession>,
    now_ns: i64,
    max_age_s: f64,
) -> (Option<RecoveredSession>, Vec<String>) {
    candidates.sort_by_key(|c| std::cmp::Reverse(c.last_activity_ns));
    let mut chosen = None;
    let mut left = Vec::new();
    for c in candidates {
        let age_s = (now_ns - c.last_activity_ns) as f64 * 1e-9;
        let recent = max_age_s > 0.0 && age_s <= max_age_s;
        if chosen.is_none() && recent {
            chosen = Some(c);
        } else {
            let why = if recent {
                "a newer unfinished session is taken over".to_string()
            } else {
                format!("last active {age_s:.0} s ago (recovery_max_age_s {max_age_s})")
            };
            left.push(format!(
                "unfinished session {:?} ({}.*, {} sequences) left as it is: {why}",
                c.session_id,
                c.stem,
                c.records.len()
            ));
        }
    }
    (chosen, left)
}
