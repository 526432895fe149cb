//! `behaviour_policy`: the paper's experiments, or the decision node.
//!   behaviour_policy experiments --epochs 400 --runs 30 --output out/policy
//!   behaviour_policy run      (DDS node: DecideAction, learns from SequenceResult)

use anyhow::{Context, bail};
use behaviour_policy::experiments::{GridSpec, curves_csv, run_grid};
use behaviour_policy::{Learning, PolicyCore, PolicyParams};
use clap::{Parser, Subcommand};
use node_shell::{NodeShell, ShellOptions, header_now};
use qt_therapy_msgs::DecideActionResponse;
use qt_therapy_msgs::topics::{DECIDE_ACTION, DECISION, SEQUENCE_RESULT};
use std::path::{Path, PathBuf};

#[derive(Parser)]
#[command(about = "Behaviour policy: the paper's experiments, or the decision node")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Train every user model x reward (and both transfers) in simulation; CSV and Figs. 4, 5.
    Experiments {
        #[arg(long, default_value = "nodes/user_model/models/migrave_study_c2.json")]
        user_models: PathBuf,
        #[arg(long, default_value_t = 400)]
        epochs: usize,
        #[arg(long, default_value_t = 30)]
        runs: usize,
        #[arg(long, default_value_t = 100)]
        sessions_per_epoch: usize,
        #[arg(long, default_value_t = 7)]
        seed: u64,
        /// PS is the latest result instead of the authors' one-step lag.
        #[arg(long)]
        no_state_lag: bool,
        #[arg(long)]
        no_transfer: bool,
        #[arg(long, default_value = "out/policy")]
        output: PathBuf,
    },
    /// Run the decision node over DDS.
    Run {
        #[command(flatten)]
        shell: ShellOptions,
    },
}

fn main() -> anyhow::Result<()> {
    match Cli::parse().command {
        Command::Run { shell } => tokio::runtime::Builder::new_multi_thread()
            .enable_all()
            .build()?
            .block_on(run(shell)),
        Command::Experiments {
            user_models,
            epochs,
            runs,
            sessions_per_epoch,
            seed,
            no_state_lag,
            no_transfer,
            output,
        } => {
            let set = user_model::UserModelSet::load(&user_models)
                .with_context(|| format!("loading {}", user_models.display()))?;
            let models = set.tables();
            if models.len() < 2 && !no_transfer {
                bail!(
                    "{} has {} cluster(s): transfer needs two (or pass --no-transfer)",
                    user_models.display(),
                    models.len()
                );
            }
            let learning = Learning {
                state_lags_result: !no_state_lag,
                ..Learning::default()
            };
            let spec = GridSpec {
                runs,
                epochs,
                sessions_per_epoch,
                seed,
                transfer: !no_transfer,
            };
            let total = (models.len() * 3 + if no_transfer { 0 } else { 2 }) * runs;
            let bar = indicatif::ProgressBar::new(total as u64).with_style(
                indicatif::ProgressStyle::with_template(
                    "{bar:40} {pos}/{len} runs  {elapsed} (eta {eta})",
                )
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
            );
            let started = std::time::Instant::now();
            let curves = run_grid(&models, &learning, &spec, &|| bar.inc(1));
            bar.finish();
            let elapsed = started.elapsed();
            std::fs::create_dir_all(&output)
                .with_context(|| format!("creating {}", output.display()))?;
            let csv = output.join("curves.csv");
            std::fs::write(&csv, curves_csv(&curves))
                .with_context(|| format!("writing {}", csv.display()))?;
            for (name, score) in [("fig4_score", true), ("fig5_engagement", false)] {
                let svg = behaviour_policy::plot::curves_svg(&curves, models.len(), score)
                    .map_err(|e| anyhow::anyhow!("plot: {e}"))?;
                figures::write_svg_and_png(&output.join(name), &svg)?;
            }
            println!(
                "{} runs x {epochs} epochs x {sessions_per_epoch} sessions in {:.2} s",
                total,
                elapsed.as_secs_f64()
            );
            println!("last epoch, mean ± std across runs:");
            println!(
                "{:<26} {:>15} {:>8} {:>15}",
                "configuration", "score", "ratio", "engagement"
            );
            for c in &curves {
                if let (Some(m), Some(s)) = (c.mean.last(), c.std.last()) {
                    println!(
                        "{:<26} {:>7.2} ± {:<5.2} {:>8.3} {:>7.3} ± {:<5.3}",
                        c.config.name, m.score, s.score, m.ratio, m.engagement, s.engagement
                    );
                }
            }
            println!(
                "curves: {}\nfigures: {}/fig4_score.{{svg,png}}, fig5_engagement.{{svg,png}}",
                csv.display(),
                output.display()
            );
            Ok(())
        }
    }
}

async fn run(options: ShellOptions) -> anyhow::Result<()> {
    let (mut shell, params): (NodeShell, PolicyParams) =
        NodeShell::start("behaviour_policy", &options)?;
    let set =
        user_model::UserModelSet::load(Path::new(&params.user_model_file)).with_context(|| {
            format!(
                "loading user_model_file from {}",
                options.params_path(shell.name()).display()
            )
        })?;
    let mut core = PolicyCore::new(&params, &set.tables(), Path::new("."))
        .context("setting up the Q-tables")?;
    tracing::info!(clusters = set.cluster_count(), exploitation_only = params.exploitation_only, q_tables = %params.q_table_dir, "policy ready");
    {
        let mut calls = shell.serve(DECIDE_ACTION, |e| DecideActionResponse {
            ok: false,
            error: e.to_string(),
            ..Default::default()
        })?;
        let mut results = shell.subscribe(SEQUENCE_RESULT, 64)?;
        let decisions = shell.publisher(DECISION)?;
        let drops = shell.drops();
        let stop = shell.shutdown_signal();
        tokio::pin!(stop);
        loop {
            tokio::select! {
                _ = &mut stop => break,
                Some(call) = calls.recv() => {
                    let response = match core.decide(&call.request, header_now()) {
                        Ok(d) => {
                            decisions.send(d.clone());
                            DecideActionResponse { ok: true, error: String::new(), decision: d }
                        }
                        Err(e) => {
                            tracing::warn!(session = %call.request.session_id, "refused a decision: {e}");
                            DecideActionResponse { ok: false, error: e.to_string(), ..Default::default() }
                        }
                    };
                    call.respond(response);
                }
                Some(result) = results.recv() => {
                    if let Err(e) = core.learn(&result) {
                        drops.record(SEQUENCE_RESULT.name, &format!("not learned from: {e}"));
                    }
                }
            }
        }
    }
    shell.stop().await;
    Ok(())
}
