#!/usr/bin/env bash
# The LCM monitor with scancell's message types (docs/telemetry.md).
#   scripts/monitor.sh BUILD_DIR spy [LCM_URL]   lcm-spy that decodes every SCANCELL_* channel
#   scripts/monitor.sh BUILD_DIR check           headless: record a running scancelld's SCANCELL_STATUS with
#                                                lcm-logger and decode it through the same jar as lcm-spy
# Installs what only the monitor needs (liblcm-java, libjchart2d-java, a headless JDK), with sudo when not
# root, builds BUILD_DIR/monitor/scancell-lcmtypes.jar from lcmtypes/*.lcm, and starts lcm.spy.Spy itself:
# Debian 12's lcm-spy wrapper passes -Xincgc, which Java 17 refuses ("Unrecognized option: -Xincgc").
set -euo pipefail
BUILD=$(mkdir -p "$1" && cd "$1" && pwd)
MODE=${2:-spy}
URL=${3:-"udpm://239.255.76.67:7667?ttl=0"}
SRC=$(cd "$(dirname "$0")/.." && pwd)
OUT="$BUILD/monitor"

missing=()
for p in liblcm-java libjchart2d-java default-jdk-headless liblcm-bin; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  echo "monitor: installing ${missing[*]}"
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
CP_LCM=/usr/share/java/lcm.jar:/usr/share/java/jchart2d.jar

# The types' jar, rebuilt when a .lcm file is newer.
JAR="$OUT/scancell-lcmtypes.jar"
if [ ! -f "$JAR" ] || [ -n "$(find "$SRC/lcmtypes" -name '*.lcm' -newer "$JAR")" ]; then
  rm -rf "$OUT/java" "$OUT/classes"
  mkdir -p "$OUT/java" "$OUT/classes"
  lcm-gen --java --jpath "$OUT/java" "$SRC"/lcmtypes/*.lcm
  javac -nowarn -cp "$CP_LCM" -d "$OUT/classes" "$OUT"/java/scancell/*.java
  jar cf "$JAR.tmp" -C "$OUT/classes" .
  mv "$JAR.tmp" "$JAR"
fi

case "$MODE" in
spy)
  if [ -z "${DISPLAY:-}${WAYLAND_DISPLAY:-}" ]; then
    echo "monitor: lcm-spy is a window and there is no display (DISPLAY unset): log in with ssh -X, or run" >&2
    echo "         'make monitor-check' for the headless check, or record with lcm-logger --lcm-url '$URL' cell.lcmlog" >&2
    exit 1
  fi
  echo "monitor: lcm-spy on $URL with $JAR"
  exec java -Djava.net.preferIPv4Stack=true -Xmx128m -ea -cp "$CP_LCM:$JAR" lcm.spy.Spy --lcm-url "$URL"
  ;;
check)
  mkdir -p "$OUT/check"
  javac -cp "$CP_LCM:$JAR" -d "$OUT/check" "$SRC/tools/monitor/MonitorCheck.java"
  W=$(mktemp -d /tmp/scancell_monitor.XXXXXX)
  PORT=$((18700 + ($$ % 400) * 8))
  LCM_PORT=$((7900 + $$ % 50))
  . "$SRC/tests/daemon/sim_cell.sh"
  trap stop_cell EXIT
  write_drivers
  write_config "{driver: sim}" "{max_rounds: 1}"
  start_sim
  lcm-logger --lcm-url="udpm://239.255.76.67:$LCM_PORT?ttl=0" -q "$W/cell.lcmlog" &
  LOGGER_PID=$!
  start_daemon || { echo "monitor check: scancelld did not start"; exit 1; }
  sleep 2.5  # SCANCELL_STATUS goes out at 1 Hz
  kill -TERM "$DAEMON_PID"; wait "$DAEMON_PID" 2>/dev/null || true; DAEMON_PID=""
  sleep 0.2
  kill -TERM "$LOGGER_PID"; wait "$LOGGER_PID" 2>/dev/null || true; LOGGER_PID=""
  java -cp "$CP_LCM:$JAR:$OUT/check" MonitorCheck "$W/cell.lcmlog"
  ;;
*)
  echo "usage: scripts/monitor.sh BUILD_DIR spy [LCM_URL] | check" >&2
  exit 2
  ;;
esac
