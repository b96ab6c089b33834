#!/bin/bash
# Crash safety of the real daemon: kill -9 scancelld at random moments of a job, N times, restarting it each
# time; after every kill the journal must be consistent (scancelld --check: every referenced scan intact, no
# view scanned twice) and the stored scans never fewer than before; finally the job must complete with every
# view of every round stored exactly once. The drives (scancell-sim) live on across the daemon's deaths, as a
# cell's drives do. Where each kill landed is read from the daemon's phase trace (jobs.phase_trace_file) and
# reported as a histogram (plan, move, sweep, store: between the end of a sweep and the durable store, other);
# every third kill is aimed at the store window, and the run fails unless at least MIN_STORE_SHARE of the
# kills landed there (a loop whose kills all land before a view is stored tests nothing about storage).
#   tests/daemon/kill_loop.sh BUILD_DIR ITERATIONS [SEED] [MIN_STORE_SHARE, default 0.2]
set -euo pipefail
BUILD=$(cd "$1" && pwd)
N=${2:-20}
RANDOM=${3:-7}
MIN_STORE_SHARE=${4:-0.2}
SRC=$(cd "$(dirname "$0")/../.." && pwd)
W=$(mktemp -d /tmp/scancell_kill.XXXXXX)
PORT=$((17000 + ($$ % 300) * 8))  # 17000-19396: each process test has its own block (they run side by side)
SIM_PID=""
LCM_PORT=$((7900 + $$ % 100))  # its own LCM port: other tests publish on the default one
DAEMON_PID=""
. "$SRC/tests/daemon/sim_cell.sh"
trap stop_cell EXIT
write_drivers
TRACE="$W/phase.trace"
write_config "{driver: sim, seed: 3}" "{max_rounds: 3, move_timeout_s: 20, scan_speed_mm_s: 400, home_timeout_s: 20, phase_trace_file: $TRACE}"
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
declare -A landed=([plan]=0 [move]=0 [sweep]=0 [store]=0 [other]=0)
phase_now() { tail -n 1 "$TRACE" 2>/dev/null; }
for i in $(seq "$N"); do
  if [ $((i % 3)) = 0 ]; then
    # Aimed: as soon as a sweep has ended and its view is not yet durable (registering, storing). The daemon
    # is stopped (SIGSTOP, every thread) and the phase read again, so the kill lands where it was seen: on a
    # loaded host the store window could pass between the read and the kill (1 aimed kill in 6 did, beside
    # two busy loops, and the run failed its store share once in a full ctest -j2).
    for _ in $(seq 10000); do
      case "$(phase_now)" in
        registering|storing)
          kill -STOP "$DAEMON_PID"
          case "$(phase_now)" in registering|storing) break ;; esac
          kill -CONT "$DAEMON_PID" ;;
      esac
      sleep 0.002
    done
  else
    # 0.15 ... 1.6 s into this life of the daemon: planning, moves, sweeps, stores all get hit.
    sleep "$(awk -v r=$RANDOM 'BEGIN { printf "%.3f", 0.15 + (r % 1450) / 1000 }')"
  fi
  kill -9 "$DAEMON_PID"
  wait "$DAEMON_PID" 2>/dev/null || true
  DAEMON_PID=""
  case "$(phase_now)" in
    planning|replanning) where=plan ;;
    moving) where=move ;;
    scanning) where=sweep ;;
    registering|storing) where=store ;;
    *) where=other ;;
  esac
  landed[$where]=$((landed[$where] + 1))
  echo "-- after kill $i: $(phase_now)" >> "$TRACE"  # the next life starts from a marked line
  report=$("$BUILD/daemon/scancelld" --check "$W/data") || { echo "kill $i: journal inconsistent: $report"; exit 1; }
  scans=$(echo "$report" | grep -o '"scans":[0-9]*' | awk -F: '{ s += $2 } END { print s + 0 }')
  state=$(echo "$report" | grep -o '"state":"[a-z]*"' | head -1 | cut -d'"' -f4)  # the newest job
  [ "$scans" -ge "$previous" ] || { echo "kill $i: stored scans fell from $previous to $scans"; exit 1; }
  echo "kill $i: landed in $where; newest job $state, $scans scans stored in all jobs, journal consistent"
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
echo "kill_loop: kills landed: plan ${landed[plan]}, move ${landed[move]}, sweep ${landed[sweep]}, store ${landed[store]} (sweep ended, view not yet durable), other ${landed[other]}"
awk -v s="${landed[store]}" -v n="$N" -v m="$MIN_STORE_SHARE" 'BEGIN { exit !(s >= m * n) }' ||
  { echo "kill_loop: only ${landed[store]} of $N kills landed between a sweep's end and its durable store (want >= $MIN_STORE_SHARE)"; exit 1; }
echo "kill_loop: $N kills survived; $jobs jobs completed; daemon starts: $(grep -c 'ready;' "$W/daemon.log")"
