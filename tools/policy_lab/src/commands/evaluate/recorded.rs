//! `policy_lab evaluate`: a new Q-table's policy judged on the sessions recorded in bags, or
//! refused where they cannot tell; the estimates printed and written with their figure.

use super::bags::{BagsRead, bag_files, read_bags};
use super::shown::{Shown, estimates_table, left_out_lines, shown, support_line};
use super::{Judged, write_outputs};
use anyhow::bail;
use policy_lab::off_policy::recorded::LeftOut;
use policy_lab::off_policy::{Limits, evaluate};
use policy_lab::plots::evaluation::evaluation_svg;
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// Bags (.mcap) or folders searched for them (recursively).
    #[arg(long, required = true, num_args = 1..)]
    bags: Vec<PathBuf>,
    #[command(flatten)]
    judged: Judged,
    /// Bootstrap resamples of the sessions for the 95 % intervals.
    #[arg(long, default_value_t = 2000)]
    bootstrap: usize,
    /// Seed of the bootstrap's draws.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Refuse when the new policy would leave the logged actions in more than this share of
    /// its sessions (0..1): what the log cannot show would bias every estimate.
    #[arg(long, default_value_t = Limits::default().max_sessions_leaving_support, value_parser = parse_share)]
    max_off_support: f64,
    /// Refuse with fewer whole sessions played by the policy than this (at least 2).
    #[arg(long, default_value_t = Limits::default().min_sessions, value_parser = parse_min_sessions)]
    min_sessions: usize,
    /// No interval for the weighted estimate below this effective sample size.
    #[arg(long, default_value_t = Limits::default().min_effective_sessions)]
    min_effective_sessions: f64,
    /// Where evaluation.json, .svg and .png go.
    #[arg(long, default_value = "out/evaluate")]
    output: PathBuf,
}

fn parse_min_sessions(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if n >= 2 => Ok(n),
        _ => Err(format!(
            "{s:?} is not a whole number of at least 2 (one session gives no interval)"
        )),
    }
}

fn parse_share(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(x) if (0.0..=1.0).contains(&x) => Ok(x),
        _ => Err(format!("{s:?} is not a share between 0 and 1")),
    }
}

/// What `evaluate` writes to evaluation.json.
#[derive(Debug, serde::Serialize)]
struct Report<'a> {
    q_table: &'a Path,
    temperature: String,
    limits: Limits,
    bags: &'a BagsRead,
    sessions_recorded: usize,
    sessions_evaluated: usize,
    left_out: &'a [LeftOut],
    estimates: Vec<Shown>,
    effective_sample_size: f64,
    sessions_with_weight: usize,
    mean_new_probability: f64,
    sessions_leaving_support: Option<f64>,
    mass_outside_support: Option<f64>,
    weights: &'a [f64],
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let (learning, target) = a.judged.load()?;
    if !(a.min_effective_sessions.is_finite() && a.min_effective_sessions >= 0.0) {
        bail!("--min-effective-sessions must be a number at least 0");
    }
    let limits = Limits {
        max_sessions_leaving_support: a.max_off_support,
        min_sessions: a.min_sessions,
        min_effective_sessions: a.min_effective_sessions,
    };
    let files = bag_files(&a.bags)?;
    if files.is_empty() {
        bail!("no .mcap bag found under {:?}", a.bags);
    }
    let (log, bags) = read_bags(&files);
    println!(
        "bags: {} read ({} damaged), {} skipped",
        bags.read,
        bags.damaged.len(),
        bags.skipped.len()
    );
    for (bag, why) in &bags.skipped {
        println!("  skipped {}: {why}", bag.display());
    }
    for (_, why) in &bags.damaged {
        println!("  damaged: {why}");
    }
    print!("{}", left_out_lines(&log));
    if log.sessions.is_empty() {
        bail!("no whole session played by the policy in the bags: nothing to evaluate");
    }
    let e = evaluate(
        &log.sessions,
        Some(&log.distributions),
        &target,
        &learning,
        a.bootstrap,
        a.seed,
    )?;
    println!(
        "new policy: {} ({}); reward {}, γ {}; {} bootstrap resamples, seed {}",
        a.judged.q_table.display(),
        a.judged.temperature.describe(),
        learning.reward,
        learning.gamma,
        a.bootstrap,
        a.seed
    );
    println!("{}", support_line(&e));
    let refusals = e.refusals(&limits);
    if !refusals.is_empty() {
        bail!(
            "refusing to estimate: {}",
            refusals
                .iter()
                .map(|r| r.to_string())
                .collect::<Vec<_>>()
                .join("; and ")
        );
    }
    let rows = shown(&e, &limits);
    println!();
    print!("{}", estimates_table(&e, &rows));
    let report = Report {
        q_table: &a.judged.q_table,
        temperature: a.judged.temperature.describe(),
        limits,
        bags: &bags,
        sessions_recorded: log.seen(),
        sessions_evaluated: e.sessions,
        left_out: &log.left_out,
        effective_sample_size: e.effective_sample_size,
        sessions_with_weight: e.sessions_with_weight,
        mean_new_probability: e.mean_new_probability,
        sessions_leaving_support: e.sessions_leaving_support,
        mass_outside_support: e.mass_outside_support,
        weights: &e.weights,
        estimates: rows.clone(),
    };
    // The figure draws no bar where the printout gives no interval.
    let mut drawn = e.clone();
    for q in [&mut drawn.discounted_return, &mut drawn.score] {
        if let Some(w) = q.weighted_is.as_mut()
            && !e.weighted_interval_holds(&limits)
        {
            (w.low, w.high) = (w.value, w.value);
        }
        if !e.per_decision_interval_holds() {
            let p = &mut q.per_decision_is;
            (p.low, p.high) = (p.value, p.value);
        }
    }
    let subtitle = format!(
        "{} judged on {} recorded session(s) ({}); reward {}, 95 % bootstrap intervals (none \
         drawn where none holds)",
        a.judged.q_table.display(),
        e.sessions,
        a.judged.temperature.describe(),
        learning.reward
    );
    write_outputs(
        &a.output,
        "evaluation",
        &report,
        evaluation_svg(&drawn, &subtitle),
    )
}
