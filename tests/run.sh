#!/usr/bin/env bash
# The suite's test command (README): installs what a fresh machine lacks, builds every binary
# (the cross-process tests start them), then runs every test. DDS tests put their processes in
# a private loopback-only network namespace themselves (tests/loopback-netns).
set -euo pipefail
cd "$(dirname "$0")/.."

need_apt=()
command -v ip >/dev/null || need_apt+=(iproute2)
command -v unshare >/dev/null || need_apt+=(util-linux)
[ -e /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf ] || need_apt+=(fonts-dejavu-core)
command -v chromium >/dev/null || need_apt+=(chromium)
command -v chromedriver >/dev/null || need_apt+=(chromium-driver)
# The browser test trusts the robot's test CA in an NSS database (certutil).
command -v certutil >/dev/null || need_apt+=(libnss3-tools)
# DDS Security test: the keystore script uses openssl; the secured build links OpenSSL.
command -v openssl >/dev/null || need_apt+=(openssl)
[ -e /usr/include/openssl/ssl.h ] || need_apt+=(libssl-dev)
command -v pkg-config >/dev/null || need_apt+=(pkg-config)
# The bag check's Python readers go into a venv: Debian's own python3 refuses `pip install`
# into the system (PEP 668), and a venv needs ensurepip, which Debian ships apart.
command -v python3 >/dev/null || need_apt+=(python3)
python3 -c 'import ensurepip' 2>/dev/null || need_apt+=(python3-venv)
if [ ${#need_apt[@]} -gt 0 ]; then
  echo "installing: ${need_apt[*]}"
  if [ "$(id -u)" = 0 ]; then SUDO=; else SUDO=sudo; fi
  $SUDO apt-get update -qq && $SUDO apt-get install -y -qq "${need_apt[@]}" >/dev/null
fi

cargo build --workspace --bins
# Everything the tests need is installed above, so a test that would skip for want of a
# network namespace or a browser fails instead: a green run has run every DDS test.
export QT_REQUIRE_ALL_TESTS=1
cargo test --workspace
# The optional DDS Security mode (README, DDS Security): built with its feature, tested apart.
cargo test -p node_shell --features security --test dds_security

# Bags must be readable by the standard Python readers too.
if [ -f tests/bags/check_bag.py ]; then
  venv="${CARGO_TARGET_DIR:-target}/bag-check-venv"
  [ -x "$venv/bin/python" ] || python3 -m venv "$venv"
  "$venv/bin/python" -m pip install -q -r tests/bags/requirements.txt
  "$venv/bin/python" tests/bags/check_bag.py
  # and the committed sample sessions
  "$venv/bin/python" tests/bags/check_bag.py bags/*.mcap
fi
