#!/usr/bin/env bash
# A month on the robot's PC in one process on the virtual clock (tests/month.rs): DAYS days
# (default 30) of one session for each of three children a day, the suite started each morning
# in a new run directory and stopped each evening, the Q-tables (one per child beside the
# clusters') kept across days. Checks every session whole and each child's state its own, and
# prints a line a day: live heap bytes after the evening's stop, RSS, allocations, the run
# directory's and the Q-tables' bytes. The sessions run at TIME_SCALE (default 1.0, the real
# pace, so the bags are as large as the robot's). Output in OUT (kept).
#   bash bench/month/month.sh [DAYS]
#   TIME_SCALE=0.2 OUT=out/month bash bench/month/month.sh 30
#   PROFILE=release bash bench/month/month.sh        (optimised, faster)
#   ROS4HRI=false bash bench/month/month.sh 6         (the classifier's ROS4HRI persons off)
set -euo pipefail
cd "$(dirname "$0")/../.."
DAYS=${1:-30}
OUT=${OUT:-out/month-$(date +%Y%m%d-%H%M%S)}
mkdir -p "$(dirname "$OUT")"
QT_MONTH_DAYS="$DAYS" QT_MONTH_TIME_SCALE="${TIME_SCALE:-1.0}" QT_MONTH_OUT="$(realpath -m "$OUT")" \
  QT_MONTH_ROS4HRI="${ROS4HRI:-true}" \
  cargo test --profile "${PROFILE:-dev}" -p suite_tests --test month -- --ignored --nocapture \
  a_month_of_daily_sessions_at_the_robots_pace 2>&1 | tee "$OUT.log"
exit "${PIPESTATUS[0]}"
