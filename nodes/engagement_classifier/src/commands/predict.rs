//! `predict`: margin and probability of engagement for each row of a CSV whose header names
//! the 32 OpenFace columns (any order, extra columns ignored).

use anyhow::Context;
use engagement_classifier::EngagementModel;
use engagement_classifier::table::read_feature_csv;
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// XGBoost JSON model.
    #[arg(long)]
    model: PathBuf,
    /// CSV with the 32 feature columns (`of_AU01_c` or `AU01_c` ...).
    #[arg(long)]
    input: PathBuf,
    /// Output CSV (margin, probability, label); standard output if not given.
    #[arg(long)]
    output: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let model = EngagementModel::load(&args.model)?;
    let rows = read_feature_csv(&args.input)?;
    let mut out = String::with_capacity(rows.len() * 40 + 32);
    out.push_str("margin,probability,label\n");
    for row in &rows {
        let p = model.predict(row);
        // f32 Display is the shortest text that parses back to the same f32.
        let _ = writeln!(out, "{},{},{}", p.margin, p.probability, p.label);
    }
    match &args.output {
        Some(path) => {
            atomic_file::write(path, out.as_bytes())
                .with_context(|| format!("writing {}", path.display()))?;
            tracing::info!("{} rows -> {}", rows.len(), path.display());
        }
        None => print!("{out}"),
    }
    Ok(())
}
