//! One rule for what arrives twice (docs/session_log.md), and a session's messages read
//! through it. The durable topics (`SequenceResult`, `Decision`, `ActionProposal`) hand their
//! history to every reader that joins again, and a recorder that joins again records it again;
//! so a reader, live or from bags, meets a message twice. Each such message has an identity
//! ([`Identified`]): a message whose identity was taken before is a repeat when it equals the
//! first (dropped and counted) and a conflict when it differs (an error naming both). Live
//! readers (the console, the tablet bridge) feed [`Once`] message by message; readers of bags
//! (user models, the policy's evaluation, the session report) read through [`SessionReader`],
//! which applies the same [`Once`] across every bag it reads.

pub mod once;

pub use once::{Arrival, Conflict, Identified, Once};

use bag_file::{BagError, BagReader, Stamped};
use qt_therapy_msgs::topics::{
    ACTION_PROPOSAL, DECISION, EXPECTED_ENGAGEMENT, GAME_STATE, SEQUENCE_RESULT, TABLET_TASK, Topic,
};
use qt_therapy_msgs::{
    ActionProposal, Decision, ExpectedEngagement, GameState, MessageDefinition, SequenceResult,
    TabletTask,
};

/// Why a session log could not be read.
#[derive(Debug, thiserror::Error)]
pub enum SessionLogError {
    #[error(transparent)]
    Bag(#[from] BagError),
    #[error("{0}")]
    Conflict(#[from] Conflict),
}

/// A session's messages on the topics its readers use, each in log-time order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Messages {
    pub results: Vec<Stamped<SequenceResult>>,
    pub decisions: Vec<Stamped<Decision>>,
    pub proposals: Vec<Stamped<ActionProposal>>,
    /// State topics (keep last 1): a reader joining again gets the last one again, which
    /// tells nothing new; their readers take them as states, so they are kept as recorded.
    pub states: Vec<Stamped<GameState>>,
    pub tasks: Vec<Stamped<TabletTask>>,
    pub engagement: Vec<Stamped<ExpectedEngagement>>,
}

impl Messages {
    /// The messages of `bag`, and the topics it does not have (none sent on them).
    pub fn from_bag(bag: &BagReader) -> Result<(Messages, Vec<&'static str>), BagError> {
        let mut missing = Vec::new();
        let mut read = |name: &'static str| missing.push(name);
        let messages = Messages {
            results: topic(bag, SEQUENCE_RESULT, &mut read)?,
            decisions: topic(bag, DECISION, &mut read)?,
            proposals: topic(bag, ACTION_PROPOSAL, &mut read)?,
            states: topic(bag, GAME_STATE, &mut read)?,
            tasks: topic(bag, TABLET_TASK, &mut read)?,
            engagement: topic(bag, EXPECTED_ENGAGEMENT, &mut read)?,
        };
        Ok((messages, missing))
    }

    /// Appends `other`'s messages (another bag's), each topic staying in log-time order.
    pub fn extend(&mut self, other: Messages) {
        fn merge<M>(a: &mut Vec<Stamped<M>>, b: Vec<Stamped<M>>) {
            a.extend(b);
            a.sort_by_key(|m| m.log_time);
        }
        merge(&mut self.results, other.results);
        merge(&mut self.decisions, other.decisions);
        merge(&mut self.proposals, other.proposals);
        merge(&mut self.states, other.states);
        merge(&mut self.tasks, other.tasks);
        merge(&mut self.engagement, other.engagement);
    }

    /// The session id of the last result, if any (the bag's last session).
    pub fn last_session(&self) -> Option<&str> {
        self.results.last().map(|r| r.message.session_id.as_str())
    }
}

fn topic<M: MessageDefinition>(
    bag: &BagReader,
    t: Topic<M>,
    missing: &mut impl FnMut(&'static str),
) -> Result<Vec<Stamped<M>>, BagError> {
    match bag.topic(t) {
        Err(BagError::NoSuchTopic { .. }) => {
            missing(t.name);
            Ok(Vec::new())
        }
        other => other,
    }
}

/// A message dropped as a repeat, and where its first came from.
#[derive(Debug, Clone, PartialEq)]
pub struct Repeat {
    /// The topic it came on.
    pub topic: &'static str,
    pub what: String,
    pub first: String,
    pub again: String,
}

/// One source's messages taken through the rule.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SessionLog {
    /// The bag's name (its path), or what the messages came from.
    pub source: String,
    /// What was taken: every repeat dropped.
    pub messages: Messages,
    /// The repeats dropped, in log-time order per topic.
    pub repeats: Vec<Repeat>,
    /// The bag's damage, if any: its messages are those before it.
    pub damage: Option<String>,
    /// Whether the bag was closed cleanly (false: cut off; read to its last whole record).
    pub complete: bool,
    /// Topics the bag does not have.
    pub missing_topics: Vec<&'static str>,
}

impl SessionLog {
    /// One bag read alone through the rule.
    pub fn read(bag: &BagReader) -> Result<SessionLog, SessionLogError> {
        SessionReader::new().read_bag(bag)
    }

