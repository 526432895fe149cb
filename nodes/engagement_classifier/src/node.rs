//! The engagement node's run loop, on any bus (`node_shell::Bus`: DDS on the robot, in process
//! in the cross-node tests). OpenFace frames in; per frame an `EngagementEstimate`, per second
//! of message time and source an `ExpectedEngagement` out, and with `ros4hri` the same second
//! as a ROS4HRI person's topics (REP-155). All logic is in `EngagementEstimator` and
//! `ros4hri::PersonEngagement`; the conversion of messages is `messages::Sources`. When the
//! machine's wall clock is stepped, the frames' stamps jump with it: `FramesClock` tells such a
//! jump from a late or stalled frame, and the seconds are counted again from the new time.

use crate::messages::Sources;
use crate::ros4hri::{HriOutput, PersonEngagement};
use crate::{EngagementClassifierParams, EngagementEstimator, EngagementSecond, FrameOutcome};
use anyhow::Context;
use clock_steps::ClockSteps;
use node_shell::{Bus, Clock, Outbox};
use qt_therapy_msgs::hri_msgs::{EngagementLevel, IdsList};
use qt_therapy_msgs::std_msgs::BoolMsg;
use qt_therapy_msgs::topics::{
    ENGAGEMENT_ESTIMATE, EXPECTED_ENGAGEMENT, GAME_STATE, OPENFACE_FEATURES, PERSONS_KNOWN,
    PERSONS_TRACKED, engagement_status, person_anonymous,
};
use qt_therapy_msgs::{EngagementEstimate, ExpectedEngagement};
use std::collections::HashMap;
use std::path::Path;
use std::time::Duration;
use tokio::time::Instant;

/// The node's name on the graph (and its parameter file's).
pub const NODE: &str = "engagement_classifier";

/// The model `params` name, loaded (relative paths from the working directory): done before
/// the node joins the graph, so a bad model file stops it without it ever appearing to its
/// peers. `params_file` is named in the error.
pub fn estimator(
    params: &EngagementClassifierParams,
    params_file: &Path,
) -> anyhow::Result<EngagementEstimator> {
    EngagementEstimator::from_params(params, Path::new("."))
        .with_context(|| format!("setting up from {}", params_file.display()))
}

