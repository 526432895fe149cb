//! The subcommands of the `behaviour_policy` binary, one module each, and what they share:
//! the learning constants on the command line and loading user models.

pub mod child_study;
pub mod evaluate;
pub mod experiments;
pub mod per_child;
pub mod run;
pub mod show_q_table;
pub mod supervision;
pub mod train;
pub mod user_models;

use behaviour_policy::params::validate_learning;
use behaviour_policy::{Learning, Reward, TemperatureSchedule};

/// Learning constants; defaults are the authors' (as `params/behaviour_policy.yaml`).
#[derive(Debug, Clone, clap::Args)]
pub struct LearningArgs {
    #[arg(long, default_value_t = Learning::default().alpha)]
    pub alpha: f64,
    #[arg(long, default_value_t = Learning::default().gamma)]
    pub gamma: f64,
    /// T_s = max(min, initial - decay * visits_s).
    #[arg(long, default_value_t = TemperatureSchedule::default().initial)]
    pub initial_temperature: f64,
    #[arg(long, default_value_t = TemperatureSchedule::default().minimum)]
    pub min_temperature: f64,
    #[arg(long, default_value_t = TemperatureSchedule::default().decay_per_visit)]
    pub temperature_decay: f64,
    #[arg(long, default_value_t = Learning::default().beta)]
    pub beta: f64,
    #[arg(long, default_value_t = Learning::default().lambda)]
    pub lambda: f64,
}

impl LearningArgs {
    pub fn learning(&self, reward: Reward) -> anyhow::Result<Learning> {
        let l = Learning {
            alpha: self.alpha,
            gamma: self.gamma,
            temperature: TemperatureSchedule {
                initial: self.initial_temperature,
                minimum: self.min_temperature,
                decay_per_visit: self.temperature_decay,
            },
            beta: self.beta,
            lambda: self.lambda,
            reward,
        };
        validate_learning(&l)
            .map_err(|e| anyhow::anyhow!("--{}", e.to_string().replace('_', "-")))?;
        Ok(l)
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
