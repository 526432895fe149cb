#!/usr/bin/env bash
# Fuzzes the suite's input formats with libFuzzer the way `cargo fuzz run TARGET` would (same
# instrumentation flags, nightly, AddressSanitizer), for machines without cargo-fuzz.
#   fuzz/run.sh [SECONDS_PER_TARGET] [TARGET...]      (default 300 s, every target; 0 builds only)
# Targets: msg_decode user_model_file q_table_file xgboost_model params_file launch_file
# tablet_ws read_bag. Each runs in turn (nice -n 10); its corpus grows in corpus/TARGET (kept in the
# repository) from the seeds in target/seeds.<pid>/TARGET (generated, plus the repository's own
# files); crashes, timeouts and out-of-memory inputs land in artifacts/TARGET/.
# PLATEAU=600 fuzz/run.sh 3600 TARGET  stops TARGET early once 10 minutes bring no new edge.
# STABLE=1 PLATEAU=600 ...  the same, counting only edges that do not depend on the hash seed
# (each count also says how many of them are in the suite's own crates).
# MERGE=1 fuzz/run.sh 0 TARGET  minimises corpus/TARGET in place: a subset of the inputs
# (smallest first) that still reaches every coverage edge (libFuzzer -merge=1 -use_counters=0; hit
# counts are dropped, which keeps the kept corpora small). The seeds stay out of it: every run
# regenerates them.
# SANITIZER=none fuzz/run.sh ...  without AddressSanitizer (libfuzzer_flags.sh says why), in
# its own build (target/sanitizer-none); several times the executions per second.
# REPLAY=1 fuzz/run.sh 0 TARGET  runs every input of corpus/TARGET once and stops at the first
# crash, leak or timeout: under ASan (the default build) after a SANITIZER=none run, so what a
# faster run found still meets the memory checks.
set -euo pipefail
cd "$(dirname "$0")"
secs=${1:-300}
shift || true
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  targets=(msg_decode user_model_file q_table_file xgboost_model params_file launch_file tablet_ws read_bag)
fi
source ./libfuzzer_flags.sh
# Some binaries always come from the default (ASan) build: make_seeds, which is no fuzz target
# and finds the coverage callbacks its instrumented code calls only in ASan's runtime (without
# it, it fails to link), and with STABLE=1 the targets that count the stable edges
# (stable_functions.sh says why).
default_bins=(--bin=make_seeds)
[ "${STABLE:-0}" = 1 ] && default_bins+=("${targets[@]/#/--bin=}")
(SANITIZER=address && source ./libfuzzer_flags.sh &&
  CARGO_TARGET_DIR="$PWD/$build_dir" nice -n 10 cargo +nightly build --release --target "$triple" \
    "${default_bins[@]}")
export CARGO_TARGET_DIR="$PWD/$build_dir"
nice -n 10 cargo +nightly build --release --target "$triple" "${targets[@]/#/--bin=}"
bin="$build_dir/$triple/release"
if [ "$secs" = 0 ] && [ "${MERGE:-0}" != 1 ] && [ "${REPLAY:-0}" != 1 ]; then
  for t in "${targets[@]}"; do echo "=== $t: built, $bin/$t"; done
  exit 0
fi

