#!/usr/bin/env bash
# The soak: SESSIONS simulated sessions (default 1000) back to back on one running suite over
# DDS, inside a private loopback-only network namespace; every reliable message counted by its
# publisher's sequence number, every session checked, each node's memory and open files
# sampled. Prints a line per session, the tables and a verdict; exits non-zero on a loss, a
# duplicate, an incomplete session or growth. Output (bag, session files, logs) in OUT.
#   bash bench/soak/soak.sh [SESSIONS] [soak options, e.g. --time-scale 0.02]
#   OUT=out/soak nice -n 10 bash bench/soak/soak.sh 1000
#   PROFILE=release bash bench/soak/soak.sh 100        (the binaries the package installs)
set -euo pipefail
cd "$(dirname "$0")/../.."
SESSIONS=${1:-1000}
shift || true
OUT=${OUT:-out/soak-$(date +%Y%m%d-%H%M%S)}
PROFILE=${PROFILE:-dev}
cargo build --profile "$PROFILE" --workspace --bins
case "$PROFILE" in dev) dir=debug ;; *) dir=$PROFILE ;; esac
mkdir -p "$OUT"
tests/loopback-netns "${CARGO_TARGET_DIR:-target}/$dir/soak" --sessions "$SESSIONS" --out "$OUT" "$@" 2>&1 | tee "$OUT.log"
exit "${PIPESTATUS[0]}"
