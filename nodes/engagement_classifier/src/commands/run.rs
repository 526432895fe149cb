//! `engagement_classifier run`: the DDS node. OpenFace frames in; per frame an
//! `EngagementEstimate`, per second of message time and source an `ExpectedEngagement` out,
//! and with `ros4hri` the same second as a ROS4HRI person's topics (REP-155). All logic is in
//! `EngagementEstimator` and `ros4hri::PersonEngagement`; the conversion of messages is
//! `messages::Sources`.

use anyhow::Context;
use engagement_classifier::messages::Sources;
use engagement_classifier::ros4hri::{HriOutput, PersonEngagement};
use engagement_classifier::{
    EngagementClassifierParams, EngagementEstimator, EngagementSecond, FrameOutcome,
};
use node_shell::{NodeShell, Outbox, ShellOptions};
use qt_therapy_msgs::EngagementEstimate;
use qt_therapy_msgs::hri_msgs::{EngagementLevel, IdsList};
use qt_therapy_msgs::std_msgs::BoolMsg;
use qt_therapy_msgs::topics::{
    ENGAGEMENT_ESTIMATE, EXPECTED_ENGAGEMENT, GAME_STATE, OPENFACE_FEATURES, PERSONS_KNOWN,
    PERSONS_TRACKED, engagement_status, person_anonymous,
};
use std::collections::HashMap;
use std::path::Path;
use std::time::{Duration, Instant};

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    shell: ShellOptions,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    // One thread: each frame is microseconds of work and nothing here blocks, and a frame
    // handed from node_shell's reader task to this loop then wakes no other thread (40-50 µs
    // a frame at the median on the multi-threaded runtime: docs/performance.md, "DDS").
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?
        .block_on(serve(args))
}

const NODE: &str = "engagement_classifier";

/// The parameters and the model, read before the node joins the ROS graph: a bad parameter or
/// model file stops it at start-up without it ever appearing to its peers.
fn set_up(
    options: &ShellOptions,
) -> anyhow::Result<(EngagementClassifierParams, EngagementEstimator)> {
    let (params, path): (EngagementClassifierParams, _) = options.parameters(NODE)?;
    let estimator = EngagementEstimator::from_params(&params, Path::new("."))
        .with_context(|| format!("setting up from {}", path.display()))?;
    Ok((params, estimator))
}

async fn serve(args: Args) -> anyhow::Result<()> {
    let (params, mut estimator) = set_up(&args.shell)?;
    // The shell reads the same file and overrides again; those parameters are already checked.
    let (mut shell, _): (NodeShell, EngagementClassifierParams) =
        NodeShell::start(NODE, &args.shell)?;
    tracing::info!(model = %params.model_file, trees = estimator.model().tree_count(), "model loaded");
    {
        let mut frames = shell.subscribe(OPENFACE_FEATURES, 512)?;
        let estimates = shell.publisher(ENGAGEMENT_ESTIMATE)?;
        let seconds = shell.publisher(EXPECTED_ENGAGEMENT)?;
        let mut states = shell.subscribe(GAME_STATE, 16)?;
        let mut hri = if params.ros4hri {
            Some(Ros4Hri {
                tracked: shell.publisher(PERSONS_TRACKED)?,
                known: shell.publisher(PERSONS_KNOWN)?,
                persons: HashMap::new(),
            })
        } else {
            None
        };
        let mut persons = PersonEngagement::new(&params);
        let drops = shell.drops();
        let mut sources = Sources::default();
        let mut closed: Vec<EngagementSecond> = Vec::with_capacity(16);
        let publish_closed = |closed: &mut Vec<EngagementSecond>,
                              sources: &Sources,
                              persons: &mut PersonEngagement,
                              hri: &mut Option<Ros4Hri>,
                              shell: &mut NodeShell| {
            for s in closed.drain(..) {
                let second = sources.expected_engagement(&s);
                seconds.send(second.clone());
                if let Some(hri) = hri {
                    hri.publish(persons.on_second(&second), shell);
                }
            }
        };
        // Message time runs on between frames at the wall clock's pace, so a camera that stops
        // still gets its last seconds reported.
        let mut last_stamp: Option<(i64, Instant)> = None;
        let mut tick = tokio::time::interval(Duration::from_millis(250));
        let stop = shell.shutdown_signal();
        tokio::pin!(stop);
        loop {
            tokio::select! {
                _ = &mut stop => break,
                Some(frame) = frames.recv() => {
                    let face = sources.face_frame(&frame);
                    let stamp_ns = face.stamp_ns;
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
                    publish_closed(&mut closed, &sources, &mut persons, &mut hri, &mut shell);
                }
                Some(g) = states.recv() => persons.on_game_state(&g),
                _ = tick.tick() => {
                    if let Some((stamp, at)) = last_stamp {
                        let now = stamp + at.elapsed().as_nanos() as i64;
                        estimator.advance_to(now, &mut |s| closed.push(*s));
                        publish_closed(&mut closed, &sources, &mut persons, &mut hri, &mut shell);
                    }
                }
            }
        }
        estimator.flush(&mut |s| closed.push(*s));
        publish_closed(&mut closed, &sources, &mut persons, &mut hri, &mut shell);
        if let Some(hri) = &mut hri {
            hri.publish(persons.close(node_shell::header_now().stamp), &mut shell);
        }
    }
    shell.stop().await;
    Ok(())
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
    fn publish(&mut self, outputs: Vec<HriOutput>, shell: &mut NodeShell) {
        for o in outputs {
            match o {
                HriOutput::NewPerson { person, anonymous } => {
                    let topics = shell.publisher(person_anonymous(&person)).and_then(|a| {
                        Ok(PersonTopics {
                            engagement: shell.publisher(engagement_status(&person))?,
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
