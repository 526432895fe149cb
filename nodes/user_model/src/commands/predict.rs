//! `user_model predict`: prints F^p and F^e (mean, std) of every cluster and every input of a
//! model file as CSV on stdout, one row per (cluster, L, F, PS, O).

use anyhow::Context;
use sequence_game::{ModelInput, Outcome};
use std::io::Write;
use std::path::PathBuf;
use user_models::UserModelSet;

#[derive(clap::Args)]
pub struct Args {
    /// A model file written by `user_model fit`.
    #[arg(long)]
    model: PathBuf,
}

pub fn main(a: Args) -> anyhow::Result<()> {
    let set =
        UserModelSet::load(&a.model).with_context(|| format!("loading {}", a.model.display()))?;
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    writeln!(
        out,
        "cluster,level,feedback,previous_score,outcome,p_success,p_success_std,engagement,engagement_std"
    )?;
    for table in set.tables() {
        for input in ModelInput::all() {
            let p = table.success(input);
            for outcome in Outcome::ALL {
                let e = table.engagement(input, outcome);
                writeln!(
                    out,
                    "{},{},{},{},{},{:.6},{:.6},{:.6},{:.6}",
                    table.cluster,
                    input.level.get(),
                    u8::from(input.feedback),
                    input.previous_score,
                    outcome.sign(),
                    p.mean,
                    p.std,
                    e.mean,
                    e.std
                )?;
            }
        }
    }
    out.flush()?;
    Ok(())
}
