#!/usr/bin/env bash
# The MPI transport end to end (issue 17 item 6): tests/coupling/scenes/
# tire_window.cfg (tire_small with a shifting terrain window) for END s run
# through ./run over the shared-memory ring (one dem_server process), then
# with --transport mpi (one MPMD mpirun job: dem_server on 1 and on 2 ranks,
# fem_server) must end in the same dem_world_hash and fem_state_hash and
# write the same result files (same_results.sh: the CSV and JSON files and
# run records byte for byte, every HDF5 dataset; not the profiles' timings). So that the test could fail, the MPI runs must
# have spoken over MPI (the servers name the channel "mpi").
# Then fem_server is killed (-9) in a longer MPI run that is exchanging (its
# log shows the surface received, a line that stays): mpirun must end the
# whole job, dem_server included, within 10 s, and ./run must exit non-zero.
# Usage: mpi_transport.sh SOURCE_DIR BUILD_DIR [END]
set -uo pipefail
src=$1 build=$2 end=${3:-0.05}
work=$(mktemp -d /tmp/demfem_mpi_transport_XXXXXX)
trap 'rm -rf "$work"' EXIT
export DEMFEM_NO_BUILD=1 DEMFEM_BUILD_DIR=$build
scene=$src/tests/coupling/scenes/tire_window.cfg
hashes() { # LOG: "DEM FEM" final hashes
  local dem fem
  dem=$(sed -n 's/.*final state: dem_world_hash \([0-9a-f]*\).*/\1/p' "$1" | head -n 1)
  fem=$(sed -n 's/.*final state: fem_state_hash \([0-9a-f]*\).*/\1/p' "$1" | head -n 1)
  [ -n "$dem" ] && [ -n "$fem" ] && echo "$dem $fem"
}
run() { # NAME [./run options]
  local name=$1; shift
  "$src/run" "$scene" --out "$work/$name" --set run.end_time="$end" --set coupling.stall_timeout=60 "$@" \
    > "$work/$name.log" 2>&1 || { cat "$work/$name.log"; echo "$name: the coupled run failed"; exit 1; }
  hashes "$work/$name.log" > "$work/$name.hash" || { cat "$work/$name.log"; echo "$name: no final hashes logged"; exit 1; }
}
run ring
echo "ring: $(cat "$work/ring.hash")"
for n in 1 2; do
  name=mpi$n
  run $name --transport mpi --ranks $n
  echo "MPI, dem_server on $n rank(s): $(cat "$work/$name.hash")"
  grep -q 'waiting for dem_server on mpi' "$work/$name.log" && grep -q 'attaching to mpi' "$work/$name.log" ||
    { cat "$work/$name.log"; echo "$name: the servers did not speak over MPI"; exit 1; }
  cmp "$work/ring.hash" "$work/$name.hash" || { echo "$name: the final states differ from the ring's"; exit 1; }
  "$src/tests/coupling/same_results.sh" "$work/ring" "$work/$name" || exit 1
done
[ "$(grep -c 'rank [01] of 2' "$work/mpi2.log")" -ge 2 ] || { echo "mpi2: dem_server did not run on 2 ranks"; exit 1; }

# fem_server killed in an MPMD job: nothing may hang
"$src/run" "$scene" --out "$work/kill" --set run.end_time=1.0 --set coupling.stall_timeout=60 --transport mpi \
  > "$work/kill.log" 2>&1 &
launcher=$!
for _ in $(seq 1200); do # up to 120 s for the job to exchange (a loaded machine)
  grep -q 'surface: .* from fem_server' "$work/kill.log" && break
  kill -0 $launcher 2>/dev/null || break
  sleep 0.1
done
grep -q 'surface: .* from fem_server' "$work/kill.log" || { cat "$work/kill.log"; echo "kill: the run never exchanged"; kill $launcher; exit 1; }
mpirun_pid=$(pgrep -P $launcher -x mpirun) && fem_pid=$(pgrep -P "$mpirun_pid" -x fem_server) &&
  dem_pid=$(pgrep -P "$mpirun_pid" -x dem_server) ||
  { echo "kill: no mpirun with fem_server and dem_server under ./run"; kill $launcher; exit 1; }
t0=$(date +%s.%N)
kill -9 "$fem_pid"
for _ in $(seq 300); do kill -0 $launcher 2>/dev/null || break; sleep 0.1; done
wait $launcher
rc=$?
took=$(echo "$(date +%s.%N) - $t0" | bc)
echo "fem_server killed: ./run exited $rc after $took s"
[ "$rc" -ne 0 ] || { cat "$work/kill.log"; echo "kill: ./run exited 0"; exit 1; }
state=$(awk '{print $3}' "/proc/$dem_pid/stat" 2>/dev/null); echo "dem_server state after: ${state:-gone}"; [ -z "$state" ] || [ "$state" = Z ] || { kill -9 "$dem_pid"; echo "kill: dem_server outlived the job"; exit 1; }
awk -v t="$took" 'BEGIN { exit !(t < 10) }' || { cat "$work/kill.log"; echo "kill: the job took $took s to end"; exit 1; }
echo "the MPI transport: same final states and result files as the ring for 1 and 2 DEM ranks; a killed fem_server ends the job"
