#!/bin/bash
# Times two builds of one Google Benchmark binary against each other on a noisy machine: OLD and
# NEW are alternated ROUNDS times in short runs, and per benchmark row the minimum and the median
# over the rounds are printed with their new/old ratios. On hosts whose single runs swing by 10-30%
# (a shared VM's neighbours), a change of a few percent shows only this way, if at all.
#
#   OLD=/tmp/old_registrar_bench NEW=build/tests/bench/registrar_bench \
#     FILTER='BM_RegisterObjects/mode:1$' ROUNDS=8 MINTIME=0.5 tests/bench/alternate_binaries.sh
#
# Build OLD from the commit before a change (e.g. git stash; ninja -C build X; cp; git stash pop).
# COLUMN=cpu compares the benchmark's CPU time instead of its wall time: on a VM whose neighbours
# take the core away (wall time well above CPU time in the output), the wall time mostly
# measures them.
set -euo pipefail
: "${OLD:?set OLD to the old binary}" "${NEW:?set NEW to the new binary}"
filter=${FILTER:-.}
rounds=${ROUNDS:-8}
min_time=${MINTIME:-0.5}
case "${COLUMN:-wall}" in
  wall) fields='$1, $2, $3' ;;
  cpu) fields='$1, $4, $5' ;;
  *) echo "COLUMN must be wall or cpu" >&2; exit 2 ;;
esac
times=$(mktemp)
trap 'rm -f "$times"' EXIT
for _ in $(seq "$rounds"); do
  for side in old new; do
    binary=$OLD
    [ "$side" = new ] && binary=$NEW
    env -u OPENBLAS_CORETYPE OMP_WAIT_POLICY=PASSIVE "$binary" --benchmark_filter="$filter" \
      --benchmark_min_time="$min_time" 2>/dev/null |
      awk -v side="$side" "/^BM_/ {print side, $fields}" >>"$times"
  done
done
python3 - "$times" <<'PY'
import collections, statistics, sys
rows = collections.defaultdict(list)
units = {}
for line in open(sys.argv[1]):
    side, name, time, unit = line.split()
    rows[(name, side)].append(float(time))
    units[name] = unit
for name in sorted({n for n, _ in rows}):
    old, new = rows[(name, "old")], rows[(name, "new")]
    if not old or not new:
        continue
    o_min, o_med, n_min, n_med = min(old), statistics.median(old), min(new), statistics.median(new)
    print(f"{name:45s} {units[name]}: old min {o_min:8.2f} med {o_med:8.2f} | "
          f"new min {n_min:8.2f} med {n_med:8.2f} | new/old min {n_min / o_min:.3f} "
          f"med {n_med / o_med:.3f}")
PY
