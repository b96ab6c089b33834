#!/bin/bash
# scancelld and scancellctl as an integrator uses them: a bad config refuses the start naming the key; the
# control socket refuses bad requests and keeps serving; pause, resume and abort act on a running job; SIGHUP
# reloads; LCM status goes out (recorded by lcm-logger from another process); SIGTERM stops cleanly.
#   tests/daemon/daemon_cli_test.sh BUILD_DIR
set -uo pipefail
BUILD=$(cd "$1" && pwd)
SRC=$(cd "$(dirname "$0")/../.." && pwd)
W=$(mktemp -d /tmp/scancell_cli.XXXXXX)
PORT=$((19400 + ($$ % 300) * 8))  # 19400-21796 (kill_loop.sh: blocks apart)
LCM_PORT=$((7800 + $$ % 100))  # its own LCM port: other tests publish on the default one
fail() { echo "FAIL: $*"; [ -f "$W/daemon.log" ] && tail -20 "$W/daemon.log"; exit 1; }
. "$(dirname "$0")/sim_cell.sh"
trap stop_cell EXIT
write_drivers
JOBS="{max_rounds: 2, move_timeout_s: 20, scan_speed_mm_s: 400, home_timeout_s: 20"

# 1. Bad configuration: refused at start, key path named, exit 4.
write_config "{driver: sim}" "$JOBS, max_roundz: 3}"
out=$("$BUILD/daemon/scancelld" --config "$W/scancelld.yaml" 2>&1); rc=$?
[ $rc = 4 ] || fail "bad config: exit $rc, want 4"
echo "$out" | grep -q "jobs.max_roundz: unknown key" || fail "bad config message: $out"
# The scanner's driver and its GenICam keys are checked at start, by key path.
write_config "{driver: vendor_sdk}" "$JOBS}"
out=$("$BUILD/daemon/scancelld" --config "$W/scancelld.yaml" 2>&1); rc=$?
[ $rc = 4 ] && echo "$out" | grep -q "scanner.driver: must be sim, sim_gige or genicam, got 'vendor_sdk'" || fail "bad scanner driver: exit $rc: $out"
write_config "{driver: genicam, trigger: {chip: gpiochip0, offset: 3}}" "$JOBS}"
out=$("$BUILD/daemon/scancelld" --config "$W/scancelld.yaml" 2>&1); rc=$?
[ $rc = 4 ] && echo "$out" | grep -q "scanner.device: empty" || fail "genicam without a device: exit $rc: $out"
write_config "{driver: sim_gige, profiles_per_frame: 4096}" "$JOBS}"
out=$("$BUILD/daemon/scancelld" --config "$W/scancelld.yaml" 2>&1); rc=$?
[ $rc = 4 ] && echo "$out" | grep -q "scanner.profiles_per_frame" || fail "profiles_per_frame out of range: exit $rc: $out"
# What triggers the scanner: the daemon or the sweep drive's position compare, and only a drive that has one.
write_config "{driver: sim, trigger_source: encoder}" "$JOBS}"
out=$("$BUILD/daemon/scancelld" --config "$W/scancelld.yaml" 2>&1); rc=$?
[ $rc = 4 ] && echo "$out" | grep -q "scanner.trigger_source: must be daemon or drive_compare, got 'encoder'" || fail "bad trigger_source: exit $rc: $out"
cp "$W/drivers.yaml" "$W/drivers-modbus.yaml"
sed -i 's|^  sweep: .*|  sweep: {driver: canopen, interface: can0, node_id: 9, counts_per_mm: 1000, profile_velocity_mm_s: 100}|' "$W/drivers.yaml"
write_config "{driver: sim, trigger_source: drive_compare}" "$JOBS}"
out=$("$BUILD/daemon/scancelld" --config "$W/scancelld.yaml" 2>&1); rc=$?
[ $rc = 4 ] && echo "$out" | grep -q "scanner.trigger_source: drive_compare needs a sweep drive with a position-compare output.*axes.sweep in .* is canopen: use daemon" || fail "drive_compare on canopen: exit $rc: $out"
mv "$W/drivers-modbus.yaml" "$W/drivers.yaml"
write_config "{driver: sim}" "$JOBS, fill_sweeps: 9}"
out=$("$BUILD/daemon/scancelld" --config "$W/scancelld.yaml" 2>&1); rc=$?
[ $rc = 4 ] && echo "$out" | grep -q "jobs.fill_sweeps: must be in \[0, 5\]" || fail "fill_sweeps out of range: exit $rc: $out"
# A timeout of 0 would mean no time at all, not no limit: refused, as is one over an hour.
write_config "{driver: sim}" "{max_rounds: 2, move_timeout_s: 0, home_timeout_s: 20}"
out=$("$BUILD/daemon/scancelld" --config "$W/scancelld.yaml" 2>&1); rc=$?
[ $rc = 4 ] && echo "$out" | grep -q "jobs.move_timeout_s: must be in (0, 3600], got 0" || fail "move_timeout_s 0: exit $rc: $out"
write_config "{driver: sim}" "$JOBS}"
printf 'rough_scan:\n  tilts_rad: [1.15, x]\n' >> "$W/scancelld.yaml"
out=$("$BUILD/daemon/scancelld" --config "$W/scancelld.yaml" 2>&1); rc=$?
[ $rc = 4 ] && echo "$out" | grep -q "rough_scan.tilts_rad\[1\]: cannot read it as a number" || fail "bad rough_scan: exit $rc: $out"
write_config "{driver: sim}" "$JOBS}"
sed -i 's|planner: .*|planner: /nonexistent/planner.yaml|' "$W/scancelld.yaml"
out=$("$BUILD/daemon/scancelld" --config "$W/scancelld.yaml" 2>&1); rc=$?
[ $rc = 4 ] && echo "$out" | grep -q "planner: no such file" || fail "missing file: exit $rc: $out"
mkdir -p "$W/inbox"
write_config "{driver: sim}" "$JOBS, allowed_dirs: [$SRC/tests/data, $W/inbox]}"

