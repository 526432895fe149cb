#!/usr/bin/env bash
# How much faster a fuzz target runs without AddressSanitizer (fuzz/run.sh's SANITIZER=none)
# than with it (the default build), both measured in this run on this machine. Per target, the
# two builds take turns, REPEATS times, at
#   1. one pass over the committed corpus (-runs=0): wall seconds;
#   2. FUZZ_SECS seconds of fuzzing from a copy of that corpus (same -seed, no dictionary):
#      executions per second, libFuzzer's own final figure.
# Prints each turn, then the medians and the ratios none / address. Builds both (fuzz/run.sh 0).
# Run it with nothing else busy: the two cores are shared with whatever else runs.
#   bash bench/fuzz/sanitizer.sh [TARGET...]        (default: params_file launch_file)
#   REPEATS=3 FUZZ_SECS=30 bash bench/fuzz/sanitizer.sh params_file
set -euo pipefail
cd "$(dirname "$0")/../../fuzz"
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(params_file launch_file)
repeats=${REPEATS:-3}
fuzz_secs=${FUZZ_SECS:-30}
for s in address none; do
  SANITIZER=$s ./run.sh 0 "${targets[@]}" >/dev/null 2>&1 || {
    echo "building the SANITIZER=$s fuzzers failed: SANITIZER=$s fuzz/run.sh 0 ${targets[*]}" >&2
    exit 1
  }
done
source ./libfuzzer_flags.sh # $triple, max_len
binary() { (SANITIZER=$1; source ./libfuzzer_flags.sh; echo "$build_dir/$triple/release/$2"); }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
median() { printf '%s\n' "$@" | sort -g | awk '{ v[NR] = $1 } END { print v[int((NR + 1) / 2)] }'; }

for t in "${targets[@]}"; do
  inputs=$(find "corpus/$t" -type f | wc -l)
  echo "== $t: $inputs committed inputs, $repeats turns each, fuzzing $fuzz_secs s a turn"
  declare -A pass=() rate=()
  for ((i = 1; i <= repeats; i++)); do
    for s in address none; do
      bin=$(binary "$s" "$t")
      start=$(date +%s.%N)
      "$bin" -runs=0 -rss_limit_mb=4096 -max_len="$(max_len "$t")" "corpus/$t" >"$work/pass.log" 2>&1 || {
        echo "$bin failed on corpus/$t:" >&2; tail -20 "$work/pass.log" >&2; exit 1; }
      secs=$(echo "$(date +%s.%N) - $start" | bc)
      rm -rf "$work/corpus" && cp -r "corpus/$t" "$work/corpus"
      "$bin" -seed=1 -max_total_time="$fuzz_secs" -max_len="$(max_len "$t")" -timeout=10 \
        -rss_limit_mb=4096 -print_final_stats=1 -artifact_prefix="$work/" "$work/corpus" \
        >"$work/fuzz.log" 2>&1 || {
        echo "$bin failed while fuzzing:" >&2; tail -20 "$work/fuzz.log" >&2; exit 1; }
      execs=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$work/fuzz.log")
      printf '%s turn %d  SANITIZER=%-7s  pass %6.2f s  fuzzing %6d exec/s\n' "$t" "$i" "$s" "$secs" "$execs"
      pass[$s]+="$secs "
      rate[$s]+="$execs "
    done
  done
  # shellcheck disable=SC2086 # the lists are space-separated numbers
  {
    pa=$(median ${pass[address]}) pn=$(median ${pass[none]})
    ra=$(median ${rate[address]}) rn=$(median ${rate[none]})
  }
  printf '%s median  pass: address %.2f s, none %.2f s -> %.1fx faster without ASan\n' \
    "$t" "$pa" "$pn" "$(echo "$pa / $pn" | bc -l)"
  printf '%s median  fuzzing: address %d exec/s, none %d exec/s -> %.1fx the executions\n' \
    "$t" "$ra" "$rn" "$(echo "$rn / $ra" | bc -l)"
  unset pass rate
done
