//! `policy_lab experiments`: the paper's evaluation in simulation. Every user model x
//! reward (and the transfers) for R runs of E epochs, in parallel; writes the curves as CSV,
//! the user-model tables used, Figs. 4 and 5 (SVG + PNG), and the last-epoch table.

use super::{LearningArgs, parse_reward, progress_bar, user_models};
use anyhow::{Context, bail};
use policy_lab::experiments::grid::{GridSpec, run_grid};
use policy_lab::experiments::report::{curves_csv, last_epoch_table};
use policy_lab::plots::{Figure, curves_svg};
use q_learning::Reward;
use q_learning::training::{EpochScheme, RunSpec};
use std::path::PathBuf;

#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// Fitted user models (user_model file), or a JSON list of tabulated user-model tables.
    #[arg(long, default_value = "nodes/user_model/models/migrave_study_c2.json")]
    user_models: PathBuf,
    /// Use the hand-made per-level tables from REFERENCE.md instead (not a fitted model).
    #[arg(long)]
    per_level_reference: bool,
    /// Epochs per run (the authors: 400 = 40,000 sessions).
    #[arg(long, default_value_t = 400)]
    epochs: usize,
    #[arg(long, default_value_t = 30)]
    runs: usize,
    #[arg(long, default_value_t = 100)]
    sessions_per_epoch: usize,
    /// Master seed; each run's seed derives from it and the run's configuration and index.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Clusters to train against (default: all in the file).
    #[arg(long, value_delimiter = ',')]
    clusters: Vec<usize>,
    /// Reward functions (default: RE,RE+bE,lE).
    #[arg(long, value_delimiter = ',', value_parser = parse_reward)]
    rewards: Vec<Reward>,
    #[arg(long)]
    no_transfer: bool,
    /// blocks: epoch e = sessions 100e..100e+99, visits counted in its first session;
    /// authors: their exact bookkeeping (100E-1 sessions, first point = session 1 alone).
    #[arg(long, default_value = "blocks", value_parser = ["blocks", "authors"])]
    epoch_scheme: String,
    /// PS is the latest result instead of the authors' (and Algorithm 1's) one-step lag.
    #[arg(long)]
    no_state_lag: bool,
    #[command(flatten)]
    learning: LearningArgs,
    #[arg(long, default_value = "out/policy")]
    output: PathBuf,
    /// Skip Figs. 4 and 5 (benchmarks).
    #[arg(long)]
    no_figures: bool,
    /// Also write {"iterations", "seconds", "threads", "ns_per_iteration"} of the grid here.
    #[arg(long)]
    timing_json: Option<PathBuf>,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let (models, source) = user_models::load(&a.user_models, a.per_level_reference)?;
    let clusters = if a.clusters.is_empty() {
        (0..models.len()).collect()
    } else {
        a.clusters.clone()
    };
    user_models::check_clusters(&models, &clusters, &source)?;
    let rewards = if a.rewards.is_empty() {
        Reward::ALL.to_vec()
    } else {
        a.rewards.clone()
    };
    let transfer = !a.no_transfer && clusters.len() >= 2;
    if transfer && !rewards.contains(&Reward::RePlusBetaE) {
        bail!("transfer starts from RE+bE policies: add RE+bE to --rewards or pass --no-transfer");
    }
    if a.epochs == 0 || a.sessions_per_epoch == 0 || a.runs == 0 {
        bail!("--epochs, --runs and --sessions-per-epoch must be at least 1");
    }
    let learning = a.learning.learning(Reward::Re)?;
    let spec = GridSpec {
        runs: a.runs,
        seed: a.seed,
        run: RunSpec {
            epochs: a.epochs,
            sessions_per_epoch: a.sessions_per_epoch,
            scheme: if a.epoch_scheme == "authors" {
                EpochScheme::Authors
            } else {
                EpochScheme::Blocks
            },
            state_lags_result: !a.no_state_lag,
        },
        learning,
        clusters: clusters.clone(),
        rewards: rewards.clone(),
        transfer,
    };
    let transfers = if transfer {
        clusters.len() * (clusters.len() - 1)
    } else {
        0
    };
    let total_runs = (clusters.len() * rewards.len() + transfers) * a.runs;
    eprintln!("user models: {source}\n{}", user_models::describe(&models));
    let bar = progress_bar(total_runs as u64);
    let started = std::time::Instant::now();
    let grid = run_grid(&models, &spec, &|| bar.inc(1));
    let seconds = started.elapsed().as_secs_f64();
    bar.finish_and_clear();
    let threads = rayon::current_num_threads();
    let ns = seconds * 1e9 / grid.iterations.max(1) as f64;

    std::fs::create_dir_all(&a.output)
        .with_context(|| format!("creating {}", a.output.display()))?;
    let csv_path = a.output.join("curves.csv");
    atomic_file::write(&csv_path, &curves_csv(&grid.curves)?)
        .with_context(|| format!("writing {}", csv_path.display()))?;
    let tables_path = a.output.join("user_model_tables.json");
    atomic_file::write(&tables_path, serde_json::to_string(&models)?.as_bytes())
        .with_context(|| format!("writing {}", tables_path.display()))?;
    let table = last_epoch_table(&grid.curves);
    let command: Vec<String> = std::env::args().collect();
    let summary = format!(
        "command: {}\nuser models: {source}\n{} runs x {} epochs x {} sessions: {} Q-iterations \
         in {seconds:.3} s on {threads} thread(s): {ns:.1} ns per iteration of wall time, \
         {:.1} ns of thread time\n\nlast epoch, mean ± std across runs (90% at: first epoch where \
         the 5-epoch moving mean score has covered 90% of its way from epoch 1 to the mean of \
         the last 10):\n{table}",
        command.join(" "),
        total_runs,
        a.epochs,
        a.sessions_per_epoch,
        grid.iterations,
        ns * threads as f64,
    );
    atomic_file::write(&a.output.join("summary.txt"), summary.as_bytes())?;
    if let Some(path) = &a.timing_json {
        let timing = serde_json::json!({
            "iterations": grid.iterations,
            "seconds": seconds,
            "threads": threads,
            "ns_per_iteration": ns * threads as f64,
        });
        atomic_file::write(path, timing.to_string().as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if !a.no_figures {
        let subtitle = format!(
            "{} runs per configuration, {} sessions per epoch, seed {}; {source}",
            a.runs, a.sessions_per_epoch, a.seed
        );
        for (name, figure) in [
            ("fig4_score", Figure::Score),
            ("fig5_engagement", Figure::Engagement),
        ] {
            let svg = curves_svg(&grid.curves, figure, &subtitle)
                .map_err(|e| anyhow::anyhow!("drawing {name}: {e}"))?;
            figures::write_svg_and_png(&a.output.join(name), &svg)?;
        }
    }
    println!("{summary}");
    println!(
        "wrote {}, {}, summary.txt{}",
        csv_path.display(),
        tables_path.display(),
        if a.no_figures {
            String::new()
        } else {
            ", fig4_score.{svg,png}, fig5_engagement.{svg,png}".into()
        }
    );
    Ok(())
}
