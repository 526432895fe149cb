//! Per-frame labels -> expected engagement per second of MESSAGE time, per source (camera or
//! face id). A window [k s, (k+1) s) closes once message time passes its end plus the allowed
//! lateness; every known source then reports it, with `engagement = None` when it saw no
//! valid face (never as disengaged). Fixed storage per source: no allocation per frame.

use crate::smoothing::ExponentialSmoother;

/// Caller-chosen id of a frame source (a camera, or a face id within one).
pub type SourceId = u32;

const SECOND_NS: i64 = 1_000_000_000;

/// One source's summary of one second.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EngagementSecond {
    pub source: SourceId,
    pub window_start_ns: i64,
    pub window_end_ns: i64,
    /// (n+ - n-) / (n+ + n-) in [-1, 1]; `None` when no frame in the window had a valid face.
    pub engagement: Option<f64>,
    /// Exponentially smoothed over this source's seconds with a face; `None` likewise.
    pub smoothed_engagement: Option<f64>,
    pub engaged_frames: u32,
    pub disengaged_frames: u32,
    /// Frames without a usable face (detection failed or low confidence).
    pub missing_frames: u32,
}

impl EngagementSecond {
    /// Frames that counted (had a valid face).
    pub fn frame_count(&self) -> u32 {
        self.engaged_frames + self.disengaged_frames
    }
}

/// Aggregation settings (from `EngagementClassifierParams`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AggregatorConfig {
    pub smoothing_alpha: f64,
    pub smoothing_adjust: bool,
    /// How far behind the newest message time a frame may arrive and still count; < 1 s.
    pub max_lateness_ns: i64,
    /// A source without frames for this long stops reporting (a face that left).
    pub source_timeout_ns: i64,
    pub max_sources: usize,
}

/// Why a frame could not be counted. The caller logs it and goes on.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AggregateError {
    #[error(
        "frame of source {source_id} at {stamp_ns} ns is late: seconds before {closed_before_ns} ns were already reported"
    )]
    LateFrame {
        source_id: SourceId,
        stamp_ns: i64,
        closed_before_ns: i64,
    },
    #[error(
        "frame of source {source_id} dropped: already tracking max_sources = {max_sources} sources"
    )]
    TooManySources {
        source_id: SourceId,
        max_sources: usize,
    },
}

#[derive(Debug, Clone, Copy)]
struct Window {
    index: i64,
    engaged: u32,
    disengaged: u32,
    missing: u32,
}

const EMPTY: Window = Window {
    index: i64::MIN,
    engaged: 0,
    disengaged: 0,
    missing: 0,
};

#[derive(Debug, Clone)]
struct Source {
    id: SourceId,
    /// Windows k and k+1 can be open at once (lateness < 1 s); slot = k mod 2.
    windows: [Window; 2],
    smoother: ExponentialSmoother,
    /// First window this source reports (it says nothing about seconds before it appeared).
    since_window: i64,
    last_frame_ns: i64,
}

/// The sans-IO per-second aggregator.
#[derive(Debug, Clone)]
pub struct SecondAggregator {
    config: AggregatorConfig,
    sources: Vec<Source>,
    /// Next window to report; `None` before the first frame.
    next_close: Option<i64>,
    latest_ns: i64,
}

impl SecondAggregator {
    pub fn new(config: AggregatorConfig) -> SecondAggregator {
        SecondAggregator {
            config,
            sources: Vec::with_capacity(config.max_sources),
            next_close: None,
            latest_ns: i64::MIN,
        }
    }

