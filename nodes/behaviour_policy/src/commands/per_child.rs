//! `behaviour_policy per-child`: per-child adaptation measured on the study's participants,
//! leave one child out at a time (`behaviour_policy::per_child`): the cluster's policy, a
//! per-user table started from it, and a table learned on the child from scratch, over a run
//! of simulated sessions against the child's own fitted model. Prints the table, writes
//! per_child.csv and the figure.

use super::{LearningArgs, parse_reward};
use anyhow::{Context, bail};
use behaviour_policy::Reward;
use behaviour_policy::per_child::{Arm, ChildResult, Metric, StudySpec, cases, run_study, summary};
use behaviour_policy::plot::per_child_svg;
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// The study's records (the paper's: 20 participants, 10 sequences each).
    #[arg(long, default_value = "../shared/data/migrave-study")]
    study: PathBuf,
    /// Clusters of the user models fitted without each child.
    #[arg(long, default_value_t = 2)]
    clusters: usize,
    #[arg(long, default_value = "RE+bE", value_parser = parse_reward)]
    reward: Reward,
    #[command(flatten)]
    learning: LearningArgs,
    /// Sessions each child plays with each policy.
    #[arg(long, default_value_t = 20)]
    sessions: usize,
    /// Repetitions per child and policy (independent random streams).
    #[arg(long, default_value_t = 30)]
    seeds: usize,
    /// The cluster's policy is pretrained as the node does: runs x epochs x 100 sessions.
    #[arg(long, default_value_t = 100)]
    pretrain_epochs: usize,
    #[arg(long, default_value_t = 5)]
    pretrain_runs: usize,
    /// Seed of the fits (K-means) and of every simulated session.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    #[arg(long, default_value = "out/per_child")]
    output: PathBuf,
}

fn table(results: &[ChildResult], sessions: usize) -> String {
    let late = sessions.saturating_sub(5)..sessions;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{:<40} {:>17} {:>17} {:>17} {:>17}",
        "policy (mean ± std over seeds)",
        format!("score 1-{sessions}"),
        format!("score {}-{sessions}", late.start + 1),
        format!("engagement 1-{sessions}"),
        format!("return 1-{sessions}"),
    );
    for arm in Arm::ALL {
        let cell = |metric, range: std::ops::Range<usize>| {
            let m = summary(results, arm, metric, range, &|_| true);
            format!("{:>8.3} ± {:<6.3}", m.mean, m.std)
        };
        let _ = writeln!(
            out,
            "{:<40} {:>17} {:>17} {:>17} {:>17}",
            arm.name(),
            cell(Metric::Score, 0..sessions),
            cell(Metric::Score, late.clone()),
            cell(Metric::Engagement, 0..sessions),
            cell(Metric::Return, 0..sessions),
        );
    }
    out
}

fn csv(results: &[ChildResult]) -> String {
    let mut out = String::from("user,cluster,policy,seed,session,score,engagement,return\n");
    for r in results {
        for (arm, runs) in Arm::ALL.iter().zip(&r.runs) {
            for (seed, run) in runs.iter().enumerate() {
                for (k, m) in run.iter().enumerate() {
                    let _ = writeln!(
                        out,
                        "{},{},{:?},{seed},{},{},{},{}",
                        r.user,
                        r.cluster,
                        arm,
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

pub fn run(a: Args) -> anyhow::Result<()> {
    let learning = a.learning.learning(a.reward)?;
    if a.sessions == 0 || a.seeds == 0 || a.pretrain_epochs == 0 || a.pretrain_runs == 0 {
        bail!("--sessions, --seeds, --pretrain-epochs and --pretrain-runs must be at least 1");
    }
    if !a.study.is_dir() {
        bail!(
            "{}: no such folder (the study's records; ../shared/data/migrave-study beside the \
             repository, or --study DIR)",
            a.study.display()
        );
    }
    let records = user_models::data::study::read_study(&a.study)
        .with_context(|| format!("reading the study in {}", a.study.display()))?;
    let spec = StudySpec {
        fit: user_models::FitOptions {
            clusters: a.clusters,
            seed: a.seed,
            provenance: format!("{} without one child", a.study.display()),
            ..Default::default()
        },
        learning,
        pretrain_epochs: a.pretrain_epochs,
        pretrain_runs: a.pretrain_runs,
        sessions: a.sessions,
        seeds: a.seeds,
        seed: a.seed,
    };
    let started = std::time::Instant::now();
    let cases = cases(&records, &spec.fit).context("fitting the leave-one-child-out models")?;
    println!(
        "{} children from {}: each placed by {}-cluster models fitted without them (cluster \
         sizes {:?}), simulated by a model fitted on their own sequences; {} sessions x {} seeds \
         per policy, reward {}",
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
    print!("\n{}", table(&results, a.sessions));
    println!("({:.1} s)", started.elapsed().as_secs_f64());
    std::fs::create_dir_all(&a.output)
        .with_context(|| format!("creating {}", a.output.display()))?;
    let csv_path = a.output.join("per_child.csv");
    atomic_file::write(&csv_path, csv(&results).as_bytes())
        .with_context(|| format!("writing {}", csv_path.display()))?;
    let subtitle = format!(
        "{} children, leave one out; {} seeds; mean over children, band ± std over seeds; reward {}",
        cases.len(),
        a.seeds,
        learning.reward
    );
    let svg = per_child_svg(&results, &subtitle).map_err(|e| anyhow::anyhow!("drawing: {e}"))?;
    let (svg, png) = figures::write_svg_and_png(&a.output.join("per_child"), &svg)?;
    println!(
        "wrote {}, {} and {}",
        csv_path.display(),
        svg.display(),
        png.display()
    );
    Ok(())
}
