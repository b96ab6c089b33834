#!/bin/bash
# Crash safety across setups (issue 20), with the real daemon and scancellctl: a two-setup job on the elephant
# (100 mm) ends its first setup waiting for the operator (watch exits 15, naming `scancellctl continue`);
# kill -9 while it waits leaves it waiting (the restarted daemon does not run it); `continue` queues it; kill
# -9 in the middle of setup 2's exploration; the restarted daemon resumes the exploration without retaking a
# stored view, aligns the part, and the job ends with both setups and the alignment in its result and a
# consistent journal (scancelld --check: every scan intact, no view scanned twice).
#   tests/daemon/setup_kill.sh BUILD_DIR
set -euo pipefail
BUILD=$(cd "$1" && pwd)
SRC=$(cd "$(dirname "$0")/../.." && pwd)
W=$(mktemp -d /tmp/scancell_setups.XXXXXX)
PORT=$((21800 + ($$ % 300) * 8))  # 21800-24196 (kill_loop.sh: blocks apart)
LCM_PORT=$((7700 + $$ % 100))  # its own LCM port: other tests publish on the default one
SIM_PID=""
DAEMON_PID=""
. "$SRC/tests/daemon/sim_cell.sh"
trap stop_cell EXIT
fail() {
  echo "setup_kill: $*"
  tail -n 15 "$W"/daemon*.log 2>/dev/null || true
  exit 1
}
kill_daemon() {
  kill -9 "$DAEMON_PID"
  wait "$DAEMON_PID" 2>/dev/null || true
  DAEMON_PID=""
  rm -f "$W/control.sock"  # left by the killed daemon: start_daemon waits for the new one's
  report=$("$BUILD/daemon/scancelld" --check "$W/data") || fail "journal inconsistent after kill -9 $1: $report"
}
state_of() { ctl status 1 | grep -o '"state": "[a-z_]*"' | head -1 | cut -d'"' -f4; }

write_drivers
write_config "{driver: sim, seed: 3}" \
  "{max_rounds: 1, move_timeout_s: 20, scan_speed_mm_s: 400, home_timeout_s: 20, sim_placement_error_mm: 6, sim_placement_error_rad: 0.15}"
start_sim
start_daemon "$W/daemon1.log" || exit 1
ctl submit --mesh "$SRC/tests/data/elephant.off" --fit-mm 100 --rough-vertices 600 --setups 2 > /dev/null || fail "submit"

# 1. Setup 1 ends waiting for the operator.
set +e
ctl watch 1 > "$W/watch1.log"
rc=$?
set -e
[ "$rc" = 15 ] || fail "setup 1: watch exit $rc, want 15 (awaiting the operator): $(tail -n 5 "$W/watch1.log")"
grep -q "turn the part over" "$W/watch1.log" && grep -q "scancellctl continue 1" "$W/watch1.log" ||
  fail "the operator's instruction: $(tail -n 5 "$W/watch1.log")"

# 2. kill -9 while it waits: the restarted daemon leaves it waiting.
kill_daemon "while awaiting the operator"
start_daemon "$W/daemon2.log" || exit 1
sleep 1
[ "$(state_of)" = awaiting_operator ] || fail "after a restart the job is '$(state_of)', not awaiting the operator"
out=$(ctl resume 1 2>&1) && fail "resume of a job awaiting the operator was accepted: $out"

# 3. continue, then kill -9 after setup 2's 3rd exploration view.
ctl continue 1 > /dev/null || fail "continue"
for _ in $(seq 1200); do
  ctl status 1 | grep -q 'setup 2 exploration [4-9]/' && break
  sleep 0.05
done
ctl status 1 | grep -q 'setup 2 exploration [4-9]/' || fail "setup 2's exploration did not reach its 4th view in 60 s: $(ctl status 1 | tr -d '\n' | cut -c1-400)"
kill_daemon "during setup 2's exploration"
explored=$(echo "$report" | grep -o '"scans":[0-9]*' | head -1 | cut -d: -f2)

# 4. The restarted daemon resumes the exploration, aligns and finishes the job.
start_daemon "$W/daemon3.log" || exit 1
set +e
ctl watch 1 > "$W/watch2.log"
rc=$?
set -e
[ "$rc" = 0 ] || [ "$rc" = 10 ] || fail "setup 2: watch exit $rc, want 0 or 10: $(tail -n 8 "$W/watch2.log")"
kill -TERM "$DAEMON_PID"
wait "$DAEMON_PID" 2>/dev/null || true
DAEMON_PID=""
report=$("$BUILD/daemon/scancelld" --check "$W/data") || fail "final journal inconsistent: $report"
scans=$(echo "$report" | grep -o '"scans":[0-9]*' | head -1 | cut -d: -f2)
[ "$scans" -gt "$explored" ] || fail "no scan stored after the restart ($explored before, $scans after)"
grep -q "setup 2 .*aligned: residual" "$W/watch2.log" || fail "the result names no alignment of setup 2: $(tail -n 8 "$W/watch2.log")"
grep -q "setup 1 .*verified m_v" "$W/watch2.log" || fail "the result names no verified m_v of setup 1"
echo "setup_kill: $(grep -E '^  setup [12] ' "$W/watch2.log" | tr -s ' ')"
echo "setup_kill: $explored scans stored when killed in the exploration, $scans at the end; journal consistent"
