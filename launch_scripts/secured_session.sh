#!/usr/bin/env bash
# The main job under DDS Security: one whole simulated session (launch_scripts/
# simulated_session.launch.yaml, every node its own process) in a secured domain. Builds the
# suite with its `security` feature into its own target directory (the plain build stays as it
# is), makes a test keystore (security/make_keystore.sh: an enclave per node; the console may
# command, since no therapist tablet takes part), and runs the launch file with the SROS2
# variables, strategy Enforce, inside a private loopback-only network namespace, then checks
# the bag and writes the report.
#   bash launch_scripts/secured_session.sh [cluster:=1] [time_scale:=0.1] ...
set -euo pipefail
cd "$(dirname "$0")/.."

need_apt=()
command -v ip >/dev/null || need_apt+=(iproute2)
command -v unshare >/dev/null || need_apt+=(util-linux)
command -v openssl >/dev/null || need_apt+=(openssl)
[ -e /usr/include/openssl/ssl.h ] || need_apt+=(libssl-dev)
command -v pkg-config >/dev/null || need_apt+=(pkg-config)
[ -e /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf ] || need_apt+=(fonts-dejavu-core)
if [ ${#need_apt[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ]; then SUDO=; else SUDO=sudo; fi
  $SUDO apt-get update -qq && $SUDO apt-get install -y -qq "${need_apt[@]}" >/dev/null
fi

target=${SECURED_TARGET_DIR:-target/secured}
CARGO_TARGET_DIR=$target cargo build --workspace --bins --features node_shell/security
bin=$target/debug
OUT=${OUT:-out/secured-session-$(date +%Y%m%d-%H%M%S)}
mkdir -p "$OUT"
echo "session output: $OUT"
CONSOLE_MAY_COMMAND=1 security/make_keystore.sh "$OUT/keystore" >/dev/null

export ROS_SECURITY_ENABLE=true ROS_SECURITY_STRATEGY=Enforce
ROS_SECURITY_KEYSTORE=$(cd "$OUT/keystore" && pwd)
export ROS_SECURITY_KEYSTORE
tests/loopback-netns "$bin/launch" launch_scripts/simulated_session.launch.yaml --log-dir "$OUT/logs" \
  bin:="$bin" out:="$OUT" "$@"
"$bin/bag" info "$OUT/session.mcap"
"$bin/session_report" "$OUT/session.mcap" --output "$OUT/report.html"
echo "bag:    $OUT/session.mcap"
echo "report: $OUT/report.html"
