#!/usr/bin/env bash
# Sphere on an FE rubber block at several mesh sizes (issue 16 item 2):
#   tests/coupling/block/measure.sh OUTDIR [h ...]     (h in m; default 0.002 0.0015 0.001)
# Each run's peak force and contact time (traction.csv) and the grain's
# rebound energy (dem_series.csv) against Hertz, by analyse.py.
set -uo pipefail
HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
ROOT=$(cd "$HERE/../../.." && pwd)
OUT=${1:?usage: measure.sh OUTDIR [h ...]}
shift
SIZES=("$@")
[ ${#SIZES[@]} -gt 0 ] || SIZES=(0.002 0.0015 0.001)
mkdir -p "$OUT"
for h in "${SIZES[@]}"; do
  d="$OUT/h$h"
  mkdir -p "$d"
  cp "$HERE/sphere_block.cfg" "$d/"
  /usr/bin/python3 "$HERE/block_mesh.py" "$d/block.msh" "$h" || exit 1
  DEMFEM_NO_BUILD=${DEMFEM_NO_BUILD:-1} "$ROOT/run" "$d/sphere_block.cfg" --out "$d/run" > "$d/run.log" 2>&1
  echo "h = $h m: run exit $? (log $d/run.log)"
done
/usr/bin/python3 "$HERE/analyse.py" "$OUT"/h*/run
