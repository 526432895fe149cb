#!/usr/bin/env python3
"""Benchmark of the behaviour policy's Q-learning (Algorithm 1) against a straightforward
Python/NumPy implementation of the same algorithm, run in this script on the same slice. Ours
is libs/q_learning, run by `policy_lab experiments`.

  python3 bench/behaviour_policy/bench_policy.py [--user-models FILE] [--python-runs 2]

Measures, with the release binary:
  1. the issue's whole grid: 2 user models x 3 rewards x 30 runs x 20 epochs x 1000 steps,
     plus both transfers, on all cores (target: <= 1 s);
  2. ns per Q-iteration on one thread, over that whole grid (target: <= 50 ns);
  3. the slice "cluster 0, RE+bE, 20 epochs" on one thread in Rust and in the NumPy
     implementation below, and prints the ratio (target: >= 200x).
Run from the repository root. The machine is shared, so per-iteration figures are CPU time
(rusage of the binary, process_time of Python), with wall time beside them; the grid's wall
time is the binary's own (user models are loaded as tables, outside the timing). Each figure is
the best of --repeats runs.
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
BIN = os.path.join(ROOT, "target", "release", "policy_lab")
ALPHA, GAMMA, BETA, LAMBDA = 0.05, 0.95, 3.0, 3.0
T0, T_MIN, T_DECAY = 300.0, 0.5, 5.0


def experiments(args, out, threads=None):
    """Runs `policy_lab experiments`; returns its timing JSON plus the process's CPU
    seconds (user + system, from rusage: this machine is shared, so wall time over-counts)."""
    timing = os.path.join(out, "timing.json")
    env = dict(os.environ)
    if threads is not None:
        env["RAYON_NUM_THREADS"] = str(threads)
    cmd = [BIN, "experiments", "--no-figures", "--output", out, "--timing-json", timing] + args
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(cmd, check=True, env=env, cwd=ROOT, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    with open(timing) as f:
        t = json.load(f)
    t["cpu_seconds"] = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return t


def best_of(n, args, out, threads=None):
    runs = [experiments(args, out, threads) for _ in range(n)]
    return min(runs, key=lambda t: t["seconds"]), min(runs, key=lambda t: t["cpu_seconds"])


def load_tables(path, cluster):
    """F^p by input (L, F, PS) and F^e by (input, outcome) in the crate's table order."""
    with open(path) as f:
        tables = json.load(f)
    t = tables[cluster]
    success = np.array([p["mean"] for p in t["success"]])
    engagement = np.array([p["mean"] for p in t["engagement"]]).reshape(63, 2)
    return success, engagement


