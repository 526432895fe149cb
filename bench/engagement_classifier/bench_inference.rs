//! Timing half of `bench/engagement_classifier/bench_inference.py` (which runs this with
//! `--release` and puts Python xgboost beside it): per-frame latency and throughput of
//! `EngagementModel::predict` (standardisation + trees), and of the whole per-frame path
//! (`EngagementEstimator::on_frame`, 4 interleaved cameras). Prints one JSON object.
//!
//! usage: bench_inference MODEL ROWS_CSV PROBABILITIES_OUT

use engagement_classifier::table::read_feature_csv;
use engagement_classifier::{
    EngagementClassifierParams, EngagementEstimator, EngagementModel, FaceFrame,
};
use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    anyhow::ensure!(
        args.len() == 4,
        "usage: bench_inference MODEL ROWS_CSV PROBABILITIES_OUT"
    );
    let model = EngagementModel::load(Path::new(&args[1]))?;
    let rows = read_feature_csv(Path::new(&args[2]))?;
    anyhow::ensure!(!rows.is_empty(), "no rows");

    let probabilities: Vec<String> = rows
        .iter()
        .map(|r| model.predict(r).probability.to_string())
        .collect();
    std::fs::write(&args[3], probabilities.join("\n") + "\n")?;

    // Latency: each call timed on its own (Instant costs ~20 ns, included).
    let mut latencies: Vec<f64> = Vec::with_capacity(rows.len() * 5);
    for _ in 0..5 {
        for r in &rows {
            let t = Instant::now();
            black_box(model.predict(black_box(r)));
            latencies.push(t.elapsed().as_secs_f64());
        }
    }
    latencies.sort_by(f64::total_cmp);
    let pct = |q: f64| latencies[((latencies.len() - 1) as f64 * q) as usize];

    // Throughput: back-to-back calls.
    let repeats = 50;
    let t = Instant::now();
    for _ in 0..repeats {
        for r in &rows {
            black_box(model.predict(black_box(r)));
        }
    }
    let per_row = t.elapsed().as_secs_f64() / (repeats * rows.len()) as f64;

    // Whole per-frame path: classify + aggregate, 4 cameras at 30 fps of message time.
    let params = EngagementClassifierParams::default();
    let mut est = EngagementEstimator::new(
        model.clone(),
        params.min_confidence,
        params.aggregator_config(),
    );
    let f32_rows: Vec<[f32; 32]> = rows.iter().map(|r| r.map(|v| v as f32)).collect();
    let mut seconds = 0usize;
    let frames = repeats * rows.len();
    let t = Instant::now();
    for k in 0..frames {
        let frame = FaceFrame {
            stamp_ns: (k / 4) as i64 * 1_000_000_000 / 30,
            source: (k % 4) as u32,
            detection_success: true,
            confidence: 0.95,
            features: &f32_rows[k % rows.len()],
        };
        est.on_frame(&frame, &mut |_| seconds += 1)?;
    }
    let per_frame = t.elapsed().as_secs_f64() / frames as f64;

    println!(
        "{{\"rows\": {}, \"trees\": {}, \"latency_median_s\": {:e}, \"latency_p99_s\": {:e}, \
         \"predict_per_row_s\": {:e}, \"on_frame_per_frame_s\": {:e}, \"seconds_reported\": {}}}",
        rows.len(),
        model.tree_count(),
        pct(0.5),
        pct(0.99),
        per_row,
        per_frame,
        seconds
    );
    Ok(())
}
