//! `policy_lab child-belief-prior`: the prior covariance of a child's own model for the
//! behaviour policy node (`child_belief: true`), learned from a study as `per-child-belief`'s
//! learned-covariance arms learn it: each study child's own model against their cluster's
//! model in the node's user-model file, the second moment of those deviations shrunk towards
//! its diagonal with a floor on every variance. The file holds that covariance alone, no
//! child's model.

use anyhow::Context;
use child_belief::LearnedCovariance;
use child_belief::prior_file::PriorFile;
use policy_lab::child_study::per_child_belief::BeliefSpec;
use std::path::PathBuf;
use user_models::UserModelSet;

#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// The study's records (a folder in the migrave-study layout).
    #[arg(long, default_value = "../shared/data/migrave-study")]
    study: PathBuf,
    /// The user-model file the node plays (its clusters' models are the prior means).
    #[arg(long, default_value = "nodes/user_model/models/migrave_study_c2.json")]
    user_models: PathBuf,
    /// Shrinkage of the correlations towards 0 (0: the sample covariance, 1: its diagonal).
    #[arg(long, default_value_t = BeliefSpec::default().shrinkage)]
    shrinkage: f64,
    /// The least variance of any input.
    #[arg(long, default_value_t = BeliefSpec::default().variance_floor)]
    variance_floor: f64,
    /// The covariance is multiplied by this (the study's chosen rule doubles it: a child may
    /// lie further from their cluster than the known children did).
    #[arg(long, default_value_t = BeliefSpec::default().covariance_scale)]
    scale: f64,
    /// Seed of the children's own fits (as `per-child`'s --seed).
    #[arg(long, default_value_t = 7)]
    seed: u64,
    #[arg(
        long,
        default_value = "nodes/behaviour_policy/models/child_belief_prior_c2.json"
    )]
    output: PathBuf,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if !args.study.is_dir() {
        anyhow::bail!(
            "{}: no such folder (the study's records; ../shared/data/migrave-study beside the \
             repository, or --study DIR)",
            args.study.display()
        );
    }
    if !(args.scale.is_finite() && args.scale > 0.0) {
        anyhow::bail!("--scale {} must be a number > 0", args.scale);
    }
    let records = user_models::data::study::read_study(&args.study)
        .with_context(|| format!("reading the study in {}", args.study.display()))?;
    let set = UserModelSet::load(&args.user_models)
        .with_context(|| format!("user models {}", args.user_models.display()))?;
    let fit = user_models::FitOptions {
        seed: args.seed,
        provenance: format!("{} (one child)", args.study.display()),
        ..Default::default()
    };
    let mut pairs = Vec::new();
    let mut per_cluster = vec![0usize; set.tables().len()];
    for (user, vector) in user_models::fit::user_vectors(&records)? {
        let cluster = set
            .assign_cluster(&vector)
            .with_context(|| format!("assigning {user} a cluster"))?;
        let own = user_models::fit::fit_user(&user, &records, &fit)
            .with_context(|| format!("fitting {user}'s own model"))?;
        per_cluster[cluster] += 1;
        pairs.push((own, set.table(cluster as i64)?.clone()));
    }
    let borrowed: Vec<_> = pairs.iter().map(|(c, p)| (c, p)).collect();
    let mut covariance =
        LearnedCovariance::from_children(&borrowed, args.shrinkage, args.variance_floor)?;
    covariance.success *= args.scale;
    covariance.engagement *= args.scale;
    let mean_sd = |variances: Vec<f64>| {
        variances.iter().map(|v| v.sqrt()).sum::<f64>() / variances.len() as f64
    };
    println!(
        "{} children (per cluster {:?}); mean prior sd of P(success) {:.3}, of engagement {:.3}",
        pairs.len(),
        per_cluster,
        mean_sd(covariance.success.diagonal().iter().copied().collect()),
        mean_sd(covariance.engagement.diagonal().iter().copied().collect())
    );
    let file = PriorFile::new(
        &covariance,
        format!(
            "policy_lab child-belief-prior: {} children of {} against their clusters in {}",
            pairs.len(),
            args.study.display(),
            args.user_models.display()
        ),
        pairs.len(),
        (args.shrinkage, args.variance_floor, args.scale),
    );
    if let Some(dir) = args.output.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    file.save(&args.output)?;
    // Read back as the node reads it: a file the node would refuse is not left as written.
    PriorFile::load(&args.output)?;
    println!("wrote {}", args.output.display());
    Ok(())
}
