# Sourced by the fuzz scripts (fuzz/run.sh, nodes/bag/fuzz/run.sh): the instrumentation that
# `cargo fuzz build` uses (libFuzzer coverage counters, AddressSanitizer, debug assertions and
# overflow checks in release), and the host triple to build for, so both build fuzzers alike.
triple=$(rustc -vV | sed -n 's/^host: //p')
export RUSTFLAGS="-Cpasses=sancov-module -Cllvm-args=-sanitizer-coverage-level=4 \
-Cllvm-args=-sanitizer-coverage-inline-8bit-counters -Cllvm-args=-sanitizer-coverage-pc-table \
-Cllvm-args=-sanitizer-coverage-trace-compares --cfg fuzzing -Cdebug-assertions \
-Coverflow-checks -Zsanitizer=address"
