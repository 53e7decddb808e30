#!/usr/bin/env bash
# Sphere on an FE rubber block at several mesh sizes (issue 16 item 2):
#   tests/coupling/block/measure.sh OUTDIR [h ...]     (h in m; default 0.002 0.0015 0.001)
# Each run's peak force and contact time (traction.csv), the grain's
# rebound energy (dem_series.csv) and, at the peak, the approach, the FE
# block's deflection and the contact's own overlap (snapshots every 10 us)
# against Hertz, by analyse.py. BLOCK_SETS="--set KEY=VALUE ..." adds
# overrides to every run (e.g. the contact rule under test), BLOCK_EVERY=N
# snapshots every N steps instead of 10; BLOCK_SCENE=FILE (in this folder)
# another scene than sphere_block.cfg, BLOCK_MESH="L D f grow" the block's
# extent for block_mesh.py.
set -uo pipefail
HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
ROOT=$(cd "$HERE/../../.." && pwd)
OUT=${1:?usage: measure.sh OUTDIR [h ...]}
shift
SIZES=("$@")
SCENE=${BLOCK_SCENE:-sphere_block.cfg}
EVERY=${BLOCK_EVERY:-10}   # steps between snapshots: 10 us at the scene's 1 us
[ ${#SIZES[@]} -gt 0 ] || SIZES=(0.002 0.0015 0.001)
mkdir -p "$OUT"
for h in "${SIZES[@]}"; do
  d="$OUT/h$h"
  mkdir -p "$d"
  cp "$HERE/$SCENE" "$d/"
  /usr/bin/python3 "$HERE/block_mesh.py" "$d/block.msh" "$h" ${BLOCK_MESH:-} || exit 1
  DEMFEM_NO_BUILD=${DEMFEM_NO_BUILD:-1} "$ROOT/run" "$d/$SCENE" --out "$d/run" \
    --set dem.output.every=$EVERY --set dem.output.series_every=$EVERY --set fem.output.every=$EVERY ${BLOCK_SETS:-} \
    > "$d/run.log" 2>&1
  echo "h = $h m: run exit $? (log $d/run.log)"
done
/usr/bin/python3 "$HERE/analyse.py" "$OUT"/h*/run
