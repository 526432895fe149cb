#!/usr/bin/env bash
# Edge coverage of a corpus without the edges that depend on the process's random hash seed,
# so corpora (snapshots of one run, or before and after) can be compared exactly.
#   fuzz/stable_edges.sh TARGET DIR...           one line: the edges the inputs in DIRs reach
#   RUNS=3 fuzz/stable_edges.sh TARGET DIR...    run 3 times; says whether the counts agree
#   BIN=FILE fuzz/stable_edges.sh TARGET DIR...  with that build of the target (default: the
#                                                one fuzz/run.sh built last)
# Why: serde-saphyr checks YAML mappings for duplicate keys in HashMaps (of key fingerprints,
# and of usize) under std's randomly seeded hasher, so which keys share a probe group, and
# with it the edges of those maps' functions and of KeyFingerprint::eq, changes from process
# to process with the same input. libFuzzer's "cov:" counts them, so the YAML targets' edge
# count moves by chance (params_file, one corpus, 7 runs: 13,582 to 13,588). This runs the
# fuzz binary fuzz/run.sh built (-runs=0 -print_coverage=1), sums the covered edges of every
# function and leaves those functions out (about 100 edges, some of them steady): what remains
# is the same on every run (the 7 runs: 11,895 each; RUNS=3 checks it). It also names how
# many of them are in the suite's own crates, the rest being the YAML, JSON and DDS libraries
# and std.
set -euo pipefail
t=${1:?usage: fuzz/stable_edges.sh TARGET DIR...}
shift
[ $# -gt 0 ] || { echo "usage: fuzz/stable_edges.sh TARGET DIR..." >&2; exit 2; }
dirs=()
for d in "$@"; do dirs+=("$(realpath "$d")"); done
set -- "${dirs[@]}"
BIN=${BIN:+$(realpath "$BIN")}
cd "$(dirname "$0")"
source ./libfuzzer_flags.sh
source ./stable_functions.sh "$t"

out=$(mktemp)
trap 'rm -f "$out"' EXIT
counts=()
for ((i = 1; i <= ${RUNS:-1}; i++)); do
  "$bin" -runs=0 -print_coverage=1 "$@" >"$out" 2>&1 || {
    echo "$bin failed on the corpus:" >&2
    tail -20 "$out" >&2
    exit 1
  }
  # A function is ours when the first path segment of its name is one of our crates (so the
  # code serde derives for our types is ours, a std generic instantiated for them is std's).
  line=$(awk -v seeded="$hash_seeded" -v ours="$our_crates" '
    /^COVERED_FUNC/ { split($5, e, "/"); all += e[1]
      if ($0 ~ seeded) { rnd += e[1]; next }
      name = $6; sub(/^[<&]+/, "", name); match(name, /^[A-Za-z0-9_]+/)
      if (substr(name, 1, RLENGTH) ~ ours) own += e[1] }
    /DONE/ { for (i = 1; i <= NF; i++) if ($i == "cov:") cov = $(i + 1) }
    END { printf "%d %d %d %d %d", all - rnd, own, rnd, all, cov }' "$out")
  read -r stable own seeded all cov <<<"$line"
  echo "$t: $stable stable edges, $own of them in the suite's own crates (+$seeded in the" \
    "hash-seeded functions = $all; libFuzzer cov: $cov) from $*"
  counts+=("$stable")
done
if [ "${RUNS:-1}" -gt 1 ]; then
  if [ "$(printf '%s\n' "${counts[@]}" | sort -u | wc -l)" -eq 1 ]; then
    echo "$t: the same ${counts[0]} stable edges in all ${RUNS} runs"
  else
    echo "$t: stable edges differ between runs: ${counts[*]}" >&2
    exit 1
  fi
fi
