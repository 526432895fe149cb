//! Steps of the wall clock, told against a clock that never steps. A robot PC's wall clock
//! jumps when NTP first syncs after boot or when someone sets it by hand. The suite stamps its
//! messages with the wall clock (the ROS convention) but times every duration, timer and
//! ordering inside a process on a *steady* clock: the wall clock as it read when the process
//! started, advanced by the monotonic clock since (`node_shell::Clock::steady_nanos`). The two
//! differ by an offset that stays put, but for NTP's slewing, until the wall clock is stepped.
//!
//! [`ClockSteps`] follows that offset from readings of both clocks, tells each step, and places
//! a wall stamp (this process's, or another's on the same machine, whose clock stepped with
//! it) on the steady clock on the right side of a step: a second of engagement stamped just
//! before a step and received just after it belongs before it.

use std::collections::VecDeque;

/// A change of the offset between two readings larger than this is a step. NTP slews a
/// difference under 128 ms at most 0.5 ms a second, and the nodes read both clocks several
/// times a second; anything larger is stepped (NTP's `step` threshold is 128 ms; a step by hand
/// is seconds to hours).
pub const STEP_NS: i64 = 500_000_000;

/// How far a stamp placed by one offset may fall before the time that offset began or after
/// the stamp was seen, and still belong to it: a second of engagement is reported about 1.2 s
/// after it starts, and a second that closes at a step began up to a second before it.
const SLACK_NS: i64 = 3_000_000_000;

/// Offsets remembered (the oldest dropped first): a process runs for months.
const KEPT: usize = 64;

/// One step of the wall clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Step {
    /// The steady time of the first reading after it.
    pub at_steady_ns: i64,
    /// How far the wall clock moved against the steady clock: negative when it went back.
    pub by_ns: i64,
}

/// An offset of the wall clock from the steady clock (wall - steady), from when it held.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Span {
    from_steady_ns: i64,
    offset_ns: i64,
}

/// The wall clock's offsets from the steady clock over time, and the steps between them.
#[derive(Debug, Clone, Default)]
pub struct ClockSteps {
    /// Oldest first; empty before the first reading.
    spans: VecDeque<Span>,
}

impl ClockSteps {
    /// Nothing read yet.
    pub fn new() -> ClockSteps {
        ClockSteps::default()
    }

    /// The offsets a record of steps gives, where the steady clock was started on the wall
    /// clock (offset 0 before the first step), as a bag's recorder tells them.
    pub fn from_steps(steps: impl IntoIterator<Item = Step>) -> ClockSteps {
        let mut c = ClockSteps {
            spans: VecDeque::from([Span {
                from_steady_ns: i64::MIN,
                offset_ns: 0,
            }]),
        };
        for s in steps {
            let offset_ns = c.offset_ns().saturating_add(s.by_ns);
            c.push(Span {
                from_steady_ns: s.at_steady_ns,
                offset_ns,
            });
        }
        c
    }

    /// Both clocks read at one moment. Returns the step when the wall clock was stepped since
    /// the previous reading; otherwise follows its slewing.
    pub fn observe(&mut self, steady_ns: i64, wall_ns: i64) -> Option<Step> {
        let offset_ns = wall_ns.saturating_sub(steady_ns);
        let Some(last) = self.spans.back_mut() else {
            self.push(Span {
                from_steady_ns: steady_ns,
                offset_ns,
            });
            return None;
        };
        let by_ns = offset_ns.saturating_sub(last.offset_ns);
        if by_ns.abs() <= STEP_NS {
            last.offset_ns = offset_ns;
            return None;
        }
        self.push(Span {
            from_steady_ns: steady_ns,
            offset_ns,
        });
        Some(Step {
            at_steady_ns: steady_ns,
            by_ns,
        })
    }

    fn push(&mut self, span: Span) {
        if self.spans.len() >= KEPT {
            self.spans.pop_front();
        }
        self.spans.push_back(span);
    }

    /// The offset now (wall - steady); 0 before the first reading.
    pub fn offset_ns(&self) -> i64 {
        self.spans.back().map_or(0, |s| s.offset_ns)
    }

    /// The wall time of steady time `steady_ns` by the offset now: how a time kept on the
    /// steady clock is stamped.
    pub fn wall_of(&self, steady_ns: i64) -> i64 {
        steady_ns.saturating_add(self.offset_ns())
    }

