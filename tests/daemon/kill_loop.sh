#!/bin/bash
# Crash safety of the real daemon: kill -9 scancelld at random moments of a job, N times, restarting it each
# time; after every kill the journal must be consistent (scancelld --check: every referenced scan intact, no
# view scanned twice) and the stored scans never fewer than before; finally the job must complete with every
# view of every round stored exactly once. The drives (scancell-sim) live on across the daemon's deaths, as a
# cell's drives do.
#   tests/daemon/kill_loop.sh BUILD_DIR ITERATIONS [SEED]
set -euo pipefail
BUILD=$(cd "$1" && pwd)
N=${2:-20}
RANDOM=${3:-7}
SRC=$(cd "$(dirname "$0")/../.." && pwd)
W=$(mktemp -d /tmp/scancell_kill.XXXXXX)
PORT=$((17000 + ($$ % 500) * 8))
SIM_PID=""
LCM_PORT=$((7900 + $$ % 100))  # its own LCM port: other tests publish on the default one
DAEMON_PID=""
cleanup() {
  [ -n "$DAEMON_PID" ] && kill -9 "$DAEMON_PID" 2>/dev/null || true
  [ -n "$SIM_PID" ] && kill -TERM "$SIM_PID" 2>/dev/null || true
  wait 2>/dev/null || true
  rm -rf "$W"
}
trap cleanup EXIT

. "$SRC/tests/daemon/sim_cell.sh"
write_drivers
write_config "{driver: sim, seed: 3}" "{max_rounds: 3, move_timeout_s: 20, scan_speed_mm_s: 400, home_timeout_s: 20}"
start_sim

start_daemon() {
  rm -f "$W/control.sock"
  "$BUILD/daemon/scancelld" --config "$W/scancelld.yaml" >> "$W/daemon.log" 2>&1 &
  DAEMON_PID=$!
  for _ in $(seq 400); do [ -S "$W/control.sock" ] && return 0; sleep 0.025; done
  echo "kill_loop: scancelld did not come up"; tail -5 "$W/daemon.log"; exit 1
}

start_daemon
ctl submit --mesh "$SRC/tests/data/cube50.off" --rough-vertices 400 > /dev/null
jobs=1
previous=0
for i in $(seq "$N"); do
  # 0.15 ... 1.6 s into this life of the daemon: planning, moves, sweeps, stores all get hit.
  sleep "$(awk -v r=$RANDOM 'BEGIN { printf "%.3f", 0.15 + (r % 1450) / 1000 }')"
  kill -9 "$DAEMON_PID"
  wait "$DAEMON_PID" 2>/dev/null || true
  DAEMON_PID=""
  report=$("$BUILD/daemon/scancelld" --check "$W/data") || { echo "kill $i: journal inconsistent: $report"; exit 1; }
  scans=$(echo "$report" | grep -o '"scans":[0-9]*' | awk -F: '{ s += $2 } END { print s + 0 }')
  state=$(echo "$report" | grep -o '"state":"[a-z]*"' | head -1 | cut -d'"' -f4)  # the newest job
  [ "$scans" -ge "$previous" ] || { echo "kill $i: stored scans fell from $previous to $scans"; exit 1; }
  echo "kill $i: newest job $state, $scans scans stored in all jobs, journal consistent"
  previous=$scans
  start_daemon
  # A finished job: queue another, so that every kill lands in a running job.
  if [ "$state" = "done" ] || [ "$state" = "stalled" ]; then
    ctl submit --mesh "$SRC/tests/data/cube50.off" --rough-vertices 400 > /dev/null
    jobs=$((jobs + 1))
  fi
done
# Let the last job finish undisturbed.
set +e
ctl watch "$jobs" > "$W/watch.log"
rc=$?
set -e
kill -TERM "$DAEMON_PID"; wait "$DAEMON_PID" 2>/dev/null || true; DAEMON_PID=""
report=$("$BUILD/daemon/scancelld" --check "$W/data") || { echo "final: journal inconsistent: $report"; exit 1; }
echo "final: $report"
tail -12 "$W/watch.log"
[ "$rc" = 0 ] || [ "$rc" = 10 ] || { echo "final: the job ended with exit $rc"; exit 1; }
if echo "$report" | grep -q '"state":"\(queued\|planning\|executing\|verifying\|replanning\|faulted\)"'; then
  echo "final: a job did not finish"; exit 1
fi
echo "kill_loop: $N kills survived; $jobs jobs completed; daemon starts: $(grep -c 'ready;' "$W/daemon.log")"
