//! The rule for what arrives twice, fed one message at a time: a message whose identity was
//! taken before is a repeat when it equals the first (dropped, counted) and a conflict when it
//! differs (reported naming both; the first is kept). Live readers feed it as messages come;
//! bag readers through [`crate::SessionReader`].

use qt_therapy_msgs::{ActionProposal, Decision, SequenceResult};
use std::collections::BTreeMap;
use std::fmt;

/// A message of a durable topic with an identity: what it is about, so that a message
/// delivered again can be told from a new one.
pub trait Identified: Clone + PartialEq + fmt::Debug {
    type Id: Ord + Clone + fmt::Debug;
    fn id(&self) -> Self::Id;
    /// The identity in words, for errors: `sequence 3 of session "s1" (user "u1")`.
    fn describe(&self) -> String;
}

/// A sequence has one result: (user, session, sequence index). The user is in it because
/// session ids alone may repeat across robots.
impl Identified for SequenceResult {
    type Id = (String, String, u8);

    fn id(&self) -> Self::Id {
        (
            self.user_id.clone(),
            self.session_id.clone(),
            self.sequence_index,
        )
    }

    fn describe(&self) -> String {
        format!(
            "the result of sequence {} of session {:?} (user {:?})",
            self.sequence_index, self.session_id, self.user_id
        )
    }
}

/// A decision is one answer of the policy: (session, step, its stamp). The policy may be asked
/// twice for a step (a game manager started again); each answer is a decision of its own.
impl Identified for Decision {
    type Id = (String, u8, i64);

    fn id(&self) -> Self::Id {
        (
            self.session_id.clone(),
            self.step,
            self.header.stamp.to_nanos(),
        )
    }

    fn describe(&self) -> String {
        format!(
            "the decision for sequence {} of session {:?} stamped {} ns",
            self.step,
            self.session_id,
            self.header.stamp.to_nanos()
        )
    }
}

/// A proposal is shown one or more times (again on resume, with a new deadline) and settled
/// once: (session, proposal id, the deadline of a showing or None for the settlement).
impl Identified for ActionProposal {
    type Id = (String, u64, Option<i64>);

    fn id(&self) -> Self::Id {
        let showing = (self.status == ActionProposal::PROPOSED).then(|| self.deadline.to_nanos());
        (self.session_id.clone(), self.proposal_id, showing)
    }

    fn describe(&self) -> String {
        let what = if self.status == ActionProposal::PROPOSED {
            format!("shown until {} ns", self.deadline.to_nanos())
        } else {
            "settled".to_string()
        };
        format!(
            "proposal {} for sequence {} of session {:?}, {what}",
            self.proposal_id, self.step, self.session_id
        )
    }
}

/// What a message was, by the rule.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Arrival {
    /// Its identity is new: take it.
    New,
    /// The same message again (a durable topic's history delivered once more): dropped.
    Repeat,
}

/// Two messages with one identity that differ: one of them is not what happened.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{what} arrived twice and differs ({fields}): first from {first}, then from {second}")]
pub struct Conflict {
    /// The identity in words.
    pub what: String,
    /// Where the first came from (a bag and the message's place in it, or a live topic).
    pub first: String,
    pub second: String,
    /// The fields that differ, with both values.
    pub fields: String,
}

/// The rule's memory: the first message of every identity seen, and where it came from.
#[derive(Debug, Clone)]
pub struct Once<M: Identified> {
    first: BTreeMap<M::Id, (M, String)>,
    repeats: u64,
}

impl<M: Identified> Default for Once<M> {
    fn default() -> Self {
        Once {
            first: BTreeMap::new(),
            repeats: 0,
        }
    }
}

impl<M: Identified> Once<M> {
    pub fn new() -> Self {
        Self::default()
    }

    /// Takes `m`, which came from `origin` (named in a conflict): New the first time its
    /// identity is seen, Repeat (counted) when it equals the first, a [`Conflict`] naming
    /// both when it differs; the first stays what was taken.
    pub fn arrive(&mut self, m: &M, origin: impl fmt::Display) -> Result<Arrival, Conflict> {
        match self.first.get(&m.id()) {
            None => {
                self.first.insert(m.id(), (m.clone(), origin.to_string()));
                Ok(Arrival::New)
            }
            Some((first, _)) if first == m => {
                self.repeats += 1;
                Ok(Arrival::Repeat)
            }
            Some((first, first_origin)) => Err(Conflict {
                what: m.describe(),
                first: first_origin.clone(),
                second: origin.to_string(),
                fields: differences(first, m),
            }),
        }
    }

    /// Where the first message with `m`'s identity came from, if one was taken.
    pub fn first_origin(&self, m: &M) -> Option<&str> {
        self.first.get(&m.id()).map(|(_, o)| o.as_str())
    }

    /// Distinct messages taken.
    pub fn len(&self) -> usize {
        self.first.len()
    }

    pub fn is_empty(&self) -> bool {
        self.first.is_empty()
    }

    /// Repeats dropped.
    pub fn repeats(&self) -> u64 {
        self.repeats
    }
}

