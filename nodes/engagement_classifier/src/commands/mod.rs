//! Subcommands of the `engagement_classifier` binary and what they share: the parameter
//! file, the shared-data directory and progress bars.

mod cross_validate;
mod plot_study;
mod predict;
pub mod run;
mod synthesize;
mod train;

use anyhow::Context;
use engagement_classifier::EngagementClassifierParams;
use engagement_classifier::repair::CleaningReport;
use engagement_classifier::table::{FeatureTable, load_labelled_csv};
use std::path::{Path, PathBuf};

#[derive(clap::Subcommand)]
pub enum Command {
    /// Train a model on a labelled feature table and save it as XGBoost JSON.
    Train(train::Args),
    /// Leave-one-participant-out cross-validation on a labelled feature table.
    CrossValidate(cross_validate::Args),
    /// Margin and probability of engagement for every row of a feature CSV.
    Predict(predict::Args),
    /// Write a SYNTHETIC labelled feature table (for tests and demos).
    Synthesize(synthesize::Args),
    /// Plot one study participant's expected engagement over the session (paper Fig. 2).
    PlotStudy(plot_study::Args),
    /// Run the DDS node: OpenFace features in, engagement per frame and per second out.
    Run(run::Args),
}

impl Command {
    pub fn run(self) -> anyhow::Result<()> {
        match self {
            Command::Train(a) => train::run(a),
            Command::CrossValidate(a) => cross_validate::run(a),
            Command::Predict(a) => predict::run(a),
            Command::Synthesize(a) => synthesize::run(a),
            Command::PlotStudy(a) => plot_study::run(a),
            Command::Run(a) => run::run(a),
        }
    }
}

/// The parameter file the tools read unless told otherwise (relative to the workspace root).
const DEFAULT_PARAMS: &str = "params/engagement_classifier.yaml";

/// Reads `path`, or the default parameter file when it exists, or the built-in defaults.
pub fn load_params(path: Option<&Path>) -> anyhow::Result<EngagementClassifierParams> {
    let path = match path {
        Some(p) => p.to_path_buf(),
        None if Path::new(DEFAULT_PARAMS).exists() => PathBuf::from(DEFAULT_PARAMS),
        None => {
            tracing::info!("no {DEFAULT_PARAMS} here; using built-in defaults");
            return Ok(EngagementClassifierParams::default());
        }
    };
    let params = EngagementClassifierParams::from_yaml_file(&path)
        .with_context(|| format!("reading parameters {}", path.display()))?;
    tracing::info!("parameters from {}", path.display());
    Ok(params)
}

/// What `train` and `cross-validate` both start from: the parameters with the command line's
/// data-policy overrides, validated, and the labelled table read under them.
pub fn load_training_data(
    params: Option<&Path>,
    neutral_label: Option<String>,
    decimal_repair: Option<String>,
    data: &Path,
) -> anyhow::Result<(EngagementClassifierParams, FeatureTable, CleaningReport)> {
    let mut params = load_params(params)?;
    if let Some(v) = neutral_label {
        params.neutral_label = v;
    }
    if let Some(v) = decimal_repair {
        params.decimal_repair = v;
    }
    params.validate()?;
    let (table, report) = load_labelled_csv(data, &params.load_options()?)
        .with_context(|| format!("loading {}", data.display()))?;
    Ok((params, table, report))
}

/// `QT_SHARED_DIR`, else `../shared` beside the workspace.
pub fn shared_dir() -> PathBuf {
    std::env::var_os("QT_SHARED_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("../shared"))
}

/// A progress bar on stderr.
pub fn progress_bar(len: u64, what: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(len);
    let style = indicatif::ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} {elapsed}")
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar());
    bar.set_style(style.progress_chars("=> "));
    bar.set_message(what.to_string());
    bar
}