# 2. Start on simulated drives; watch LCM from another process.
start_sim
lcm-logger --lcm-url="udpm://239.255.76.67:$LCM_PORT?ttl=0" -q "$W/lcm.log" &
LOGGER_PID=$!
start_daemon || fail "daemon did not start"
[ "$(stat -c %a "$W/control.sock")" = 660 ] || fail "socket mode $(stat -c %a "$W/control.sock")"

# 2b. A second daemon on the same data directory (and socket) is refused, naming the running one's PID, and
# leaves it serving (issue 16, defect 6: it used to take over the socket and home the drives mid-sweep).
out=$(timeout 10 "$BUILD/daemon/scancelld" --config "$W/scancelld.yaml" 2>&1); rc=$?
[ $rc = 1 ] && echo "$out" | grep -q "in use by another scancelld (PID $DAEMON_PID" || fail "second daemon: exit $rc: $out"
[ -S "$W/control.sock" ] || fail "the second daemon removed the first one's socket"

# 3. Bad requests are refused with a reason; the daemon keeps serving.
out=$(ctl submit --mesh "$SRC/tests/data/bad/empty.stl" 2>&1); rc=$?
[ $rc = 1 ] && echo "$out" | grep -q "empty.stl" || fail "bad mesh: exit $rc: $out"
out=$(ctl watch 99 2>&1); rc=$?
[ $rc = 1 ] && echo "$out" | grep -q "no job 99" || fail "unknown job: exit $rc: $out"
out=$(ctl resume 99 2>&1); [ $? = 1 ] || fail "resume of an unknown job accepted"
ctl status > /dev/null || fail "status after bad requests"
# Issue 16, defect 5: a FIFO named as a spec blocked a daemon thread (and later its shutdown); files outside
# jobs.allowed_dirs are refused unread; a refusal does not quote what a client-named file holds.
mkfifo "$W/inbox/spec.yaml"
out=$(timeout 10 "$BUILD/tools/scancellctl" --socket "$W/control.sock" submit --mesh "$SRC/tests/data/cube50.off" --spec "$W/inbox/spec.yaml" 2>&1); rc=$?
[ $rc = 1 ] && echo "$out" | grep -q "spec.yaml' is a FIFO, not a regular file" || fail "FIFO spec: exit $rc: $out"
printf 'precision_mm: 0.05\ndensity_per_mm2: 2\n' > "$W/outside.yaml"
out=$(ctl submit --mesh "$SRC/tests/data/cube50.off" --spec "$W/outside.yaml" 2>&1); rc=$?
[ $rc = 1 ] && echo "$out" | grep -q "outside jobs.allowed_dirs" || fail "file outside allowed_dirs: exit $rc: $out"
printf 'precision_mm: hunter2-secret\ndensity_per_mm2: 2\n' > "$W/inbox/bad-spec.yaml"
out=$(ctl submit --mesh "$SRC/tests/data/cube50.off" --spec "$W/inbox/bad-spec.yaml" 2>&1); rc=$?
[ $rc = 1 ] && echo "$out" | grep -q "precision_mm" || fail "bad spec: exit $rc: $out"
echo "$out" | grep -q "hunter2" && fail "the refusal quoted the file's content: $out"
# placement auto (issue 15) chooses how a mesh's object rests; a bounding-box job already stands on the table.
out=$(ctl submit --bbox-mm 60,60,60 --truth "$SRC/tests/data/cube50.off" --placement auto 2>&1); rc=$?
[ $rc = 1 ] && echo "$out" | grep -q "'placement' auto needs a mesh" || fail "placement auto on a bounding-box job: exit $rc: $out"

