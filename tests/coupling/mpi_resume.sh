#!/usr/bin/env bash
# A one-process checkpoint resumed with the DEM side on 2 and 3 MPI ranks
# (issue 17, phase 2): tests/coupling/scenes/tire_ckpt.cfg run to 0.03 s by
# one plain dem_server with a checkpoint every 0.015 s; its newest
# checkpoints removed from a copy of the results, `./run --resume COPY
# --ranks N` continues from exchange 749 (rank 0 reads the checkpoint, the
# grains spread at the first neighbour rebuild) and must end in the
# uninterrupted run's dem_world_hash and fem_state_hash with the same
# traction.csv, summary.json, fem_series.csv and every dataset of
# dem_grains.h5, wheel.h5 and fem.h5 (dem_series.csv and the run records,
# which count the resumed run's exchanges only, are left out). So that the
# test could fail, the resumed run must have spread the grains (rank 1 ends
# holding some).
# Usage: mpi_resume.sh SOURCE_DIR BUILD_DIR
set -uo pipefail
src=$1 build=$2
work=$(mktemp -d /tmp/demfem_mpi_resume_XXXXXX)
trap 'rm -rf "$work"' EXIT
export DEMFEM_NO_BUILD=1 DEMFEM_BUILD_DIR=$build
hashes() { # LOG -> "dem fem"
  local dem fem
  dem=$(sed -n 's/.*final state: dem_world_hash \([0-9a-f]*\).*/\1/p' "$1" | head -n 1)
  fem=$(sed -n 's/.*final state: fem_state_hash \([0-9a-f]*\).*/\1/p' "$1" | head -n 1)
  [ -n "$dem" ] && [ -n "$fem" ] || { cat "$1"; echo "$1: no final hashes logged"; exit 1; }
  echo "$dem $fem"
}
"$src/run" "$src/tests/coupling/scenes/tire_ckpt.cfg" --out "$work/one" --set run.end_time=0.03 \
  --set run.checkpoint_every=0.015 --set coupling.stall_timeout=60 \
  --set "dem.bed.file=\"$work/tire_ckpt_bed.h5\"" > "$work/one.log" 2>&1 \
  || { cat "$work/one.log"; echo "the one-process run failed"; exit 1; }
want=$(hashes "$work/one.log")
echo "one process, uninterrupted: $want"
for n in 2 3; do
  cp -r "$work/one" "$work/ranks$n"
  rm -f "$work/ranks$n/checkpoint/dem.h5" "$work/ranks$n/checkpoint/fem.h5"
  "$src/run" --resume "$work/ranks$n" --ranks $n > "$work/ranks$n.log" 2>&1 \
    || { cat "$work/ranks$n.log"; echo "$n ranks: the resumed run failed"; exit 1; }
  got=$(hashes "$work/ranks$n.log")
  grep -h 'resumed after\|rank .* of' "$work/ranks$n.log"
  echo "resumed on $n ranks: $got"
  [ "$got" = "$want" ] || { echo "$n ranks: the resumed run's final state differs"; exit 1; }
  grep -q 'resumed after exchange 749,' "$work/ranks$n.log" || { echo "$n ranks: not resumed from exchange 749"; exit 1; }
  held=$(sed -n 's/.*rank 1 of [0-9]*: \([0-9]*\) grains (.*/\1/p' "$work/ranks$n.log" | head -n 1)
  [ "${held:-0}" -gt 0 ] || { echo "$n ranks: the grains never spread to rank 1"; exit 1; }
  for f in traction.csv summary.json fem_series.csv; do
    cmp "$work/one/$f" "$work/ranks$n/$f" || { echo "$n ranks: $f differs"; exit 1; }
  done
  "${DEMFEM_PYTHON:-/usr/bin/python3}" "$src/tests/coupling/same_h5.py" "$work/one" "$work/ranks$n" ||
    { echo "$n ranks: HDF5 results differ"; exit 1; }
done
echo "a one-process checkpoint resumed on 2 and 3 DEM ranks ends as the uninterrupted run"
