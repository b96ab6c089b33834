# Shared by the process tests (sourced): the demo's driver config moved to five ports from $PORT, a daemon
# config in $W, the drive simulator, and stop_cell for the EXIT trap. Needs BUILD, SRC, W, PORT, LCM_PORT.

# stop_cell: kill what the test started (DAEMON_PID hard, SIM_PID and LOGGER_PID cleanly) and remove $W.
stop_cell() {
  [ -n "${DAEMON_PID:-}" ] && kill -9 "$DAEMON_PID" 2>/dev/null || true
  [ -n "${SIM_PID:-}" ] && kill -TERM "$SIM_PID" 2>/dev/null || true
  [ -n "${LOGGER_PID:-}" ] && kill -TERM "$LOGGER_PID" 2>/dev/null || true
  wait 2>/dev/null || true
  rm -rf "$W"
}

# write_drivers: config/drivers/demo-sim.yaml with its ports 15501-15505 moved to PORT ... PORT+4.
write_drivers() {
  awk -v base="$PORT" '{ if (match($0, /port: [0-9]+/)) { p = substr($0, RSTART + 6, RLENGTH - 6); sub(/port: [0-9]+/, "port: " base + (p % 10) - 1) } print }' \
    "$SRC/config/drivers/demo-sim.yaml" > "$W/drivers.yaml"
}

# write_config SCANNER JOBS: $W/scancelld.yaml with these flow mappings for `scanner` and `jobs`.
write_config() {
  cat > "$W/scancelld.yaml" <<YAML
cell: $SRC/config/cells/turntable-lift-tilt.yaml
drivers: $W/drivers.yaml
sensor: $SRC/config/sensors/line-scan-thesis.yaml
spec: $SRC/config/spec/thesis.yaml
planner: $SRC/config/planner/default.yaml
data_dir: $W/data
lcm_url: "udpm://239.255.76.67:$LCM_PORT?ttl=0"
control: {socket: $W/control.sock}
scanner: $1
jobs: $2
YAML
}

# start_sim: the five drives in the background (SIM_PID), returning once the last one serves.
start_sim() {
  "$BUILD/tools/scancell-sim" modbus --tcp "$PORT" --drives 5 --max-velocity 4000000 --accel 40000000 --no-stdin > "$W/sim.log" 2>&1 &
  SIM_PID=$!
  for _ in $(seq 100); do grep -q "drive 4 on" "$W/sim.log" 2>/dev/null && return 0; sleep 0.05; done
  echo "the drive simulator did not start:"; cat "$W/sim.log"; exit 1
}

# start_daemon [LOG]: scancelld on $W/scancelld.yaml in the background (DAEMON_PID), logging to LOG (default
# $W/daemon.log); returns once its control socket is up, or 1 with the log shown when it is not within 10 s.
start_daemon() {
  local log="${1:-$W/daemon.log}"
  "$BUILD/daemon/scancelld" --config "$W/scancelld.yaml" > "$log" 2>&1 &
  DAEMON_PID=$!
  for _ in $(seq 400); do [ -S "$W/control.sock" ] && return 0; sleep 0.025; done
  echo "scancelld did not start:"; cat "$log"; return 1
}

ctl() { "$BUILD/tools/scancellctl" --socket "$W/control.sock" "$@"; }
