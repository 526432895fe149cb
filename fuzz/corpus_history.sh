#!/usr/bin/env bash
# How a target's committed corpus grew, commit by commit: for every commit that changed
# corpus/TARGET (oldest first), that corpus counted by fuzz/stable_edges.sh (one build, one
# set of seeds for all, so the rows compare): its inputs, its stable edges and how many of
# those are in the suite's own crates. A plateau in our code shows as a still last column.
#   fuzz/corpus_history.sh TARGET [SEEDS_DIR]     (BIN=FILE: another build, as stable_edges.sh)
set -euo pipefail
t=${1:?usage: fuzz/corpus_history.sh TARGET [SEEDS_DIR]}
seeds=()
[ -n "${2:-}" ] && seeds=("$(realpath "$2")")
cd "$(dirname "$0")"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
echo "| commit | date | inputs | stable edges | in our crates |"
echo "| --- | --- | --- | --- | --- |"
git log --reverse --format='%h %cd' --date=format:'%Y-%m-%d %H:%M' -- "corpus/$t" |
  while read -r rev day time; do
    rm -rf "$work/c" && mkdir -p "$work/c"
    git archive "$rev" "corpus/$t" | tar -x -C "$work/c"
    line=$(./stable_edges.sh "$t" "$work/c/corpus/$t" "${seeds[@]}" </dev/null)
    read -r stable own < <(sed -n 's/.*: \([0-9]*\) stable edges, \([0-9]*\) of them.*/\1 \2/p' \
      <<<"$line")
    echo "| $rev | $day $time | $(find "$work/c/corpus/$t" -type f | wc -l) | $stable | $own |"
  done