# Generated seeds, then the repository's real files of each format: one directory per run, so
# runs side by side (two targets on two cores) never delete each other's seeds.
seeds=target/seeds.$$
trap 'rm -rf "$seeds"' EXIT
"$default_bin_dir/make_seeds" "$seeds"
add() { local dir="$seeds/$1"; shift; mkdir -p "$dir"; for f in "$@"; do
  [ -f "$f" ] && cp "$f" "$dir/$(echo "${f#../}" | tr / _)"; done; return 0; }
add params_file ../params/*.yaml ../tests/params/*.yaml
add launch_file ../launch_scripts/*.yaml ../tests/launch/*.yaml
add user_model_file ../nodes/user_model/models/*.json
add q_table_file ../bags/q_tables/*.json
# The shipped 200 kB engagement model is too slow a seed (under 1,000 runs/s); make_seeds
# cuts it to its first two trees instead.

# libFuzzer dictionaries for the two YAML formats: their keys (from the repository's own files
# and the launch parser's fields), substitutions, node names and the values at the edges of the
# checks, so mutations make well-formed keys holding wrong values rather than misspelt keys.
# Without them the parameter checks past the first of each struct were never reached
# (fuzz/coverage.sh params_file lists the lines never run).
yaml_keys() { grep -ohE '^[ -]*[A-Za-z_/*][A-Za-z0-9_/*]*:' "$@" | sed -E 's/^[ -]*//' | sort -u; }
write_dict() { local out=$1 w; shift; for w in "$@"; do
  w=${w//\\/\\\\}; w=${w//\"/\\\"}; w=${w//$'\n'/\\x0A}; printf '"%s"\n' "$w"; done > "$out"; }
edge_values=(": 0" ": -1" ": 0.0" ": -0.5" ": 1.5" ": 1e309" ": .nan" ": .inf" ": -.inf"
  ": true" ": false" ": ''" ": []" ": {}" ": ~" ": 9223372036854775807" ": 4294967296" ": 65536"
  ": \"\"" " " $'\n  ' $'\n    ' ":=")
mapfile -t param_keys < <(yaml_keys ../params/*.yaml ../tests/params/*.yaml)
mapfile -t param_nodes < <(for f in ../params/*.yaml; do basename "$f" .yaml; done)
write_dict "$seeds/params_file.dict" "${param_keys[@]}" "${param_nodes[@]}" "${edge_values[@]}" \
  "/**:" "/**/" "ros__parameters:" RE RE+bE lE engaged disengaged magnitude none \
  127.0.0.1:8080 "[::1]:80" en de fr
mapfile -t launch_keys < <(yaml_keys ../launch_scripts/*.yaml ../tests/launch/*.yaml;
  sed -nE 's/^    ([a-z_]+): .*/\1:/p' ../tools/launcher/src/description.rs)
write_dict "$seeds/launch_file.dict" "${launch_keys[@]}" "${edge_values[@]}" "- " "{" "}" \
  "\$(var " "\$(env " "\$(find-pkg-share " "\$(" ")" "'" "\"" true false True False \
  screen log both shutdown "if:" "unless:"

# PLATEAU=S: stop a target once its edge coverage ("cov:" in libFuzzer's status lines, not
# the slowly growing "ft:" features) has not grown for S seconds: a plateau, written to the log.
# STABLE=1 with it: count the edges with stable_edges.sh every S seconds instead (the corpus
# and seeds run once by the default build's binary, leaving out the edges the hash seed
# decides), and stop when one count is no higher than the one before. For the YAML targets,
# whose "cov:" moves by chance (stable_edges.sh says why).
# Prints "STABLE OURS": the stable edges, and how many of them are in the suite's own crates.
stable_count() {
  BIN="$default_bin_dir/$1" nice -n 10 ./stable_edges.sh "$1" "corpus/$1" "$seeds/$1" |
    sed -n 's/.*: \([0-9]*\) stable edges, \([0-9]*\) of them.*/\1 \2/p'
}
watch_plateau() {
  local t=$1 log=$2 quiet=$3 best=0 since=$SECONDS cov ours pid waited
  sleep 5
  pid=$(pgrep -n -f "release/$t " || true)
  if [ "${STABLE:-0}" = 1 ]; then
    while [ -n "$pid" ] && kill -0 "$pid" 2>/dev/null; do
      # In steps, so a fuzzer that ends (its time is up) is not waited on for a whole interval.
      for ((waited = 0; waited < quiet; waited += 10)); do
        sleep 10
        kill -0 "$pid" 2>/dev/null || return 0
      done
      read -r cov ours < <(stable_count "$t" || true) || true
      [ -n "$cov" ] || continue
      echo "=== $t: $cov stable edges ($ours in our crates) after $((SECONDS - since)) s" |
        tee -a "$log"
      if [ "$best" -gt 0 ] && [ "$cov" -le "$best" ]; then
        echo "=== $t: plateau, $best stable edges, none new for $quiet s" | tee -a "$log"
        kill -INT "$pid"
        return 0
      fi
      best=$cov
    done
    return 0
  fi
  while [ -n "$pid" ] && kill -0 "$pid" 2>/dev/null; do
    cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | cut -d' ' -f2)
    if [ -n "$cov" ] && [ "$cov" -gt "$best" ]; then best=$cov; since=$SECONDS; fi
    if [ $((SECONDS - since)) -ge "$quiet" ]; then
      echo "=== $t: plateau, $best edges, none new for $quiet s" | tee -a "$log"
      kill -INT "$pid"
      return 0
    fi
    sleep 10
  done
}

for t in "${targets[@]}"; do
  mkdir -p "corpus/$t" "artifacts/$t" "$seeds/$t"
  if [ "${MERGE:-0}" = 1 ]; then
    rm -rf "target/merged/$t" && mkdir -p "target/merged/$t"
    nice -n 10 "$bin/$t" -merge=1 -use_counters=0 -max_len="$(max_len "$t")" \
      -rss_limit_mb=2048 "target/merged/$t" "corpus/$t"
    rm -rf "corpus/$t" && mv "target/merged/$t" "corpus/$t"
    continue
  fi
  if [ "${REPLAY:-0}" = 1 ]; then
    echo "=== $t: replaying $(find "corpus/$t" -type f | wc -l) inputs (SANITIZER=${SANITIZER:-address})"
    nice -n 10 "$bin/$t" -runs=0 -timeout=10 -rss_limit_mb=2048 -artifact_prefix="artifacts/$t/" \
      "corpus/$t"
    echo "=== $t: every input ran, no crash"
    continue
  fi
  echo "=== $t: $secs s${PLATEAU:+, or until no new edge for $PLATEAU s}"
  log="target/fuzz-$t.log"
  dict=()
  [ -f "$seeds/$t.dict" ] && dict=(-dict="$seeds/$t.dict")
  nice -n 10 "$bin/$t" "${dict[@]}" -max_total_time="$secs" -max_len="$(max_len "$t")" -timeout=10 \
    -rss_limit_mb=2048 -print_final_stats=1 -interrupt_exit_code=0 -artifact_prefix="artifacts/$t/" \
    "corpus/$t" "$seeds/$t" 2>&1 | tee "$log" &
  if [ -n "${PLATEAU:-}" ]; then watch_plateau "$t" "$log" "$PLATEAU"; fi
  wait
done
