# Sourced by the fuzz scripts (fuzz/run.sh): the instrumentation that
# `cargo fuzz build` uses (libFuzzer coverage counters, AddressSanitizer, debug assertions and
# overflow checks in release), and the host triple to build for, so both build fuzzers alike.
# SANITIZER=none (fuzz/run.sh; the bag reader's script keeps ASan) leaves AddressSanitizer out,
# as `cargo fuzz build -s none` does: the workspace denies unsafe code, so ASan only watches our
# dependencies' unsafe code (smallvec, encoding_rs, number formatting), and without it a run
# executes several times more inputs (bench/fuzz/sanitizer.sh measures how many). That build
# has its own target directory ($build_dir), so switching back and forth rebuilds neither;
# replay what it found under ASan afterwards (REPLAY=1 fuzz/run.sh 0 TARGET).
triple=$(rustc -vV | sed -n 's/^host: //p')
case ${SANITIZER:-address} in
address) asan=" -Zsanitizer=address" build_dir=target ;;
none) asan="" build_dir=target/sanitizer-none ;;
*) echo "SANITIZER=${SANITIZER} unknown: address (the default) or none" >&2; exit 2 ;;
esac
export RUSTFLAGS="-Cpasses=sancov-module -Cllvm-args=-sanitizer-coverage-level=4 \
-Cllvm-args=-sanitizer-coverage-inline-8bit-counters -Cllvm-args=-sanitizer-coverage-pc-table \
-Cllvm-args=-sanitizer-coverage-trace-compares --cfg fuzzing -Cdebug-assertions \
-Coverflow-checks$asan"
# The default (ASan) build's binaries, which some work needs whatever SANITIZER says (run.sh
# and stable_functions.sh say why).
default_bin_dir=target/$triple/release
# Largest input per target (libFuzzer -max_len): room for the model files seeded.
max_len() { case $1 in
  user_model_file | read_bag) echo 65536 ;; xgboost_model) echo 32768 ;; q_table_file) echo 32768 ;;
  *) echo 8192 ;; esac; }
