#!/usr/bin/env bash
# Checkpoints and the DEM over MPI ranks (issue 17): tests/coupling/scenes/
# tire_ckpt.cfg with the rolling spring (rolling_model = "spring", the soil's
# rolling friction 0.1: six doubles per spring, the rolling rows non-zero)
# run to 0.03 s with a checkpoint every 0.01 s (exchanges 499 and 999; the
# wheel's travel ends the run at exchange 1458),
#   1. by one plain dem_server (the reference), and by `./run --ranks 2`,
#      uninterrupted: the same final dem_world_hash and fem_state_hash, the
#      same result files, and both DEM checkpoints (checkpoint/dem.prev.h5 of
#      exchange 499, checkpoint/dem.h5 of 999) the same datasets byte for
#      byte (same_h5.py): a distributed run writes one process's checkpoint
#      (its grains gathered on rank 0 in one process's order, with the pair
#      list, springs, history table, wall forces and loop state);
#   2. resumed from exchange 499 (the newest checkpoints removed from a copy
#      of the results): the 2-rank run's checkpoint on 3 ranks and on one
#      process, the one process's checkpoint on 2 ranks. Each must end in the
#      uninterrupted run's hashes with the same traction.csv, summary.json,
#      fem_series.csv, dem_series.csv and every dataset of dem_grains.h5,
#      wheel.h5 and fem.h5 (the run records, which count the resumed run's
#      exchanges only, are left out).
# So that the test could fail, the distributed runs must have spread the
# grains (rank 1 ends holding some) and the checkpoints must hold rolling
# springs that are not zero.
# Usage: mpi_resume.sh SOURCE_DIR BUILD_DIR
set -uo pipefail
src=$1 build=$2
work=$(mktemp -d /tmp/demfem_mpi_resume_XXXXXX)
trap 'rm -rf "$work"' EXIT
export DEMFEM_NO_BUILD=1 DEMFEM_BUILD_DIR=$build
py=${DEMFEM_PYTHON:-/usr/bin/python3}
materials='({ name = "soil"; density = 2600.0; young = 5.0e7; poisson = 0.3; restitution = 0.5; friction = 0.6; '
materials+='rolling_friction = 0.1; }, { name = "tread"; young = 2.0e7; poisson = 0.45; restitution = 0.5; '
materials+='friction = 0.3; })'
hashes() { # LOG -> "dem fem"
  local dem fem
  dem=$(sed -n 's/.*final state: dem_world_hash \([0-9a-f]*\).*/\1/p' "$1" | head -n 1)
  fem=$(sed -n 's/.*final state: fem_state_hash \([0-9a-f]*\).*/\1/p' "$1" | head -n 1)
  [ -n "$dem" ] && [ -n "$fem" ] || { cat "$1"; echo "$1: no final hashes logged"; exit 1; }
  echo "$dem $fem"
}
spread() { # LOG NAME: rank 1 ended holding grains
  local held
  held=$(sed -n 's/.*rank 1 of [0-9]*: \([0-9]*\) grains (.*/\1/p' "$1" | head -n 1)
  [ "${held:-0}" -gt 0 ] || { echo "$2: the grains never spread to rank 1"; exit 1; }
}
same_results() { # DIR NAME: DIR's result files are the reference's
  for f in traction.csv summary.json fem_series.csv dem_series.csv; do
    cmp "$work/one/$f" "$1/$f" || { echo "$2: $f differs"; exit 1; }
  done
  "$py" "$src/tests/coupling/same_h5.py" "$work/one" "$1" || { echo "$2: HDF5 results differ"; exit 1; }
}
uninterrupted() { # NAME [--ranks N]
  local name=$1; shift
  "$src/run" "$src/tests/coupling/scenes/tire_ckpt.cfg" --out "$work/$name" --set run.end_time=0.03 \
    --set run.checkpoint_every=0.01 --set coupling.stall_timeout=60 --set 'dem.rolling_model="spring"' \
    --set "dem.materials=$materials" --set "dem.bed.file=\"$work/tire_ckpt_bed.h5\"" "$@" \
    > "$work/$name.log" 2>&1 || { cat "$work/$name.log"; echo "$name: the run failed"; exit 1; }
}
resume() { # FROM NAME [--ranks N]: FROM's results resumed from its older checkpoint
  local from=$1 name=$2; shift 2
  cp -r "$work/$from" "$work/$name"
  rm -f "$work/$name/checkpoint/dem.h5" "$work/$name/checkpoint/fem.h5"
  "$src/run" --resume "$work/$name" "$@" > "$work/$name.log" 2>&1 \
    || { cat "$work/$name.log"; echo "$name: the resumed run failed"; exit 1; }
  grep -q 'resumed after exchange 499,' "$work/$name.log" || { echo "$name: not resumed from exchange 499"; exit 1; }
  local got
  got=$(hashes "$work/$name.log")
  echo "$name: $got"
  [ "$got" = "$want" ] || { echo "$name: the resumed run's final state differs"; exit 1; }
  same_results "$work/$name" "$name"
}

uninterrupted one
want=$(hashes "$work/one.log")
echo "one process, uninterrupted: $want"
"$py" - "$work/one/checkpoint/dem.h5" <<'PY' || { echo "the checkpoint holds no rolling spring"; exit 1; }
import sys
import h5py
import numpy as np
f = h5py.File(sys.argv[1], "r")
n = int(np.asarray(f["/pairs/n"][()]).reshape(-1)[0])
s = f["/pairs/springs"][()].reshape(n, 6)
rolling = int(np.count_nonzero(np.any(s[:, 3:] != 0.0, axis=1)))
print(f"one process's checkpoint: {n} pairs, {rolling} with a rolling spring")
assert rolling > 0
PY

uninterrupted ranks2 --ranks 2
got=$(hashes "$work/ranks2.log")
grep -h 'rank .* of' "$work/ranks2.log"
echo "2 ranks, uninterrupted: $got"
[ "$got" = "$want" ] || { echo "2 ranks: the final state differs"; exit 1; }
spread "$work/ranks2.log" "2 ranks"
grep -q 'checkpoint of exchange 999 written' "$work/ranks2.log" || { echo "2 ranks: no checkpoint written"; exit 1; }
same_results "$work/ranks2" "2 ranks"
"$py" "$src/tests/coupling/same_h5.py" "$work/one" "$work/ranks2" checkpoint/dem.prev.h5 checkpoint/dem.h5 ||
  { echo "2 ranks: the DEM checkpoints differ from one process's"; exit 1; }

resume ranks2 ranks2_on3 --ranks 3
spread "$work/ranks2_on3.log" "2 ranks' checkpoint on 3 ranks"
resume ranks2 ranks2_on1
resume one one_on2 --ranks 2
spread "$work/one_on2.log" "one process's checkpoint on 2 ranks"
echo "a 2-rank run writes one process's DEM checkpoints; resumed on 1, 2 and 3 ranks, every run ends as the" \
  "uninterrupted one"
