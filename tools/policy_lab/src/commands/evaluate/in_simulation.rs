//! `policy_lab evaluate-in-simulation`: `evaluate`'s estimators where the truth is known:
//! sessions logged by one policy against a user model, the judged policy's exact value beside
//! its estimates over many seeds; several logging policies or session counts make a `sweep`.

use super::super::{progress_bar, user_models};
use super::sweep::run_sweep;
use super::{Judged, Temperature, parse_temperature, write_outputs};
use anyhow::{Context, bail};
use policy_lab::off_policy::{Validation, validate};
use policy_lab::plots::evaluation::validation_svg;
use q_learning::QTableFile;
use q_learning::mdp::TargetPolicy;
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(Debug, Clone, clap::Args)]
pub struct SimulationArgs {
    #[arg(long, default_value = "nodes/user_model/models/migrave_study_c2.json")]
    pub(super) user_models: PathBuf,
    #[arg(long)]
    pub(super) per_level_reference: bool,
    /// The user model (cluster) the simulated children come from.
    #[arg(long, default_value_t = 0)]
    pub(super) cluster: usize,
    /// The Q-table of the policy that plays and logs the sessions.
    #[arg(long)]
    pub(super) logging_q_table: PathBuf,
    /// How the logging policy picks (it must explore for the estimates to see other actions):
    /// a softmax temperature, `per-state`, `greedy`, or `epsilon:E` (the live policy's logged
    /// exploration, `exploration_epsilon`). Several, comma-separated, make a sweep.
    #[arg(long, default_value = "2", value_parser = parse_temperature, value_delimiter = ',')]
    pub(super) logging_temperature: Vec<Temperature>,
    #[command(flatten)]
    pub(super) judged: Judged,
    /// Logged sessions per seed; several, comma-separated, make a sweep (a seed's first N
    /// sessions are the same whatever the number after them, and the same uniforms drive
    /// every logging policy).
    #[arg(long, default_value = "200", value_delimiter = ',')]
    pub(super) sessions: Vec<usize>,
    /// Seeds 0..N, each its own logged sessions and estimate.
    #[arg(long, default_value_t = 100)]
    pub(super) seeds: u64,
    #[arg(long, default_value_t = 1000)]
    pub(super) bootstrap: usize,
    /// Points of score: how often is the judged policy's score judged within ± this?
    #[arg(long, default_value_t = 1.0)]
    pub(super) tolerance: f64,
    #[arg(long, default_value = "out/evaluate-in-simulation")]
    pub(super) output: PathBuf,
}

/// The lines saying how often the score was judged within the tolerance.
fn closeness_lines(v: &Validation, tolerance: f64) -> String {
    let c = v.score_closeness(tolerance);
    let mut out = String::new();
    for (name, x) in [
        ("weighted IS, score", c.weighted_is),
        ("per-decision IS, score", c.per_decision_is),
    ] {
        let _ = writeln!(
            out,
            "{name:<34} estimate within ±{tolerance} of the truth in {:.1} % of seeds; \
             interval shown in {:.1} %, inside truth ±{tolerance} in {:.1} %{}",
            100.0 * x.estimate_within,
            100.0 * x.interval_shown,
            100.0 * x.interval_within,
            x.median_half_width
                .map(|h| format!(" (median half-width {h:.2})"))
                .unwrap_or_default()
        );
    }
    out
}

pub fn run_in_simulation(a: SimulationArgs) -> anyhow::Result<()> {
    let (learning, target) = a.judged.load()?;
    let (tables, source) = user_models::load(&a.user_models, a.per_level_reference)?;
    user_models::check_clusters(&tables, &[a.cluster], &source)?;
    let logging_table = QTableFile::load(&a.logging_q_table)
        .context("the logging policy (--logging-q-table)")?
        .table;
    if a.sessions.contains(&0) || a.seeds == 0 {
        bail!("--sessions and --seeds must be at least 1");
    }
    if !(a.tolerance.is_finite() && a.tolerance > 0.0) {
        bail!("--tolerance must be a positive number of points");
    }
    if a.logging_temperature.len() > 1 || a.sessions.len() > 1 {
        return run_sweep(
            &a,
            &learning,
            &target,
            (&tables[a.cluster], &source),
            logging_table,
        );
    }
    let (logging_temperature, sessions) = (a.logging_temperature[0], a.sessions[0]);
    let logging = TargetPolicy::new(logging_table, logging_temperature.target(&learning))?;
    println!(
        "children: cluster {} of {source}; logging: {} ({}); judged: {} ({}); {} sessions per \
         seed, {} seeds, {} bootstrap resamples",
        a.cluster,
        a.logging_q_table.display(),
        logging_temperature.describe(),
        a.judged.q_table.display(),
        a.judged.temperature.describe(),
        sessions,
        a.seeds,
        a.bootstrap
    );
    let bar = progress_bar(a.seeds);
    let v = validate(
        &tables[a.cluster],
        &logging,
        &target,
        &learning,
        sessions,
        0..a.seeds,
        a.bootstrap,
        &|| bar.inc(1),
    )?;
    bar.finish_and_clear();
    println!(
        "exact value per session (backward induction over the user model): judged policy \
         return {:.3}, score {:.3}; logging policy return {:.3}, score {:.3}",
        v.truth.discounted_return,
        v.truth.score,
        v.logging_truth.discounted_return,
        v.logging_truth.score
    );
    println!(
        "{:<34} {:>8} {:>8} {:>15}",
        "estimator", "bias", "RMSE", "95 % coverage"
    );
    for (name, c) in [
        ("weighted IS, return", v.weighted_is_return),
        ("per-decision IS, return", v.per_decision_is_return),
        ("weighted IS, score", v.weighted_is_score),
        ("per-decision IS, score", v.per_decision_is_score),
        (
            "weighted IS, return, where shown",
            v.weighted_is_return_where_shown,
        ),
    ] {
        if c.seeds == 0 {
            println!("{name:<34} (no seed gave one)");
            continue;
        }
        println!(
            "{name:<34} {:>+8.3} {:>8.3} {:>8.1} % of {}",
            c.bias,
            c.rmse,
            100.0 * c.coverage,
            c.seeds
        );
    }
    println!(
        "mean effective sample size: {:.1} of {} sessions",
        v.mean_effective_sample_size, v.sessions
    );
    print!("{}", closeness_lines(&v, a.tolerance));
    let subtitle = format!(
        "{} sessions logged by {} ({}) against cluster {}; judged: {} ({})",
        sessions,
        a.logging_q_table.display(),
        logging_temperature.describe(),
        a.cluster,
        a.judged.q_table.display(),
        a.judged.temperature.describe()
    );
    write_outputs(&a.output, "validation", &v, validation_svg(&v, &subtitle))
}
