//! Algorithm 1's order across two channels: a sequence's result is learned before the next
//! action is chosen. Results arrive on a topic and decision requests on a service, so either
//! may reach the node first; each request names the last result it follows
//! (`DecideAction.after_sequence`), and a request whose result has not been seen yet is held
//! until it comes, or refused once `result_wait` has passed (the game manager then falls back,
//! with the reason in its session file). Sans-IO: the node's shell keeps the calls (`C`) and
//! the clock.

use qt_therapy_msgs::DecideActionRequest;
use std::collections::HashMap;

/// A request held for its result.
#[derive(Debug)]
struct Held<C> {
    call: C,
    request: DecideActionRequest,
    since_ns: i64,
}

/// A request that waited too long for its result.
#[derive(Debug)]
pub struct Expired<C> {
    pub call: C,
    pub request: DecideActionRequest,
    /// Why, in words (the refusal's error).
    pub reason: String,
}

/// What the gate has done, for the log and the tests.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct GateCounts {
    /// Requests that came before their result and were held for it.
    pub held: u64,
    /// Of those, answered once the result had been learned.
    pub released: u64,
    /// Of those, refused: the result did not come within the wait.
    pub refused: u64,
}

/// Holds decision requests until the result they follow has been seen.
#[derive(Debug)]
pub struct LearnFirst<C> {
    wait_ns: i64,
    /// Per session, the highest sequence whose result reached the node (learned, already
    /// learned, or refused: a result that cannot be learned must not hold a decision).
    seen: HashMap<String, u8>,
    held: Vec<Held<C>>,
    counts: GateCounts,
}

/// Sessions remembered at most (the oldest forgotten first): a node runs for months.
const MAX_SESSIONS: usize = 4096;

impl<C> LearnFirst<C> {
    /// A gate that waits at most `wait_ns` for a request's result.
    pub fn new(wait_ns: i64) -> LearnFirst<C> {
        LearnFirst {
            wait_ns,
            seen: HashMap::new(),
            held: Vec::new(),
            counts: GateCounts::default(),
        }
    }

    pub fn counts(&self) -> GateCounts {
        self.counts
    }

    /// A request arrived at `now_ns`. `learned` is the highest sequence of its session the
    /// policy has learned (from its Q-table file: it survives a restart). Returns the call to
    /// answer now, or `None` when it is held.
    pub fn request(
        &mut self,
        call: C,
        request: DecideActionRequest,
        learned: Option<u8>,
        now_ns: i64,
    ) -> Option<(C, DecideActionRequest)> {
        let seen = self
            .seen
            .get(&request.session_id)
            .copied()
            .max(learned)
            .unwrap_or(0);
        if request.after_sequence <= seen {
            return Some((call, request));
        }
        self.counts.held += 1;
        self.held.push(Held {
            call,
            request,
            since_ns: now_ns,
        });
        None
    }

    /// Sequence `index` of `session` reached the node (after the policy has learned it, or
    /// failed to): the requests it releases, in the order they came.
    pub fn result_seen(&mut self, session: &str, index: u8) -> Vec<(C, DecideActionRequest)> {
        if !self.seen.contains_key(session) && self.seen.len() >= MAX_SESSIONS {
            // Forget the session seen longest ago... by the smallest key is good enough: a
            // forgotten session only falls back on the Q-table file's memory.
            if let Some(k) = self.seen.keys().min().cloned() {
                self.seen.remove(&k);
            }
        }
        let entry = self.seen.entry(session.to_string()).or_insert(0);
        *entry = (*entry).max(index);
        let (ready, still): (Vec<_>, Vec<_>) = std::mem::take(&mut self.held)
            .into_iter()
            .partition(|h| h.request.session_id == session && h.request.after_sequence <= index);
        self.held = still;
        self.counts.released += ready.len() as u64;
        ready.into_iter().map(|h| (h.call, h.request)).collect()
    }

