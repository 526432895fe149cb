//! `plot-study`: the paper's Fig. 2 for one participant of the MigrAVE study: expected
//! engagement per second (and smoothed), answer moments and stage ends, as SVG and PNG.

use anyhow::Context;
use engagement_classifier::plot::{EngagementPlot, write_engagement_plot};
use engagement_classifier::study::load_study_session;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Study directory (default: $QT_SHARED_DIR/data/migrave-study or ../shared/...).
    #[arg(long)]
    study_dir: Option<PathBuf>,
    /// Pseudonymous participant id (the authors' notebook plots 1CZ1CL1P).
    #[arg(long, default_value = "1CZ1CL1P")]
    participant: String,
    /// Output path without extension; .svg and .png are written.
    #[arg(long)]
    output: Option<PathBuf>,
    /// Parameter file (default: params/engagement_classifier.yaml if present).
    #[arg(long)]
    params: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let params = super::load_params(args.params.as_deref())?;
    let dir = args
        .study_dir
        .unwrap_or_else(|| super::shared_dir().join("data/migrave-study"));
    let session = load_study_session(&dir, &args.participant, params.smoothing_alpha)
        .with_context(|| format!("reading the study records in {}", dir.display()))?;
    let title = format!(
        "Expected engagement, participant {} (MigrAVE study)",
        session.participant
    );
    let plot = EngagementPlot {
        title: &title,
        seconds: &session.seconds,
        engagement: &session.engagement,
        smoothed: &session.smoothed,
        answers: &session.answers,
        stage_ends: &session.stage_ends,
    };
    let stem = args
        .output
        .unwrap_or_else(|| PathBuf::from(format!("out/engagement_{}", session.participant)));
    let (svg, png) = write_engagement_plot(&stem, &plot)?;
    println!("{} and {}", svg.display(), png.display());
    Ok(())
}