# 4. A job: pause at a safe point, resume, abort.
ctl submit --mesh "$SRC/tests/data/cube50.off" --rough-vertices 400 > /dev/null || fail "submit"
for _ in $(seq 400); do ctl status 1 | grep -q '"view": [3-9]' && break; sleep 0.05; done
ctl status 1 | grep -q '"view": [3-9]' || fail "view 3 not reached within 20 s"
ctl pause 1 > /dev/null || fail "pause"
ctl watch 1 > "$W/watch1.log"; rc=$?
[ $rc = 13 ] || fail "watch after pause: exit $rc, want 13 (paused)"
stored=$("$BUILD/daemon/scancelld" --check "$W/data" | grep -o '"scans":[0-9]*' | cut -d: -f2)
ctl resume 1 > /dev/null || fail "resume"
for _ in $(seq 400); do
  now=$("$BUILD/daemon/scancelld" --check "$W/data" | grep -o '"scans":[0-9]*' | cut -d: -f2)
  [ "$now" -gt "$stored" ] && break; sleep 0.05
done
[ "$now" -gt "$stored" ] || fail "the resumed job stored no further view in 20 s ($stored scans before the pause, '$now' now); its status: $(ctl status 1 | tr -d '\n' | cut -c1-600); the cell: $(ctl status | tr -d '\n' | cut -c1-800)"
ctl abort 1 > /dev/null || fail "abort"
ctl watch 1 > "$W/watch2.log"; rc=$?
[ $rc = 11 ] || fail "watch after abort: exit $rc, want 11 (aborted)"
out=$(ctl abort 1 2>&1); [ $? = 1 ] && echo "$out" | grep -q "already aborted" || fail "second abort: $out"
# Issue 20: continue confirms a turned-over part; a job not awaiting the operator is refused, naming its state.
out=$(ctl continue 1 2>&1); [ $? = 1 ] && echo "$out" | grep -q "job 1 is aborted, not awaiting the operator" || fail "continue of an aborted job: $out"
out=$(ctl submit --mesh "$SRC/tests/data/cube50.off" --setups 9 2>&1); [ $? = 2 ] || fail "--setups 9 accepted: $out"
# Issue 19: the aborted job hands over what it measured: its product, plans, events and range images.
out=$(ctl export 1 --out "$W/export1" --with-scans 2>&1) || fail "export: $out"
for f in cloud.ply model.ply job.json plans.json events.txt; do [ -s "$W/export1/$f" ] || fail "export lacks $f: $out"; done
grep -q '"state": "aborted"' "$W/export1/job.json" || fail "exported job.json: $(head -c 400 "$W/export1/job.json")"
grep -q '"cloud": "cloud.ply"' "$W/export1/job.json" || fail "exported job.json names no cloud"
grep -q "aborted" "$W/export1/events.txt" || fail "exported events lack the abort"
[ "$(ls "$W/export1/scans" | wc -l)" -ge 3 ] || fail "export --with-scans: $(ls "$W/export1/scans" | wc -l) range images"
# ... and is what scancell fuse reads.
out=$("$BUILD/tools/scancell" fuse --scans "$W/export1/scans" --spec "$SRC/config/spec/thesis.yaml" --out "$W/fused.ply" 2>&1) || fail "fuse of the exported scans: $out"
[ -s "$W/fused.ply" ] || fail "fuse wrote no model: $out"
out=$(ctl export 1 --out "$W/export1" 2>&1); [ $? = 1 ] && echo "$out" | grep -q "not an empty directory" || fail "export over a full directory: $out"
out=$(ctl export 99 --out "$W/export99" 2>&1); [ $? = 1 ] && echo "$out" | grep -q "no job 99" || fail "export of an unknown job: $out"

