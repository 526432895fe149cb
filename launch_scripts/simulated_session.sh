#!/usr/bin/env bash
# The main job: one whole simulated therapy session. Builds the suite, runs every node as its
# own process over DDS inside a private loopback-only network namespace (the launcher, the
# simulated child, the bag recorder, the tablet bridge, the therapist console), then writes the
# session report next to the bag.
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
# In the background so the pages' address can be shown; Ctrl-C still reaches the launcher (same
# process group), which stops every node; this script ignores it and goes on to the report.
trap '' INT
tests/loopback-netns target/debug/launch launch_scripts/simulated_session.launch.yaml \
  --log-dir "$OUT/logs" out:="$OUT" "$@" &
LAUNCH=$!
# The tablet bridge serves both pages on the namespace's own loopback (params/tablet_bridge.yaml,
# 127.0.0.1:8080): reachable only from inside it, e.g. with nsenter.
if [ "$(id -u)" = 0 ]; then ENTER="nsenter -t $LAUNCH -n"; else ENTER="nsenter -t $LAUNCH -U -n --preserve-credentials"; fi
echo "tablet pages, inside the session's network namespace: http://127.0.0.1:8080/therapist (PIN"
echo "  from params/tablet_bridge.yaml or QT_TABLET_PIN) and http://127.0.0.1:8080/child; e.g."
echo "  $ENTER curl -s http://127.0.0.1:8080/therapist"
wait $LAUNCH
trap - INT
target/debug/session_report "$OUT/session.mcap" --output "$OUT/report.html"
echo "bag:    $OUT/session.mcap"
echo "report: $OUT/report.html"
