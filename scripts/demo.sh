#!/bin/bash
# make demo: a whole simulated scan job end to end. Starts five simulated Modbus TCP drives (scancell-sim on
# loopback), starts scancelld on them with the simulated line scanner, submits a job on the mushroom's rough
# model, watches it with scancellctl and prints the result table (views, measured coverage, m_v verified
# against the ground-truth mesh, time, coverage picture). Usage: scripts/demo.sh BUILD_DIR [rough|flip|gige]
# With "rough" the job starts from nothing but the object's bounding box: rough scan, fusion into a rough
# model, plan, execute, register, replan (make demo-rough). With "flip" the job measures the fandisk in two
# setups, turned over by the (simulated) operator in between (make demo-flip). With "gige" the mushroom job
# runs with the scanner on the GigE Vision path (config/demo/scancelld-gige.yaml; make demo-gige).
set -euo pipefail
BUILD=${1:-build}
MODE=${2:-mesh}
D="$BUILD/demo"
rm -rf "$D"
mkdir -p "$D"
SIM_PID=""
DAEMON_PID=""
cleanup() {
  [ -n "$DAEMON_PID" ] && kill -TERM "$DAEMON_PID" 2>/dev/null && wait "$DAEMON_PID" 2>/dev/null || true
  [ -n "$SIM_PID" ] && kill -TERM "$SIM_PID" 2>/dev/null && wait "$SIM_PID" 2>/dev/null || true
}
trap cleanup EXIT
T0=$(date +%s.%N)
"$BUILD/tools/scancell-sim" modbus --tcp 15501 --drives 5 --max-velocity 4000000 --accel 40000000 --no-stdin \
  > "$D/sim.log" 2>&1 &
SIM_PID=$!
for _ in $(seq 100); do grep -q "drive 4 on" "$D/sim.log" 2>/dev/null && break; sleep 0.05; done
grep -q "drive 4 on" "$D/sim.log" || { echo "demo: the drive simulator did not start:"; cat "$D/sim.log"; exit 1; }
echo "== drives: 5 simulated Modbus TCP drives on 127.0.0.1:15501-15505"
CONFIG=config/demo/scancelld.yaml
[ "$MODE" = gige ] && CONFIG=config/demo/scancelld-gige.yaml
"$BUILD/daemon/scancelld" --config "$CONFIG" --data-dir "$D/data" --socket "$D/control.sock" \
  > "$D/scancelld.log" 2>&1 &
DAEMON_PID=$!
for _ in $(seq 200); do [ -S "$D/control.sock" ] && break; sleep 0.05; done
[ -S "$D/control.sock" ] || { echo "demo: scancelld did not start:"; cat "$D/scancelld.log"; exit 1; }
echo "== scancelld: $(head -1 "$D/scancelld.log")"
set +e
if [ "$MODE" = flip ]; then
  # Issue 20: two setups. The fandisk rests on its large flat base, which the plate hides; after setup 1 the
  # job asks for the part to be turned over (awaiting_operator), the simulated operator puts it down within
  # 8 mm and 0.2 rad of the pose asked, and setup 2 aligns it to the model and measures the rest.
  # FLIP_MESH=tests/data/elephant.off make demo-flip tries another part.
  FLIP_MESH=${FLIP_MESH:-tests/data/fandisk.off}
  echo "== submit: $FLIP_MESH, longest side 200 mm, two setups"
  "$BUILD/tools/scancellctl" --socket "$D/control.sock" submit --mesh "$FLIP_MESH" --fit-mm 200 --setups 2 --watch
  RC=$?
  if [ "$RC" = 15 ]; then
    echo "== the operator turns the part over as asked (the picture: $D/data/jobs/1/next_setup.png), then:"
    echo "   scancellctl continue 1"
    "$BUILD/tools/scancellctl" --socket "$D/control.sock" continue 1 > /dev/null
    "$BUILD/tools/scancellctl" --socket "$D/control.sock" watch 1
    RC=$?
  fi
elif [ "$MODE" = rough ]; then
  echo "== submit: nothing but a 125 x 125 x 60 mm box on the table (the simulated cell holds the mushroom, 120 mm)"
  "$BUILD/tools/scancellctl" --socket "$D/control.sock" submit --bbox-mm 125,125,60 --truth tests/data/mushroom.off \
    --fit-mm 120 --rough-vertices 1500 --watch
  RC=$?
  grep -h "rough model:" "$D/scancelld.log" 2>/dev/null || true
else
  [ "$MODE" = gige ] && echo "== scanner: the virtual scanner as a GigE Vision device on 127.0.0.1, read by the GenICam driver"
  echo "== submit: tests/data/mushroom.off, longest side 200 mm, thesis spec (0.05 mm, 2 samples/mm2)"
  "$BUILD/tools/scancellctl" --socket "$D/control.sock" submit --mesh tests/data/mushroom.off --fit-mm 200 --watch
  RC=$?
fi
set -e
T1=$(date +%s.%N)
awk -v a="$T0" -v b="$T1" 'BEGIN { printf "  %-34s %.1f s\n", "demo wall time (all of it)", b - a }'
echo "  journal: $D/data/journal.sqlite   daemon log: $D/scancelld.log"
# Done, or stalled on a sliver the rough model promised and no view delivered (reported above): the job ran
# end to end either way. Anything else is a failure of the demo.
[ "$RC" = 0 ] || [ "$RC" = 10 ] || exit "$RC"
exit 0