def algorithm_1(success, engagement, epochs, sessions_per_epoch, seed, lag=True):
    """Straightforward Q-learning with softmax per state, as in the paper (RE + beta E).
    Returns the per-epoch mean score per session and the number of Q-iterations."""
    rng = np.random.default_rng(seed)
    q = np.zeros((64, 5))
    visits = np.ones(64)
    scores = []
    iterations = 0
    for session in range(epochs * sessions_per_epoch):
        count = session % sessions_per_epoch == 0
        state, previous_score, score = 0, 0, 0
        for t in range(10):
            n = 3 if state == 0 else 5
            values = q[state, :n]
            temperature = max(T_MIN, T0 - T_DECAY * visits[state])
            w = np.exp((values - values.max()) / temperature)
            p = w / w.sum()
            action = int(np.searchsorted(np.cumsum(p), rng.random(), side="right"))
            action = min(action, n - 1)
            if count:
                visits[state] += 1
            if action < 3:
                level, feedback = action + 1, 0
            else:
                level, feedback = (state - 1) // 21 + 1, action - 2
            j = (level - 1) * 21 + feedback * 7 + previous_score + 3
            ok = rng.random() <= success[j]
            e = engagement[j, 1 if ok else 0]
            result = level if ok else -1
            reward = result + BETA * e
            cs = level if ok else -level
            nxt = 1 + j if lag else 1 + (level - 1) * 21 + feedback * 7 + cs + 3
            target = reward if t == 9 else reward + GAMMA * q[nxt].max()
            q[state, action] += ALPHA * (target - q[state, action])
            score += cs
            previous_score, state = cs, nxt
            iterations += 1
        scores.append(score)
    per_epoch = np.array(scores).reshape(epochs, sessions_per_epoch).mean(axis=1)
    return per_epoch, iterations


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--user-models", default="nodes/user_model/models/migrave_study_c2.json")
    ap.add_argument("--python-runs", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--rust-runs", type=int, default=300)
    a = ap.parse_args()
    subprocess.run(["cargo", "build", "--release", "-p", "policy_lab"], check=True, cwd=ROOT)
    with tempfile.TemporaryDirectory() as out:
        # First run: tabulate the fitted user models once; later runs read the tables, so
        # loading (refitting the GPs) stays out of the CPU times.
        experiments(["--epochs", "1", "--runs", "1", "--user-models", a.user_models], out)
        tables = os.path.join(out, "user_model_tables.json")
        keep = os.path.join(out, "tables.json")
        os.replace(tables, keep)
        models = ["--user-models", keep]
        grid = ["--epochs", "20", "--runs", "30"] + models
        whole, _ = best_of(a.repeats, grid, out)
        single_wall, single_cpu = best_of(a.repeats, grid, out, threads=1)
        # The slice, many runs so that fixed costs (start-up, files) vanish.
        slice_args = ["--epochs", "20", "--runs", str(a.rust_runs), "--clusters", "0",
                      "--rewards", "RE+bE", "--no-transfer"] + models
        slice_wall, slice_cpu = best_of(a.repeats, slice_args, out, threads=1)
        with open(os.path.join(out, "curves.csv")) as f:
            rows = [line.split(",") for line in f.read().splitlines()[1:]]
        rust_mean_score = np.mean([float(r[6]) for r in rows])
        success, engagement = load_tables(keep, 0)

    py_cpu, py_wall, py_scores = [], [], []
    for r in range(a.python_runs):
        c0, w0 = time.process_time(), time.perf_counter()
        per_epoch, iterations = algorithm_1(success, engagement, 20, 100, seed=r)
        py_cpu.append((time.process_time() - c0) * 1e9 / iterations)
        py_wall.append((time.perf_counter() - w0) * 1e9 / iterations)
        py_scores.append(per_epoch.mean())

    n = whole["iterations"]
    grid_cpu_ns = single_cpu["cpu_seconds"] * 1e9 / n
    grid_wall_ns = single_wall["seconds"] * 1e9 / n
    rust_cpu_ns = slice_cpu["cpu_seconds"] * 1e9 / slice_cpu["iterations"]
    rust_wall_ns = slice_wall["seconds"] * 1e9 / slice_wall["iterations"]
    ok = lambda met: "MET" if met else "MISSED"
    print(f"\nmachine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} (shared); "
          f"best of {a.repeats} runs of the release binary")
    print(f"whole grid: 6 configurations + 2 transfers x 30 runs x 20 epochs x 1000 steps = "
          f"{n:,} Q-iterations")
    print(f"  {whole['threads']} threads, wall: {whole['seconds']:.3f} s   target <= 1 s   "
          f"{ok(whole['seconds'] <= 1.0)}")
    print(f"  1 thread: {grid_cpu_ns:.1f} ns CPU per Q-iteration ({grid_wall_ns:.1f} ns wall)   "
          f"target <= 50 ns   {ok(grid_cpu_ns <= 50)}")
    print(f"slice: cluster 0, RE+bE, softmax, 20 epochs x 1000 steps, one thread")
    print(f"  Rust : {rust_cpu_ns:9.1f} ns CPU per Q-iteration ({rust_wall_ns:.1f} wall; "
          f"{a.rust_runs} runs); mean score per session {rust_mean_score:.2f}")
    print(f"  NumPy: {min(py_cpu):9.1f} ns CPU per Q-iteration ({min(py_wall):.1f} wall; "
          f"best of {a.python_runs} runs); mean score per session {np.mean(py_scores):.2f}")
    ratio = min(py_cpu) / rust_cpu_ns
    print(f"  ratio: {ratio:.0f}x CPU ({min(py_wall) / rust_wall_ns:.0f}x wall)   target >= 200x   "
          f"{ok(ratio >= 200)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