    /// The steps remembered, oldest first.
    pub fn steps(&self) -> impl Iterator<Item = Step> + '_ {
        self.spans
            .iter()
            .zip(self.spans.iter().skip(1))
            .map(|(before, after)| Step {
                at_steady_ns: after.from_steady_ns,
                by_ns: after.offset_ns.saturating_sub(before.offset_ns),
            })
    }

    /// Places `wall_ns`, a stamp of the wall clock that reached this process at steady time
    /// `seen_ns`, on the steady clock: by the latest offset under which it falls between that
    /// offset's start and `seen_ns` (give or take a few seconds), else by the offset now. A step
    /// shorter than those few seconds cannot be told from a late stamp: a stamp near it may be
    /// placed up to the step off.
    pub fn steady_of(&self, wall_ns: i64, seen_ns: i64) -> i64 {
        for span in self.spans.iter().rev() {
            let steady = wall_ns.saturating_sub(span.offset_ns);
            if steady <= seen_ns.saturating_add(SLACK_NS)
                && steady >= span.from_steady_ns.saturating_sub(SLACK_NS)
            {
                return steady;
            }
        }
        wall_ns.saturating_sub(self.offset_ns())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: i64 = 1_000_000_000;
    const HOUR: i64 = 3600 * S;
    /// A wall clock reading of 2026 (the steady clock starts on it).
    const T0: i64 = 1_780_000_000 * S;

    #[test]
    fn slewing_is_followed_and_a_step_is_told_once() {
        let mut c = ClockSteps::new();
        assert_eq!(c.observe(T0, T0), None);
        // NTP's slewing: a millisecond over ten seconds.
        assert_eq!(c.observe(T0 + 10 * S, T0 + 10 * S + 1_000_000), None);
        assert_eq!(c.offset_ns(), 1_000_000);
        // An hour back.
        let step = c.observe(T0 + 11 * S, T0 + 11 * S - HOUR);
        assert_eq!(
            step,
            Some(Step {
                at_steady_ns: T0 + 11 * S,
                by_ns: -HOUR - 1_000_000,
            })
        );
        assert_eq!(c.observe(T0 + 12 * S, T0 + 12 * S - HOUR), None);
        assert_eq!(c.steps().collect::<Vec<_>>(), vec![step.unwrap()]);
        assert_eq!(c.wall_of(T0 + 20 * S), T0 + 20 * S - HOUR);
    }

    #[test]
    fn a_stamp_taken_before_a_step_and_seen_after_it_is_placed_before_it() {
        for by in [-HOUR, 2 * HOUR, -10 * S, 10 * S] {
            let mut c = ClockSteps::new();
            c.observe(T0, T0);
            c.observe(T0 + 10 * S, T0 + 10 * S);
            c.observe(T0 + 10 * S + S / 10, T0 + 10 * S + S / 10 + by);
            // A second that began 1.2 s before the step, stamped on the old offset, seen
            // 0.3 s after it.
            let before = T0 + 10 * S - 12 * S / 10;
            assert_eq!(
                c.steady_of(before, T0 + 10 * S + 3 * S / 10),
                before,
                "{by}"
            );
            // One stamped after it, on the new offset.
            let after = T0 + 11 * S;
            assert_eq!(c.steady_of(after + by, T0 + 12 * S), after, "{by}");
        }
    }

    #[test]
    fn stamps_before_any_step_keep_their_time() {
        let mut c = ClockSteps::new();
        assert_eq!(c.steady_of(T0, T0), T0, "nothing read yet");
        c.observe(T0, T0);
        assert_eq!(c.steady_of(T0 - 5 * S, T0), T0 - 5 * S);
        // A replay's stamps, days old, keep the offset now.
        assert_eq!(c.steady_of(T0 - 86_400 * S, T0), T0 - 86_400 * S);
    }

    #[test]
    fn a_record_of_steps_gives_the_offsets_back() {
        let steps = [
            Step {
                at_steady_ns: T0 + 10 * S,
                by_ns: -HOUR,
            },
            Step {
                at_steady_ns: T0 + 20 * S,
                by_ns: 2 * HOUR,
            },
        ];
        let c = ClockSteps::from_steps(steps);
        assert_eq!(c.steps().collect::<Vec<_>>(), steps.to_vec());
        assert_eq!(c.steady_of(T0 + 5 * S, T0 + 6 * S), T0 + 5 * S);
        assert_eq!(c.steady_of(T0 + 15 * S - HOUR, T0 + 16 * S), T0 + 15 * S);
        assert_eq!(c.steady_of(T0 + 25 * S + HOUR, T0 + 26 * S), T0 + 25 * S);
        assert_eq!(c.offset_ns(), HOUR);
    }

    #[test]
    fn a_process_of_months_keeps_its_latest_offsets() {
        let mut c = ClockSteps::new();
        for i in 0..1000 {
            c.observe(T0 + i * 10 * S, T0 + i * 10 * S + (i % 2) * HOUR);
        }
        assert!(c.steps().count() < KEPT);
        assert_eq!(c.offset_ns(), HOUR);
    }
}
