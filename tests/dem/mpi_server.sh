#!/usr/bin/env bash
# dem_server itself over MPI: a DEM-only scene (tests/dem/scenes/mpi_drop.cfg)
# run by one plain process and by mpirun with 2 and 3 ranks (oversubscribed)
# must log the same final state hash (dem_mpi_hash gathers the whole world
# in tag order), write the same grain frames (every dataset of every
# frame byte for byte: the ranks' grains gathered on rank 0) and the same
# dem_series.csv byte for byte (more than its initial row: kinetic energies
# summed along the global grain order from rank to rank, the ranks' contact
# counts added), and the
# distributed runs must have moved grains between ranks.
# Usage: mpi_server.sh DEM_SERVER MPIEXEC
set -uo pipefail
exe=$1 mpiexec=$2
src=$(cd "$(dirname "$0")" && pwd)
work=$(mktemp -d /tmp/demfem_mpi_server_XXXXXX)
trap 'rm -rf "$work"' EXIT
run() { # NAME [mpirun -np N ...]: the final hash into $work/NAME.hash
  local name=$1; shift
  "$@" "$exe" --scene "$src/scenes/mpi_drop.cfg" --standalone --out "$work/$name" > "$work/$name.log" 2>&1 \
    || { cat "$work/$name.log"; echo "$name: dem_server failed"; exit 1; }
  sed -n 's/.*final state: dem_world_hash \([0-9a-f]*\).*/\1/p' "$work/$name.log" | head -n 1 > "$work/$name.hash"
  [ -s "$work/$name.hash" ] || { cat "$work/$name.log"; echo "$name: no final hash logged"; exit 1; }
}
run one
h1=$(cat "$work/one.hash")
mpi=("$mpiexec" --allow-run-as-root --oversubscribe --bind-to none --mca mpi_yield_when_idle 1
     --mca mca_base_component_disable_dlclose 1 --mca btl_vader_single_copy_mechanism none -np)
for n in 2 3; do
  run ranks$n "${mpi[@]}" $n
  h=$(cat "$work/ranks$n.hash")
  grep -h 'rank .* of' "$work/ranks$n.log"
  echo "one process $h1, $n ranks $h"
  [ "$h" = "$h1" ] || { cat "$work/ranks$n.log"; echo "$n ranks: final state differs"; exit 1; }
  moved=$(sed -n 's/.*rank [0-9]* of [0-9]*:.*, \([0-9]*\) migrated;.*/\1/p' "$work/ranks$n.log" |
          awk '{s += $1} END {print s + 0}')
  [ "$moved" -gt 0 ] || { echo "$n ranks: no grain migrated between ranks"; exit 1; }
  rows=$(wc -l < "$work/one/dem_series.csv")
  [ "$rows" -gt 3 ] || { echo "one process: $rows lines in dem_series.csv"; exit 1; }
  cmp "$work/one/dem_series.csv" "$work/ranks$n/dem_series.csv" || { echo "$n ranks: dem_series.csv differs"; exit 1; }
  echo "dem_series.csv: $rows lines identical"
  "${DEMFEM_PYTHON:-/usr/bin/python3}" - "$work/one/dem_grains.h5" "$work/ranks$n/dem_grains.h5" <<'PY' || { echo "$n ranks: frames differ"; exit 1; }
import sys
import h5py
a, b = h5py.File(sys.argv[1], "r"), h5py.File(sys.argv[2], "r")
fa = sorted(k for k in a if k.startswith("frame_"))
fb = sorted(k for k in b if k.startswith("frame_"))
assert fa == fb and len(fa) == 5, f"frames {fa} vs {fb}"
for f in fa:
    assert sorted(a[f]) == sorted(b[f]), f"{f}: datasets {sorted(a[f])} vs {sorted(b[f])}"
    assert a[f].attrs["time"] == b[f].attrs["time"], f"{f}: time"
    for d in a[f]:
        x, y = a[f][d][()], b[f][d][()]
        assert x.shape == y.shape and x.tobytes() == y.tobytes(), f"{f}/{d} differs"
print(f"{len(fa)} frames identical ({', '.join(sorted(a[fa[-1]]))})")
PY
done
echo "same final state for 1, 2 and 3 ranks"
