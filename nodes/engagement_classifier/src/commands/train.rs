//! `train`: fits the preprocessing and a boosted ensemble on a labelled feature table and
//! writes it as an XGBoost JSON model (Python xgboost loads it as it is).

use anyhow::Context;
use engagement_classifier::train::{to_model_file, train};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Labelled CSV: participant, timestamp, engagement (1 / 0 / -1), of_AU01_c ... of_pose_Rz.
    #[arg(long)]
    data: PathBuf,
    /// Where to write the model (XGBoost JSON).
    #[arg(long)]
    output: PathBuf,
    /// Parameter file (default: params/engagement_classifier.yaml if present).
    #[arg(long)]
    params: Option<PathBuf>,
    /// Override neutral_label: engaged, disengaged or drop.
    #[arg(long)]
    neutral_label: Option<String>,
    /// Override decimal_repair: magnitude, missing or keep.
    #[arg(long)]
    decimal_repair: Option<String>,
    /// Stored in the model's `description` attribute.
    #[arg(
        long,
        default_value = "engagement classifier trained by engagement_classifier train"
    )]
    description: String,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let (params, table, report) = super::load_training_data(
        args.params.as_deref(),
        args.neutral_label,
        args.decimal_repair,
        &args.data,
    )?;
    tracing::info!("{}", report.summary());
    let train_params = params.train_params();
    let bar = super::progress_bar(train_params.n_estimators as u64, "trees");
    let booster = train(&table, &train_params, |t| bar.set_position(t as u64));
    bar.finish_and_clear();
    let file = to_model_file(&booster, &args.description);
    let text = serde_json::to_string(&file).context("serialising the model")?;
    atomic_file::write(&args.output, text.as_bytes())
        .with_context(|| format!("writing {}", args.output.display()))?;
    println!(
        "trained {} trees on {} frames of {} participants -> {}",
        booster.trees.len(),
        table.len(),
        table.participant_ids().len(),
        args.output.display()
    );
    Ok(())
}
