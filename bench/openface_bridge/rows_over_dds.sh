#!/usr/bin/env bash
# The OpenFace bridge at the load of 8 cameras at 30 fps (240 full-width rows per second,
# appended to one CSV as OpenFace appends them), publishing to the real engagement classifier
# over DDS, all in a private loopback-only network namespace. Prints the share of one core the
# bridge process used while the rows flowed, the classifier's share in the same run (the
# reference: it classifies every row the bridge publishes), and the core's own rows per second.
#   bash bench/openface_bridge/rows_over_dds.sh [SECONDS] [RATE]    (default 20 s, 240 rows/s)
set -euo pipefail
cd "$(dirname "$0")/../.."
SECONDS_RUN=${1:-20}
RATE=${2:-240}
cargo build --release -q -p openface_bridge -p engagement_classifier -p suite_bench \
  --bin openface_bridge --bin engagement_classifier --bin bench_openface
bin=target/release
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$bin/bench_openface" core
tests/loopback-netns bash -c '
  set -euo pipefail
  bin=$1; work=$2; secs=$3; rate=$4
  export ROS_LOCALHOST_ONLY=1 QT_PARAMS_DIR=params
  ticks() { awk "{print \$14 + \$15}" /proc/$1/stat; }
  "$bin/engagement_classifier" run 2>"$work/cls.err" & C=$!
  "$bin/openface_bridge" --csv "$work/webcam.csv" --param report_interval_s:=0 2>"$work/bridge.err" & B=$!
  sleep 3
  b0=$(ticks $B); c0=$(ticks $C); t0=$(date +%s.%N)
  "$bin/bench_openface" write --file "$work/webcam.csv" --rate "$rate" --seconds "$secs" >/dev/null
  b1=$(ticks $B); c1=$(ticks $C); t1=$(date +%s.%N)
  kill -INT $B $C; wait $B $C || true
  hz=$(getconf CLK_TCK)
  awk -v b=$((b1 - b0)) -v c=$((c1 - c0)) -v t0="$t0" -v t1="$t1" -v hz="$hz" -v rate="$rate" "BEGIN {
    wall = t1 - t0; bp = 100 * b / hz / wall; cp = 100 * c / hz / wall;
    printf \"{\\\"rows_per_s\\\": %d, \\\"seconds\\\": %.1f, \\\"bridge_pct_of_one_core\\\": %.2f, \\\"classifier_pct_of_one_core\\\": %.2f, \\\"bridge_over_classifier\\\": %.2f}\\n\", rate, wall, bp, cp, (cp > 0 ? bp / cp : 0)
  }"
  grep -h "rows:" "$work/bridge.err" | tail -1
' bench "$bin" "$work" "$SECONDS_RUN" "$RATE"
