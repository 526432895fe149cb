#!/usr/bin/env bash
# Therapy sessions with the real child and therapist tablets, on the robot's computer: builds the
# suite, runs launch_scripts/tablet_session.launch.yaml (every node but the simulated child) until
# Ctrl-C, then writes the report of the last session beside the bag. NOT in a network namespace:
# the tablets reach the bridge over the real network. DDS stays on this computer
# (ROS_LOCALHOST_ONLY=1, set by the launch file).
# The pages are served over HTTPS with this computer's own CA and certificate, made in
# $TLS_DIR (default out/tls) the first time and kept (the tablets install the CA once:
# target/debug/tablet_tls --dir out/tls export-ca FILE; docs/install.md).
#   QT_TABLET_PIN=8642 bash launch_scripts/tablet_session.sh bridge_args:='--param http_bind:=0.0.0.0:8080'
set -euo pipefail
cd "$(dirname "$0")/.."

cargo build --workspace --bins
OUT=${OUT:-out/tablets-$(date +%Y%m%d-%H%M%S)}
TLS_DIR=${TLS_DIR:-out/tls}
mkdir -p "$OUT"
echo "session output: $OUT"
target/debug/tablet_tls --dir "$TLS_DIR" init
echo "tablets: https://<this computer's name or address>:<port>/child and /therapist (http_bind in"
echo "  params/tablet_bridge.yaml or bridge_args:='--param http_bind:=...'; PIN from QT_TABLET_PIN)"
# The certificate goes first in the bridge's arguments, the caller's bridge_args after it.
tls="--param tls_cert_file:=$TLS_DIR/server.crt --param tls_key_file:=$TLS_DIR/server.key"
args=()
for a in "$@"; do
  case "$a" in
    bridge_args:=*) tls="$tls ${a#bridge_args:=}" ;;
    *) args+=("$a") ;;
  esac
done
status=0
target/debug/launch launch_scripts/tablet_session.launch.yaml out:="$OUT" bridge_args:="$tls" \
  "${args[@]}" || status=$?
if [ -f "$OUT/session.mcap" ]; then
  RUST_BACKTRACE=0 target/debug/session_report "$OUT/session.mcap" --output "$OUT/report.html" ||
    echo "no report (no session was played?)"
  echo "bag:    $OUT/session.mcap"
fi
exit $status