/// Classifies frames with `estimator` until the node is asked to stop, then reports the last
/// seconds.
pub async fn run<B: Bus>(
    bus: &mut B,
    mut params: EngagementClassifierParams,
    mut estimator: EngagementEstimator,
) -> anyhow::Result<()> {
    tracing::info!(model = %params.model_file, trees = estimator.model().tree_count(), "model loaded");
    let mut frames = bus.subscribe(OPENFACE_FEATURES, 512)?;
    let estimates = bus.publisher(ENGAGEMENT_ESTIMATE)?;
    let seconds = bus.publisher(EXPECTED_ENGAGEMENT)?;
    let mut states = bus.subscribe(GAME_STATE, 16)?;
    // `ros2 param set` of min_confidence and the ROS4HRI thresholds.
    let mut changes = bus.parameter_changes::<EngagementClassifierParams>();
    let mut hri = if params.ros4hri {
        Some(Ros4Hri {
            tracked: bus.publisher(PERSONS_TRACKED)?,
            known: bus.publisher(PERSONS_KNOWN)?,
            persons: HashMap::new(),
        })
    } else {
        None
    };
    let mut out = Closed {
        seconds: &seconds,
        sources: Sources::default(),
        persons: PersonEngagement::new(&params),
        hri: &mut hri,
        closed: Vec::with_capacity(16),
    };
    let drops = bus.drops();
    let clock = bus.clock();
    let mut frames_clock = FramesClock::default();
    // Message time runs on between frames at the clock's pace, so a camera that stops
    // still gets its last seconds reported.
    let mut last_stamp: Option<(i64, Instant)> = None;
    let mut tick = tokio::time::interval(Duration::from_millis(250));
    let stop = bus.shutdown_signal();
    tokio::pin!(stop);
    loop {
        // Biased: what is ready is taken in this order, never by tokio's random pick, so a
        // run on the in-process bus is the same every time.
        tokio::select! {
            biased;
            _ = &mut stop => break,
            Some(g) = states.recv() => out.persons.on_game_state(&g),
            Some(change) = changes.recv() => {
                let result = params.change(change.parameters.clone());
                if result.is_ok() {
                    estimator.set_min_confidence(params.min_confidence);
                    out.persons.set_thresholds(&params);
                    tracing::info!(min_confidence = params.min_confidence,
                        engaged = params.ros4hri_engaged_threshold,
                        disengaged = params.ros4hri_disengaged_threshold, "parameters changed");
                }
                change.respond(result);
            }
            Some(frame) = frames.recv() => {
                let face = out.sources.face_frame(&frame);
                let stamp_ns = face.stamp_ns;
                let closed = &mut out.closed;
                let expected = last_stamp.map(|(stamp, at)| stamp + at.elapsed().as_nanos() as i64);
                if let Some(by) = frames_clock.stepped(read(&clock), stamp_ns, expected) {
                    tracing::warn!("the frames' clock stepped {:+.3} s with this machine's: \
                        the open seconds are reported and counting starts again", by as f64 * 1e-9);
                    estimator.restart_at(stamp_ns, &mut |s| closed.push(*s));
                }
                match estimator.on_frame(&face, &mut |s| closed.push(*s)) {
                    Ok(outcome) => {
                        let (label, probability) = match outcome {
                            FrameOutcome::Classified(p) => (p.label, p.probability),
                            FrameOutcome::Missing(_) => (EngagementEstimate::MISSING, f32::NAN),
                        };
                        estimates.send(EngagementEstimate { header: frame.header.clone(), face_id: frame.face_id.clone(), label, probability });
                    }
                    Err(e) => {
                        drops.record(OPENFACE_FEATURES.name, &e.to_string());
                    }
                }
                last_stamp = Some((stamp_ns, Instant::now()));
                out.publish(bus);
            }
            _ = tick.tick() => {
                frames_clock.read(read(&clock));
                if let Some((stamp, at)) = last_stamp {
                    let now = stamp + at.elapsed().as_nanos() as i64;
                    let closed = &mut out.closed;
                    estimator.advance_to(now, &mut |s| closed.push(*s));
                    out.publish(bus);
                }
            }
        }
    }
    let closed = &mut out.closed;
    estimator.flush(&mut |s| closed.push(*s));
    out.publish(bus);
    if let Some(hri) = out.hri.as_mut() {
        hri.publish(out.persons.close(bus.clock().now()), bus);
    }
    Ok(())
}

/// The seconds the estimator closed, and where they go.
struct Closed<'a> {
    seconds: &'a Outbox<ExpectedEngagement>,
    sources: Sources,
    persons: PersonEngagement,
    hri: &'a mut Option<Ros4Hri>,
    closed: Vec<EngagementSecond>,
}

impl Closed<'_> {
    /// Publishes the closed seconds (and their ROS4HRI person's topics).
    fn publish(&mut self, bus: &mut impl Bus) {
        for s in self.closed.drain(..) {
            let second = self.sources.expected_engagement(&s);
            self.seconds.send(second.clone());
            if let Some(hri) = self.hri.as_mut() {
                hri.publish(self.persons.on_second(&second), bus);
            }
        }
    }
}

/// The ROS4HRI topics: the two lists, and each reported person's own.
struct Ros4Hri {
    tracked: Outbox<IdsList>,
    known: Outbox<IdsList>,
    /// One pair of publishers per person reported now (a few at most); dropped when the
    /// person ends, so its topics leave the graph.
    persons: HashMap<String, PersonTopics>,
}

struct PersonTopics {
    /// Latched: kept for libhri's subscription made once the lists name the person.
    anonymous: Outbox<BoolMsg>,
    engagement: Outbox<EngagementLevel>,
}

