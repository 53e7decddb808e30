#!/usr/bin/env bash
# A short coupled run (tests/coupling/scenes/tire_small.cfg, 0.19 s) through ./run must end in
# the final states stored below, on any x86-64 machine: the servers are
# deterministic, ./run pins glibc's libm to its baseline (non-FMA) variants,
# and the bed is settled by this build (a cached bed of other code is refused).
# The stall timeout (not physics: the hashes do not depend on it) is raised
# so that a heavily loaded machine, where a heartbeat thread can go
# unscheduled for over a second, does not stop the run.
#
# Regenerate (print the hashes of this build) with
#   tests/repro/stored_hash.sh SOURCE_DIR BUILD_DIR --print
# It is legitimate to store new hashes only in a commit that changes the
# results on purpose (physics, integration order, a fixed bug, compiler
# flags), saying so in its message; never to make a failing CI pass when the
# change was meant to leave results alone.
set -uo pipefail
src=$1 build=$2 mode=${3:-check}
DEM_WANT=a3b7f971b88d967a
FEM_WANT=a36cfade91676f11
out=$(mktemp -d /tmp/demfem_repro_XXXXXX)
trap 'rm -rf "$out"' EXIT
DEMFEM_NO_BUILD=1 DEMFEM_BUILD_DIR=$build "$src/run" "$src/tests/coupling/scenes/tire_small.cfg" --out "$out/r" \
  --set coupling.stall_timeout=60 > "$out/log" 2>&1 \
  || { cat "$out/log"; echo "run failed"; exit 1; }
dem=$(sed -n 's/.*dem_world_hash \([0-9a-f]*\).*/\1/p' "$out/log")
fem=$(sed -n 's/.*fem_state_hash \([0-9a-f]*\).*/\1/p' "$out/log")
if [ "$mode" = --print ]; then echo "DEM_WANT=$dem"; echo "FEM_WANT=$fem"; exit 0; fi
echo "dem_world_hash $dem (stored $DEM_WANT), fem_state_hash $fem (stored $FEM_WANT)"
[ "$dem" = "$DEM_WANT" ] && [ "$fem" = "$FEM_WANT" ] || { echo "final state differs from the stored one"; exit 1; }
