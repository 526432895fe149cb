#!/usr/bin/env bash
# The main job: one whole simulated therapy session. Builds the suite, runs every node as its
# own process over DDS inside a private loopback-only network namespace (the launcher, the
# simulated child, the bag recorder, the therapist console), then writes the session report
# next to the bag.
#   bash launch_scripts/simulated_session.sh [cluster:=1] [user:=sim-child-2] ...
set -euo pipefail
cd "$(dirname "$0")/.."

need_apt=()
command -v ip >/dev/null || need_apt+=(iproute2)
command -v unshare >/dev/null || need_apt+=(util-linux)
[ -e /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf ] || need_apt+=(fonts-dejavu-core)
if [ ${#need_apt[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ]; then SUDO=; else SUDO=sudo; fi
  $SUDO apt-get update -qq && $SUDO apt-get install -y -qq "${need_apt[@]}" >/dev/null
fi

cargo build --workspace --bins
OUT=${OUT:-out/session-$(date +%Y%m%d-%H%M%S)}
mkdir -p "$OUT"
echo "session output: $OUT"
tests/loopback-netns target/debug/launch launch_scripts/simulated_session.launch.yaml out:="$OUT" "$@"
target/debug/session_report "$OUT/session.mcap" --output "$OUT/report.html"
echo "bag:    $OUT/session.mcap"
echo "report: $OUT/report.html"
