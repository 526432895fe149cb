//! `user_model`: fit user models, print their predictions, write a synthetic study, or run the
//! user-model node.
//!   user_model fit --data ../shared/data/migrave-study --clusters 2 --output models/m.json
//!   user_model predict --model models/m.json > predictions.csv
//!   user_model simulate-study --output out/synthetic_study.csv
//!   user_model run            (DDS node: PredictUser, AssignCluster, UserModelInfo)

use anyhow::{Context, bail};
use clap::{Parser, Subcommand};
use node_shell::{NodeShell, ShellOptions, header_now};
use qt_therapy_msgs::topics::{ASSIGN_CLUSTER, PREDICT_USER, USER_MODEL_INFO};
use qt_therapy_msgs::{AssignClusterResponse, PredictUserResponse, UserModelInfo};
use sequence_game::{Feedback, Level, ModelInput, Outcome};
use std::path::PathBuf;
use user_model::simulate::{StudySpec, simulate_study};
use user_model::{FitOptions, Kernel, UserModelParams, UserModelSet};

#[derive(Parser)]
#[command(about = "User models: fit, predict, simulate a study, or run the node")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Fit user models from interaction data (a study directory or our CSV).
    Fit(FitArgs),
    /// Print F^p and F^e (mean, std) of every cluster and input as CSV.
    Predict {
        #[arg(long)]
        model: PathBuf,
    },
    /// Write a SYNTHETIC study (20 users, two behaviour groups) in our CSV format.
    SimulateStudy {
        #[arg(long)]
        output: PathBuf,
        #[arg(long, default_value_t = 7)]
        seed: u64,
    },
    /// Run the user-model node over DDS.
    Run {
        #[command(flatten)]
        shell: ShellOptions,
    },
}

#[derive(clap::Args)]
struct FitArgs {
    /// The study directory (sequences.csv, engagement_per_second.csv) or a CSV of records.
    #[arg(long, default_value = "../shared/data/migrave-study")]
    data: PathBuf,
    #[arg(long, default_value_t = 2)]
    clusters: usize,
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// rational-quadratic (the authors'), rbf, matern12, matern32 or matern52.
    #[arg(long, default_value = "rational-quadratic")]
    kernel: String,
    #[arg(long, default_value_t = 1.0)]
    length_scale: f64,
    /// RationalQuadratic alpha.
    #[arg(long, default_value_t = 1.5)]
    alpha: f64,
    /// Keep the given hyperparameters instead of maximising the log marginal likelihood.
    #[arg(long)]
    fixed: bool,
    /// Random restarts of the hyperparameter search besides the initial values (0, as the
    /// authors' scikit-learn setting).
    #[arg(long, default_value_t = 0)]
    restarts: usize,
    #[arg(long)]
    output: PathBuf,
    /// Where to write the Fig. 3 plots [default: beside the output].
    #[arg(long)]
    figures: Option<PathBuf>,
}

fn kernel(a: &FitArgs) -> anyhow::Result<Kernel> {
    let l = a.length_scale;
    if !(l.is_finite() && l > 0.0 && a.alpha.is_finite() && a.alpha > 0.0) {
        bail!("--length-scale and --alpha must be positive");
    }
    Ok(match a.kernel.as_str() {
        "rational-quadratic" => Kernel::RationalQuadratic {
            length_scale: l,
            alpha: a.alpha,
        },
        "rbf" => Kernel::Rbf { length_scale: l },
        "matern12" => Kernel::Matern {
            length_scale: l,
            nu: 0.5,
        },
        "matern32" => Kernel::Matern {
            length_scale: l,
            nu: 1.5,
        },
        "matern52" => Kernel::Matern {
            length_scale: l,
            nu: 2.5,
        },
        other => bail!(
            "--kernel {other:?} is not rational-quadratic, rbf, matern12, matern32 or matern52"
        ),
    })
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    if let Command::Run { shell } = cli.command {
        return tokio::runtime::Builder::new_multi_thread()
            .enable_all()
            .build()?
            .block_on(run(shell));
    }
    match cli.command {
        Command::Fit(a) => fit(a),
        Command::Predict { model } => predict(model),
        Command::SimulateStudy { output, seed } => {
            let records = simulate_study(&StudySpec {
                seed,
                ..StudySpec::default()
            });
            user_model::data::write_csv(&output, &records)?;
            println!(
                "wrote {} SYNTHETIC records of 20 users to {}",
                records.len(),
                output.display()
            );
            Ok(())
        }
        Command::Run { .. } => Ok(()),
    }
}

