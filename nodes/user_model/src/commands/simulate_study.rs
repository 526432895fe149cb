//! `user_model simulate-study`: writes a SYNTHETIC data set shaped like the paper's study (no
//! real person behind it) in our CSV format.

use anyhow::Context;
use std::io::Write;
use std::path::PathBuf;
use user_models::simulate::{StudySpec, simulate_study};

#[derive(clap::Args)]
pub struct Args {
    /// The CSV file to write.
    #[arg(long)]
    output: PathBuf,
    #[arg(long, default_value_t = 7)]
    seed: u64,
}

pub fn main(a: Args) -> anyhow::Result<()> {
    let spec = StudySpec {
        seed: a.seed,
        ..StudySpec::default()
    };
    let records = simulate_study(&spec);
    user_models::data::write_csv(&a.output, &records)
        .with_context(|| format!("writing {}", a.output.display()))?;
    // Written with errors returned (a closed pipe is not a panic).
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "wrote {} SYNTHETIC records of {} simulated users ({} engaged, {} disengaged) to {}",
        records.len(),
        spec.engaged_users + spec.disengaged_users,
        spec.engaged_users,
        spec.disengaged_users,
        a.output.display()
    )?;
    Ok(())
}
