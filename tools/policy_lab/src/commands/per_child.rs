//! `policy_lab per-child`: per-child adaptation measured on the study's participants,
//! leave one child out at a time (`policy_lab::child_study::per_child`): the cluster's policy, a
//! per-user table started from it, a table learned on the child from scratch, and the optimal
//! policy for the child's own model, each on the same simulated sessions, compared child by
//! child. Prints the policies' means, the paired comparisons and the per-child table; writes
//! them as CSV with every session, and the figures.

use super::child_study::ChildStudyArgs;
use super::{LearningArgs, parse_reward};
use anyhow::Context;
use policy_lab::child_study::per_child::{
    Arm, COMPARISONS, ChildResult, Window, cases, child_mean, mean_over_children, paired, run_study,
};
use policy_lab::plots::{per_child_paired_svg, per_child_svg};
use policy_lab::stats::{Interval, PairedComparison, PairedSummary, Verdict, mean};
use q_learning::Reward;
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    #[command(flatten)]
    study: ChildStudyArgs,
    #[arg(long, default_value = "RE+bE", value_parser = parse_reward)]
    reward: Reward,
    #[command(flatten)]
    learning: LearningArgs,
    /// Where the CSV files and the figures go.
    #[arg(long, default_value = "out/per_child")]
    output: PathBuf,
}

fn interval(i: Option<Interval>) -> String {
    i.map_or_else(
        || "-".into(),
        |i| format!("[{:+.2}, {:+.2}]", i.low, i.high),
    )
}

/// The policies' means over children, and what the child's model allows at best.
fn means_table(results: &[ChildResult], windows: &[Window]) -> String {
    let mut out = String::new();
    let _ = write!(out, "{:<40}", "policy (mean over children)");
    for w in windows {
        let _ = write!(out, " {:>22}", w.describe());
    }
    out.push('\n');
    for arm in Arm::ALL {
        let _ = write!(out, "{:<40}", arm.name());
        for w in windows {
            let _ = write!(out, " {:>22.3}", mean_over_children(results, arm, w));
        }
        out.push('\n');
    }
    let exact = |f: &dyn Fn(&ChildResult) -> f64| mean(&results.iter().map(f).collect::<Vec<_>>());
    let _ = writeln!(
        out,
        "exact, per session against the child's own model (backward induction): the optimal \
         policy's expected return {:.3} (the most any policy can expect) and score {:.3}; the \
         most any policy can expect to score {:.3}",
        exact(&|c| c.bounds.optimal.discounted_return),
        exact(&|c| c.bounds.optimal.score),
        exact(&|c| c.bounds.best_score),
    );
    out
}

fn summary_cells(s: &PairedSummary) -> String {
    format!(
        "{:>+7.3} ± {:<5.3} {:>17} {:>17} {:>+7.3} {:>3}/{:>2}/{:<3} {:>6.3}",
        s.mean,
        s.standard_error,
        interval(s.t_interval),
        interval(s.bootstrap_interval),
        s.median,
        s.wins,
        s.ties,
        s.losses,
        s.sign_test_p
    )
}

/// The paired comparisons: all children, then without the most influential one.
fn paired_table(comparisons: &[(String, Window, PairedComparison)]) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{:<58} {:>15} {:>17} {:>17} {:>7} {:>10} {:>6}",
        "difference, by child (mean ± s.e. over children)",
        "mean ± s.e.",
        "95 % t",
        "95 % bootstrap",
        "median",
        "W/T/L",
        "sign p"
    );
    for (name, w, c) in comparisons {
        let _ = writeln!(
            out,
            "{:<58} {}",
            format!("{name}, {}", w.describe()),
            summary_cells(&c.all)
        );
        if let Some((u, without)) = &c.most_influential {
            let _ = writeln!(
                out,
                "{:<58} {}",
                format!("  without {} ({:+.3})", u.unit, u.difference),
                summary_cells(without)
            );
        }
    }
    out
}

fn verdict(v: Verdict) -> &'static str {
    match v {
        Verdict::Win => "win",
        Verdict::Tie => "tie",
        Verdict::Loss => "loss",
    }
}

/// Per child, the score with each policy and the first comparison's difference.
fn child_table(results: &[ChildResult], score: &Window, first: &PairedComparison) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{:<10} {:>7} {:>8} {:>9} {:>8} {:>8} {:>26} {:>7} {:>11} {:>12}",
        "child",
        "cluster",
        "cluster",
        "per-user",
        "scratch",
        "optimal",
        "per-user − cluster [seeds]",
        "",
        "best score",
        "best return"
    );
    for (c, u) in results.iter().zip(&first.per_unit) {
        let _ = writeln!(
            out,
            "{:<10} {:>7} {:>8.2} {:>9.2} {:>8.2} {:>8.2} {:>+8.3} {:>17} {:>7} {:>11.2} {:>12.2}",
            c.user,
            c.cluster,
            child_mean(c, Arm::Cluster, score),
            child_mean(c, Arm::PerUser, score),
            child_mean(c, Arm::Scratch, score),
            child_mean(c, Arm::Optimal, score),
            u.difference,
            interval(u.interval),
            verdict(u.verdict),
            c.bounds.best_score,
            c.bounds.optimal.discounted_return,
        );
    }
    out
}

