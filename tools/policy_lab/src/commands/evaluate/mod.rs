//! `policy_lab evaluate`: judges a new Q-table on recorded sessions before it meets a
//! child (counterfactual evaluation from the bags' decisions, results and game states), or
//! refuses where the sessions cannot tell (too few, or a new policy that leaves the logged
//! actions: `off_policy::Limits`); it names damaged bags and the share of sessions left out; and
//! `policy_lab evaluate-in-simulation`: the same estimators where the truth is known
//! (sessions logged against a user model, the new policy's exact value beside the estimates).
//!
//! Here: the policy judged, as both commands take it, and how their results are written. The
//! commands: `recorded` (on bags, which `bags` reads; `shown` is what it prints) and
//! `in_simulation` (one case, or a `sweep` of logging policies and session counts).

mod bags;
mod in_simulation;
mod recorded;
mod shown;
mod sweep;

pub use in_simulation::{SimulationArgs, run_in_simulation};
pub use recorded::{Args, run};

use super::{LearningArgs, parse_reward};
use anyhow::Context;
use q_learning::mdp::{TargetPolicy, TargetTemperature};
use q_learning::{Learning, QTableFile, Reward};
use std::path::{Path, PathBuf};

/// How the judged policy picks from its table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Temperature {
    Greedy,
    PerState,
    Fixed(f64),
    /// ε-greedy: the live policy's logged exploration.
    Epsilon(f64),
}

fn parse_temperature(s: &str) -> Result<Temperature, String> {
    let bad = || {
        format!(
            "{s:?} is not `greedy`, `per-state`, a positive temperature or `epsilon:E` with E \
             in [0, 1]"
        )
    };
    match s {
        "greedy" => Ok(Temperature::Greedy),
        "per-state" => Ok(Temperature::PerState),
        _ => match s.strip_prefix("epsilon:") {
            Some(e) => match e.parse::<f64>() {
                Ok(e) if (0.0..=1.0).contains(&e) => Ok(Temperature::Epsilon(e)),
                _ => Err(bad()),
            },
            None => match s.parse::<f64>() {
                Ok(t) if t.is_finite() && t > 0.0 => Ok(Temperature::Fixed(t)),
                _ => Err(bad()),
            },
        },
    }
}

impl Temperature {
    fn target(self, learning: &Learning) -> TargetTemperature {
        match self {
            Temperature::Greedy => TargetTemperature::Greedy,
            Temperature::PerState => TargetTemperature::PerState(learning.temperature),
            Temperature::Fixed(t) => TargetTemperature::Fixed(t),
            Temperature::Epsilon(e) => TargetTemperature::EpsilonGreedy(e),
        }
    }

    fn describe(self) -> String {
        match self {
            Temperature::Greedy => "greedy, as in real sessions".into(),
            Temperature::PerState => "softmax at each state's T_s".into(),
            Temperature::Fixed(t) => format!("softmax at T = {t}"),
            Temperature::Epsilon(e) => format!("ε-greedy, ε = {e}"),
        }
    }

    /// Short form for tables and files: `T=2`, `eps=0.1`.
    fn short(self) -> String {
        match self {
            Temperature::Greedy => "greedy".into(),
            Temperature::PerState => "per-state".into(),
            Temperature::Fixed(t) => format!("T={t}"),
            Temperature::Epsilon(e) => format!("eps={e}"),
        }
    }
}

/// The policy judged and the reward it is judged by (both commands).
#[derive(Debug, Clone, clap::Args)]
pub struct Judged {
    /// The Q-table file of the policy to judge.
    #[arg(long)]
    q_table: PathBuf,
    /// How it picks: `greedy` (real sessions), `per-state` (softmax at each state's T_s from
    /// its visits) or a fixed softmax temperature.
    #[arg(long, default_value = "greedy", value_parser = parse_temperature)]
    temperature: Temperature,
    #[arg(long, default_value = "RE+bE", value_parser = parse_reward)]
    reward: Reward,
    #[command(flatten)]
    learning: LearningArgs,
}

impl Judged {
    /// The learning constants (γ, reward) and the judged policy.
    fn load(&self) -> anyhow::Result<(Learning, TargetPolicy)> {
        let learning = self.learning.learning(self.reward)?;
        let file = QTableFile::load(&self.q_table).context("the policy to evaluate (--q-table)")?;
        let target = TargetPolicy::new(file.table, self.temperature.target(&learning))?;
        Ok((learning, target))
    }
}

fn write_outputs(
    dir: &Path,
    name: &str,
    json: &impl serde::Serialize,
    svg: Result<String, String>,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let path = dir.join(format!("{name}.json"));
    atomic_file::write(&path, serde_json::to_string_pretty(json)?.as_bytes())
        .with_context(|| format!("writing {}", path.display()))?;
    let svg = svg.map_err(|e| anyhow::anyhow!("drawing {name}: {e}"))?;
    let (svg, png) = figures::write_svg_and_png(&dir.join(name), &svg)?;
    println!(
        "wrote {}, {} and {}",
        path.display(),
        svg.display(),
        png.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temperatures_parse_or_say_what_is_expected() {
        assert_eq!(parse_temperature("greedy"), Ok(Temperature::Greedy));
        assert_eq!(parse_temperature("per-state"), Ok(Temperature::PerState));
        assert_eq!(parse_temperature("0.5"), Ok(Temperature::Fixed(0.5)));
        assert_eq!(
            parse_temperature("epsilon:0.1"),
            Ok(Temperature::Epsilon(0.1))
        );
        for bad in [
            "0",
            "-1",
            "nan",
            "hot",
            "epsilon:1.5",
            "epsilon:",
            "epsilon:nan",
        ] {
            let e = parse_temperature(bad).unwrap_err();
            assert!(e.contains("greedy"), "{e}");
        }
    }
}
