#!/usr/bin/env bash
# Therapy sessions with the real child and therapist tablets, on the robot's computer: builds the
# suite, runs launch_scripts/tablet_session.launch.yaml (every node but the simulated child) until
# Ctrl-C, then writes the report of the last session beside the bag. NOT in a network namespace:
# the tablets reach the bridge over the real network. DDS stays on this computer
# (ROS_LOCALHOST_ONLY=1, set by the launch file).
#   QT_TABLET_PIN=8642 bash launch_scripts/tablet_session.sh bridge_args:='--param http_bind:=0.0.0.0:8080'
set -euo pipefail
cd "$(dirname "$0")/.."

cargo build --workspace --bins
OUT=${OUT:-out/tablets-$(date +%Y%m%d-%H%M%S)}
mkdir -p "$OUT"
echo "session output: $OUT"
echo "tablets: http://<this computer's address>:<port>/child and /therapist (http_bind in"
echo "  params/tablet_bridge.yaml or bridge_args:='--param http_bind:=...'; PIN from QT_TABLET_PIN)"
status=0
target/debug/launch launch_scripts/tablet_session.launch.yaml out:="$OUT" "$@" || status=$?
if [ -f "$OUT/session.mcap" ]; then
  RUST_BACKTRACE=0 target/debug/session_report "$OUT/session.mcap" --output "$OUT/report.html" ||
    echo "no report (no session was played?)"
  echo "bag:    $OUT/session.mcap"
fi
exit $status