fn sessions_csv(results: &[ChildResult]) -> String {
    let mut out = String::from("user,cluster,policy,seed,session,score,engagement,return\n");
    for r in results {
        for (arm, runs) in Arm::ALL.iter().zip(&r.runs) {
            for (seed, run) in runs.iter().enumerate() {
                for (k, m) in run.iter().enumerate() {
                    let _ = writeln!(
                        out,
                        "{},{},{},{seed},{},{},{},{}",
                        r.user,
                        r.cluster,
                        arm.key(),
                        k + 1,
                        m.score,
                        m.engagement,
                        m.discounted_return
                    );
                }
            }
        }
    }
    out
}

fn children_csv(
    results: &[ChildResult],
    windows: &[Window],
    comparisons: &[(String, Window, PairedComparison)],
) -> String {
    let key = |w: &Window| {
        format!(
            "{}_{}_{}",
            w.metric.name(),
            w.sessions.start + 1,
            w.sessions.end
        )
    };
    let mut out = String::from("user,cluster");
    for arm in Arm::ALL {
        for w in windows {
            let _ = write!(out, ",{}_{}", arm.key(), key(w));
        }
    }
    out.push_str(",optimal_expected_return,optimal_expected_score,best_expected_score");
    for (_, w, _) in comparisons {
        let _ = write!(out, ",{0}_low,{0}_high,{0}_verdict", key(w));
    }
    out.push('\n');
    for (i, c) in results.iter().enumerate() {
        let _ = write!(out, "{},{}", c.user, c.cluster);
        for arm in Arm::ALL {
            for w in windows {
                let _ = write!(out, ",{}", child_mean(c, arm, w));
            }
        }
        let _ = write!(
            out,
            ",{},{},{}",
            c.bounds.optimal.discounted_return, c.bounds.optimal.score, c.bounds.best_score
        );
        for (_, _, p) in comparisons {
            let u = &p.per_unit[i];
            let (lo, hi) = u.interval.map_or((String::new(), String::new()), |i| {
                (i.low.to_string(), i.high.to_string())
            });
            let _ = write!(out, ",{lo},{hi},{}", verdict(u.verdict));
        }
        out.push('\n');
    }
    out
}

fn paired_csv(comparisons: &[(String, Window, PairedComparison)]) -> String {
    let mut out = String::from(
        "comparison,metric,first_session,last_session,children_left_out,children,mean,\
         standard_error,t_low,t_high,bootstrap_low,bootstrap_high,median,wins,ties,losses,\
         exactly_zero,sign_test_p\n",
    );
    let opt = |i: Option<Interval>| {
        i.map_or((String::new(), String::new()), |i| {
            (i.low.to_string(), i.high.to_string())
        })
    };
    for (name, w, c) in comparisons {
        // ASCII in the file: "per_user-cluster".
        let name = name.replace(" − ", "-");
        let mut rows = vec![(String::new(), &c.all)];
        if let Some((u, without)) = &c.most_influential {
            rows.push((u.unit.clone(), without));
        }
        for (left_out, s) in rows {
            let (tl, th) = opt(s.t_interval);
            let (bl, bh) = opt(s.bootstrap_interval);
            let _ = writeln!(
                out,
                "{name},{},{},{},{left_out},{},{},{},{tl},{th},{bl},{bh},{},{},{},{},{},{}",
                w.metric.name(),
                w.sessions.start + 1,
                w.sessions.end,
                s.units,
                s.mean,
                s.standard_error,
                s.median,
                s.wins,
                s.ties,
                s.losses,
                s.exactly_zero,
                s.sign_test_p
            );
        }
    }
    out
}

