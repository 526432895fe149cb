//! `policy_lab train`: pretrains one cluster's Q-table in simulation and writes it as a
//! Q-table file for the node: R runs, the best by mean return over its last epoch is kept.
//! With `--transfer-from k`, cluster k's best RE + βE policy initialises the table, which is
//! then trained exploitation-only (the paper's policy transfer).

use super::{LearningArgs, parse_reward, progress_bar, user_models};
use anyhow::{Context, bail};
use instance_lock::InstanceLock;
use q_learning::simulation::{SessionSettings, SimulatedUser};
use q_learning::training::{EpochScheme, Run, RunSpec, best_run, train_run};
use q_learning::{Mode, QTable, QTableFile, QTableOwner, Reward};
use rayon::prelude::*;
use sequence_game::UserModelTable;
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    #[arg(long, default_value = "nodes/user_model/models/migrave_study_c2.json")]
    user_models: PathBuf,
    #[arg(long)]
    per_level_reference: bool,
    /// The cluster whose Q-table is trained.
    #[arg(long)]
    cluster: usize,
    #[arg(long, default_value = "RE+bE", value_parser = parse_reward)]
    reward: Reward,
    /// Start from this cluster's best RE+bE policy and train exploitation-only.
    #[arg(long)]
    transfer_from: Option<usize>,
    #[arg(long, default_value_t = 100)]
    epochs: usize,
    #[arg(long, default_value_t = 5)]
    runs: usize,
    #[arg(long, default_value_t = 100)]
    sessions_per_epoch: usize,
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// PS is the latest result (as the live game reports it) instead of the authors' lag.
    #[arg(long)]
    no_state_lag: bool,
    #[command(flatten)]
    learning: LearningArgs,
    /// The Q-table file to write (default: out/q_tables/cluster_<k>.json).
    #[arg(long)]
    output: Option<PathBuf>,
    /// Replace an existing file (it may hold what real sessions taught).
    #[arg(long)]
    force: bool,
}

struct Trainer<'a> {
    models: &'a [UserModelTable],
    spec: RunSpec,
    runs: usize,
}

impl Trainer<'_> {
    /// `runs` runs from `initial`; run r of stage `stage` is seeded from (seed, stage, r).
    fn train(
        &self,
        cluster: usize,
        settings: &SessionSettings,
        initial: &QTable,
        seed: u64,
        bar: &indicatif::ProgressBar,
    ) -> Vec<Run> {
        let user = SimulatedUser::new(&self.models[cluster], &settings.learning);
        (0..self.runs)
            .into_par_iter()
            .map(|r| {
                let run = train_run(
                    &user,
                    settings,
                    initial.clone(),
                    &self.spec,
                    seed ^ (r as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
                );
                bar.inc(1);
                run
            })
            .collect()
    }
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let (models, source) = user_models::load(&a.user_models, a.per_level_reference)?;
    let mut clusters = vec![a.cluster];
    clusters.extend(a.transfer_from);
    user_models::check_clusters(&models, &clusters, &source)?;
    if a.epochs == 0 || a.runs == 0 || a.sessions_per_epoch == 0 {
        bail!("--epochs, --runs and --sessions-per-epoch must be at least 1");
    }
    let owner = QTableOwner::Cluster(a.cluster);
    let output = match &a.output {
        Some(p) => p.clone(),
        None => PathBuf::from("out/q_tables").join(owner.file_name()?),
    };
    // A node running on that directory would overwrite the table with its own at its next
    // update: refuse before training rather than lose the result. The lock is the node's,
    // taken under its name, so the error names the node that holds it.
    let dir = output
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let _dir_lock = InstanceLock::acquire(dir, "behaviour_policy", "Q-tables")
        .with_context(|| format!("writing {}", output.display()))?;
    if output.exists() && !a.force {
        bail!(
            "{} exists (it may hold what real sessions taught): pass --force to replace it",
            output.display()
        );
    }
    let trainer = Trainer {
        models: &models,
        spec: RunSpec {
            epochs: a.epochs,
            sessions_per_epoch: a.sessions_per_epoch,
            scheme: EpochScheme::Blocks,
            state_lags_result: !a.no_state_lag,
        },
        runs: a.runs,
    };
    let stages = 1 + usize::from(a.transfer_from.is_some());
    let bar = progress_bar((stages * a.runs) as u64);
    let (initial, mode, reward, how) = match a.transfer_from {
        Some(from) => {
            let settings = SessionSettings {
                learning: a.learning.learning(Reward::RePlusBetaE)?,
                mode: Mode::Explore,
                state_lags_result: trainer.spec.state_lags_result,
            };
            let runs = trainer.train(from, &settings, &QTable::default(), a.seed, &bar);
            let best = best_run(&runs).context("no source run")?;
            let how = format!(
                "transferred from cluster {from} (best of {} RE+bE runs, return {:.3}), then ",
                a.runs, runs[best].final_return
            );
            (
                runs[best].q_table.clone(),
                Mode::Exploit,
                Reward::RePlusBetaE,
                how,
            )
        }
        None => (QTable::default(), Mode::Explore, a.reward, String::new()),
    };
    let settings = SessionSettings {
        learning: a.learning.learning(reward)?,
        mode,
        state_lags_result: trainer.spec.state_lags_result,
    };
    let runs = trainer.train(a.cluster, &settings, &initial, a.seed.wrapping_add(1), &bar);
    bar.finish_and_clear();
    let best = best_run(&runs).context("no run")?;
    let last = runs[best].epochs.last().copied().unwrap_or_default();
    let provenance = format!(
        "policy_lab train: {how}{} x {} epochs x {} sessions, reward {}, {:?}, state lag {}, \
         seed {}, best run {best} (last epoch: score {:.2}, engagement {:.3}, return {:.3}); {source}",
        a.runs,
        a.epochs,
        a.sessions_per_epoch,
        reward.name(),
        mode,
        trainer.spec.state_lags_result,
        a.seed,
        last.score,
        last.engagement,
        runs[best].final_return,
    );
    QTableFile {
        owner,
        provenance: provenance.clone(),
        updates: 0,
        learned: Default::default(),
        table: runs[best].q_table.clone(),
    }
    .save(&output)?;
    println!("wrote {}\n{provenance}", output.display());
    Ok(())
}