# 5. A calibration run as a daemon job: the turntable axis from a sphere (the simulated cell's is nominal).
out=$(ctl calibrate lens 2>&1); [ $? = 2 ] || fail "unknown calibration kind accepted: $out"
ctl calibrate turntable_axis --watch > "$W/calibrate.log"; rc=$?
[ $rc = 0 ] || { cat "$W/calibrate.log"; fail "calibrate turntable_axis: exit $rc"; }
grep -q "table_axis_direction" "$W/calibrate.log" || fail "calibration values not shown"
calfile=$(ls "$W"/data/calibration/turntable_axis-*.yaml) || fail "no calibration file written"
grep -q "^scancell_calibration: 1" "$calfile" || fail "calibration file not versioned"
ctl status | grep -q "turntable_axis-" || fail "status does not list the calibration in force"
# The planner reads the same file offline.
out=$("$BUILD/tools/scancell" plan --mesh "$SRC/tests/data/cube50.off" --sensor "$SRC/config/sensors/line-scan-thesis.yaml" \
  --spec "$SRC/config/spec/thesis.yaml" --cell "$SRC/config/cells/turntable-lift-tilt.yaml" --calibration "$calfile" \
  --out "$W/plan.json" 2>&1) || fail "scancell plan --calibration: $out"
# On a cell the plan covers as a job does (the settings' constrained reads as greedy) and says so.
grep -q '"mode": "greedy"' "$W/plan.json" && echo "$out" | grep -q "on a cell the cover is greedy" \
  || fail "scancell plan --cell: not covered as a job covers: $out"
out=$("$BUILD/tools/scancell" plan --mesh "$SRC/tests/data/cube50.off" --sensor "$SRC/config/sensors/line-scan-thesis.yaml" \
  --spec "$SRC/config/spec/thesis.yaml" --calibration "$calfile" --out "$W/plan.json" 2>&1); rc=$?
[ $rc = 2 ] && echo "$out" | grep -q "needs --cell" || fail "axis calibration without a cell: exit $rc: $out"

# 6. SIGHUP reloads; SIGTERM stops at a safe point and exits 0.
kill -HUP "$DAEMON_PID"; sleep 0.3
grep -q "SIGHUP reload" "$W/daemon.log" || fail "SIGHUP not handled"
# A submit whose mesh hangs the reader (a PLY without end_header: 30 s until the reader's limit) is under way
# when SIGTERM comes: the daemon stops it and exits promptly (issue 16: it waited out the read).
"$BUILD/tools/scancellctl" --socket "$W/control.sock" submit --mesh "$SRC/tests/data/bad/ply-header-typo-hang.ply" > "$W/hang.log" 2>&1 &
HANG_PID=$!
sleep 0.5
t0=$(date +%s.%N)
kill -TERM "$DAEMON_PID"
for _ in $(seq 400); do kill -0 "$DAEMON_PID" 2>/dev/null || break; sleep 0.05; done
kill -0 "$DAEMON_PID" 2>/dev/null && fail "SIGTERM: still running 20 s later with a submit reading a hanging mesh (the read alone lasts 30 s)"
wait "$DAEMON_PID"; rc=$?; DAEMON_PID=""
wait "$HANG_PID" 2>/dev/null
[ $rc = 0 ] || fail "SIGTERM exit $rc"
awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN { printf "daemon_cli: stopped %.1f s after SIGTERM with a hanging mesh read under way\n", b - a }'
grep -q "scancelld: stopped" "$W/daemon.log" || fail "no clean stop"
# 7. A restarted daemon loads the calibration its run wrote.
start_daemon "$W/daemon2.log" || fail "restarted daemon did not start"
ctl status | grep -q "turntable_axis-" || fail "restarted daemon did not load $calfile"
kill -TERM "$DAEMON_PID"; wait "$DAEMON_PID"; DAEMON_PID=""
kill -TERM "$LOGGER_PID"; wait "$LOGGER_PID" 2>/dev/null; LOGGER_PID=""
for ch in SCANCELL_STATUS SCANCELL_PROGRESS SCANCELL_AXIS_STATE SCANCELL_PLAN; do
  grep -aq "$ch" "$W/lcm.log" || fail "lcm-logger recorded no $ch"
done
"$BUILD/daemon/scancelld" --check "$W/data" > /dev/null || fail "journal inconsistent"
# The cell's data is owner and group only: directories 0750, files 0640 (issue 16: they were 0644).
[ "$(stat -c %a "$W/data")" = 750 ] || fail "data directory mode $(stat -c %a "$W/data")"
loose=$(find "$W/data" \( -type f -perm /o=rwx \) -o \( -type d -perm /o=rwx \) | head -3)
[ -z "$loose" ] || fail "world-accessible data: $loose"
[ "$(stat -c %a "$W/data/journal.sqlite")" = 640 ] || fail "journal mode $(stat -c %a "$W/data/journal.sqlite")"
[ -n "$(find "$W/data/scans" -type f | head -1)" ] || fail "no scans stored to check"
echo "daemon_cli_test: all checks passed"
