#!/usr/bin/env python3
"""Per-frame engagement inference: our Rust evaluator vs Python xgboost, same model, same rows,
one run, ratios printed.

Run from the workspace root:  python3 bench/engagement_classifier/bench_inference.py
(builds the `bench_inference` benchmark binary with --release; needs xgboost, numpy, pandas)

Model: nodes/engagement_classifier/models/synthetic_engagement.json (100 trees, with the
stored standardisation). Rows: 3,600 SYNTHETIC frames from `engagement_classifier synthesize`.
Rust times `predict` on raw rows, standardisation included. Python gets the rows already
standardised (its timing excludes that work) and runs with nthread=1, like our single thread:
  - single: Booster.inplace_predict on one row at a time (what a per-frame node does)
  - batched: inplace_predict on all rows at once (the best case for Python; a live node
    cannot batch frames it has not received yet)
"""
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
import pandas as pd
import xgboost as xgb

MODEL = "nodes/engagement_classifier/models/synthetic_engagement.json"


def run(cmd):
    return subprocess.run(cmd, check=True, capture_output=True, text=True).stdout


def main():
    tmp = tempfile.mkdtemp(prefix="engagement_bench_")
    rows_csv = os.path.join(tmp, "rows.csv")
    run(["cargo", "run", "--release", "-q", "-p", "engagement_classifier", "--",
         "synthesize", "--output", rows_csv])
    run(["cargo", "build", "--release", "-q", "-p", "suite_bench", "--bin", "bench_inference"])
    probs_out = os.path.join(tmp, "rust_probabilities.txt")
    rust = json.loads(run(["target/release/bench_inference", MODEL, rows_csv, probs_out]))

    booster = xgb.Booster(model_file=MODEL)
    booster.set_param({"nthread": 1})
    block = json.loads(booster.attr("engagement_preprocessing"))
    raw = pd.read_csv(rows_csv)
    z = np.empty((len(raw), len(block["features"])), dtype=np.float32)
    for j, (name, mean, std, fill) in enumerate(zip(block["features"], block["mean"],
                                                    block["std"], block["nan_fill"])):
        col = raw[name].to_numpy(np.float64)
        col = col - mean if abs(std) < 1e-10 else (col - mean) / std
        z[:, j] = np.where(np.isnan(col), np.nan if fill is None else fill, col)
    p_python = booster.inplace_predict(z)
    p_rust = np.loadtxt(probs_out)
    max_diff = float(np.max(np.abs(p_python - p_rust)))

    singles = [z[i:i + 1] for i in range(len(z))]
    for s in singles[:200]:  # warm-up
        booster.inplace_predict(s)
    lat = []
    t_all = time.perf_counter()
    for s in singles:
        t = time.perf_counter()
        booster.inplace_predict(s)
        lat.append(time.perf_counter() - t)
    single_per_row = (time.perf_counter() - t_all) / len(singles)
    lat.sort()
    batch_reps = 20
    t = time.perf_counter()
    for _ in range(batch_reps):
        booster.inplace_predict(z)
    batch_per_row = (time.perf_counter() - t) / (batch_reps * len(z))

    med, p99 = lat[len(lat) // 2], lat[int((len(lat) - 1) * 0.99)]
    us = 1e6
    print(f"xgboost {xgb.__version__} (nthread=1) vs Rust engagement_classifier, "
          f"{rust['rows']} SYNTHETIC rows, {rust['trees']} trees; "
          f"max |p_rust - p_python| = {max_diff:.2e}")
    print(f"{'':34}{'per row [us]':>14}{'rows/s':>14}")
    print(f"{'Rust predict, latency median':34}{rust['latency_median_s'] * us:14.3f}")
    print(f"{'Rust predict, latency p99':34}{rust['latency_p99_s'] * us:14.3f}")
    print(f"{'Rust predict, back-to-back':34}{rust['predict_per_row_s'] * us:14.3f}"
          f"{1 / rust['predict_per_row_s']:14.0f}")
    print(f"{'Rust on_frame (4 cameras, +agg.)':34}{rust['on_frame_per_frame_s'] * us:14.3f}"
          f"{1 / rust['on_frame_per_frame_s']:14.0f}")
    print(f"{'Python inplace_predict, 1 row: med':34}{med * us:14.3f}")
    print(f"{'Python inplace_predict, 1 row: p99':34}{p99 * us:14.3f}")
    print(f"{'Python inplace_predict, 1 row':34}{single_per_row * us:14.3f}{1 / single_per_row:14.0f}")
    print(f"{'Python inplace_predict, batched':34}{batch_per_row * us:14.3f}{1 / batch_per_row:14.0f}")
    print("ratios (Python time / Rust time, higher = Rust faster):")
    print(f"  per-frame latency, median:             {med / rust['latency_median_s']:8.1f}x")
    print(f"  per-frame throughput vs 1-row Python:  {single_per_row / rust['predict_per_row_s']:8.1f}x")
    print(f"  whole on_frame path vs 1-row Python:   {single_per_row / rust['on_frame_per_frame_s']:8.1f}x")
    print(f"  per-frame throughput vs batched Python:{batch_per_row / rust['predict_per_row_s']:8.1f}x")
    if max_diff > 1e-6:
        sys.exit(f"predictions differ by {max_diff}")


if __name__ == "__main__":
    main()