/// The top-level fields of two messages of one type that differ, as `name: a -> b` (from their
/// pretty Debug form, where each field starts on a line of its own, indented 4).
fn differences<M: fmt::Debug>(a: &M, b: &M) -> String {
    fn fields(m: &str) -> Vec<String> {
        let mut out: Vec<String> = Vec::new();
        for line in m.lines() {
            let top = line.starts_with("    ") && !line.starts_with("     ");
            match out.last_mut() {
                Some(f) if !top => {
                    f.push(' ');
                    f.push_str(line.trim());
                }
                _ if top => out.push(line.trim().trim_end_matches(',').to_string()),
                _ => {}
            }
        }
        out
    }
    let (a, b) = (fields(&format!("{a:#?}")), fields(&format!("{b:#?}")));
    let differ: Vec<String> = a
        .iter()
        .zip(&b)
        .filter(|(x, y)| x != y)
        .map(|(x, y)| {
            let name = x.split(':').next().unwrap_or(x);
            let value = |f: &str| {
                let v = f.split_once(':').map_or(f, |(_, v)| v).trim().to_string();
                if v.chars().count() > 60 {
                    format!("{}...", v.chars().take(60).collect::<String>())
                } else {
                    v
                }
            };
            format!("{name}: {} -> {}", value(x), value(y))
        })
        .collect();
    if differ.is_empty() {
        "in their shape".to_string()
    } else {
        differ.join("; ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use qt_therapy_msgs::builtin_interfaces::Time;

    fn result(index: u8, outcome: i8) -> SequenceResult {
        SequenceResult {
            session_id: "s1".into(),
            user_id: "u1".into(),
            sequence_index: index,
            outcome,
            level: 2,
            ..Default::default()
        }
    }

    #[test]
    fn a_repeat_is_dropped_and_counted_and_a_differing_one_is_a_conflict_naming_both() {
        let mut once = Once::new();
        assert_eq!(once.arrive(&result(1, 1), "bag a #1"), Ok(Arrival::New));
        assert_eq!(once.arrive(&result(2, 1), "bag a #2"), Ok(Arrival::New));
        assert_eq!(once.arrive(&result(1, 1), "bag a #3"), Ok(Arrival::Repeat));
        let e = once
            .arrive(&result(2, -1), "bag b #1")
            .expect_err("differs");
        assert_eq!(e.first, "bag a #2");
        assert_eq!(e.second, "bag b #1");
        assert_eq!(e.fields, "outcome: 1 -> -1");
        let text = e.to_string();
        assert!(
            text.contains("the result of sequence 2 of session \"s1\" (user \"u1\")"),
            "{text}"
        );
        // The first is what stays taken.
        assert_eq!(once.arrive(&result(2, 1), "bag c"), Ok(Arrival::Repeat));
        assert_eq!((once.len(), once.repeats()), (2, 2));
        // Another user's session of the same id is another sequence.
        let other = SequenceResult {
            user_id: "u2".into(),
            ..result(2, -1)
        };
        assert_eq!(once.arrive(&other, "bag d"), Ok(Arrival::New));
    }

    #[test]
    fn a_proposal_shown_again_is_new_and_the_same_showing_or_settlement_again_is_a_repeat() {
        let shown = |deadline_s: i64| ActionProposal {
            session_id: "s1".into(),
            proposal_id: 7,
            step: 3,
            deadline: Time::from_nanos(deadline_s * 1_000_000_000),
            ..Default::default()
        };
        let settled = ActionProposal {
            status: ActionProposal::ACCEPTED,
            command_id: 12,
            ..shown(40)
        };
        let mut once = Once::new();
        assert_eq!(once.arrive(&shown(30), "live"), Ok(Arrival::New));
        assert_eq!(once.arrive(&shown(30), "live"), Ok(Arrival::Repeat));
        // Shown again on resume: a new deadline.
        assert_eq!(once.arrive(&shown(40), "live"), Ok(Arrival::New));
        assert_eq!(once.arrive(&settled, "live"), Ok(Arrival::New));
        assert_eq!(once.arrive(&settled, "live"), Ok(Arrival::Repeat));
        // Settled twice, two ways: not what happened.
        let e = once
            .arrive(
                &ActionProposal {
                    status: ActionProposal::TIMED_OUT,
                    command_id: 0,
                    ..settled.clone()
                },
                "live",
            )
            .expect_err("settled twice");
        assert_eq!(e.fields, "status: 1 -> 3; command_id: 12 -> 0");
        // Another proposal of the same step (the game manager proposing anew) is new.
        let anew = ActionProposal {
            proposal_id: 8,
            ..shown(30)
        };
        assert_eq!(once.arrive(&anew, "live"), Ok(Arrival::New));
    }

    #[test]
    fn decisions_of_one_step_at_two_times_are_two() {
        let d = |t: i64, action: u8| Decision {
            session_id: "s1".into(),
            step: 2,
            action,
            header: qt_therapy_msgs::std_msgs::Header::at(Time::from_nanos(t)),
            ..Default::default()
        };
        let mut once = Once::new();
        assert_eq!(once.arrive(&d(5, 1), "x"), Ok(Arrival::New));
        assert_eq!(once.arrive(&d(9, 3), "x"), Ok(Arrival::New));
        assert_eq!(once.arrive(&d(5, 1), "x"), Ok(Arrival::Repeat));
        assert!(once.arrive(&d(5, 2), "y").is_err());
    }
}