    /// Repeats dropped on `topic`.
    pub fn repeats_on<M>(&self, topic: Topic<M>) -> usize {
        self.repeats
            .iter()
            .filter(|r| r.topic == topic.name)
            .count()
    }

    /// A warning naming the repeats dropped, if any: `2 messages delivered again in a.mcap
    /// were taken once (the result of sequence 3 ... first from ...)`.
    pub fn repeats_warning(&self) -> Option<String> {
        let first = self.repeats.first()?;
        Some(format!(
            "{} message(s) delivered again in {} taken once (the first: {} from {}, again from {})",
            self.repeats.len(),
            self.source,
            first.what,
            first.first,
            first.again
        ))
    }
}

/// The rule's memory across every source read: a result in two bags (one session recorded
/// twice, or a bag and its copy) is taken once too. A source with a conflict is refused
/// whole, leaving the memory as it was.
#[derive(Debug, Clone, Default)]
pub struct SessionReader {
    results: Once<SequenceResult>,
    decisions: Once<Decision>,
    proposals: Once<ActionProposal>,
}

impl SessionReader {
    pub fn new() -> Self {
        Self::default()
    }

    /// Reads `bag`'s session messages through the rule.
    pub fn read_bag(&mut self, bag: &BagReader) -> Result<SessionLog, SessionLogError> {
        let (messages, missing_topics) = Messages::from_bag(bag)?;
        let mut log = self.take(bag.name(), messages)?;
        log.damage = bag.damage().map(|e| e.to_string());
        log.complete = bag.is_complete();
        log.missing_topics = missing_topics;
        Ok(log)
    }

    /// Takes the messages of `source` (a bag's, or made in memory) through the rule.
    pub fn take(&mut self, source: &str, messages: Messages) -> Result<SessionLog, Conflict> {
        let mut next = self.clone();
        let mut repeats = Vec::new();
        let Messages {
            results,
            decisions,
            proposals,
            states,
            tasks,
            engagement,
        } = messages;
        let taken = Messages {
            results: once(
                &mut next.results,
                SEQUENCE_RESULT,
                source,
                results,
                &mut repeats,
            )?,
            decisions: once(
                &mut next.decisions,
                DECISION,
                source,
                decisions,
                &mut repeats,
            )?,
            proposals: once(
                &mut next.proposals,
                ACTION_PROPOSAL,
                source,
                proposals,
                &mut repeats,
            )?,
            states,
            tasks,
            engagement,
        };
        *self = next;
        Ok(SessionLog {
            source: source.to_string(),
            messages: taken,
            repeats,
            damage: None,
            complete: true,
            missing_topics: Vec::new(),
        })
    }

    /// Repeats dropped so far, over every source.
    pub fn repeats(&self) -> u64 {
        self.results.repeats() + self.decisions.repeats() + self.proposals.repeats()
    }
}

/// The messages of one topic that the rule takes; `n` in an origin counts from 1 in log-time
/// order on the topic, as the bag tools number them.
fn once<M: Identified + MessageDefinition>(
    once: &mut Once<M>,
    topic: Topic<M>,
    source: &str,
    messages: Vec<Stamped<M>>,
    repeats: &mut Vec<Repeat>,
) -> Result<Vec<Stamped<M>>, Conflict> {
    let mut out = Vec::with_capacity(messages.len());
    for (n, m) in messages.into_iter().enumerate() {
        let origin = format!(
            "{source}, {} #{} (log time {} ns)",
            M::NAME,
            n + 1,
            m.log_time
        );
        match once.arrive(&m.message, &origin)? {
            Arrival::New => out.push(m),
            Arrival::Repeat => repeats.push(Repeat {
                topic: topic.name,
                what: m.message.describe(),
                first: once
                    .first_origin(&m.message)
                    .unwrap_or_default()
                    .to_string(),
                again: origin,
            }),
        }
    }
    Ok(out)
}
