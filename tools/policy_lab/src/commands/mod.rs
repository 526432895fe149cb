//! The subcommands of the `policy_lab` binary, one module each, and what they share:
//! the learning constants on the command line and loading user models.

pub mod child_belief_prior;
pub mod child_study;
pub mod evaluate;
pub mod experiments;
pub mod per_child;
pub mod per_child_belief;
pub mod supervision;
pub mod train;
pub mod user_models;

use q_learning::{LearningConstants, Reward};

/// Learning constants; defaults are the authors' (as `params/behaviour_policy.yaml`).
#[derive(Debug, Clone, clap::Args)]
pub struct LearningArgs {
    #[arg(long, default_value_t = LearningConstants::default().alpha)]
    pub alpha: f64,
    #[arg(long, default_value_t = LearningConstants::default().gamma)]
    pub gamma: f64,
    /// T_s = max(min, initial - decay * visits_s).
    #[arg(long, default_value_t = LearningConstants::default().initial_temperature)]
    pub initial_temperature: f64,
    #[arg(long, default_value_t = LearningConstants::default().min_temperature)]
    pub min_temperature: f64,
    #[arg(long, default_value_t = LearningConstants::default().temperature_decay)]
    pub temperature_decay: f64,
    #[arg(long, default_value_t = LearningConstants::default().beta)]
    pub beta: f64,
    #[arg(long, default_value_t = LearningConstants::default().lambda)]
    pub lambda: f64,
}

impl LearningArgs {
    pub fn learning(&self, reward: Reward) -> anyhow::Result<q_learning::Learning> {
        LearningConstants {
            alpha: self.alpha,
            gamma: self.gamma,
            initial_temperature: self.initial_temperature,
            min_temperature: self.min_temperature,
            temperature_decay: self.temperature_decay,
            beta: self.beta,
            lambda: self.lambda,
        }
        .learning(reward)
        // The flag is the parameter's name with dashes.
        .map_err(|e| anyhow::anyhow!("--{}: {}", e.key.replace('_', "-"), e.reason))
    }
}

pub fn parse_reward(s: &str) -> Result<Reward, String> {
    Reward::parse(s).ok_or_else(|| format!("{s:?} is not RE, RE+bE or lE"))
}

/// A progress bar on stderr for `total` runs.
pub fn progress_bar(total: u64) -> indicatif::ProgressBar {
    indicatif::ProgressBar::new(total).with_style(
        indicatif::ProgressStyle::with_template(
            "{bar:40} {pos}/{len} runs  {elapsed_precise} (eta {eta})",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    )
}
