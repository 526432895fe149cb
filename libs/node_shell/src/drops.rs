//! Bookkeeping for input a node refused: the first message per topic and reason is logged as a
//! warning, repeats are counted (and logged again with the count at powers of two from 8 and
//! at 10, 100, 1000, 10000), so a flood of nonsense cannot flood the log while the reason
//! stays visible.

use std::collections::HashMap;
use std::sync::Mutex;

#[derive(Debug, Default)]
pub struct DropLog {
    counts: Mutex<HashMap<(String, String), u64>>,
}

/// Reasons carry values (e.g. "level = 4"); the key keeps only their first words so one kind of
/// fault counts as one reason.
fn reason_kind(reason: &str) -> String {
    reason
        .split(['=', ':'])
        .take(2)
        .collect::<Vec<_>>()
        .join(":")
}

impl DropLog {
    /// Records one dropped message; returns how many of this kind were dropped so far.
    pub fn record(&self, topic: &str, reason: &str) -> u64 {
        let count = {
            let mut counts = match self.counts.lock() {
                Ok(c) => c,
                Err(poisoned) => poisoned.into_inner(),
            };
            let c = counts
                .entry((topic.to_string(), reason_kind(reason)))
                .or_insert(0);
            *c += 1;
            *c
        };
        if count == 1 {
            tracing::warn!(topic, reason, "dropped a message");
        } else if count.is_power_of_two() && count >= 8 || [10, 100, 1000, 10_000].contains(&count)
        {
            tracing::warn!(topic, reason, count, "dropped messages (same reason)");
        }
        count
    }

    /// Total dropped on `topic`.
    pub fn total(&self, topic: &str) -> u64 {
        let counts = match self.counts.lock() {
            Ok(c) => c,
            Err(poisoned) => poisoned.into_inner(),
        };
        counts
            .iter()
            .filter(|((t, _), _)| t == topic)
            .map(|(_, c)| c)
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_per_topic_and_kind_of_reason() {
        let d = DropLog::default();
        assert_eq!(d.record("/a", "GameState: level = 4 is outside 0..=3"), 1);
        assert_eq!(d.record("/a", "GameState: level = 5 is outside 0..=3"), 2);
        assert_eq!(d.record("/a", "GameState: phase = 9 is outside 0..=8"), 1);
        assert_eq!(d.record("/b", "GameState: level = 4 is outside 0..=3"), 1);
        assert_eq!(d.total("/a"), 3);
    }
}
