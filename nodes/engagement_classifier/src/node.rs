//! The engagement node's run loop, on any bus (`node_shell::Bus`: DDS on the robot, in process
//! in the cross-node tests). OpenFace frames in; per frame an `EngagementEstimate`, per second
//! of message time and source an `ExpectedEngagement` out, and with `ros4hri` the same second
//! as a ROS4HRI person's topics (REP-155). All logic is in `EngagementEstimator` and
//! `ros4hri::PersonEngagement`; the conversion of messages is `messages::Sources`.

use crate::messages::Sources;
use crate::ros4hri::{HriOutput, PersonEngagement};
use crate::{EngagementClassifierParams, EngagementEstimator, EngagementSecond, FrameOutcome};
use anyhow::Context;
use node_shell::{Bus, Outbox};
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
    params: EngagementClassifierParams,
    mut estimator: EngagementEstimator,
) -> anyhow::Result<()> {
    tracing::info!(model = %params.model_file, trees = estimator.model().tree_count(), "model loaded");
    let mut frames = bus.subscribe(OPENFACE_FEATURES, 512)?;
    let estimates = bus.publisher(ENGAGEMENT_ESTIMATE)?;
    let seconds = bus.publisher(EXPECTED_ENGAGEMENT)?;
    let mut states = bus.subscribe(GAME_STATE, 16)?;
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
            Some(frame) = frames.recv() => {
                let face = out.sources.face_frame(&frame);
                let stamp_ns = face.stamp_ns;
                let closed = &mut out.closed;
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