fn fit(a: FitArgs) -> anyhow::Result<()> {
    let records = user_model::data::read_any(&a.data)
        .with_context(|| format!("reading {}", a.data.display()))?;
    let options = FitOptions {
        clusters: a.clusters,
        seed: a.seed,
        kernel: kernel(&a)?,
        optimise: !a.fixed,
        optimiser_restarts: a.restarts,
        provenance: format!(
            "user_model fit --data {} --clusters {} --seed {} --kernel {}{}",
            a.data.display(),
            a.clusters,
            a.seed,
            a.kernel,
            if a.fixed { " --fixed" } else { "" }
        ),
        ..FitOptions::default()
    };
    let set = user_model::fit(&records, &options)?;
    set.save(&a.output)?;
    let figures = a
        .figures
        .clone()
        .unwrap_or_else(|| a.output.parent().map(PathBuf::from).unwrap_or_default());
    let written = user_model::plot::write_figures(set.file(), &figures)
        .map_err(|e| anyhow::anyhow!("plots: {e}"))?;
    println!(
        "{} records of {} users -> {} clusters",
        records.len(),
        set.file().users.len(),
        set.cluster_count()
    );
    println!(
        "cluster  users  P(s|L1)  P(s|L2)  P(s|L3)    E|L1    E|L2    E|L3   F^p kernel / F^e kernel"
    );
    for c in &set.file().clusters {
        let l = &c.levels;
        println!(
            "{:>7}  {:>5}  {:>7.3}  {:>7.3}  {:>7.3}  {:>+6.3}  {:>+6.3}  {:>+6.3}   {:?} / {:?}",
            c.cluster,
            c.users.len(),
            l[0].success_mean,
            l[1].success_mean,
            l[2].success_mean,
            l[0].engagement_mean,
            l[1].engagement_mean,
            l[2].engagement_mean,
            c.success.kernel,
            c.engagement.kernel
        );
    }
    println!("model: {}", a.output.display());
    for w in written {
        println!("figure: {}", w.display());
    }
    Ok(())
}

fn predict(model: PathBuf) -> anyhow::Result<()> {
    let set = UserModelSet::load(&model)?;
    println!(
        "cluster,level,feedback,previous_score,outcome,p_success,p_success_std,engagement,engagement_std"
    );
    for table in set.tables() {
        for input in ModelInput::all() {
            for outcome in Outcome::ALL {
                let p = table.success(input);
                let e = table.engagement(input, outcome);
                println!(
                    "{},{},{},{},{},{:.6},{:.6},{:.6},{:.6}",
                    table.cluster,
                    input.level.get(),
                    input.feedback as u8,
                    input.previous_score,
                    outcome.sign(),
                    p.mean,
                    p.std,
                    e.mean,
                    e.std
                );
            }
        }
    }
    Ok(())
}

async fn run(shell_options: ShellOptions) -> anyhow::Result<()> {
    let (mut shell, params): (NodeShell, UserModelParams) =
        NodeShell::start("user_model", &shell_options)?;
    let set = UserModelSet::load(std::path::Path::new(&params.model_file)).with_context(|| {
        format!(
            "loading model_file from {}",
            shell_options.params_path(shell.name()).display()
        )
    })?;
    tracing::info!(model = %params.model_file, clusters = set.cluster_count(), "user models loaded, every prediction tabulated");
    {
        let info = shell.publisher(USER_MODEL_INFO)?;
        info.send(UserModelInfo {
            header: header_now(),
            model_file: params.model_file.clone(),
            format_version: set.file().version,
            clusters: set
                .file()
                .clusters
                .iter()
                .map(|c| c.cluster as i32)
                .collect(),
            cluster_sizes: set
                .file()
                .clusters
                .iter()
                .map(|c| c.users.len() as u32)
                .collect(),
            kernel: set
                .file()
                .clusters
                .first()
                .map(|c| c.success.kernel.name().to_string())
                .unwrap_or_default(),
        });
        let mut predict = shell.serve(PREDICT_USER, |e| PredictUserResponse {
            ok: false,
            error: e.to_string(),
            ..Default::default()
        })?;
        let mut assign = shell.serve(ASSIGN_CLUSTER, |e| AssignClusterResponse {
            ok: false,
            error: e.to_string(),
            cluster: -1,
            ..Default::default()
        })?;
        let stop = shell.shutdown_signal();
        tokio::pin!(stop);
        loop {
            tokio::select! {
                _ = &mut stop => break,
                Some(call) = predict.recv() => {
                    let r = &call.request;
                    let response = match (set.table(r.cluster.into()), Level::new(r.level.into()), Feedback::new(r.feedback.into()), Outcome::new(r.outcome.into())) {
                        (Ok(table), Ok(level), Ok(feedback), Ok(outcome)) => match ModelInput::new(level, feedback, r.previous_score) {
                            Ok(input) => {
                                let (p, e) = (table.success(input), table.engagement(input, outcome));
                                PredictUserResponse { ok: true, error: String::new(), success_probability: p.mean, success_std: p.std, engagement: e.mean, engagement_std: e.std }
                            }
                            Err(e) => PredictUserResponse { ok: false, error: e.to_string(), ..Default::default() },
                        },
                        (Err(e), ..) => PredictUserResponse { ok: false, error: e.to_string(), ..Default::default() },
                        _ => PredictUserResponse { ok: false, error: "input outside the state space".into(), ..Default::default() },
                    };
                    call.respond(response);
                }
                Some(call) = assign.recv() => {
                    let v: Result<[f64; 6], _> = call.request.user_vector.as_slice().try_into();
                    let response = match v {
                        Ok(v) => match set.assign_cluster(&v) {
                            Ok(c) => AssignClusterResponse { ok: true, error: String::new(), cluster: c as i32, projection: set.project(&v) },
                            Err(e) => AssignClusterResponse { ok: false, error: e.to_string(), cluster: -1, projection: vec![] },
                        },
                        Err(_) => AssignClusterResponse { ok: false, error: "user_vector must have 6 values".into(), cluster: -1, projection: vec![] },
                    };
                    call.respond(response);
                }
            }
        }
    }
    shell.stop().await;
    Ok(())
}
