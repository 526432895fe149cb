#!/usr/bin/env python3
"""Python xgboost on exactly the folds our `cross-validate --export-folds DIR` trained on.

For each fold_<participant>_{train,test}.csv in DIR (inputs already standardised, f32 as our
trees saw them) trains XGBClassifier with the same hyperparameters (100 trees, max_depth 6,
eta 0.3, exact method, one thread for a deterministic summation order) and prints, per fold,
our accuracy, xgboost's, how often the two agree on the label and the largest probability
difference. Prints a markdown table for the README.

usage: compare_cross_validation.py DIR [--n-estimators 100 --max-depth 6 --learning-rate 0.3]
"""
import argparse
import glob
import os
import sys

import numpy as np
import pandas as pd
import xgboost as xgb


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dir")
    ap.add_argument("--n-estimators", type=int, default=100)
    ap.add_argument("--max-depth", type=int, default=6)
    ap.add_argument("--learning-rate", type=float, default=0.3)
    args = ap.parse_args()
    trains = sorted(glob.glob(os.path.join(args.dir, "fold_*_train.csv")))
    if not trains:
        sys.exit(f"no fold_*_train.csv in {args.dir}")
    rows = []
    for train_path in trains:
        participant = os.path.basename(train_path)[len("fold_"):-len("_train.csv")]
        train = pd.read_csv(train_path)
        test = pd.read_csv(train_path.replace("_train.csv", "_test.csv"))
        features = [c for c in train.columns if c.startswith("of_")]
        clf = xgb.XGBClassifier(
            n_estimators=args.n_estimators,
            max_depth=args.max_depth,
            learning_rate=args.learning_rate,
            tree_method="exact",
            n_jobs=1,
        )
        clf.fit(train[features].to_numpy(np.float32), train["label"].to_numpy())
        p = clf.predict_proba(test[features].to_numpy(np.float32))[:, 1]
        y = test["label"].to_numpy()
        ours = test["our_probability"].to_numpy()
        rows.append(
            dict(
                participant=participant,
                test=len(y),
                ours=np.mean((ours > 0.5) == (y == 1)),
                xgboost=np.mean((p > 0.5) == (y == 1)),
                agree=np.mean((ours > 0.5) == (p > 0.5)),
                max_dp=np.max(np.abs(ours - p)),
            )
        )
    print(f"xgboost {xgb.__version__}, {args.n_estimators} trees, depth {args.max_depth}, "
          f"eta {args.learning_rate}, exact, 1 thread")
    print("| participant | test frames | ours | Python xgboost | labels agree | max abs diff p |")
    print("|---|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['participant']} | {r['test']} | {r['ours']:.4f} | {r['xgboost']:.4f} | "
              f"{r['agree']:.4f} | {r['max_dp']:.2e} |")
    print(f"| mean | | {np.mean([r['ours'] for r in rows]):.4f} | "
          f"{np.mean([r['xgboost'] for r in rows]):.4f} | | |")


if __name__ == "__main__":
    main()
