//! Whose each message of a bag is, and bags made of some of another bag's messages.
//!
//! A bag of a run holds every session played in it, so messages are given to users thus
//! (sans-IO, over a read bag):
//! 1. a message that carries a user id (`GameState`, `SequenceResult`, a START
//!    `TherapistCommand`) is that user's;
//! 2. one that carries a session id (those three, `Decision`, `ActionProposal`, `TabletTask`,
//!    `TabletAnswer`; a `GameState` between sessions its `command_session_id`) is the user's of
//!    that session, as the messages of rule 1 name it;
//! 3. any other (faces, engagement, heartbeats, the robot's words, ROS4HRI) is the user's of
//!    the session whose time it was logged in: the bag's time is cut where the `GameState`'s
//!    session id changes to a new one, the first session's stretch reaching back to the bag's
//!    start and each one lasting until the next session starts (the goodbye, the idle robot
//!    after it).
//!
//! Rules 1 and 2 go first, so another child's START or a late answer of theirs logged in this
//! child's stretch stays theirs.

use bag_file::{BagReader, BagWriter, Compression, Stamp, WriterOptions, cdr};
use qt_therapy_msgs::{
    ActionProposal, Decision, GameState, MessageDefinition, SequenceResult, TabletAnswer,
    TabletTask, TherapistCommand,
};
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// The user and session fields of one message, where its type has them.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
struct Ids {
    user: String,
    session: String,
    /// A `GameState`'s own session id (the one that cuts the bag's time).
    state_session: Option<String>,
}

fn decode<M: MessageDefinition>(data: &[u8]) -> Result<M, String> {
    cdr::decode::<M>(data).map_err(|e| e.to_string())
}

/// The ids a message of type `type_name` carries; None for a type that carries none.
fn ids_of(type_name: &str, data: &[u8]) -> Option<Result<Ids, String>> {
    let ids = |user: &str, session: &str| Ids {
        user: user.to_string(),
        session: session.to_string(),
        state_session: None,
    };
    let r = match type_name.strip_prefix("qt_therapy_msgs/msg/")? {
        "GameState" => decode::<GameState>(data).map(|m| {
            let session = if m.session_id.is_empty() {
                &m.command_session_id
            } else {
                &m.session_id
            };
            Ids {
                state_session: Some(m.session_id.clone()),
                ..ids(&m.user_id, session)
            }
        }),
        "SequenceResult" => decode::<SequenceResult>(data).map(|m| ids(&m.user_id, &m.session_id)),
        "TherapistCommand" => {
            decode::<TherapistCommand>(data).map(|m| ids(&m.user_id, &m.session_id))
        }
        "Decision" => decode::<Decision>(data).map(|m| ids("", &m.session_id)),
        "ActionProposal" => decode::<ActionProposal>(data).map(|m| ids("", &m.session_id)),
        "TabletTask" => decode::<TabletTask>(data).map(|m| ids("", &m.session_id)),
        "TabletAnswer" => decode::<TabletAnswer>(data).map(|m| ids("", &m.session_id)),
        _ => return None,
    };
    Some(r)
}

/// One session's stretch of a bag.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BagSession {
    pub session_id: String,
    /// None when no message of the bag names the session's user.
    pub user: Option<String>,
    /// Log time of the `GameState` that began its stretch (ns since the epoch).
    pub starts: u64,
}

/// Whose each message of a bag is.
#[derive(Debug, Clone, Default)]
pub struct Ownership {
    /// Per message, in the reader's (log-time) order: an index into `users`, or None.
    pub owners: Vec<Option<usize>>,
    pub users: Vec<String>,
    /// The sessions' stretches, in time order.
    pub sessions: Vec<BagSession>,
    /// Messages that should carry ids and did not decode (they went by time instead).
    pub warnings: Vec<String>,
}

