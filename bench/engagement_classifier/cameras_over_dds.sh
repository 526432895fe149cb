#!/usr/bin/env bash
# Several cameras over DDS, end to end: does the real `engagement_classifier run` process keep
# up with 30 fps from several cameras with no backlog? One release node (params/
# engagement_classifier.yaml, as the launch files start it) and, one after the other, the peer
# `bench/engagement_classifier/cameras_over_dds.rs` for 1, 4 and 8 cameras of SYNTHETIC OpenFace frames, all inside
# one private loopback-only network namespace. Per run: frames sent, estimates back (lost: the
# frame and estimate topics are best effort), latency from send to estimate receipt (median,
# p99, max), median latency of the first vs the last quarter (a backlog grows it), achieved vs
# offered estimate rate, ExpectedEngagement seconds reported per camera against seconds elapsed,
# and the node's CPU. Then the 8-camera / 1-camera median latency ratio, the 1-camera run being
# the reference measured in the same script. The node stops on SIGINT at the end.
#   bash bench/engagement_classifier/cameras_over_dds.sh
#   CAMERAS="1 2 4 8" SECONDS_PER_RUN=60 FPS=30 SEED=7 OUT=out/cameras bash bench/engagement_classifier/cameras_over_dds.sh
# Output (per-run reports with a per-second timeline, logs, runs.tsv) in OUT.
set -euo pipefail
cd "$(dirname "$0")/../.."
CAMERAS=${CAMERAS:-1 4 8}
SECONDS_PER_RUN=${SECONDS_PER_RUN:-20}
FPS=${FPS:-30}
SEED=${SEED:-7}

if [ -z "${CAMERAS_OVER_DDS_INSIDE:-}" ]; then
  cargo build --release -p engagement_classifier --bin engagement_classifier
  cargo build --release -p suite_bench --bin cameras_over_dds
  OUT=${OUT:-out/cameras_over_dds-$(date +%Y%m%d-%H%M%S)}
  mkdir -p "$OUT"
  export OUT CAMERAS SECONDS_PER_RUN FPS SEED
  # Everything below runs again inside one namespace: node and peers must share it.
  CAMERAS_OVER_DDS_INSIDE=1 exec tests/loopback-netns bash bench/engagement_classifier/cameras_over_dds.sh
fi

# The namespace holds only loopback; this keeps RustDDS on it too, as the launch files do.
export ROS_LOCALHOST_ONLY=1
# RUST_LOG is left to the caller: unset, the node shell's default filter (info, RustDDS at
# error) applies, as when launched. With RUST_LOG=info, RustDDS logs a line per sample received
# ("PollEventSender.send: Resource temporarily unavailable": a reader's poll-event socketpair,
# which our async readers never drain, is full; seen in both processes from about 9.6 s into a
# 30 fps camera on), which costs both processes CPU.
NODE_LOG="$OUT/node.log"
"${CARGO_TARGET_DIR:-target}"/release/engagement_classifier run --params-file params/engagement_classifier.yaml \
  >"$OUT/node.out" 2>"$NODE_LOG" &
NODE=$!
stop_node() {
  if kill -0 "$NODE" 2>/dev/null; then
    kill -INT "$NODE"
    for _ in $(seq 200); do kill -0 "$NODE" 2>/dev/null || break; sleep 0.1; done
    if kill -0 "$NODE" 2>/dev/null; then
      echo "the node did not stop within 20 s of SIGINT; killing it" >&2
      kill -KILL "$NODE"
    fi
  fi
  wait "$NODE" && echo "node stopped on SIGINT, exit 0" || echo "node exit status $?"
}
trap stop_node EXIT

# It loads the model before it joins the graph; "node started" is logged once it has.
for _ in $(seq 300); do
  grep -q "node started" "$NODE_LOG" && break
  kill -0 "$NODE" 2>/dev/null || { echo "the node exited at start-up:" >&2; cat "$NODE_LOG" >&2; exit 1; }
  sleep 0.1