    /// The requests whose wait is over at `now_ns`, to be refused.
    pub fn expired(&mut self, now_ns: i64) -> Vec<Expired<C>> {
        let wait_ns = self.wait_ns;
        let (over, still): (Vec<_>, Vec<_>) = std::mem::take(&mut self.held)
            .into_iter()
            .partition(|h| now_ns - h.since_ns >= wait_ns);
        self.held = still;
        self.counts.refused += over.len() as u64;
        over.into_iter()
            .map(|h| {
                let reason = format!(
                    "the result of sequence {} of session {:?} has not reached the policy within \
                     {:.1} s: it learns a result before the next decision (Algorithm 1), so it \
                     does not decide step {} without it",
                    h.request.after_sequence,
                    h.request.session_id,
                    wait_ns as f64 / 1e9,
                    h.request.step
                );
                Expired {
                    call: h.call,
                    request: h.request,
                    reason,
                }
            })
            .collect()
    }

    /// When the next held request's wait ends.
    pub fn next_deadline_ns(&self) -> Option<i64> {
        self.held.iter().map(|h| h.since_ns + self.wait_ns).min()
    }

    /// Requests held now.
    pub fn holding(&self) -> usize {
        self.held.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: i64 = 1_000_000;

    fn request(session: &str, step: u8) -> DecideActionRequest {
        DecideActionRequest {
            session_id: session.into(),
            step,
            after_sequence: step - 1,
            ..Default::default()
        }
    }

    #[test]
    fn a_request_whose_result_came_first_is_answered_at_once() {
        let mut gate = LearnFirst::new(1000 * MS);
        assert!(gate.result_seen("s", 1).is_empty());
        let (call, req) = gate.request(7, request("s", 2), None, 0).expect("now");
        assert_eq!((call, req.step), (7, 2));
        // The first step follows no result.
        assert!(gate.request(8, request("t", 1), None, 0).is_some());
        assert_eq!(gate.counts(), GateCounts::default());
    }

    #[test]
    fn a_request_before_its_result_waits_for_it() {
        let mut gate = LearnFirst::new(1000 * MS);
        gate.result_seen("s", 3);
        assert!(gate.request(1, request("s", 5), None, 10 * MS).is_none());
        assert_eq!(gate.holding(), 1);
        assert_eq!(gate.next_deadline_ns(), Some(1010 * MS));
        // Another session's result, or an older one, releases nothing.
        assert!(gate.result_seen("other", 4).is_empty());
        assert!(gate.result_seen("s", 3).is_empty());
        assert!(gate.expired(500 * MS).is_empty());
        let released = gate.result_seen("s", 4);
        assert_eq!(released.len(), 1);
        assert_eq!(released[0].1.step, 5);
        assert_eq!(gate.holding(), 0);
        assert_eq!(
            gate.counts(),
            GateCounts {
                held: 1,
                released: 1,
                refused: 0
            }
        );
    }

    #[test]
    fn what_the_q_table_learned_before_a_restart_counts_as_seen() {
        let mut gate = LearnFirst::new(1000 * MS);
        assert!(gate.request(1, request("s", 4), Some(3), 0).is_some());
    }

    #[test]
    fn a_result_that_never_comes_is_refused_after_the_wait_with_its_reason() {
        let mut gate = LearnFirst::new(1000 * MS);
        assert!(gate.request(1, request("s", 2), None, 0).is_none());
        assert!(gate.expired(999 * MS).is_empty());
        let over = gate.expired(1000 * MS);
        assert_eq!(over.len(), 1);
        assert!(
            over[0].reason.contains(
                "the result of sequence 1 of session \"s\" has not reached the policy within 1.0 s"
            ),
            "{}",
            over[0].reason
        );
        assert_eq!(gate.counts().refused, 1);
        // It came late: nothing is held for it any more.
        assert!(gate.result_seen("s", 1).is_empty());
    }
}
