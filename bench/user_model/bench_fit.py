#!/usr/bin/env python3
"""User-model fitting and query latency: our Rust `user_model` vs scikit-learn, same data, same
run, ratios printed. Not a test.

Run from the workspace root:  python3 bench/user_model/bench_fit.py [--reps N]
(builds the `bench_fit` benchmark binary and the user_model binary with --release; needs numpy and scikit-learn)

Data: the REAL MigrAVE study in ../shared/data/migrave-study when it is there, else the
SYNTHETIC study written by `user_model simulate-study`.
Rust times `user_model::fit` on the records in memory: user vectors, PCA, K-means (10
k-means++ restarts), the authors' target grouping, four GPs (RationalQuadratic, l = 1, alpha =
1.5 initial, noise 1e-10, L-BFGS-B-like search, no restarts) and tabulating all 63 + 126
predictions per cluster. scikit-learn gets the same user vectors and the same (already grouped
and encoded) GP training sets from the model file Rust wrote, so its timing excludes the
grouping: PCA(2), KMeans(2, n_init=10), four GaussianProcessRegressor fits with the same kernel,
bounds and noise, and predict(return_std=True) over the same 63 / 126 inputs.
Query: Rust looks up F^p and F^e in the precomputed tables (1,000,000 random queries); the
Python references are one GaussianProcessRegressor.predict call per query (what a node without
tables would do) and a lookup in precomputed numpy tables.
Also prints how our optimised GPs compare with scikit-learn's on this data (log marginal
likelihood, hyperparameters, predictions).
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import warnings

import numpy as np
import sklearn
from sklearn.cluster import KMeans
from sklearn.decomposition import PCA
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RationalQuadratic

STUDY = "../shared/data/migrave-study"


def run(cmd):
    return subprocess.run(cmd, check=True, capture_output=True, text=True).stdout


def encode(level, feedback, ps, outcome=None):
    x = [level / 3, 0.0, 0.0, 0.0, ps / 3]
    x[1 + feedback] = 1.0
    if outcome is not None:
        x.append(float(outcome))
    return x


STATES = [(l, f, ps) for l in (1, 2, 3) for f in (0, 1, 2) for ps in range(-3, 4)]
P_INPUTS = np.array([encode(*s) for s in STATES])
E_INPUTS = np.array([encode(*s, o) for s in STATES for o in (-1, 1)])


def gp_fit(component):
    x = np.array(component["inputs"])
    y = np.array(component["targets"])
    mu, scale = x.mean(axis=0), np.sqrt(x.var(axis=0) + 1e-8)
    kernel = RationalQuadratic(1.0, 1.5, length_scale_bounds=(1e-5, 1e5), alpha_bounds=(1e-5, 1e5))
    gp = GaussianProcessRegressor(kernel, alpha=1e-10, n_restarts_optimizer=0, random_state=0)
    gp.fit((x - mu) / scale, y)
    return gp, mu, scale


def sklearn_fit(model):
    vectors = np.array([u["vector"] for u in model["users"]])
    projected = PCA(n_components=2).fit_transform(vectors)
    KMeans(n_clusters=len(model["clusters"]), n_init=10, random_state=0).fit(projected)
    gps = []
    for c in model["clusters"]:
        for name, inputs, lo, hi in (("success", P_INPUTS, 0, 1), ("engagement", E_INPUTS, -1, 1)):
            gp, mu, scale = gp_fit(c[name])
            mean, std = gp.predict((inputs - mu) / scale, return_std=True)
            gps.append((c["cluster"], name, gp, mu, scale, np.clip(mean, lo, hi), std))
    return gps


def timed(f, reps):
    times = []
    for _ in range(reps):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return float(np.median(times)), float(np.min(times))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--reps", type=int, default=10, help="scikit-learn fit repetitions")
    args = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="user_model_bench_")
    if os.path.exists(os.path.join(STUDY, "sequences.csv")):
        data, label = STUDY, "REAL MigrAVE study"
    else:
        data, label = os.path.join(tmp, "synthetic_study.csv"), "SYNTHETIC study"
        run(["cargo", "run", "--release", "-q", "-p", "user_model", "--", "simulate-study", "--output", data])
    run(["cargo", "build", "--release", "-q", "-p", "user_model", "--bin", "user_model"])
    run(["cargo", "build", "--release", "-q", "-p", "suite_bench", "--bin", "bench_fit"])
    model_path = os.path.join(tmp, "model.json")
    rust = json.loads(run(["target/release/bench_fit", data, model_path, "30"]))
    model = json.load(open(model_path))

    warnings.simplefilter("ignore", ConvergenceWarning)
    gps = sklearn_fit(model)  # warm-up, and the fits compared below
    py_fit_median, py_fit_min = timed(lambda: sklearn_fit(model), args.reps)

    # Query references: one GP predict per query, and a lookup in precomputed numpy tables.
    _, _, gp, mu, scale, _, _ = gps[0]
    point = ((P_INPUTS[10] - mu) / scale)[None, :]
    per_call = []
    for _ in range(2000):
        t = time.perf_counter()
        gp.predict(point, return_std=True)
        per_call.append(time.perf_counter() - t)
    py_predict_ns = float(np.median(per_call)) * 1e9
    tables = {(c, n): (m, s) for c, n, _, _, _, m, s in gps}
    rng = np.random.default_rng(1)
    qs = [(int(c), int(i), int(o)) for c, i, o in zip(rng.integers(0, len(model["clusters"]), 200_000),
                                                    rng.integers(0, 63, 200_000), rng.integers(0, 2, 200_000))]
    t = time.perf_counter()
    total = 0.0
    for c, i, o in qs:
        total += tables[(c, "success")][0][i] + tables[(c, "engagement")][0][2 * i + o]
    py_lookup_ns = (time.perf_counter() - t) / len(qs) * 1e9

    print(f"data: {label} ({rust['records']} records, {rust['users']} users, {rust['clusters']} clusters); "
          f"scikit-learn {sklearn.__version__}, numpy {np.__version__}")
    print(f"{'':34}{'Rust':>12}{'scikit-learn':>16}{'ratio':>10}")
    print(f"{'fit (median)':34}{rust['fit_ms_median']:>9.2f} ms{py_fit_median * 1e3:>13.2f} ms"
          f"{py_fit_median * 1e3 / rust['fit_ms_median']:>9.1f}x")
    print(f"{'fit (best)':34}{rust['fit_ms_min']:>9.2f} ms{py_fit_min * 1e3:>13.2f} ms"
          f"{py_fit_min * 1e3 / rust['fit_ms_min']:>9.1f}x")
    q = rust["query_ns_median"]
    print(f"{'query F^p+F^e vs GP.predict':34}{q:>9.1f} ns{py_predict_ns:>13.0f} ns{py_predict_ns / q:>9.0f}x")
    print(f"{'query F^p+F^e vs numpy tables':34}{q:>9.1f} ns{py_lookup_ns:>13.0f} ns{py_lookup_ns / q:>9.0f}x")
    print(f"{'assign_cluster':34}{rust['assign_cluster_ns']:>9.1f} ns")
    print(f"query target < 1 us: {'met' if q < 1000 else 'NOT met'}; "
          f"fit target >= 10x: {'met' if py_fit_median * 1e3 / rust['fit_ms_median'] >= 10 else 'NOT met'}")

    print("\nagreement with scikit-learn on this data (same training sets, same settings):")
    print(f"{'cluster':>7} {'model':>10} {'n':>3} {'lml ours':>11} {'lml sklearn':>12} "
          f"{'l ours':>10} {'l sklearn':>10} {'a ours':>9} {'a sklearn':>9} {'max|dmean|':>10}")
    # Our tabulated predictions, printed with 6 decimals by `user_model predict`.
    rows = [r.split(",") for r in run(["target/release/user_model", "predict", "--model", model_path]).strip().splitlines()[1:]]
    for c, name, gp, _, _, mean, _ in gps:
        ours = model["clusters"][c][name]
        print(f"{c:>7} {name:>10} {len(ours['targets']):>3} {ours['log_marginal_likelihood']:>11.5f} "
              f"{gp.log_marginal_likelihood_value_:>12.5f} {ours['kernel']['length_scale']:>10.3g} "
              f"{gp.kernel_.length_scale:>10.3g} {ours['kernel']['alpha']:>9.3g} {gp.kernel_.alpha:>9.3g}", end="")
        if name == "success":
            ours_mean = np.array([float(r[5]) for r in rows if int(r[0]) == c and r[4] == "-1"])
        else:
            ours_mean = np.array([float(r[7]) for r in rows if int(r[0]) == c])
        print(f" {np.max(np.abs(ours_mean - mean)):>10.2e}")


if __name__ == "__main__":
    sys.exit(main())
