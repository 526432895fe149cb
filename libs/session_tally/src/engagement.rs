//! A sequence's engagement E, from the per-second ExpectedEngagement windows: the mean smoothed
//! expected engagement over the seconds the robot talked for the sequence (the authors: from the
//! end of the previous answer to the start of this one); windows without a face are skipped and
//! a second seen by several cameras counts once. The game manager scores live with this, and
//! the user models read recorded sessions with the same rule.

use qt_therapy_msgs::ExpectedEngagement;
use std::collections::BTreeMap;

/// A sequence's engagement: the mean, and the per-second values it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct SequenceEngagement {
    /// Mean of `per_second`; 0 when there is none (the result then carries no seconds).
    pub mean: f32,
    pub per_second: Vec<f32>,
}

/// ExpectedEngagement windows received during a session, kept until their period is scored.
#[derive(Debug, Clone, Default)]
pub struct EngagementLog {
    /// (window_start, window_end, source) -> smoothed engagement; faceless windows never enter.
    windows: BTreeMap<(i64, i64, String), f32>,
}

/// Most windows kept: an hour of one camera; older ones are dropped first.
const MAX_WINDOWS: usize = 3600;

impl EngagementLog {
    /// Keeps a window with a face; returns false (and keeps nothing) for a faceless or
    /// malformed one.
    pub fn push(&mut self, e: &ExpectedEngagement) -> bool {
        let (start, end) = (e.window_start.to_nanos(), e.window_end.to_nanos());
        if !e.has_faces || !e.smoothed.is_finite() || !(-1.0..=1.0).contains(&e.smoothed) {
            return false;
        }
        if end <= start {
            return false;
        }
        self.windows
            .insert((start, end, e.source.clone()), e.smoothed);
        while self.windows.len() > MAX_WINDOWS {
            self.windows.pop_first();
        }
        true
    }

    /// Windows whose midpoint lies in `[start_ns, end_ns)`, averaged over sources per
    /// second (each second counts once whichever cameras saw the face).
    pub fn gather(&self, start_ns: i64, end_ns: i64) -> SequenceEngagement {
        let mut per_window: BTreeMap<(i64, i64), (f64, u32)> = BTreeMap::new();
        for ((ws, we, _), v) in &self.windows {
            let mid = ws + (we - ws) / 2;
            if mid >= start_ns && mid < end_ns {
                let slot = per_window.entry((*ws, *we)).or_insert((0.0, 0));
                slot.0 += f64::from(*v);
                slot.1 += 1;
            }
        }
        let per_second: Vec<f32> = per_window
            .values()
            .map(|(sum, n)| (sum / f64::from(*n)) as f32)
            .collect();
        let mean = if per_second.is_empty() {
            0.0
        } else {
            (per_second.iter().map(|v| f64::from(*v)).sum::<f64>() / per_second.len() as f64) as f32
        };
        SequenceEngagement { mean, per_second }
    }

    /// Forgets windows that end before `ns` (already scored).
    pub fn forget_before(&mut self, ns: i64) {
        self.windows.retain(|(_, end, _), _| *end >= ns);
    }

    pub fn clear(&mut self) {
        self.windows.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use qt_therapy_msgs::builtin_interfaces::Time;

    const S: i64 = 1_000_000_000;

    fn window(start_s: i64, smoothed: f32, has_faces: bool, source: &str) -> ExpectedEngagement {
        ExpectedEngagement {
            source: source.into(),
            window_start: Time::from_nanos(start_s * S),
            window_end: Time::from_nanos((start_s + 1) * S),
            has_faces,
            smoothed,
            ..Default::default()
        }
    }

    #[test]
    fn engagement_is_the_mean_of_the_talking_seconds_with_faces() {
        let mut log = EngagementLog::default();
        for (t, v) in [(9, 0.9), (10, 0.5), (11, -0.1), (12, 0.2), (20, -1.0)] {
            assert!(log.push(&window(t, v, true, "cam/0")));
        }
        assert!(
            !log.push(&window(13, 0.0, false, "cam/0")),
            "faceless windows are skipped"
        );
        // A second camera saw second 11 too: that second counts once, as the mean.
        log.push(&window(11, 0.3, true, "cam2/0"));
        let e = log.gather(10 * S, 14 * S);
        let expected = [0.5, 0.1, 0.2];
        assert_eq!(e.per_second.len(), 3);
        assert!(
            e.per_second
                .iter()
                .zip(expected)
                .all(|(a, b)| (a - b).abs() < 1e-6),
            "{e:?}"
        );
        assert!((e.mean - 0.8 / 3.0).abs() < 1e-6);
        let none = log.gather(14 * S, 19 * S);
        assert_eq!((none.mean, none.per_second.len()), (0.0, 0));
        log.forget_before(13 * S);
        assert_eq!(log.gather(0, 30 * S).per_second, vec![0.2, -1.0]);
    }
}
