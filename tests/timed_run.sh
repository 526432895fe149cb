#!/usr/bin/env bash
# The test command, timed: builds every binary (the build, timed apart), then runs
# `bash tests/run.sh` with each line of its output stamped with the seconds since it started,
# and prints how long the command took after the build and how long each test binary ran
# (from cargo's "Running"/"Doc-tests" line to its result). docs/testing.md's figures come
# from this on a fresh clone:
#   git clone /path/to/repo /tmp/fresh && cd /tmp/fresh && bash tests/timed_run.sh /tmp/times
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-target/test-times}"
mkdir -p "$out"
export CARGO_TERM_COLOR=never
start=$(date +%s.%N)
cargo build --workspace --bins
built=$(date +%s.%N)
echo "the build (cargo build --workspace --bins): $(echo "$built - $start" | bc) s" | tee "$out/summary.txt"
set +e
bash tests/run.sh 2>&1 | while IFS= read -r line; do
  printf '%8.1f %s\n' "$(echo "$(date +%s.%N) - $built" | bc)" "$line"
done > "$out/run.log"
rc=${PIPESTATUS[0]}
set -e
after=$(echo "$(date +%s.%N) - $built" | bc)
{
  echo "bash tests/run.sh after the build: $after s (exit $rc), load average $(cut -d' ' -f1-3 /proc/loadavg) at its end"
  python3 - "$out/run.log" <<'EOF'
import re, sys
lines = open(sys.argv[1], errors="replace").read().splitlines()
last = {}
rows = []
for l in lines:
    m = re.match(r"\s*([\d.]+) (\[\w+\] )?(.*)", l)
    if not m:
        continue
    t, lane, text = float(m.group(1)), m.group(2) or "", m.group(3)
    r = re.search(r"(Running|Doc-tests) (.*?)(?: \((\S+)\))?$", text)
    if r:
        name = r.group(3).split("/")[-1] if r.group(3) else "doc-tests " + r.group(2)
        last[lane] = (t, name)
        continue
    r = re.search(r"test result: (\w+)\. (\d+) passed; (\d+) failed; (\d+) ignored", text)
    if r and lane in last:
        t0, name = last.pop(lane)
        rows.append((t - t0, name, int(r.group(2)), r.group(1), lane.strip()))
rows.sort(reverse=True)
print(f"{len(rows)} test binaries and doc-test runs; the slowest:")
for secs, name, passed, ok, lane in rows[:25]:
    print(f"  {secs:7.1f} s  {lane} {name}  ({passed} passed, {ok})")
print(f"  sum of all: {sum(r[0] for r in rows):.1f} s")
EOF
} | tee -a "$out/summary.txt"
exit "$rc"
