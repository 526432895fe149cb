#!/usr/bin/env bash
# Which source the kept fuzz corpora reach, split into the suite's own code and its
# dependencies, so a target still finding new edges can be judged: are they in our parsers or
# deep in a library (a YAML or JSON parser) the target passes through?
#   fuzz/coverage.sh TARGET [CORPUS_DIR...]     (default corpus: fuzz/corpus/TARGET)
#   REV=HEAD fuzz/coverage.sh TARGET            the corpus as committed at REV instead
# Builds the fuzz targets with LLVM source-based coverage (-Cinstrument-coverage, the flags
# `cargo fuzz coverage` uses, no sanitizer) into fuzz/target/coverage, runs every input once
# (libFuzzer -runs=0) and prints llvm-cov's region and line totals for the suite's sources
# (msgs/, libs/, nodes/, tools/) and for everything else, then the suite's files. Needs nightly's llvm-tools
# (`rustup component add llvm-tools --toolchain nightly`).
set -euo pipefail
cd "$(dirname "$0")"
t=${1:?usage: fuzz/coverage.sh TARGET [CORPUS_DIR...]}
shift
triple=$(rustc -vV | sed -n 's/^host: //p')
tools=$(rustc +nightly --print sysroot)/lib/rustlib/$triple/bin
[ -x "$tools/llvm-cov" ] || {
  echo "llvm-cov not found in $tools: rustup component add llvm-tools --toolchain nightly" >&2
  exit 2
}

work=target/coverage-run.$$
trap 'rm -rf "$work"' EXIT
mkdir -p "$work"
corpora=("$@")
if [ -n "${REV:-}" ]; then
  # The committed corpus, to compare coverage before and after a run.
  mkdir -p "$work/committed"
  git -C .. archive "$REV" "fuzz/corpus/$t" | tar -x -C "$work/committed"
  corpora=("$work/committed/fuzz/corpus/$t")
elif [ ${#corpora[@]} -eq 0 ]; then
  corpora=("corpus/$t")
fi

export CARGO_TARGET_DIR="$PWD/target/coverage"
export RUSTFLAGS="-Cinstrument-coverage --cfg fuzzing -Cdebug-assertions -Coverflow-checks"
nice -n 10 cargo +nightly build --release --target "$triple" --bin "$t" >&2
bin="$CARGO_TARGET_DIR/$triple/release/$t"

inputs=$(find "${corpora[@]}" -type f | wc -l)
echo "=== $t: $inputs inputs from ${corpora[*]}" >&2
LLVM_PROFILE_FILE="$work/%p.profraw" nice -n 10 "$bin" -runs=0 -rss_limit_mb=2048 \
  -max_len=65536 "${corpora[@]}" > "$work/run.log" 2>&1 || {
  tail -n 20 "$work/run.log" >&2
  exit 1
}
"$tools/llvm-profdata" merge -sparse "$work"/*.profraw -o "$work/merged.profdata"

root=$(cd .. && pwd)
"$tools/llvm-cov" export -summary-only -instr-profile="$work/merged.profdata" "$bin" \
  > "$work/summary.json"
"$tools/llvm-cov" export -format=lcov -instr-profile="$work/merged.profdata" "$bin" \
  > "$work/lines.lcov"
python3 - "$work/summary.json" "$root" "$t" "$inputs" "$work/lines.lcov" <<'EOF'
import json, sys
summary, root, target, inputs = sys.argv[1], sys.argv[2] + "/", sys.argv[3], sys.argv[4]
lcov = sys.argv[5]
files = json.load(open(summary))["data"][0]["files"]
ours = {f["filename"][len(root):]: f["summary"] for f in files
        if f["filename"][len(root):].split("/")[0] in ("msgs", "libs", "nodes", "tools")}
deps = [f["summary"] for f in files if f["filename"][len(root):] not in ours]
def total(summaries, kind):
    c = sum(s[kind]["covered"] for s in summaries)
    n = sum(s[kind]["count"] for s in summaries)
    return c, n
def pct(c, n):
    return f"{100 * c / n:.1f} %" if n else "-"
print(f"{target}: {inputs} inputs")
print(f"{'':<14}{'regions covered':>26}{'lines covered':>26}")
for name, group in (("suite", list(ours.values())), ("dependencies", deps)):
    rc, rn = total(group, "regions")
    lc, ln = total(group, "lines")
    print(f"{name:<14}{f'{rc:,} of {rn:,}':>18}{pct(rc, rn):>8}{f'{lc:,} of {ln:,}':>18}{pct(lc, ln):>8}")
print()
print("suite files reached (regions covered of regions):")
for name, s in sorted(ours.items()):
    r = s["regions"]
    if r["covered"]:
        print(f"  {name}: {r['covered']} of {r['count']}")

# Where to look for what the fuzzer has not reached: the lines run zero times in the suite's
# files it did reach, as ranges (a function never called shows as one range).
uncovered, current = {}, None
for line in open(lcov):
    if line.startswith("SF:"):
        current = line[3:].strip()[len(root):]
    elif line.startswith("DA:") and current in ours and ours[current]["regions"]["covered"]:
        n, count = line[3:].split(",")[:2]
        if int(count) == 0:
            uncovered.setdefault(current, []).append(int(n))
print()
print("lines never run in those files:")
for name, lines in sorted(uncovered.items()):
    ranges, start = [], None
    for a, b in zip(lines, lines[1:] + [None]):
        start = a if start is None else start
        if b != a + 1:
            ranges.append(f"{start}" if start == a else f"{start}-{a}")
            start = None
    print(f"  {name}: {', '.join(ranges)}")
EOF
