#!/bin/bash
# The production scanner path as a cell runs it (issue 18): scancelld with scanner.driver genicam (the real
# driver, no simulation inside the daemon) and trigger_source drive_compare, against `scancell-sim scanner`,
# a GigE Vision device in its own process whose Line0 is the sweep drive's position-compare output (read
# over Modbus TCP beside the daemon), and the simulated drives. The job must finish having measured the part
# as the in-process drive-compare job does (the same views, coverage within 0.01), and every profile the
# drives' compare fired must have reached the daemon.
#   tests/daemon/sim_scanner_process.sh BUILD_DIR
set -uo pipefail
BUILD=$(cd "$1" && pwd)
SRC=$(cd "$(dirname "$0")/../.." && pwd)
W=$(mktemp -d /tmp/scancell_scanner.XXXXXX)
PORT=$((26600 + ($$ % 300) * 8))  # 26600-28996 (kill_loop.sh: blocks apart)
LCM_PORT=$((7600 + $$ % 100))
SCANNER_PID=
fail() { echo "FAIL: $*"; for f in daemon.log scanner.log; do [ -f "$W/$f" ] && { echo "--- $f"; tail -20 "$W/$f"; }; done; exit 1; }
. "$(dirname "$0")/sim_cell.sh"
stop_all() { [ -n "$SCANNER_PID" ] && kill -TERM "$SCANNER_PID" 2>/dev/null; stop_cell; }
trap stop_all EXIT
write_drivers
# fill_sweeps 5: a loaded CI host (two tests side by side) can lag the scanner process behind the sweep; the
# missed profiles are then swept again (docs/daemon.md step 2) and both jobs still measure the same.
JOBS="{max_rounds: 1, move_timeout_s: 20, scan_speed_mm_s: 50, home_timeout_s: 20, fill_sweeps: 5}"
# A simulated trigger line cannot reach a real scanner: refused unless the drive's compare triggers it.
write_config "{driver: genicam, device: 127.0.0.1, trigger: {chip: sim, offset: 0}}" "$JOBS"
out=$("$BUILD/daemon/scancelld" --config "$W/scancelld.yaml" 2>&1); rc=$?
[ $rc = 4 ] && echo "$out" | grep -q "scanner.trigger.chip: sim is no line a real scanner can see" || fail "genicam with a sim trigger line: exit $rc: $out"
start_sim
"$BUILD/tools/scancell-sim" scanner --gige 127.0.0.1 --mesh "$SRC/tests/data/cube50.off" --cell "$SRC/config/cells/turntable-lift-tilt.yaml" \
  --sensor "$SRC/config/sensors/line-scan-thesis.yaml" --drivers "$W/drivers.yaml" > "$W/scanner.log" 2>&1 &
SCANNER_PID=$!
for _ in $(seq 100); do grep -q "GigE Vision scanner" "$W/scanner.log" 2>/dev/null && break; sleep 0.05; done
grep -q "GigE Vision scanner" "$W/scanner.log" || fail "the scanner did not start"
write_config "{driver: genicam, device: 127.0.0.1, profiles_per_frame: 16, trigger_source: drive_compare, trigger: {chip: sim, offset: 0}}" "$JOBS"
start_daemon || fail "daemon did not start"
grep -q "scanner genicam, profiles triggered by the sweep drive's position compare" "$W/daemon.log" || fail "the daemon does not say what triggers the scanner"
ctl submit --mesh "$SRC/tests/data/cube50.off" --rough-vertices 400 > /dev/null || fail "submit"
timeout 240 "$BUILD/tools/scancellctl" --socket "$W/control.sock" watch 1 > "$W/watch.log"
ctl status 1 > "$W/status.json"
grep -q '"state": "done"\|"state": "stalled"' "$W/status.json" || { cat "$W/status.json"; fail "job did not end"; }
views=$(grep -o '"views": [0-9]*' "$W/status.json" | head -1 | grep -o '[0-9]*$')
cov=$(grep -o '"measured_coverage": [0-9.]*' "$W/status.json" | head -1 | grep -o '[0-9.]*$')
# A real scanner's profiles carry no simulation side data: the job's ground-truth checks are not run.
grep -q '"ground_truth_checks": "not run' "$W/status.json" || fail "ground-truth checks on a real scanner's path"
kill -TERM "$DAEMON_PID"; wait "$DAEMON_PID"; DAEMON_PID=
kill -TERM "$SCANNER_PID"; wait "$SCANNER_PID"; SCANNER_PID=
profiles=$(grep -o '[0-9]* profiles' "$W/scanner.log" | grep -o '^[0-9]*')
# The same job in process, the drive's compare triggering the virtual scanner inside the daemon.
rm -rf "$W/data"; rm -f "$W/control.sock"
write_config "{driver: sim, trigger_source: drive_compare}" "$JOBS"
start_daemon "$W/daemon-sim.log" || fail "daemon (sim scanner) did not start"
ctl submit --mesh "$SRC/tests/data/cube50.off" --rough-vertices 400 > /dev/null || fail "submit (sim)"
timeout 240 "$BUILD/tools/scancellctl" --socket "$W/control.sock" watch 1 > /dev/null
ctl status 1 > "$W/status-sim.json"
views_sim=$(grep -o '"views": [0-9]*' "$W/status-sim.json" | head -1 | grep -o '[0-9]*$')
cov_sim=$(grep -o '"measured_coverage": [0-9.]*' "$W/status-sim.json" | head -1 | grep -o '[0-9.]*$')
[ "$views" = "$views_sim" ] || fail "$views views with the scanner process, $views_sim in process"
awk -v a="$cov" -v b="$cov_sim" 'BEGIN { d = a - b; if (d < 0) d = -d; exit !(d <= 0.01) }' ||
  fail "measured coverage $cov with the scanner process against $cov_sim in process"
[ "${profiles:-0}" -ge $((views * 256)) ] || fail "the scanner process sent ${profiles:-0} profiles for $views views of 256"
echo "scanner process: $views views, measured coverage $cov (in process $cov_sim), $profiles profiles over GigE Vision"
