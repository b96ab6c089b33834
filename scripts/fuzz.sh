#!/bin/bash
# make fuzz: runs every libFuzzer target for SECONDS, from a copy of its committed corpus (new inputs stay in
# BUILD/corpus/<target>, the committed one is not touched) with the reproducers as seeds, and prints one line
# per target: executions, coverage (edges), corpus size, and whether it found a crash (artifacts in BUILD/).
#   scripts/fuzz.sh BUILD_DIR SECONDS
set -uo pipefail
BUILD=$1
SECONDS_EACH=${2:-60}
SRC=$(cd "$(dirname "$0")/.." && pwd)
export LSAN_OPTIONS=suppressions=$SRC/tests/lsan.supp UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
status=0
printf '%-12s %12s %10s %8s %s\n' target executions cov_edges corpus result
for t in mesh range_image plan_file config control; do
  work="$BUILD/corpus/$t"
  mkdir -p "$work" "$BUILD/artifacts/$t"
  cp -n "$SRC/fuzz/corpus/$t"/* "$work/" 2>/dev/null
  seeds=("$work")
  [ -d "$SRC/fuzz/reproducers/$t" ] && seeds+=("$SRC/fuzz/reproducers/$t")
  log="$BUILD/fuzz_$t.log"
  # -timeout: a single input over 10 s is reported (mesh reads are bounded at 2 s by the child's limit).
  "$BUILD/fuzz/fuzz_$t" -max_total_time="$SECONDS_EACH" -timeout=10 -rss_limit_mb=4096 -print_final_stats=1 \
    -artifact_prefix="$BUILD/artifacts/$t/" "${seeds[@]}" > "$log" 2>&1
  rc=$?
  execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$')
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | grep -o '[0-9]*')
  size=$(ls "$work" | wc -l)
  result=ok
  [ $rc != 0 ] && { result="FOUND (exit $rc): see $log and $BUILD/artifacts/$t/"; status=1; }
  printf '%-12s %12s %10s %8s %s\n' "$t" "${execs:-?}" "${cov:-?}" "$size" "$result"
done
exit $status