impl Ownership {
    /// Gives every message of `reader` its user (see the module's rules).
    pub fn of(reader: &BagReader) -> Ownership {
        let messages = reader.raw_messages();
        let mut warnings = Vec::new();
        let ids: Vec<Option<Ids>> = messages
            .iter()
            .map(|m| {
                let c = reader.channel(m.channel_id)?;
                match ids_of(c.type_name(), &m.data)? {
                    Ok(ids) => Some(ids),
                    Err(e) => {
                        if warnings.len() < 5 {
                            warnings.push(format!(
                                "a {} message on {} (log time {} ns) does not decode ({e}); \
                                 it goes by its time",
                                c.type_name(),
                                c.topic,
                                m.log_time
                            ));
                        }
                        None
                    }
                }
            })
            .collect();
        // Each session's user, from the messages that name both.
        let mut session_user: BTreeMap<String, String> = BTreeMap::new();
        for i in ids.iter().flatten() {
            if !i.user.is_empty() && !i.session.is_empty() {
                session_user
                    .entry(i.session.clone())
                    .or_insert_with(|| i.user.clone());
            }
        }
        // The stretches: a new one where the game state's session id changes to another.
        let mut sessions: Vec<BagSession> = Vec::new();
        let mut window: Vec<Option<usize>> = Vec::with_capacity(messages.len());
        for (m, i) in messages.iter().zip(&ids) {
            if let Some(Some(s)) = i.as_ref().map(|i| i.state_session.as_ref())
                && !s.is_empty()
                && sessions.last().is_none_or(|last| last.session_id != *s)
            {
                sessions.push(BagSession {
                    session_id: s.clone(),
                    user: session_user.get(s).cloned(),
                    starts: m.log_time,
                });
            }
            window.push(sessions.len().checked_sub(1));
        }
        let mut users: Vec<String> = Vec::new();
        let mut index = |u: &str| match users.iter().position(|x| x == u) {
            Some(k) => k,
            None => {
                users.push(u.to_string());
                users.len() - 1
            }
        };
        let mut owners = Vec::with_capacity(messages.len());
        for (k, i) in ids.iter().enumerate() {
            let by_ids = i.as_ref().and_then(|i| {
                if !i.user.is_empty() {
                    Some(i.user.as_str())
                } else {
                    session_user.get(&i.session).map(String::as_str)
                }
            });
            // Before the first game state the first session's stretch applies.
            let by_time = || {
                let w = window[k].or((!sessions.is_empty()).then_some(0))?;
                sessions[w].user.as_deref()
            };
            owners.push(by_ids.or_else(by_time).map(&mut index));
        }
        Ownership {
            owners,
            users,
            sessions,
            warnings,
        }
    }

    pub fn user_index(&self, user: &str) -> Option<usize> {
        self.users.iter().position(|u| u == user)
    }

    /// How many messages are `user`'s.
    pub fn count(&self, user: &str) -> usize {
        let Some(k) = self.user_index(user) else {
            return 0;
        };
        self.owners.iter().filter(|o| **o == Some(k)).count()
    }

    /// Whether message `index` is `user`'s.
    pub fn is(&self, index: usize, user: Option<usize>) -> bool {
        user.is_some() && self.owners.get(index).copied().flatten() == user
    }
}

/// The compression most of a bag's chunks use (zstd for a bag without chunks).
pub fn compression_of(reader: &BagReader) -> Compression {
    let (_, by) = reader.chunks();
    match by.iter().max_by_key(|(_, n)| **n).map(|(c, _)| c.as_str()) {
        Some("lz4") => Compression::Lz4,
        Some("") => Compression::None,
        _ => Compression::Zstd,
    }
}

/// Writes the messages of `reader` that `keep` takes into a new bag at `path` (a
/// `BagWriter` file bag: `<path>.partial` until finished), with the source's channels as
/// they are declared (schema, QoS metadata), its compression, stamps and sequence numbers. A
/// channel whose messages all go is left out; one empty in the source too is kept. Returns
/// how many messages were written.
pub fn write_subset(
    reader: &BagReader,
    keep: &dyn Fn(usize) -> bool,
    path: &Path,
) -> Result<usize, bag_file::BagError> {
    let counts = reader.counts();
    let messages = reader.raw_messages();
    let kept: BTreeSet<u16> = messages
        .iter()
        .enumerate()
        .filter(|(i, _)| keep(*i))
        .map(|(_, m)| m.channel_id)
        .collect();
    let options = WriterOptions {
        compression: compression_of(reader),
        ..WriterOptions::default()
    };
    let mut w = BagWriter::create(path, &options)?;
    let mut ids = BTreeMap::new();
    for c in reader.channels() {
        if kept.contains(&c.id) || counts.get(&c.id).copied().unwrap_or(0) == 0 {
            ids.insert(c.id, w.add_channel_like(c)?);
        }
    }
    let mut written = 0;
    for (i, m) in messages.iter().enumerate() {
        if !keep(i) {
            continue;
        }
        let Some(&id) = ids.get(&m.channel_id) else {
            continue;
        };
        let stamp = Stamp {
            log_time: m.log_time,
            publish_time: m.publish_time,
            sequence: m.sequence,
        };
        w.write_cdr(id, stamp, &m.data)?;
        written += 1;
    }
    w.finish()?;
    Ok(written)
}

/// Per topic: (messages of the user, all messages).
pub fn per_topic(
    reader: &BagReader,
    ownership: &Ownership,
    user: &str,
) -> BTreeMap<String, (usize, usize)> {
    let k = ownership.user_index(user);
    let mut out: BTreeMap<String, (usize, usize)> = BTreeMap::new();
    for (i, m) in reader.raw_messages().iter().enumerate() {
        let topic = reader
            .channel(m.channel_id)
            .map_or_else(|| format!("channel {}", m.channel_id), |c| c.topic.clone());
        let e = out.entry(topic).or_default();
        e.1 += 1;
        if ownership.is(i, k) {
            e.0 += 1;
        }
    }
    out
}
