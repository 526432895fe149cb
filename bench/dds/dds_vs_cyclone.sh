#!/usr/bin/env bash
# The suite's DDS round trips beside Cyclone DDS's own ddsperf, on the same loopback-only
# network namespace, alternating (ours, Cyclone; next round Cyclone, ours), ROUNDS rounds of
# SECONDS seconds per case, release builds:
#   decide         DecideAction (the game manager's call to the policy) to a fixed answer,
#                  vs ddsperf ping/pong of the response's size (reliable)
#   results        a 281-byte SequenceResult on the results' QoS (reliable, transient-local),
#                  vs ddsperf ping/pong of that size (reliable)
#   faces          an OpenFaceFeatures frame, best effort, vs ddsperf -u of that size
#   decide-policy  DecideAction to the real `behaviour_policy run` (ours only)
#   *-raw          the same over ros2-client directly, without node_shell (bench_dds --raw):
#                  what is left of the difference is RustDDS's and ros2-client's
#   *-ct           the same through node_shell on a one-thread runtime (--current-thread), as
#                  the engagement classifier runs: node_shell's hand-over wakes no other thread
# Prints the table (bench_dds compare); raw outputs in OUT.
#   bash bench/dds/dds_vs_cyclone.sh [ROUNDS] [SECONDS]
set -euo pipefail
cd "$(dirname "$0")/../.."
ROUNDS=${1:-3}
SECS=${2:-10}
if ! command -v ddsperf >/dev/null; then
  if [ "$(id -u)" = 0 ]; then SUDO=; else SUDO=sudo; fi
  $SUDO apt-get update -qq && $SUDO apt-get install -y -qq cyclonedds-tools >/dev/null
fi
cargo build --release -p suite_bench --bin bench_dds -p behaviour_policy --bin behaviour_policy
bin=${CARGO_TARGET_DIR:-target}/release
OUT=${OUT:-out/dds-$(date +%Y%m%d-%H%M%S)}
mkdir -p "$OUT/params"
for node in bench_dds_serve bench_dds_ping; do
  printf '%s:\n  ros__parameters: {}\n' "$node" >"$OUT/params/$node.yaml"
done
sed "s#q_table_dir: \"out/q_tables\"#q_table_dir: \"$OUT/q_tables\"#" params/behaviour_policy.yaml \
  >"$OUT/params/behaviour_policy.yaml"
sizes=$("$bin/bench_dds" sizes)
size_of() { sed -n "s/.*\"$1\":\([0-9]*\).*/\1/p" <<<"$sizes"; }
echo "payloads (CDR bytes): $sizes; ddsperf sizes: decide $(size_of decide_response), results $(size_of results), faces $(size_of faces)"
echo "$(nproc) cores; ${ROUNDS} rounds of ${SECS} s per case; output in $OUT"

cat >"$OUT/run.sh" <<RUN
set -u
# RustDDS and ros2-client warn once per request on this path (a missing related_sample_identity
# that ros2-client's own Enhanced client never sends): as in the nodes, only their errors.
export QT_PARAMS_DIR=$OUT/params RUST_LOG=warn,rustdds=error,ros2_client=error
ours() { # case [--raw | --current-thread]
  case "\${2:-}" in --raw) name=\$1-raw ;; --current-thread) name=\$1-ct ;; *) name=\$1 ;; esac
  $bin/bench_dds serve --case \$1 \${2:-} >/dev/null 2>>$OUT/serve.err & S=\$!
  $bin/bench_dds ping --case \$1 \${2:-} --seconds $SECS --warmup 2 >"$OUT/ours-\$name-\$r.json" 2>>$OUT/ping.err
  kill -INT \$S; wait \$S
}
cyclone() { # case size [-u]
  ddsperf -D $((SECS + 3)) \${3:-} pong >/dev/null 2>&1 & P=\$!
  ddsperf -D $((SECS + 2)) \${3:-} ping size \$2 >"$OUT/cyclone-\$1-\$r.out" 2>&1
  kill -INT \$P 2>/dev/null; wait \$P
}
policy() {
  $bin/behaviour_policy run >/dev/null 2>>$OUT/policy.err & S=\$!
  $bin/bench_dds ping --case decide-policy --seconds $SECS --warmup 2 >"$OUT/ours-decide-policy-\$r.json" 2>>$OUT/ping.err
  kill -INT \$S; wait \$S
}
for r in \$(seq 1 $ROUNDS); do
  for c in "decide $(size_of decide_response)" "results $(size_of results)" "faces $(size_of faces) -u"; do
    set -- \$c
    if [ \$((r % 2)) = 1 ]; then ours \$1; ours \$1 --raw; ours \$1 --current-thread; cyclone "\$@"
    else cyclone "\$@"; ours \$1 --current-thread; ours \$1 --raw; ours \$1; fi
    echo "round \$r: \$1 done"
  done
  policy
  echo "round \$r: decide-policy done"
done
RUN
tests/loopback-netns bash "$OUT/run.sh"

args=()
for f in "$OUT"/ours-*.json; do
  c=$(basename "$f" .json); c=${c#ours-}; args+=(--ours "${c%-*}=$f")
done
for f in "$OUT"/cyclone-*.out; do
  c=$(basename "$f" .out); c=${c#cyclone-}; args+=(--cyclone "${c%-*}=$f")
done
"$bin/bench_dds" compare "${args[@]}" | tee "$OUT/table.txt"
