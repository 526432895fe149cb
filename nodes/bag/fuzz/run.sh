#!/usr/bin/env bash
# Fuzzes the bag reader with libFuzzer the way `cargo fuzz run read_bag` would (same
# instrumentation flags, nightly, AddressSanitizer), for machines without cargo-fuzz.
#   nodes/bag/fuzz/run.sh [SECONDS]      (default 600)
# The corpus grows in corpus/read_bag (kept in the repository); crashes land in artifacts/.
set -euo pipefail
cd "$(dirname "$0")"
secs=${1:-600}
# Always with AddressSanitizer: the reader is fuzzed short enough for its cost, and this
# crate's make_seeds links only beside ASan's runtime (fuzz/run.sh says why).
SANITIZER=address
source ../../../fuzz/libfuzzer_flags.sh
export CARGO_TARGET_DIR="$PWD/target"
cargo +nightly build --release --target "$triple" --bins
"target/$triple/release/make_seeds" corpus/read_bag
mkdir -p artifacts/read_bag
"target/$triple/release/read_bag" -max_total_time="$secs" -max_len=65536 -rss_limit_mb=2048 \
  -artifact_prefix=artifacts/read_bag/ corpus/read_bag
