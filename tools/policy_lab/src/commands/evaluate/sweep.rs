//! `evaluate-in-simulation`'s sweep: every (logging policy, sessions) pair on the same seeds,
//! a table of how often the judged policy's score is judged within the tolerance, and
//! `sweep.csv` and `sweep.json`.

use super::super::progress_bar;
use super::in_simulation::SimulationArgs;
use anyhow::Context;
use policy_lab::off_policy::{EstimatorCheck, ScoreCloseness, validate};
use q_learning::mdp::{ExactValue, TargetPolicy};
use q_learning::{Learning, QTable};
use std::fmt::Write as _;

/// One case of a sweep, as `sweep.json` and `sweep.csv` hold it.
#[derive(Debug, serde::Serialize)]
struct SweepCase {
    logging: String,
    sessions: usize,
    seeds: usize,
    logging_truth: ExactValue,
    truth: ExactValue,
    mean_effective_sample_size: f64,
    weighted_is_score: EstimatorCheck,
    per_decision_is_score: EstimatorCheck,
    closeness: ScoreCloseness,
}

fn sweep_csv(cases: &[SweepCase]) -> String {
    let mut out = String::from(
        "logging,sessions,seeds,logging_true_score,judged_true_score,mean_effective_sessions,\
         wis_seeds,wis_bias,wis_rmse,wis_coverage,wis_within,wis_interval_shown,wis_interval_within,\
         wis_median_half_width,pdis_bias,pdis_rmse,pdis_coverage,pdis_within,pdis_interval_shown,\
         pdis_interval_within,pdis_median_half_width\n",
    );
    let half = |h: Option<f64>| h.map(|h| format!("{h:.4}")).unwrap_or_default();
    for c in cases {
        let (w, p) = (c.closeness.weighted_is, c.closeness.per_decision_is);
        let _ = writeln!(
            out,
            "{},{},{},{:.4},{:.4},{:.2},{},{:.4},{:.4},{:.3},{:.3},{:.3},{:.3},{},{:.4},{:.4},{:.3},{:.3},{:.3},{:.3},{}",
            c.logging,
            c.sessions,
            c.seeds,
            c.logging_truth.score,
            c.truth.score,
            c.mean_effective_sample_size,
            c.weighted_is_score.seeds,
            c.weighted_is_score.bias,
            c.weighted_is_score.rmse,
            c.weighted_is_score.coverage,
            w.estimate_within,
            w.interval_shown,
            w.interval_within,
            half(w.median_half_width),
            c.per_decision_is_score.bias,
            c.per_decision_is_score.rmse,
            c.per_decision_is_score.coverage,
            p.estimate_within,
            p.interval_shown,
            p.interval_within,
            half(p.median_half_width),
        );
    }
    out
}

/// Every (logging policy, sessions) pair on the same seeds: a table of how often the score is
/// judged within the tolerance, `sweep.csv` and `sweep.json`.
pub(super) fn run_sweep(
    a: &SimulationArgs,
    learning: &Learning,
    target: &TargetPolicy,
    (model, source): (&sequence_game::UserModelTable, &str),
    table: QTable,
) -> anyhow::Result<()> {
    println!(
        "children: cluster {} of {source}; logging: {} ({}); judged: {} ({}); sessions per \
         seed {:?}, {} seeds (the same for every case), {} bootstrap resamples; score judged \
         within ±{} point(s)",
        a.cluster,
        a.logging_q_table.display(),
        a.logging_temperature
            .iter()
            .map(|t| t.describe())
            .collect::<Vec<_>>()
            .join(" | "),
        a.judged.q_table.display(),
        a.judged.temperature.describe(),
        a.sessions,
        a.seeds,
        a.bootstrap,
        a.tolerance
    );
    let total = (a.logging_temperature.len() * a.sessions.len()) as u64 * a.seeds;
    let bar = progress_bar(total);
    let mut cases = Vec::new();
    for t in &a.logging_temperature {
        let logging = TargetPolicy::new(table.clone(), t.target(learning))?;
        for &sessions in &a.sessions {
            let v = validate(
                model,
                &logging,
                target,
                learning,
                sessions,
                0..a.seeds,
                a.bootstrap,
                &|| bar.inc(1),
            )?;
            cases.push(SweepCase {
                logging: t.short(),
                sessions,
                seeds: v.seeds,
                logging_truth: v.logging_truth,
                truth: v.truth,
                mean_effective_sample_size: v.mean_effective_sample_size,
                weighted_is_score: v.weighted_is_score,
                per_decision_is_score: v.per_decision_is_score,
                closeness: v.score_closeness(a.tolerance),
            });
        }
    }
    bar.finish_and_clear();
    if let Some(c) = cases.first() {
        println!(
            "exact score per session (backward induction over the user model): judged policy \
             {:.3} (return {:.3})",
            c.truth.score, c.truth.discounted_return
        );
    }
    let pct = |x: f64| format!("{:.0} %", 100.0 * x);
    let half = |h: Option<f64>| h.map_or_else(|| "-".into(), |h| format!("{h:.2}"));
    println!(
        "{:<9} {:>8} {:>8} {:>9} | {:>8} {:>6} {:>6} {:>6} {:>7} | {:>8} {:>6} {:>6} {:>6} {:>7}",
        "logging",
        "sessions",
        "log score",
        "eff. ses.",
        "WIS RMSE",
        "cover",
        "±tol",
        "CI in",
        "½ width",
        "PDIS RMSE",
        "cover",
        "±tol",
        "CI in",
        "½ width"
    );
    for c in &cases {
        let (w, p) = (c.closeness.weighted_is, c.closeness.per_decision_is);
        let (wc, pc) = (c.weighted_is_score, c.per_decision_is_score);
        let rmse = |e: EstimatorCheck| {
            if e.seeds == 0 {
                "-".into()
            } else {
                format!("{:.2}", e.rmse)
            }
        };
        println!(
            "{:<9} {:>8} {:>8.2} {:>9.1} | {:>8} {:>6} {:>6} {:>6} {:>7} | {:>8} {:>6} {:>6} {:>6} {:>7}",
            c.logging,
            c.sessions,
            c.logging_truth.score,
            c.mean_effective_sample_size,
            rmse(wc),
            pct(wc.coverage),
            pct(w.estimate_within),
            pct(w.interval_within),
            half(w.median_half_width),
            rmse(pc),
            pct(pc.coverage),
            pct(p.estimate_within),
            pct(p.interval_within),
            half(p.median_half_width)
        );
    }
    println!(
        "log score: the logging policy's exact score; RMSE and cover (95 % intervals holding the \
         truth) over the seeds with an estimate; ±tol: seeds whose estimate of the score is \
         within ±{0} of the truth; CI in: seeds where evaluate shows a 95 % interval lying \
         inside the truth ±{0}; ½ width: the shown intervals' median half-width",
        a.tolerance
    );
    std::fs::create_dir_all(&a.output)
        .with_context(|| format!("creating {}", a.output.display()))?;
    let json = a.output.join("sweep.json");
    atomic_file::write(&json, serde_json::to_string_pretty(&cases)?.as_bytes())
        .with_context(|| format!("writing {}", json.display()))?;
    let csv = a.output.join("sweep.csv");
    atomic_file::write(&csv, sweep_csv(&cases).as_bytes())
        .with_context(|| format!("writing {}", csv.display()))?;
    println!("wrote {} and {}", json.display(), csv.display());
    Ok(())
}