done
grep -q "node started" "$NODE_LOG" || { echo "the node did not start within 30 s" >&2; exit 1; }

TICKS=$(getconf CLK_TCK)
node_cpu_ticks() { sed 's/.*) //' "/proc/$NODE/stat" | awk '{ print $12 + $13 }'; }

TSV="$OUT/runs.tsv"
: >"$TSV"
: >"$OUT/cpu.tsv"
echo "machine: $(nproc) cores, load average $(cut -d' ' -f1-3 /proc/loadavg) before the runs"
for n in $CAMERAS; do
  echo
  echo "=== $n camera(s) x $FPS fps, $SECONDS_PER_RUN s"
  cpu0=$(node_cpu_ticks); t0=$(date +%s.%N)
  "${CARGO_TARGET_DIR:-target}"/release/cameras_over_dds --cameras "$n" --seconds "$SECONDS_PER_RUN" \
    --fps "$FPS" --seed "$SEED" --tsv "$TSV" --timeline 2>"$OUT/peer-$n.log" | tee "$OUT/peer-$n.txt"
  cpu1=$(node_cpu_ticks); t1=$(date +%s.%N)
  # The node's CPU over the peer's whole run (discovery, warm-up, measured seconds, settle).
  awk -v c0="$cpu0" -v c1="$cpu1" -v t0="$t0" -v t1="$t1" -v hz="$TICKS" \
    'BEGIN { printf "%.1f\n", 100 * (c1 - c0) / hz / (t1 - t0) }' >>"$OUT/cpu.tsv"
done

echo
echo "=== summary ($FPS fps per camera, $SECONDS_PER_RUN s per run, seed $SEED; latency = send to estimate received, ms)"
paste "$TSV" <(echo node_cpu_pct; cat "$OUT/cpu.tsv") | awk -F'\t' '
  NR == 1 { for (i = 1; i <= NF; i++) col[$i] = i; next }
  { row[NR] = $0 }
  END {
    printf "%-8s %8s %6s %9s %13s %11s %9s %8s %8s %8s %9s %9s %7s %11s %8s\n",
      "cameras", "offered/s", "sent", "estimates", "lost", "achieved/s", "ach/off",
      "median", "p99", "max", "1st-q med", "4th-q med", "4th/1st", "seconds", "node CPU"
    for (r = 2; r <= NR; r++) {
      split(row[r], f, "\t")
      printf "%-8s %8s %6s %9s %6s (%4s%%) %11s %9s %8s %8s %8s %9s %9s %7s %5s/%-5s %7s%%\n",
        f[col["cameras"]], f[col["offered_per_s"]], f[col["sent"]], f[col["estimates"]],
        f[col["lost"]], f[col["lost_pct"]], f[col["achieved_per_s"]],
        f[col["achieved_over_offered"]], f[col["median_ms"]], f[col["p99_ms"]], f[col["max_ms"]],
        f[col["first_quarter_median_ms"]], f[col["last_quarter_median_ms"]],
        f[col["last_over_first"]], f[col["seconds_reported"]], f[col["seconds_elapsed"]],
        f[col["node_cpu_pct"]]
    }
  }'
# The first run (1 camera by default) is the reference for the last (8 cameras).
awk -F'\t' '
  NR == 1 { for (i = 1; i <= NF; i++) col[$i] = i; next }
  NR == 2 { ref_n = $col["cameras"]; ref = $col["median_ms"] }
  { n = $col["cameras"]; med = $col["median_ms"] }
  END {
    if (NR > 2 && ref > 0)
      printf "median latency, %s cameras / %s camera(s), same node, same script: %.2f\n", n, ref_n, med / ref
  }' "$TSV"
echo "(seconds = ExpectedEngagement reported / whole seconds elapsed, all cameras; node CPU = % of one core"
echo " over each peer run including discovery and warm-up; per-run details and timelines in $OUT)"
echo "machine: load average $(cut -d' ' -f1-3 /proc/loadavg) after the runs"
