//! The command line the leave-one-child-out studies share (`per-child`, `supervision`): where
//! the study's records are, how the children's models are fitted, how many sessions each
//! child plays, and the seeds. One definition, so both studies read the same flags the same
//! way and refuse the same bad values.

use anyhow::{Context, bail};
use policy_lab::child_study::per_child::StudySpec;
use q_learning::Learning;
use std::path::PathBuf;
use user_models::data::InteractionRecord;

#[derive(Debug, Clone, clap::Args)]
pub struct ChildStudyArgs {
    /// The study's records (the paper's: 20 participants, 10 sequences each).
    #[arg(long, default_value = "../shared/data/migrave-study")]
    pub study: PathBuf,
    /// Clusters of the user models fitted without each child.
    #[arg(long, default_value_t = 2)]
    pub clusters: usize,
    /// Sessions each child plays under each policy or rule.
    #[arg(long, default_value_t = 20)]
    pub sessions: usize,
    /// Repetitions per child: each its own random draws, the same for every policy or rule.
    #[arg(long, default_value_t = 30)]
    pub seeds: usize,
    /// The cluster's policy is pretrained as the node does: runs x epochs x 100 sessions.
    #[arg(long, default_value_t = 100)]
    pub pretrain_epochs: usize,
    /// Pretraining runs; the best by its last epoch's return is kept.
    #[arg(long, default_value_t = 5)]
    pub pretrain_runs: usize,
    /// Bootstrap resamples of the children for the paired intervals.
    #[arg(long, default_value_t = 10_000)]
    pub bootstrap: usize,
    /// Seed of the fits (K-means), of every simulated session and of the bootstrap.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
}

impl ChildStudyArgs {
    /// Checks the counts, reads the study's records and says how the study runs with
    /// `learning`.
    pub fn read(&self, learning: Learning) -> anyhow::Result<(Vec<InteractionRecord>, StudySpec)> {
        if self.sessions == 0
            || self.seeds == 0
            || self.pretrain_epochs == 0
            || self.pretrain_runs == 0
        {
            bail!("--sessions, --seeds, --pretrain-epochs and --pretrain-runs must be at least 1");
        }
        if !self.study.is_dir() {
            bail!(
                "{}: no such folder (the study's records; ../shared/data/migrave-study beside \
                 the repository, or --study DIR)",
                self.study.display()
            );
        }
        let records = user_models::data::study::read_study(&self.study)
            .with_context(|| format!("reading the study in {}", self.study.display()))?;
        let spec = StudySpec {
            fit: user_models::FitOptions {
                clusters: self.clusters,
                seed: self.seed,
                provenance: format!("{} without one child", self.study.display()),
                ..Default::default()
            },
            learning,
            pretrain_epochs: self.pretrain_epochs,
            pretrain_runs: self.pretrain_runs,
            sessions: self.sessions,
            seeds: self.seeds,
            seed: self.seed,
        };
        Ok((records, spec))
    }
}
