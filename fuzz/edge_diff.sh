#!/usr/bin/env bash
# Where a corpus's new edges are: the functions whose covered edges differ between two corpora
# of one target, and the totals by crate, leaving out the functions whose edges the hash seed
# decides (as stable_edges.sh does), so the difference is the corpora's, not chance's.
#   fuzz/edge_diff.sh TARGET OLD_DIR NEW_DIR [SEEDS_DIR]
#   BIN=FILE ...   with that build of the target (default: the one fuzz/run.sh built last)
# Each corpus runs once (-runs=0 -print_coverage=1), with SEEDS_DIR added to both. A function
# is named as libFuzzer names it; its crate is the first path segment of that name (a generic
# of std instantiated for our types counts as std's).
set -euo pipefail
t=${1:?usage: fuzz/edge_diff.sh TARGET OLD_DIR NEW_DIR [SEEDS_DIR]}
old=$(realpath "${2:?OLD_DIR}")
new=$(realpath "${3:?NEW_DIR}")
seeds=()
[ -n "${4:-}" ] && seeds=("$(realpath "$4")")
BIN=${BIN:+$(realpath "$BIN")}
cd "$(dirname "$0")"
source ./libfuzzer_flags.sh
source ./stable_functions.sh "$t"

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# "edges<TAB>function" per covered function (functions instantiated twice are summed).
covered() {
  "$bin" -runs=0 -print_coverage=1 "$@" 2>&1 |
    awk -v seeded="$hash_seeded" '/^COVERED_FUNC/ && $0 !~ seeded {
      split($5, e, "/"); name = $6; for (i = 7; i < NF; i++) name = name " " $i
      sum[name] += e[1] }
      END { for (n in sum) printf "%d\t%s\n", sum[n], n }' | sort -t$'\t' -k2
}
covered "$old" "${seeds[@]}" >"$work/old"
covered "$new" "${seeds[@]}" >"$work/new"
join -t$'\t' -1 2 -2 2 -a 1 -a 2 -e 0 -o 0,1.1,2.1 "$work/old" "$work/new" |
  awk -F'\t' '$2 != $3 { printf "%+d\t%s\n", $3 - $2, $1 }' | sort -t$'\t' -k1,1gr >"$work/diff"
echo "== $t: functions whose stable edges differ (new - old), $old -> $new"
cat "$work/diff"
echo "== by crate"
awk -F'\t' '{ name = $2; sub(/^[<&]+/, "", name); match(name, /^[A-Za-z0-9_]+/)
  by[substr(name, 1, RLENGTH)] += $1; all += $1 }
  END { for (c in by) printf "%+d\t%s\n", by[c], c; printf "%+d\ttotal\n", all }' "$work/diff" |
  sort -t$'\t' -k1,1gr
