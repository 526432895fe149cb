//! `synthesize`: writes a SYNTHETIC labelled feature table from the seeded generator (engaged:
//! head towards the robot, gaze near 0; disengaged: head turned or down). For tests and demos.

use anyhow::Context;
use engagement_classifier::synthetic::{SyntheticSpec, generate};
use engagement_classifier::table::write_labelled_csv;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Output CSV (participant, timestamp, engagement, of_AU01_c ... of_pose_Rz).
    #[arg(long)]
    output: PathBuf,
    #[arg(long, default_value_t = 6)]
    participants: usize,
    #[arg(long, default_value_t = 600)]
    frames_per_participant: usize,
    /// Share of labels flipped.
    #[arg(long, default_value_t = 0.03)]
    label_noise: f64,
    /// Seed (default: `seed` from the parameter file).
    #[arg(long)]
    seed: Option<u64>,
    /// Parameter file (default: params/engagement_classifier.yaml if present).
    #[arg(long)]
    params: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let seed = match args.seed {
        Some(s) => s,
        None => super::load_params(args.params.as_deref())?.seed as u64,
    };
    anyhow::ensure!(
        (0.0..=1.0).contains(&args.label_noise),
        "--label-noise {} is not in [0, 1]",
        args.label_noise
    );
    let spec = SyntheticSpec {
        participants: args.participants,
        frames_per_participant: args.frames_per_participant,
        label_noise: args.label_noise,
        seed,
        ..SyntheticSpec::default()
    };
    let table = generate(&spec);
    write_labelled_csv(&args.output, &table)
        .with_context(|| format!("writing {}", args.output.display()))?;
    println!(
        "SYNTHETIC data: {} frames of {} participants (seed {seed}) -> {}",
        table.len(),
        spec.participants,
        args.output.display()
    );
    Ok(())
}