    /// Counts one frame of `source` at `stamp_ns`: `Some(+1 / -1)` for a classified face,
    /// `None` for a frame without a usable face. Windows that close are passed to `emit`.
    pub fn add(
        &mut self,
        source: SourceId,
        stamp_ns: i64,
        label: Option<i8>,
        emit: &mut impl FnMut(&EngagementSecond),
    ) -> Result<(), AggregateError> {
        let window = stamp_ns.div_euclid(SECOND_NS);
        if let Some(next) = self.next_close
            && window < next
        {
            return Err(AggregateError::LateFrame {
                source_id: source,
                stamp_ns,
                closed_before_ns: next.saturating_mul(SECOND_NS),
            });
        }
        // Message time advances even if the frame is refused below; that may retire sources.
        self.advance_to(stamp_ns, emit);
        let at = match self.sources.iter().position(|s| s.id == source) {
            Some(at) => at,
            None if self.sources.len() >= self.config.max_sources => {
                return Err(AggregateError::TooManySources {
                    source_id: source,
                    max_sources: self.config.max_sources,
                });
            }
            None => {
                // Capacity was reserved for max_sources: this push does not allocate.
                self.sources.push(Source {
                    id: source,
                    windows: [EMPTY; 2],
                    smoother: ExponentialSmoother::new(
                        self.config.smoothing_alpha,
                        self.config.smoothing_adjust,
                    ),
                    since_window: window,
                    last_frame_ns: stamp_ns,
                });
                self.sources.len() - 1
            }
        };
        let s = &mut self.sources[at];
        s.since_window = s.since_window.min(window);
        s.last_frame_ns = s.last_frame_ns.max(stamp_ns);
        let slot = &mut s.windows[window.rem_euclid(2) as usize];
        if slot.index != window {
            *slot = Window {
                index: window,
                ..EMPTY
            };
        }
        match label {
            Some(l) if l > 0 => slot.engaged += 1,
            Some(_) => slot.disengaged += 1,
            None => slot.missing += 1,
        }
        Ok(())
    }

    /// Message time has reached `stamp_ns`: report every window that ended more than the
    /// allowed lateness ago.
    pub fn advance_to(&mut self, stamp_ns: i64, emit: &mut impl FnMut(&EngagementSecond)) {
        self.latest_ns = self.latest_ns.max(stamp_ns);
        let watermark = stamp_ns.saturating_sub(self.config.max_lateness_ns);
        let next = *self
            .next_close
            .get_or_insert(watermark.div_euclid(SECOND_NS));
        self.close_until(watermark.div_euclid(SECOND_NS).max(next), emit);
    }

    /// Message time jumped to `stamp_ns`: the clock that stamps the frames was stepped (NTP, a
    /// clock set by hand). Every window still open is reported as it is, and counting starts
    /// again at `stamp_ns`'s second. Without this, a step back left every later frame "late"
    /// until the clock caught up, and a step forward reported the seconds skipped as seconds
    /// without a face.
    pub fn restart_at(&mut self, stamp_ns: i64, emit: &mut impl FnMut(&EngagementSecond)) {
        self.flush(emit);
        self.next_close = None;
        self.latest_ns = i64::MIN;
        let window = stamp_ns.div_euclid(SECOND_NS);
        for s in &mut self.sources {
            s.windows = [EMPTY; 2];
            s.since_window = window;
            s.last_frame_ns = stamp_ns;
        }
    }

    /// End of stream: report every window that holds a frame.
    pub fn flush(&mut self, emit: &mut impl FnMut(&EngagementSecond)) {
        if self.latest_ns != i64::MIN {
            self.close_until(self.latest_ns.div_euclid(SECOND_NS) + 1, emit);
        }
    }

    /// Reports windows `next_close .. end` (exclusive) for every source.
    fn close_until(&mut self, end: i64, emit: &mut impl FnMut(&EngagementSecond)) {
        let Some(mut k) = self.next_close else {
            return;
        };
        while k < end {
            if self.sources.is_empty() {
                // Nobody to report for: skip the gap in one step.
                k = end;
                break;
            }
            let window_end_ns = (k + 1).saturating_mul(SECOND_NS);
            for s in &mut self.sources {
                let slot = &mut s.windows[k.rem_euclid(2) as usize];
                let w = if slot.index == k {
                    *slot
                } else {
                    Window { index: k, ..EMPTY }
                };
                *slot = EMPTY;
                if k < s.since_window {
                    continue;
                }
                let n = w.engaged + w.disengaged;
                let engagement = (n > 0)
                    .then(|| (f64::from(w.engaged) - f64::from(w.disengaged)) / f64::from(n));
                emit(&EngagementSecond {
                    source: s.id,
                    window_start_ns: k.saturating_mul(SECOND_NS),
                    window_end_ns,
                    engagement,
                    smoothed_engagement: engagement.map(|e| s.smoother.push(e)),
                    engaged_frames: w.engaged,
                    disengaged_frames: w.disengaged,
                    missing_frames: w.missing,
                });
            }
            let timeout = self.config.source_timeout_ns;
            self.sources
                .retain(|s| s.last_frame_ns.saturating_add(timeout) > window_end_ns);
            k += 1;
        }
        self.next_close = Some(k);
    }

    /// Sources currently reporting, in the order they appeared.
    pub fn source_ids(&self) -> impl Iterator<Item = SourceId> + '_ {
        self.sources.iter().map(|s| s.id)
    }
}
