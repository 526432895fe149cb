//! `user_model fit`: reads interaction data (the study directory, our CSV, session bags),
//! fits the user models, writes the model file and the Fig. 3 plots, and prints the per-cluster numbers.

use anyhow::{Context, bail};
use std::io::Write;
use std::path::PathBuf;
use user_models::{FitOptions, Kernel, NoiseModel};

#[derive(clap::Args)]
pub struct Args {
    /// The data: a study directory (sequences.csv + engagement_per_second.csv), a CSV of
    /// records in our format, a session bag (.mcap) or a directory of bags; several may be
    /// given (`--data a.mcap b.mcap`), and all their records are fitted together.
    #[arg(long, num_args = 1.., required = true)]
    data: Vec<PathBuf>,
    /// Number of clusters c.
    #[arg(long, default_value_t = 2)]
    clusters: usize,
    /// Seed of K-means and of the hyperparameter restarts.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// rational-quadratic (the authors'), rbf, matern12, matern32 or matern52.
    #[arg(long, default_value = "rational-quadratic")]
    kernel: String,
    /// Length scale: initial value, or the fixed one with --fixed.
    #[arg(long, default_value_t = 1.0)]
    length_scale: f64,
    /// RationalQuadratic α: initial value, or the fixed one with --fixed.
    #[arg(long, default_value_t = 1.5)]
    alpha: f64,
    /// Keep the given hyperparameters instead of maximising the log marginal likelihood.
    #[arg(long)]
    fixed: bool,
    /// Seeded random starts of the hyperparameter search besides the initial values (0: the
    /// authors' setting).
    #[arg(long, default_value_t = 0)]
    restarts: usize,
    /// The GPs' noise: `paper` (the authors': 1e-10 on every target, so σ of a prediction is
    /// about 0 wherever the data has a group, however few sequences it holds, and large only
    /// where it has none) or `fitted` (each target is the mean of its group's n sequences and
    /// gets σ²/n, σ² fitted by the log marginal likelihood beside the kernel: σ says how well
    /// the data pin the prediction down).
    #[arg(long, default_value = "paper", value_parser = parse_noise)]
    noise: NoiseModel,
    /// K-means runs from different k-means++ seedings.
    #[arg(long, default_value_t = 10)]
    kmeans_restarts: usize,
    /// The model file to write.
    #[arg(long)]
    output: PathBuf,
    /// Directory for clusters.{svg,png} and levels.{svg,png} [default: beside the output].
    #[arg(long)]
    figures: Option<PathBuf>,
}

fn parse_noise(s: &str) -> Result<NoiseModel, String> {
    match s {
        "paper" => Ok(NoiseModel::Fixed),
        "fitted" => Ok(NoiseModel::FittedPerSequence),
        _ => Err(format!("{s:?} is not `paper` or `fitted`")),
    }
}

fn kernel(a: &Args) -> anyhow::Result<Kernel> {
    let l = a.length_scale;
    let k = match a.kernel.as_str() {
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
    };
    k.validate().context("--length-scale / --alpha")?;
    Ok(k)
}

pub fn main(a: Args) -> anyhow::Result<()> {
    let data = a
        .data
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(" ");
    let read =
        user_models::data::read_sources(&a.data).with_context(|| format!("reading {data}"))?;
    for w in &read.warnings {
        eprintln!("warning: {w}");
    }
    let records = read.records;
    let mut provenance = format!(
        "user_model fit --data {} --clusters {} --seed {} --kernel {} --length-scale {} --alpha {} --restarts {} --kmeans-restarts {}",
        data, a.clusters, a.seed, a.kernel, a.length_scale, a.alpha, a.restarts, a.kmeans_restarts
    );
    if a.fixed {
        provenance.push_str(" --fixed");
    }
    if a.noise == NoiseModel::FittedPerSequence {
        provenance.push_str(" --noise fitted");
        if a.fixed {
            bail!(
                "--noise fitted searches the noise by the log marginal likelihood, which --fixed \
                 turns off: use one or the other"
            );
        }
    }
    let options = FitOptions {
        clusters: a.clusters,
        seed: a.seed,
        kmeans_restarts: a.kmeans_restarts,
        kernel: kernel(&a)?,
        optimise: !a.fixed,
        optimiser_restarts: a.restarts,
        noise_model: a.noise,
        provenance,
        ..FitOptions::default()
    };
    let started = std::time::Instant::now();
    let set = user_models::fit(&records, &options).with_context(|| format!("fitting {data}"))?;
    let took = started.elapsed();
    set.save(&a.output)?;
    let figures = a
        .figures
        .clone()
        .unwrap_or_else(|| a.output.parent().map(PathBuf::from).unwrap_or_default());
    let written = crate::plot::write_figures(set.file(), &figures)
        .with_context(|| format!("writing figures to {}", figures.display()))?;
    // Written with errors returned (a closed pipe is not a panic).
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "{} records of {} users -> {} clusters in {:.1} ms",
        records.len(),
        set.file().users.len(),
        set.cluster_count(),
        took.as_secs_f64() * 1e3
    )?;
    writeln!(
        out,
        "cluster  users  P(s|L1)  P(s|L2)  P(s|L3)    E|L1    E|L2    E|L3"
    )?;
    for c in &set.file().clusters {
        let l = &c.levels;
        writeln!(
            out,
            "{:>7}  {:>5}  {:>7.3}  {:>7.3}  {:>7.3}  {:>+6.3}  {:>+6.3}  {:>+6.3}",
            c.cluster,
            c.users.len(),
            l[0].success_mean,
            l[1].success_mean,
            l[2].success_mean,
            l[0].engagement_mean,
            l[1].engagement_mean,
            l[2].engagement_mean,
        )?;
    }
    for c in &set.file().clusters {
        for (name, g) in [("F^p", &c.success), ("F^e", &c.engagement)] {
            let noise = match &g.group_sizes {
                Some(_) => format!(", noise σ² {:.4} per sequence (fitted)", g.noise),
                None => String::new(),
            };
            writeln!(
                out,
                "cluster {} {name}: {} points, {:?}{noise}, log marginal likelihood {:.4}",
                c.cluster,
                g.targets.len(),
                g.kernel,
                g.log_marginal_likelihood
            )?;
        }
    }
    // What σ of P(success) rests on: with the paper's noise it is about 0 wherever the
    // cluster's data has the input at all, once or often.
    for c in &set.file().clusters {
        let members: Vec<&user_models::InteractionRecord> = records
            .iter()
            .filter(|r| c.users.contains(&r.user_id))
            .collect();
        let table = set.table(c.cluster as i64)?;
        let buckets = user_models::supervision::sigma_by_support(table, &members);
        let parts: Vec<String> = buckets
            .iter()
            .filter(|b| b.inputs > 0)
            .map(|b| {
                format!(
                    "{}: {} inputs, {:.5}-{:.5} (mean {:.5})",
                    b.label, b.inputs, b.min, b.max, b.mean
                )
            })
            .collect();
        writeln!(
            out,
            "cluster {} σ of P(success) by the cluster's sequences at the input: {}",
            c.cluster,
            parts.join("; ")
        )?;
    }
    writeln!(out, "model: {}", a.output.display())?;
    for w in written {
        writeln!(out, "figure: {}", w.display())?;
    }
    Ok(())
}
