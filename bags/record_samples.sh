#!/usr/bin/env bash
# Records the sample bags of bags/ from the simulated suite: the main job's launch file
# (launch_scripts/simulated_session.launch.yaml, every node its own process over DDS) inside a
# private loopback-only network namespace, as launch_scripts/simulated_session.sh runs it.
# In the second sample a therapist pauses, resumes and overrides a level from a second
# console; in the third one the therapist stops the session after four sequences. Each session starts with fresh Q-tables, so the policy pretrains them with
# its seed (params/behaviour_policy.yaml); bags/q_tables/ holds what that gives (see README).
#   bash bags/record_samples.sh            # -> out/bags/<name>/session.mcap, then copied here
#   bash bags/record_samples.sh NAME...    # only these samples (e.g. cluster0_seed7)
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --workspace --bins
BIN=target/debug

# One plain session: launch args as given.
plain() {
  local name=$1
  shift
  local out=out/bags/$name
  rm -rf "$out" && mkdir -p "$out"
  tests/loopback-netns "$BIN/launch" launch_scripts/simulated_session.launch.yaml --log-dir "$out/logs" \
    out:="$out" "$@" >"$out/launch.log" 2>&1
  cp "$out/session.mcap" "bags/$name.mcap"
}

# A session during which a therapist pauses for 3 s, resumes, and sets the level of the next
# sequence to 3, from a second `therapist` console, once the first sequence is recorded.
with_therapist() {
  local name=$1
  shift
  local out=out/bags/$name
  rm -rf "$out" && mkdir -p "$out"
  tests/loopback-netns bash -c '
    set -euo pipefail
    bin=$1; out=$2; shift 2
    "$bin/launch" launch_scripts/simulated_session.launch.yaml --log-dir "$out/logs" out:="$out" "$@" \
      >"$out/launch.log" 2>&1 &
    launch=$!
    # The game manager writes <session>.jsonl after the first sequence.
    for _ in $(seq 600); do ls "$out"/session-*.jsonl >/dev/null 2>&1 && break; sleep 0.1; done
    session=$(basename "$(ls "$out"/session-*.jsonl | head -1)" .jsonl)
    # Into sequence 2'"'"'s presentation, not at its phase change: the replay test orders inputs
    # by the recorder'"'"'s receipt times, a few ms off the game manager'"'"'s.
    sleep 0.6
    export QT_PARAMS_DIR=params ROS_LOCALHOST_ONLY=1
    "$bin/therapist" pause --session "$session" >>"$out/console.log" 2>&1
    sleep 3
    "$bin/therapist" resume --session "$session" >>"$out/console.log" 2>&1
    "$bin/therapist" override --session "$session" --level 3 >>"$out/console.log" 2>&1
    wait "$launch"
  ' with_therapist "$BIN" "$out" "$@"
  cp "$out/session.mcap" "bags/$name.mcap"
}

# A session the therapist stops (`therapist stop`) once four sequences are recorded: the robot
# says goodbye, the session ends as stopped with 4 of 10 sequences.
with_stop() {
  local name=$1
  shift
  local out=out/bags/$name
  rm -rf "$out" && mkdir -p "$out"
  tests/loopback-netns bash -c '
    set -uo pipefail
    bin=$1; out=$2; shift 2
    "$bin/launch" launch_scripts/simulated_session.launch.yaml --log-dir "$out/logs" out:="$out" "$@" \
      >"$out/launch.log" 2>&1 &
    launch=$!
    for _ in $(seq 1200); do
      [ "$(cat "$out"/session-*.jsonl 2>/dev/null | wc -l)" -ge 4 ] && break
      sleep 0.1
    done
    session=$(basename "$(ls "$out"/session-*.jsonl | head -1)" .jsonl)
    QT_PARAMS_DIR=params ROS_LOCALHOST_ONLY=1 "$bin/therapist" stop --session "$session" \
      >>"$out/console.log" 2>&1
    # The console following the session exits non-zero on a stop; the launch ends with it.
    wait "$launch" || true
  ' with_stop "$BIN" "$out" "$@"
  cp "$out/session.mcap" "bags/$name.mcap"
}

wanted() { [ $# -eq 0 ] || [[ " $* " == *" $NAME "* ]]; }
NAME=cluster0_seed7; wanted "$@" && plain $NAME cluster:=0 seed:=7 user:=sim-child-1
NAME=cluster1_seed11_pause_override
wanted "$@" && with_therapist $NAME cluster:=1 seed:=11 user:=sim-child-2
NAME=cluster0_seed3_stopped; wanted "$@" && with_stop $NAME cluster:=0 seed:=3 user:=sim-child-3
# The Q-tables the policy pretrained at startup (the same for every session: same seed and user
# models): each session learned only in its own cluster's table, so the other one is untouched.
mkdir -p bags/q_tables
[ -f out/bags/cluster0_seed7/q_tables/cluster_1.json ] &&
  cp out/bags/cluster0_seed7/q_tables/cluster_1.json bags/q_tables/
[ -f out/bags/cluster1_seed11_pause_override/q_tables/cluster_0.json ] &&
  cp out/bags/cluster1_seed11_pause_override/q_tables/cluster_0.json bags/q_tables/
for f in bags/*.mcap; do
  echo "== $f ($(stat -c %s "$f") bytes)"
  "$BIN/bag" info "$f"
done