/// What the command prints after its first line, the files it writes (name, content) and
/// the comparisons it made.
struct Report {
    text: String,
    files: Vec<(&'static str, String)>,
    comparisons: Vec<(String, Window, PairedComparison)>,
}

fn report(results: &[ChildResult], sessions: usize, bootstrap: usize, seed: u64) -> Report {
    let windows = Window::standard(sessions);
    let comparisons: Vec<(String, Window, PairedComparison)> = COMPARISONS
        .iter()
        .flat_map(|&(first, second)| {
            windows.iter().map(move |w| {
                let name = format!("{} − {}", first.key(), second.key());
                let c = paired(results, first, second, w, bootstrap, seed);
                (name, w.clone(), c)
            })
        })
        .collect();
    let mut text = String::new();
    let _ = write!(text, "\n{}", means_table(results, &windows));
    let _ = writeln!(
        text,
        "\nPaired by child: per child the mean over seeds of first − second (both on the same \
         draws); W/T/L: children whose 95 % interval over seeds lies above 0 / holds 0 / lies \
         below 0; sign p: exact sign test of wins against losses; then the same without the \
         child furthest from the mean. Bootstrap: {bootstrap} resamples of the children, seed \
         {seed}."
    );
    text.push_str(&paired_table(&comparisons));
    let _ = writeln!(
        text,
        "\nPer child, score per session over sessions 1-{sessions} (mean over seeds); best \
         score and best return: what the child's own model allows at most, exactly:"
    );
    text.push_str(&child_table(results, &windows[0], &comparisons[0].2));
    let files = vec![
        ("per_child.csv", sessions_csv(results)),
        (
            "per_child_children.csv",
            children_csv(results, &windows, &comparisons),
        ),
        ("per_child_paired.csv", paired_csv(&comparisons)),
    ];
    Report {
        text,
        files,
        comparisons,
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let learning = args.learning.learning(args.reward)?;
    let (records, spec) = args.study.read(learning)?;
    let a = &args.study;
    let started = std::time::Instant::now();
    let cases = cases(&records, &spec.fit).context("fitting the leave-one-child-out models")?;
    println!(
        "{} children from {}: each placed by {}-cluster models fitted without them (cluster \
         sizes {:?}), simulated by a model fitted on their own sequences; {} sessions x {} seeds \
         per policy, every policy on the same draws; reward {}",
        cases.len(),
        a.study.display(),
        a.clusters,
        (0..a.clusters)
            .map(|k| cases.iter().filter(|c| c.cluster == k).count())
            .collect::<Vec<_>>(),
        a.sessions,
        a.seeds,
        learning.reward
    );
    let bar = super::progress_bar(cases.len() as u64);
    let results = run_study(&cases, &spec, &|| bar.inc(1));
    bar.finish_and_clear();
    let r = report(&results, a.sessions, a.bootstrap, a.seed);
    print!("{}", r.text);
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("creating {}", args.output.display()))?;
    let mut written = Vec::new();
    for (name, text) in &r.files {
        let path = args.output.join(name);
        atomic_file::write(&path, text.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
        written.push(path);
    }
    let subtitle = format!(
        "{} children, leave one out; {} seeds on the same draws for every policy; mean over \
         children, band: 95 % t interval over children; reward {}",
        cases.len(),
        a.seeds,
        learning.reward
    );
    let svg = per_child_svg(&results, &subtitle).map_err(|e| anyhow::anyhow!("drawing: {e}"))?;
    written.extend(<[PathBuf; 2]>::from(figures::write_svg_and_png(
        &args.output.join("per_child"),
        &svg,
    )?));
    let all_sessions = &Window::standard(a.sessions)[0];
    let score_all: Vec<(String, PairedComparison)> = r
        .comparisons
        .iter()
        .filter(|(_, w, _)| w == all_sessions)
        .map(|(n, _, c)| (n.clone(), c.clone()))
        .collect();
    let subtitle = format!(
        "score per session, sessions 1-{}: per child first − second (mean over {} seeds, bar: \
         95 % interval over seeds; green win, red loss, grey tie); line and band: mean over \
         children and its 95 % t interval",
        a.sessions, a.seeds
    );
    let svg = per_child_paired_svg(&score_all, "difference in score per session", &subtitle)
        .map_err(|e| anyhow::anyhow!("drawing: {e}"))?;
    written.extend(<[PathBuf; 2]>::from(figures::write_svg_and_png(
        &args.output.join("per_child_paired"),
        &svg,
    )?));
    println!(
        "\nwrote {}",
        written
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    // On stderr, so that the same run prints the same standard output.
    eprintln!("({:.1} s)", started.elapsed().as_secs_f64());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use policy_lab::child_study::per_child::StudySpec;
    use q_learning::Learning;
    use user_models::simulate::{StudySpec as SyntheticStudy, simulate_study};

    #[test]
    fn the_paired_study_prints_and_writes_the_same_twice() {
        // Two whole runs on the synthetic study (user_models' simulated one), from the fits
        // on: the same tables, CSV files and comparisons, byte for byte.
        let records = simulate_study(&SyntheticStudy::default());
        let spec = StudySpec {
            fit: user_models::FitOptions {
                optimise: false,
                ..Default::default()
            },
            learning: Learning {
                reward: Reward::RePlusBetaE,
                ..Learning::default()
            },
            pretrain_epochs: 10,
            pretrain_runs: 2,
            sessions: 6,
            seeds: 4,
            seed: 3,
        };
        let once = || {
            let cases = cases(&records, &spec.fit).expect("cases");
            let results = run_study(&cases[..6], &spec, &|| {});
            report(&results, spec.sessions, 500, spec.seed)
        };
        let (a, b) = (once(), once());
        assert_eq!(a.text, b.text);
        assert_eq!(a.files, b.files);
        assert_eq!(a.comparisons, b.comparisons);
        for words in [
            "per_user − cluster, score, sessions 1-6",
            "  without ",
            "optimal for the child's model",
            "the most any policy can expect",
        ] {
            assert!(a.text.contains(words), "{words}: {}", a.text);
        }
        // 6 children x 4 policies x 4 seeds x 6 sessions; 6 children; 3 comparisons x 4
        // windows, each with and without its most influential child.
        let lines: Vec<usize> = a.files.iter().map(|(_, f)| f.lines().count()).collect();
        assert_eq!(lines, [1 + 6 * 4 * 4 * 6, 1 + 6, 1 + 3 * 4 * 2]);
    }
}
