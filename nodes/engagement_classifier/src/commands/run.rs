//! `engagement_classifier run`: the DDS node. OpenFace frames in; per frame an
//! `EngagementEstimate`, per second of message time and source an `ExpectedEngagement` out.
//! All logic is in `EngagementEstimator`; the conversion of messages is `messages::Sources`.

use anyhow::Context;
use engagement_classifier::messages::Sources;
use engagement_classifier::{
    EngagementClassifierParams, EngagementEstimator, EngagementSecond, FrameOutcome,
};
use node_shell::{NodeShell, Outbox, ShellOptions};
use qt_therapy_msgs::topics::{ENGAGEMENT_ESTIMATE, EXPECTED_ENGAGEMENT, OPENFACE_FEATURES};
use qt_therapy_msgs::{EngagementEstimate, ExpectedEngagement};
use std::path::Path;
use std::time::{Duration, Instant};

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    shell: ShellOptions,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    tokio::runtime::Builder::new_multi_thread()
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
        let drops = shell.drops();
        let mut sources = Sources::default();
        let mut closed: Vec<EngagementSecond> = Vec::with_capacity(16);
        let publish_closed = |closed: &mut Vec<EngagementSecond>,
                              sources: &Sources,
                              out: &Outbox<ExpectedEngagement>| {
            for s in closed.drain(..) {
                out.send(sources.expected_engagement(&s));
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
                    publish_closed(&mut closed, &sources, &seconds);
                }
                _ = tick.tick() => {
                    if let Some((stamp, at)) = last_stamp {
                        let now = stamp + at.elapsed().as_nanos() as i64;
                        estimator.advance_to(now, &mut |s| closed.push(*s));
                        publish_closed(&mut closed, &sources, &seconds);
                    }
                }
            }
        }
        estimator.flush(&mut |s| closed.push(*s));
        publish_closed(&mut closed, &sources, &seconds);
    }
    shell.stop().await;
    Ok(())
}
