//! Benchmark helper for bench/user_model/bench_fit.py (not a test): times `fit` on a data set
//! and the in-process table query, writes the fitted model for the Python reference, and prints
//! one JSON line. Usage: bench_fit <data: study dir or CSV> <model out> [fit repetitions]

use anyhow::Context;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sequence_game::{ModelInput, Outcome};
use std::hint::black_box;
use std::path::PathBuf;
use std::time::Instant;
use user_models::{FitOptions, UserModelSet};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let data = PathBuf::from(
        args.get(1)
            .context("usage: bench_fit <data> <model out> [reps]")?,
    );
    let out = PathBuf::from(
        args.get(2)
            .context("usage: bench_fit <data> <model out> [reps]")?,
    );
    let reps: usize = args.get(3).map_or(Ok(30), |r| r.parse())?;
    let records = user_models::data::read_any(&data)?;
    let options = FitOptions::default();
    let set = user_models::fit(&records, &options)?;
    let mut fit_ms = Vec::new();
    for _ in 0..reps {
        let started = Instant::now();
        black_box(user_models::fit(black_box(&records), &options)?);
        fit_ms.push(started.elapsed().as_secs_f64() * 1e3);
    }
    set.save(&out)?;

    // Queries drawn beforehand so the loop times only the lookups.
    let tables = UserModelSet::load(&out)?.tables();
    let inputs: Vec<ModelInput> = ModelInput::all().collect();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let queries: Vec<(usize, ModelInput, Outcome)> = (0..1_000_000)
        .map(|_| {
            (
                rng.random_range(0..tables.len()),
                inputs[rng.random_range(0..inputs.len())],
                Outcome::ALL[rng.random_range(0..2)],
            )
        })
        .collect();
    let mut query_ns = Vec::new();
    let mut sum = 0.0;
    for _ in 0..5 {
        let started = Instant::now();
        for (c, i, o) in &queries {
            let t = &tables[*c];
            sum += t.success(*i).mean + t.engagement(*i, *o).mean;
        }
        query_ns.push(started.elapsed().as_secs_f64() * 1e9 / queries.len() as f64);
    }
    black_box(sum);

    let vectors: Vec<[f64; 6]> = (0..10_000)
        .map(|_| {
            std::array::from_fn(|k| {
                if k % 2 == 0 {
                    rng.random::<f64>()
                } else {
                    rng.random_range(-1.0..1.0)
                }
            })
        })
        .collect();
    let started = Instant::now();
    for v in &vectors {
        black_box(set.assign_cluster(v)?);
    }
    let assign_ns = started.elapsed().as_secs_f64() * 1e9 / vectors.len() as f64;

    println!(
        "{}",
        serde_json::json!({
            "records": records.len(),
            "users": set.file().users.len(),
            "clusters": set.cluster_count(),
            "fit_reps": reps,
            "fit_ms_median": median(fit_ms.clone()),
            "fit_ms_min": fit_ms.iter().copied().fold(f64::INFINITY, f64::min),
            "query_ns_median": median(query_ns),
            "assign_cluster_ns": assign_ns,
            "model": out,
        })
    );
    Ok(())
}
