//! `cross-validate`: leave-one-participant-out accuracy per fold and their mean, as the paper
//! reports it. `--export-folds` also writes each fold's prepared matrices and our
//! probabilities, so a reference (Python xgboost) can be run on exactly the same inputs.

use anyhow::Context;
use engagement_classifier::cross_validation::{Fold, FoldResult, mean_accuracy, run_fold};
use engagement_classifier::features::{AUTHORS_FEATURE_ORDER, FEATURE_COUNT, model_feature_name};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct Args {
    /// Labelled CSV: participant, timestamp, engagement (1 / 0 / -1), of_AU01_c ... of_pose_Rz.
    #[arg(long)]
    data: PathBuf,
    /// Parameter file (default: params/engagement_classifier.yaml if present).
    #[arg(long)]
    params: Option<PathBuf>,
    /// Override neutral_label: engaged, disengaged or drop.
    #[arg(long)]
    neutral_label: Option<String>,
    /// Override decimal_repair: magnitude, missing or keep.
    #[arg(long)]
    decimal_repair: Option<String>,
    /// Directory for each fold's train/test matrices and our test probabilities (CSV). Keep
    /// it outside the repository when the data is real.
    #[arg(long)]
    export_folds: Option<PathBuf>,
    /// Write the per-fold results as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
}

fn matrix_csv(
    rows: &[[f32; FEATURE_COUNT]],
    labels: &[i8],
    probabilities: Option<&[f32]>,
) -> String {
    let mut out = String::with_capacity(rows.len() * 300);
    let names: Vec<String> = AUTHORS_FEATURE_ORDER
        .iter()
        .map(|&c| model_feature_name(c))
        .collect();
    let _ = write!(out, "{},label", names.join(","));
    if probabilities.is_some() {
        out.push_str(",our_probability");
    }
    out.push('\n');
    for (i, row) in rows.iter().enumerate() {
        for v in row {
            // Shortest text that parses back to the same f32 (NaN as "nan").
            let _ = write!(out, "{v},");
        }
        let _ = write!(out, "{}", u8::from(labels[i] > 0));
        if let Some(p) = probabilities {
            let _ = write!(out, ",{}", p[i]);
        }
        out.push('\n');
    }
    out
}

fn export(dir: &Path, fold: &Fold, result: &FoldResult) -> anyhow::Result<()> {
    let train_labels: Vec<i8> = fold
        .train
        .targets
        .iter()
        .map(|&y| if y > 0.5 { 1 } else { -1 })
        .collect();
    let files = [
        (
            format!("fold_{}_train.csv", fold.participant),
            matrix_csv(&fold.train.rows, &train_labels, None),
        ),
        (
            format!("fold_{}_test.csv", fold.participant),
            matrix_csv(
                &fold.test_rows,
                &fold.test_labels,
                Some(&result.probabilities),
            ),
        ),
    ];
    for (name, text) in files {
        let path = dir.join(name);
        atomic_file::write(&path, text.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let (params, table, report) = super::load_training_data(
        args.params.as_deref(),
        args.neutral_label,
        args.decimal_repair,
        &args.data,
    )?;
    println!("{}", report.summary());
    let participants = table.participant_ids();
    anyhow::ensure!(
        participants.len() >= 2,
        "cross-validation needs at least 2 participants"
    );
    let train_params = params.train_params();
    let per_fold = train_params.n_estimators as u64;
    let bar = super::progress_bar(per_fold * participants.len() as u64, "folds x trees");
    let mut results = Vec::new();
    for (f, participant) in participants.iter().enumerate() {
        let fold = Fold::new(&table, participant);
        let result = run_fold(&fold, &train_params, |t| {
            bar.set_position(f as u64 * per_fold + t as u64)
        });
        if let Some(dir) = &args.export_folds {
            export(dir, &fold, &result)?;
        }
        results.push(result);
    }
    bar.finish_and_clear();
    println!(
        "leave-one-participant-out, neutral_label={}, decimal_repair={}, {} trees, depth {}, eta {}",
        params.neutral_label,
        params.decimal_repair,
        train_params.n_estimators,
        train_params.max_depth,
        train_params.learning_rate
    );
    println!("participant  train  test  accuracy");
    for r in &results {
        println!(
            "{:<11} {:>6} {:>5}  {:.4}",
            r.participant,
            r.train_rows,
            r.test_rows,
            r.accuracy()
        );
    }
    println!("mean accuracy {:.4}", mean_accuracy(&results));
    if let Some(path) = &args.json {
        let folds: Vec<serde_json::Value> = results
            .iter()
            .map(|r| {
                serde_json::json!({"participant": r.participant, "train_rows": r.train_rows,
                    "test_rows": r.test_rows, "accuracy": r.accuracy()})
            })
            .collect();
        let doc = serde_json::json!({"neutral_label": params.neutral_label,
            "decimal_repair": params.decimal_repair, "folds": folds,
            "mean_accuracy": mean_accuracy(&results)});
        atomic_file::write(path, serde_json::to_string_pretty(&doc)?.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}