impl Ros4Hri {
    fn publish(&mut self, outputs: Vec<HriOutput>, bus: &mut impl Bus) {
        for o in outputs {
            match o {
                HriOutput::NewPerson { person, anonymous } => {
                    let topics = bus.publisher(person_anonymous(&person)).and_then(|a| {
                        Ok(PersonTopics {
                            engagement: bus.publisher(engagement_status(&person))?,
                            anonymous: a,
                        })
                    });
                    match topics {
                        Ok(topics) => {
                            topics.anonymous.send(anonymous);
                            tracing::info!("ROS4HRI: a face seen, person {person}");
                            self.persons.insert(person, topics);
                        }
                        Err(e) => tracing::warn!("no ROS4HRI topics for {person}: {e:#}"),
                    }
                }
                HriOutput::Engagement { person, level } => {
                    if let Some(topics) = self.persons.get(&person) {
                        topics.engagement.send(level);
                    }
                }
                HriOutput::Tracked(ids) => {
                    self.tracked.send(ids);
                }
                HriOutput::Known(ids) => {
                    self.known.send(ids);
                }
                HriOutput::PersonGone { person } => {
                    if self.persons.remove(&person).is_some() {
                        tracing::info!("ROS4HRI: person {person} ended");
                    }
                }
            }
        }
    }
}

/// Whether a frame's stamp jumped because this machine's wall clock was stepped. The node
/// follows its own clocks (`ClockSteps`); a step of them is pending until a frame comes
/// stamped that far from where message time would be (the camera's clock, on the same
/// machine, stepped with it). Frames stamped before the step and received after it, late
/// frames, and a camera that stalled and catches up keep the seconds as they are.
#[derive(Debug, Default)]
struct FramesClock {
    own: ClockSteps,
    /// This machine's steps not yet seen in the frames' stamps, added up.
    pending_ns: i64,
}

/// How close a frame's jump must come to the machine's step to be it: frames arrive within
/// milliseconds of their stamps, and message time runs on between them.
const STEP_MATCH_NS: i64 = 2_000_000_000;

/// The node's steady and wall clocks, read together.
fn read(clock: &Clock) -> (i64, i64) {
    (clock.steady_nanos(), clock.now_nanos())
}

impl FramesClock {
    /// This machine's clocks read as (steady, wall).
    fn read(&mut self, (steady_ns, wall_ns): (i64, i64)) {
        if let Some(step) = self.own.observe(steady_ns, wall_ns) {
            self.pending_ns += step.by_ns;
        }
    }

    /// A frame stamped `stamp_ns`, where message time would be `expected_ns`, received when
    /// the clocks read `clocks`: the step it shows, if it is one.
    fn stepped(
        &mut self,
        clocks: (i64, i64),
        stamp_ns: i64,
        expected_ns: Option<i64>,
    ) -> Option<i64> {
        self.read(clocks);
        let expected_ns = expected_ns?;
        let jump = stamp_ns - expected_ns;
        // A jump within a second is a frame the seconds take as it is (late or early).
        if jump.abs() <= STEP_MATCH_NS / 2 || (jump - self.pending_ns).abs() > STEP_MATCH_NS {
            return None;
        }
        self.pending_ns = 0;
        Some(jump)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: i64 = 1_000_000_000;
    const T0: i64 = 1_780_000_000 * S;

    #[test]
    fn a_jump_of_the_frames_is_a_step_only_when_this_machine_stepped_that_far() {
        for by in [-3600 * S, 7200 * S] {
            let mut c = FramesClock::default();
            c.read((T0, T0));
            // Frames every 33 ms, on time.
            assert_eq!(
                c.stepped((T0 + S, T0 + S), T0 + S, Some(T0 + S - S / 100)),
                None
            );
            // A camera that stalled 6 s and catches up, and a late frame: no step.
            assert_eq!(
                c.stepped((T0 + 8 * S, T0 + 8 * S), T0 + 2 * S, Some(T0 + 8 * S)),
                None
            );
            // The machine steps; a frame stamped before it, received after it: as it is.
            let after = (T0 + 9 * S, T0 + 9 * S + by);
            assert_eq!(
                c.stepped(after, T0 + 9 * S - S / 50, Some(T0 + 9 * S)),
                None
            );
            // The first frame stamped by the stepped clock.
            assert_eq!(
                c.stepped(after, T0 + 9 * S + by, Some(T0 + 9 * S)),
                Some(by)
            );
            // Then frames follow again.
            let later = (T0 + 10 * S, T0 + 10 * S + by);
            assert_eq!(
                c.stepped(later, T0 + 10 * S + by, Some(T0 + 10 * S + by)),
                None
            );
        }
    }
}
